"""Inside or outside, decided exactly: inside a mesh means |w| >= 1/2, w its generalised winding number.

The orientation of the faces does not matter: an inside-out closed mesh (w = -1 inside) is the same solid as the
outward one, a shell facing inward inside another leaves a cavity (w = 1 - 1 = 0), shells that overlap stay solid
(w = 2), and a flat sheet covered once encloses nothing (|w| < 1/2 off it; a curved open sheet does enclose a thin
sliver on its hollow side, where |w| passes 1/2 next to it).

Warp's fast winding number (Barill et al., accuracy ``WINDING_ACCURACY``) is off by up to ``FAST_WINDING_ERROR``
(measured): a point whose fast value is farther than that from +-1/2 is decided by it. The others are decided
exactly:

- a closed mesh (every edge cancels) has an integer winding number off its surface: the integer nearest the fast
  value (re-evaluated at ``ACCURATE_WINDING_ACCURACY`` when the fast value is not within ``INTEGER_SLACK`` of one);
- an open mesh is closed by the cones over its boundary's pieces (one triangle per boundary edge, see
  :func:`.meshcheck.hole_boundary`): w + W = k, W the cones' winding number (an exact sum over the boundary edges) and
  k an integer, the one nearest the fast value + W (checked the same way), so w = k - W up to float rounding.

On an open mesh the top-down pass also needs how w changes away from a node. Off the triangles w is smooth, and its
derivatives are integrals over the boundary edges alone: the gradient is the Biot-Savart field of the boundary
(Hessian: its derivative), both summed exactly with W, and the third derivatives are bounded by 6 / (4 pi) times the
sum over the edges of min(L / d^4, pi / (2 d^3)) (L an edge's length, d its distance from the ball considered: the
line integral of 6 / |y - x|^4). A node's expansion decides the points near it by Taylor's theorem, along segments
that cross no triangle, and certifies its whole cell when w keeps to one side of +-1/2 over it (:class:`ExpansionArg`,
:func:`sign_from_parent`). A boundary too long to sum at every such node (``MAX_BOUNDARY_EDGES``) leaves the open
mesh to the accurate fast winding number (mode ``WINDING_APPROXIMATE``); a flat open mesh, however often it covers
its plane (:func:`.meshcheck.encloses_nothing`), is outside everywhere (mode ``WINDING_NONE``).
"""

from __future__ import annotations

import numpy as np
import warp as wp

from .geometry import CROSSINGS_UNKNOWN, segment_crossings, winding_number
from .octree import node_center

# Fast winding number accuracy (Barill et al.'s beta): 1 is 3x faster than Warp's default 2 near the surface.
WINDING_ACCURACY = 1.0


# ... and how far its value may be from the exact one: at most 0.24 measured (node centres and points around every
# test mesh at diagonal / 256 and / 512, against the exact sum over all triangles; p99 0.10).
FAST_WINDING_ERROR = 0.35


# The accuracy of the re-evaluation when the fast value is not within INTEGER_SLACK of the integer it should be near
# (measured error at most 0.006, p99 0.004).
ACCURATE_WINDING_ACCURACY = 2.0


INTEGER_SLACK = 0.25


# Float rounding of an exact winding number (float32 sums over the boundary: at most 6.7e-5 measured on the beetle's
# 345 edges, p99 2.8e-6; the largest next to the lines from a cone's apex to the boundary, where two cone triangles'
# terms cancel): a point whose |w| is within this of 1/2 counts as outside, and nothing is decided with less margin.
WINDING_ROUNDING = 3.0e-4


# The most boundary edges (with multiplicity) summed exactly at a node; beyond them an open mesh is left to the
# accurate fast winding number.
MAX_BOUNDARY_EDGES = 8192


# What is known of a mesh's winding number: integer off the surface (closed), exact through the boundary's cones
# (open), only as accurate as Warp's fast winding number (open, boundary beyond MAX_BOUNDARY_EDGES), or below 1/2
# everywhere (nothing enclosed).
WINDING_CLOSED, WINDING_EXACT, WINDING_APPROXIMATE, WINDING_NONE = 0, 1, 2, 3


_FOUR_PI = 12.566370614359172


# Bound of |D^3 w| when a ball reaches a boundary edge (no Taylor step there).
NO_BOUND = 1.0e30


# A coarse node its anchor decides is expanded all the same when the anchor's expansion would leave this many of its
# children undecided (finest children: each pays a winding number; coarse ones: an expansion, about twice that): its
# own expansion, nearer, decides most of them (Taylor's remainder grows with the cube of the distance).
EXPAND_FOR_FINEST = 3


EXPAND_FOR_COARSE = 2


# The top level expands a lattice of seeds (every other node along each axis) whose expansions reach this many cells:
# a node's seed is at most a diagonal (1.73 cells) away, and its cell half a diagonal further.
SEED_REACH = 2.6


@wp.struct
class WindingArg:
    """What a kernel needs to decide inside or outside of a mesh: its BVH (with winding number support), how its
    winding number is known (``mode``) and, for an open mesh, its boundary edges (start, end, length, 1 / length^2)
    in cycles, their cones' apexes and how each edge links to the one before it (:func:`.meshcheck.hole_boundary`;
    empty arrays for a closed mesh)."""

    mesh: wp.uint64
    mode: int
    start: wp.array[wp.vec3]
    end: wp.array[wp.vec3]
    length: wp.array[wp.float32]
    inv_length2: wp.array[wp.float32]
    apex: wp.array[wp.vec3]
    links: wp.array[wp.uint8]


@wp.struct
class ExpansionArg:
    """Per coarse node (node ``first + j`` in row ``j``): ``cert`` 1 when w keeps one side of +-1/2 over its whole
    cell (its descendants take its sign), ``anchor``, the node whose expansion decided it (itself when expanded, -1:
    none), and ``jumps``, what w gains through triangles from the anchor to it. An expanded node keeps its centre
    ``at``, ``w``, ``grad``, ``hess`` and bounds of |D^3 w| within ``inner`` of it (its children's distance,
    ``d3_child``) and within ``reach`` (at least its cell's radius, ``d3_cell``)."""

    first: int
    cert: wp.array[wp.uint8]
    anchor: wp.array[wp.int32]
    jumps: wp.array[wp.int32]
    at: wp.array[wp.vec3]
    inner: wp.array[wp.float32]
    reach: wp.array[wp.float32]
    w: wp.array[wp.float32]
    grad: wp.array[wp.vec3]
    hess: wp.array[wp.mat33]
    d3_child: wp.array[wp.float32]
    d3_cell: wp.array[wp.float32]


def winding_arg(mesh: wp.Mesh, boundary, device, *, encloses: bool = True) -> WindingArg:
    """What the sign kernels need of a mesh.

    Args:
        mesh: ``wp.Mesh`` of the mesh, built with ``support_winding_number=True``.
        boundary: Its :func:`.meshcheck.hole_boundary` (None for a closed mesh).
        device: Warp device of the mesh.
        encloses: False when the mesh surely encloses nothing (:func:`.meshcheck.encloses_nothing`).
    Returns:
        :class:`WindingArg`, in mode WINDING_CLOSED, WINDING_EXACT, WINDING_APPROXIMATE (more boundary edges than
        ``MAX_BOUNDARY_EDGES``) or WINDING_NONE.
    """
    arg = WindingArg()
    arg.mesh = mesh.id
    arg.mode = WINDING_CLOSED
    start = end = apex = np.zeros((0, 3), np.float32)
    links = np.zeros(0, np.uint8)
    if not encloses:
        arg.mode = WINDING_NONE
    elif boundary is not None:
        arg.mode = WINDING_EXACT
        if len(boundary["links"]) > MAX_BOUNDARY_EDGES:
            arg.mode = WINDING_APPROXIMATE
        else:
            start, end, apex, links = boundary["start"], boundary["end"], boundary["apex"], boundary["links"]
    arg.start = wp.array(start, dtype=wp.vec3, device=device)
    arg.end = wp.array(end, dtype=wp.vec3, device=device)
    length = np.linalg.norm(np.asarray(end, np.float64) - start, axis=1)
    arg.length = wp.array(length.astype(np.float32), dtype=wp.float32, device=device)
    inv_length2 = 1.0 / np.maximum(length * length, 1e-30)
    arg.inv_length2 = wp.array(inv_length2.astype(np.float32), dtype=wp.float32, device=device)
    arg.apex = wp.array(apex, dtype=wp.vec3, device=device)
    arg.links = wp.array(links, dtype=wp.uint8, device=device)
    return arg


def expansion_arg(first: int, count: int, device) -> ExpansionArg:
    """Room for the expansions of a field's coarse nodes.

    Args:
        first: Index of the first coarse node (the finest level's node count).
        count: How many coarse nodes (0 when no expansion is needed: a closed mesh).
        device: Warp device.
    Returns:
        :class:`ExpansionArg` with ``count`` rows, none certified, none expanded (anchor -1).
    """
    arg = ExpansionArg()
    arg.first = int(first)
    arg.cert = wp.zeros(count, dtype=wp.uint8, device=device)
    arg.anchor = wp.full(count, -1, dtype=wp.int32, device=device)
    arg.jumps = wp.zeros(count, dtype=wp.int32, device=device)
    for name in ("inner", "reach", "w", "d3_child", "d3_cell"):
        setattr(arg, name, wp.zeros(count, dtype=wp.float32, device=device))
    arg.at = wp.zeros(count, dtype=wp.vec3, device=device)
    arg.grad = wp.zeros(count, dtype=wp.vec3, device=device)
    arg.hess = wp.zeros(count, dtype=wp.mat33, device=device)
    return arg


# ---- winding numbers ----


@wp.func
def _turn(re: float, im: float, det: float, den: float):
    """(re, im) times (den, det), scaled back to a unit 1-norm: the arguments of a product add up, so the product of
    the cone triangles' (den, det) turns by half their solid angles (mod 2 pi) with one atan2 in all."""
    r = re * den - im * det
    i = re * det + im * den
    scale = wp.abs(r) + wp.abs(i)
    if scale > 0.0:
        inv = 1.0 / scale
        return r * inv, i * inv
    return re, im


@wp.func
def _cone_winding(f: WindingArg, x: wp.vec3) -> float:
    """W mod 1: the winding number at ``x`` of the cones that close an open mesh, up to an integer (which the
    integer k of w = k - W absorbs). Cone triangle (apex, end, start) of each edge: solid angle 2 atan2(det, den)
    (Van Oosterom and Strackee), with the terms of a vertex or an apex shared along a cycle."""
    re = float(1.0)
    im = float(0.0)
    r1 = wp.vec3(0.0)
    l1 = float(0.0)
    ra = wp.vec3(0.0)
    la = float(0.0)
    for e in range(f.links.shape[0]):
        link = int(f.links[e])
        if (link & 1) == 0:
            r1 = f.start[e] - x
            l1 = wp.length(r1)
        if (link & 2) == 0:
            ra = f.apex[e] - x
            la = wp.length(ra)
        r2 = f.end[e] - x
        l2 = wp.length(r2)
        det = -wp.dot(ra, wp.cross(r1, r2))
        den = la * l1 * l2 + wp.dot(ra, r2) * l1 + wp.dot(r1, r2) * la + wp.dot(r1, ra) * l2
        re, im = _turn(re, im, det, den)
        r1 = r2
        l1 = l2
    return wp.atan2(im, re) / (2.0 * wp.pi)


@wp.func
def _nearest_integer(f: WindingArg, x: wp.vec3, fast: float, shift: float) -> float:
    """The integer nearest ``fast + shift`` (``fast`` the fast winding number at ``x``), taken from an accurate
    re-evaluation when that sum is not within INTEGER_SLACK of one."""
    s = fast + shift
    k = wp.floor(s + 0.5)
    if wp.abs(s - k) > INTEGER_SLACK:
        k = wp.floor(winding_number(f.mesh, x, ACCURATE_WINDING_ACCURACY) + shift + 0.5)
    return k


@wp.func
def _off_cones(f: WindingArg, x: wp.vec3, fast: float, cones: float) -> float:
    """w = k - ``cones`` (the cones' winding number mod 1 at ``x``), k the integer nearest ``fast`` + ``cones``, from
    an accurate re-evaluation when that is not within INTEGER_SLACK of one. Where even that is not, ``x`` lies on a
    cone (a node in a planar hole, on the edge between two of its cone's triangles: their solid angles' signs are
    either side's, and the cones read 0 for 1/2: w came out 1 at the middle of an open box's missing face, inside, and
    Taylor's theorem spread that to the nodes about it): the accurate winding number itself."""
    s = fast + cones
    k = wp.floor(s + 0.5)
    if wp.abs(s - k) <= INTEGER_SLACK:
        return k - cones
    accurate = winding_number(f.mesh, x, ACCURATE_WINDING_ACCURACY)
    s = accurate + cones
    k = wp.floor(s + 0.5)
    if wp.abs(s - k) <= INTEGER_SLACK:
        return k - cones
    return accurate


@wp.func
def exact_winding(f: WindingArg, x: wp.vec3, fast: float) -> float:
    """The winding number at ``x`` (``fast``: its fast value there), exact up to float rounding (approximate in mode
    WINDING_APPROXIMATE, and on an open mesh's cones: :func:`_off_cones`)."""
    if f.mode == WINDING_CLOSED:
        return _nearest_integer(f, x, fast, 0.0)
    if f.mode == WINDING_EXACT:
        return _off_cones(f, x, fast, _cone_winding(f, x))
    return winding_number(f.mesh, x, ACCURATE_WINDING_ACCURACY)


@wp.func
def inside_margin(w: float) -> float:
    """How far ``w`` is from the nearer of +-1/2 (how much it may change before the side does)."""
    return wp.abs(wp.abs(w) - 0.5)


@wp.func
def side_of(w: float) -> float:
    """-1 inside (|w| >= 1/2, beyond float rounding), 1 outside."""
    return wp.where(wp.abs(w) >= 0.5 + WINDING_ROUNDING, -1.0, 1.0)


@wp.func
def inside_sign(f: WindingArg, x: wp.vec3) -> float:
    """-1 where the mesh's winding number at ``x`` is at least 1/2 in absolute value, 1 elsewhere: the fast value
    where it is farther than FAST_WINDING_ERROR from +-1/2, the exact one elsewhere."""
    if f.mode == WINDING_NONE:
        return 1.0
    fast = winding_number(f.mesh, x, WINDING_ACCURACY)
    if inside_margin(fast) >= FAST_WINDING_ERROR:
        return wp.where(wp.abs(fast) > 0.5, -1.0, 1.0)
    return side_of(exact_winding(f, x, fast))


@wp.func
def _d3_term(length: float, d: float) -> float:
    """Bound of one boundary edge's share of |D^3 w| (times 4 pi / 6) at distance ``d`` or more from it."""
    if d <= 0.0:
        return NO_BOUND
    q = 1.0 / d
    return q * q * q * wp.min(length * q, 0.5 * wp.pi)


@wp.func
def winding_expansion(f: WindingArg, x: wp.vec3, near: float, far: float):
    """(w, grad w, Hessian of w, bound of |D^3 w| within ``near`` of ``x``, the same within ``far``) of an open mesh
    in mode WINDING_EXACT at ``x`` off its triangles: one pass over the boundary edges gives the cones' winding number,
    the Biot-Savart field f (r1 x r2) of each edge (r1, r2 from ``x`` to its ends, f = (l1 + l2) / (l1 l2 P), P = l1 l2
    + r1 . r2), its derivative f [E]x + (f r1 x r2) (grad ln f)^T (E = r2 - r1, [E]x its cross-product matrix; grad ln
    f = u1 (1/l1 - 1/(l1 + l2) + l2/P) + u2 (1/l2 - 1/(l1 + l2) + l1/P) + (r1 + r2)/P, u = r/l) and the edges'
    distances."""
    re = float(1.0)
    im = float(0.0)
    grad = wp.vec3(0.0)
    spin = wp.vec3(0.0)  # sum of f E: the cross-product matrices' share of the Hessian
    hess = wp.mat33(0.0)
    d3_near = float(0.0)
    d3_far = float(0.0)
    r1 = wp.vec3(0.0)
    l1 = float(0.0)
    il1 = float(0.0)
    ra = wp.vec3(0.0)
    la = float(0.0)
    for e in range(f.links.shape[0]):
        link = int(f.links[e])
        if (link & 1) == 0:
            r1 = f.start[e] - x
            l1 = wp.length(r1)
            il1 = 1.0 / wp.max(l1, 1.0e-30)
        if (link & 2) == 0:
            ra = f.apex[e] - x
            la = wp.length(ra)
        r2 = f.end[e] - x
        l2 = wp.length(r2)
        il2 = 1.0 / wp.max(l2, 1.0e-30)
        cr = wp.cross(r1, r2)
        d12 = wp.dot(r1, r2)
        det = -wp.dot(ra, cr)
        den = la * l1 * l2 + wp.dot(ra, r2) * l1 + d12 * la + wp.dot(r1, ra) * l2
        re, im = _turn(re, im, det, den)
        edge = r2 - r1
        pair = l1 * l2 + d12
        if pair > 0.0:
            ipair = 1.0 / pair
            isum = 1.0 / (l1 + l2)
            fac = (l1 + l2) * il1 * il2 * ipair
            field = fac * cr
            grad += field
            spin += fac * edge
            g = (r1 * il1) * (il1 - isum + l2 * ipair) + (r2 * il2) * (il2 - isum + l1 * ipair) + (r1 + r2) * ipair
            hess += wp.outer(field, g)
        length = f.length[e]
        along = wp.clamp(-wp.dot(r1, edge) * f.inv_length2[e], 0.0, 1.0)
        d = wp.length(r1 + along * edge)
        d3_near += _d3_term(length, d - near)
        d3_far += _d3_term(length, d - far)
        r1 = r2
        l1 = l2
        il1 = il2
    hess += wp.mat33(0.0, -spin[2], spin[1], spin[2], 0.0, -spin[0], -spin[1], spin[0], 0.0)
    cones = wp.atan2(im, re) / (2.0 * wp.pi)
    w = _off_cones(f, x, winding_number(f.mesh, x, WINDING_ACCURACY), cones)
    scale = 1.0 / _FOUR_PI
    return w, scale * grad, scale * hess, 6.0 * scale * d3_near, 6.0 * scale * d3_far


@wp.func
def _taylor(e: ExpansionArg, j: int, delta: wp.vec3) -> float:
    """The expansion of row ``j`` at ``delta`` from its centre: w + grad . delta + delta^T hess delta / 2."""
    return e.w[j] + wp.dot(e.grad[j], delta) + 0.5 * wp.dot(delta, e.hess[j] * delta)


@wp.func
def _spread_bound(e: ExpansionArg, j: int, radius: float, far: float) -> float:
    """How much w may move within ``radius`` of a point at most ``far`` from the centre of row ``j``'s expansion
    (the ball within its reach): |grad + hess delta| radius + |hess| radius^2 / 2 + |D^3 w| far^3 / 6, with |hess|
    bounded by its Frobenius norm."""
    h = e.hess[j]
    norm = wp.sqrt(wp.ddot(h, h))
    first = (wp.length(e.grad[j]) + norm * (far - radius)) * radius
    return first + 0.5 * norm * radius * radius + e.d3_cell[j] * far * far * far / 6.0


# ---- kernels ----


@wp.kernel(enable_backward=False)
def mesh_sign_kernel(
    f: WindingArg,
    coords: wp.array[wp.vec3i],
    nodes: wp.array[wp.int32],
    origin: wp.vec3,
    spacing: float,
    sign: wp.array[wp.float32],
):
    """Sign oracle of nodes ``nodes[tid]`` (their lattice of edge ``spacing``): -1 where |w| >= 1/2, whatever the
    orientation (robust on open and multi-shell meshes, :func:`inside_sign`)."""
    i = nodes[wp.tid()]
    sign[i] = inside_sign(f, node_center(origin, spacing, coords[i]))


@wp.kernel(enable_backward=False)
def expand_winding_kernel(
    f: WindingArg,
    coords: wp.array[wp.vec3i],
    nodes: wp.array[wp.int32],
    origin: wp.vec3,
    spacing: float,
    reach: float,
    dist: wp.array[wp.float32],
    safety: float,
    sign: wp.array[wp.float32],
    e: ExpansionArg,
):
    """Sign and expansion of coarse nodes ``nodes[tid]`` of an open mesh (mode WINDING_EXACT), with |D^3 w| bounded
    over the ball of its children's centres (``d3_child``) and over ``reach`` (at least its cell's radius; more for
    the top level's seeds, whose expansions decide their neighbours: ``d3_cell``); a node whose empty ball (``dist``
    times ``safety``) holds its cell and whose w keeps one side of +-1/2 over it is certified."""
    i = nodes[wp.tid()]
    x = node_center(origin, spacing, coords[i])
    cell = 0.8660254 * spacing
    inner = 0.4331 * spacing  # a child's centre is 0.4330 cells away
    w, g, h, d3_child, d3_cell = winding_expansion(f, x, inner, reach)
    sign[i] = side_of(w)
    j = i - e.first
    e.anchor[j] = i
    e.jumps[j] = 0
    e.at[j] = x
    e.inner[j] = inner
    e.reach[j] = reach
    e.w[j] = w
    e.grad[j] = g
    e.hess[j] = h
    e.d3_child[j] = d3_child
    e.d3_cell[j] = d3_cell
    if dist[i] * safety > cell and inside_margin(w) > WINDING_ROUNDING + _spread_bound(e, j, cell, cell):
        e.cert[j] = wp.uint8(1)


@wp.kernel(enable_backward=False)
def take_known_expansion_kernel(
    start: int, where: wp.array[wp.int32], renumber: wp.array[wp.int32], before: ExpansionArg, now: ExpansionArg
):
    """Coarse node ``now.first + start + tid`` found in an earlier build (``where``: its index there) takes its
    certificate, its anchor (``renumber``: each earlier node's index now) and its expansion."""
    j = start + wp.tid()
    k = where[now.first + j] - before.first
    if k < 0:
        return
    now.cert[j] = before.cert[k]
    a = before.anchor[k]
    if a >= 0:
        a = renumber[a]
    now.anchor[j] = a
    now.jumps[j] = before.jumps[k]
    now.at[j] = before.at[k]
    now.inner[j] = before.inner[k]
    now.reach[j] = before.reach[k]
    now.w[j] = before.w[k]
    now.grad[j] = before.grad[k]
    now.hess[j] = before.hess[k]
    now.d3_child[j] = before.d3_child[k]
    now.d3_cell[j] = before.d3_cell[k]


@wp.func
def _sign_from_anchor(
    i: int, a: int, jumps: int, xi: wp.vec3, radius: float, empty: bool, e: ExpansionArg, coarse_children: int
) -> float:
    """The sign node ``i`` (centre ``xi``, cell radius ``radius``) takes from the expansion of node ``a`` (what w
    gains through triangles on the way: ``jumps``), or 0: Taylor's theorem holds for w's smooth part, as no boundary
    edge reaches the expansion's ball. A coarse node takes ``a`` for its anchor, and is certified when the expansion
    keeps w on one side of +-1/2 over its whole cell (within ``reach`` of ``a``, whose ball holds no triangle when
    ``empty``), or left to its own expansion when that would decide more of its children (see
    ``EXPAND_FOR_FINEST``; they are coarse when ``coarse_children`` is 1)."""
    ja = a - e.first
    delta = xi - e.at[ja]
    s = wp.length(delta)
    coarse = i >= e.first
    # the bounds hold within reach: of the node, or for a coarse node (an anchor for its descendants) of its cell
    if s + wp.where(coarse, radius, 0.0) > e.reach[ja]:
        return 0.0
    d3 = wp.where(s <= e.inner[ja], e.d3_child[ja], e.d3_cell[ja])
    w = _taylor(e, ja, delta) + float(jumps)
    if inside_margin(w) <= WINDING_ROUNDING + d3 * s * s * s / 6.0:
        return 0.0
    if coarse:
        j = i - e.first
        if empty and inside_margin(w) > WINDING_ROUNDING + _spread_bound(e, ja, radius, s + radius):
            e.cert[j] = wp.uint8(1)
        elif _children_left(e, ja, delta, radius) >= wp.where(
            coarse_children == 1, EXPAND_FOR_COARSE, EXPAND_FOR_FINEST
        ):
            return 0.0
        e.anchor[j] = a
        e.jumps[j] = jumps
    return side_of(w)


@wp.func
def sign_from_parent(
    f: WindingArg,
    i: int,
    p: int,
    xi: wp.vec3,
    xp: wp.vec3,
    radius: float,
    dist: wp.array[wp.float32],
    sign: wp.array[wp.float32],
    safety: float,
    e: ExpansionArg,
    coarse_children: int,
) -> float:
    """The sign node ``i`` (centre ``xi``, cell radius ``radius``) of an open mesh takes from its parent ``p`` (centre
    ``xp``), or 0 when that cannot be proven: the parent's whole cell is certified, or Taylor's theorem on the
    expansion that decided the parent (its anchor's, see :class:`ExpansionArg`) keeps w on one side of +-1/2 at
    ``xi`` (:func:`_sign_from_anchor`). w jumps by 1 through each triangle: the jumps are counted along the path
    anchor - parent - node (the parent's ``jumps``, then ``segment_crossings`` on the last leg unless the two nodes'
    empty balls cover it; none when the anchor's empty ball holds its whole reach)."""
    jp = p - e.first
    if e.cert[jp] == wp.uint8(1):
        if i >= e.first:
            e.cert[i - e.first] = wp.uint8(1)
        return sign[p]
    a = e.anchor[jp]
    if a < 0:
        return 0.0
    empty = dist[a] * safety > e.reach[a - e.first]
    jumps = int(0)
    if not empty:
        jumps = e.jumps[jp]
        if (dist[i] + dist[p]) * safety <= radius:  # the leg from the parent: a quarter of its diagonal
            leg = segment_crossings(f.mesh, xp, xi)
            if leg == CROSSINGS_UNKNOWN:
                return 0.0
            jumps += leg
    return _sign_from_anchor(i, a, jumps, xi, radius, empty, e, coarse_children)


@wp.kernel(enable_backward=False)
def sign_from_seed_kernel(
    f: WindingArg,
    coords: wp.array[wp.vec3i],
    top_lo: int,
    start: int,
    top_dims: wp.vec3i,
    origin: wp.vec3,
    spacing: float,
    dist: wp.array[wp.float32],
    safety: float,
    sign: wp.array[wp.float32],
    e: ExpansionArg,
    coarse_children: int,
):
    """Top-level node ``top_lo + start + tid`` takes its sign from the expansion of the seed at its coordinates
    rounded down to even ones (at most a diagonal away; seeds reach ``SEED_REACH`` cells), along a segment whose
    triangle crossings are counted unless the two empty balls cover it (:func:`_sign_from_anchor`)."""
    i = top_lo + start + wp.tid()
    if sign[i] != 0.0:
        return
    c = coords[i]
    cs = wp.vec3i(c[0] - c[0] % 2, c[1] - c[1] % 2, c[2] - c[2] % 2)
    a = top_lo + cs[0] + top_dims[0] * (cs[1] + top_dims[1] * cs[2])
    ja = a - e.first
    if a == i or e.anchor[ja] != a:
        return
    xi = node_center(origin, spacing, c)
    empty = dist[a] * safety > e.reach[ja]
    jumps = int(0)
    if not empty and (dist[i] + dist[a]) * safety <= wp.length(xi - e.at[ja]):
        jumps = segment_crossings(f.mesh, e.at[ja], xi)
        if jumps == CROSSINGS_UNKNOWN:
            return
    sign[i] = _sign_from_anchor(i, a, jumps, xi, 0.8660254 * spacing, empty, e, coarse_children)


@wp.func
def _children_left(e: ExpansionArg, ja: int, delta: wp.vec3, radius: float) -> int:
    """How many children of a node at ``delta`` from the centre of row ``ja``'s expansion (cell radius ``radius``)
    that expansion would leave undecided (their crossings aside)."""
    left = int(0)
    step = 0.28867513 * radius  # a child's centre is a quarter cell (radius / (4 * 0.866)) away along each axis
    for k in range(8):
        d = delta + step * wp.vec3(float(2 * (k & 1) - 1), float((k & 2) - 1), float(((k >> 1) & 2) - 1))
        s = wp.length(d)
        if inside_margin(_taylor(e, ja, d)) <= WINDING_ROUNDING + e.d3_cell[ja] * s * s * s / 6.0:
            left += 1
    return left
