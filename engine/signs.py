"""Signs of a mesh's field, top-down: inside means |w| >= 1/2, w the generalised winding number (:mod:`.winding`).

A node takes its parent's or a same-level neighbour's sign when their empty balls (unsigned distances) cover the
segment between them, or when that segment crosses no triangle: away from an open mesh's holes, where w stays within
1/4 of an integer that changes only across triangles (:func:`.meshcheck.hole_caps`). Near the holes a node takes its
parent's sign only when the parent proves it (:func:`.winding.sign_from_parent`: the parent's cell certified, or
Taylor's theorem on the parent's expansion of w). Only nodes left undecided pay the winding number
(:func:`.winding.mesh_sign_kernel`, or :func:`.winding.expand_winding_kernel` for the coarse nodes of an open mesh):
a lattice of seeds on the dense top level, a few nodes next to the surface, and the nodes near the holes whose
parents could not decide them.
"""

from __future__ import annotations

import time

import numpy as np
import warp as wp

from . import octree
from .geometry import near_cap, segment_clear
from .octree import node_center
from .parallel import EMIT_SPLIT_MIN_DIM, launch_split
from .winding import (
    SEED_REACH,
    WINDING_EXACT,
    WINDING_NONE,
    ExpansionArg,
    WindingArg,
    expand_winding_kernel,
    expansion_arg,
    mesh_sign_kernel,
    sign_from_parent,
    sign_from_seed_kernel,
    take_known_expansion_kernel,
)

# Two empty balls prove a segment crosses no surface when their radii, times this, cover it: the margin allows for
# float rounding and for the top level's leaf values, up to LEAF_TOLERANCE above their distances ((1 + 0.05) * 0.9
# = 0.945 < 1).
SIGN_SAFETY = 0.9


# Sweeps of same-level sign propagation, and the stride along each axis of the oracle's seeds on the dense top level
# (a lattice through the whole volume, so every region larger than a few top cells, inside or out, holds one).
MAX_SIGN_SWEEPS = 64


TOP_SEED_STRIDE = 4


# A sweep of the empty-ball phase that signs fewer than this share of a level's nodes ends it (another sweep over the
# whole level would sign a handful; the next phase takes them).
SIGN_SWEEP_SETTLED = 1e-3


@wp.func
def _take_sign(i: int, j: int, dist: wp.array[wp.float32], sign: wp.array[wp.float32], safety: float, spacing: float):
    """Give unsigned node ``i`` the sign of face neighbour ``j`` when their empty balls cover the edge between them."""
    if sign[j] != 0.0 and (dist[i] + dist[j]) * safety > spacing:
        sign[i] = sign[j]
        return 1
    return 0


@wp.func
def _take_sign_across(
    i: int,
    j: int,
    dist: wp.array[wp.float32],
    sign: wp.array[wp.float32],
    safety: float,
    spacing: float,
    mesh: wp.uint64,
    x: wp.vec3,
    y: wp.vec3,
):
    """``_take_sign``, or with a mesh (``mesh`` != 0) also when the segment between the nodes (at ``x`` and ``y``)
    surely crosses no triangle: away from an open mesh's holes the winding number changes only across triangles."""
    if _take_sign(i, j, dist, sign, safety, spacing) == 1:
        return 1
    if mesh != wp.uint64(0) and sign[j] != 0.0:
        if segment_clear(mesh, x, y):
            sign[i] = sign[j]
            return 1
    return 0


@wp.kernel(enable_backward=False)
def _propagate_sign_kernel(
    neighbours: wp.array2d[wp.int32],
    row0: int,
    lo: int,
    dist: wp.array[wp.float32],
    sign: wp.array[wp.float32],
    safety: float,
    spacing: float,
    coords: wp.array[wp.vec3i],
    origin: wp.vec3,
    cap_lo: wp.array[wp.vec3],
    cap_hi: wp.array[wp.vec3],
    cap_radius: wp.array[wp.float32],
    mesh: wp.uint64,
    changed: wp.array[wp.int32],
    span: int,
    reverse: int,
):
    """An unsigned node takes a signed face neighbour's sign when their empty balls cover the edge between them, or
    with a mesh (``mesh`` != 0) when the segment between them crosses no triangle. Signs only ever go from 0 to
    final, so sweeps may read and write in place (a sign travels along the launch's order within one sweep: sweeps
    alternate ``reverse``). Not near an open mesh's holes (see ``hole_caps``). Node ``i``'s neighbours are in row
    ``i - row0``; the launch covers nodes [lo, lo + span)."""
    i = lo + wp.where(reverse == 1, span - 1 - wp.tid(), wp.tid())
    if sign[i] != 0.0:
        return
    x = node_center(origin, spacing, coords[i])
    if near_cap(x, cap_lo, cap_hi, cap_radius, spacing):
        return
    faces = int(6)  # not unrolled: one copy of the segment test (compile time)
    for k in range(faces):
        j = neighbours[i - row0, k]
        if j >= 0:
            y = node_center(origin, spacing, coords[j])
            if _take_sign_across(i, j, dist, sign, safety, spacing, mesh, x, y) == 1:
                wp.atomic_add(changed, 0, 1)
                return


@wp.kernel(enable_backward=False)
def _propagate_sign_octet_kernel(
    first: int,
    codes: wp.array[wp.int64],
    parent: wp.array[wp.int32],
    child: wp.array[wp.int32],
    neighbours: wp.array2d[wp.int32],
    row0: int,
    dist: wp.array[wp.float32],
    sign: wp.array[wp.float32],
    safety: float,
    spacing: float,
    origin: wp.vec3,
    cap_lo: wp.array[wp.vec3],
    cap_hi: wp.array[wp.vec3],
    cap_radius: wp.array[wp.float32],
    mesh: wp.uint64,
    changed: wp.array[wp.int32],
    span: int,
    reverse: int,
):
    """The same on the finest level, which has no neighbour table: one thread per octet (8 consecutive nodes in
    Morton order; the launch covers octets [first, first + span)). Three face neighbours of a node are in its own
    octet; the other three are the same child of the face-adjacent octets: the children of the octet's level-1 node's
    face neighbour (``neighbours``, node ``i`` in row ``i - row0``), when it has any. With a
    mesh (``mesh`` != 0) a node also takes the sign of a neighbour when the segment between them crosses no triangle
    (``_take_sign_across``), which signs most of the nodes too near the surface for empty balls without a winding
    number."""
    t = first + wp.where(reverse == 1, span - 1 - wp.tid(), wp.tid())
    base = 8 * t
    unset = int(0)
    for k in range(8):
        if sign[base + k] == 0.0:
            unset += 1
    if unset == 0:
        return
    octet = octree.morton_decode(codes[base] >> wp.int64(3))
    centre = origin + 2.0 * spacing * wp.vec3(float(octet[0]) + 0.5, float(octet[1]) + 0.5, float(octet[2]) + 0.5)
    if near_cap(centre, cap_lo, cap_hi, cap_radius, 2.0 * spacing):
        return
    # first node of the octet across each face (-x, +x, -y, +y, -z, +z); -2: not looked up yet
    across = wp.vector(-2, -2, -2, -2, -2, -2, length=6, dtype=int)
    got = int(0)
    # loop bounds held in variables keep Warp from unrolling 2 x 8 x 3 copies of the segment test (compile time)
    sweeps = int(2)
    nodes = int(8)
    axes = int(3)
    for _sweep in range(sweeps):
        for k in range(nodes):
            i = base + k
            if sign[i] == 0.0:
                x = centre + spacing * wp.vec3(float(k & 1) - 0.5, float((k >> 1) & 1) - 0.5, float((k >> 2) & 1) - 0.5)
                for a in range(axes):
                    bit = (k >> a) & 1
                    step = wp.vec3(0.0)
                    step[a] = wp.where(bit == 0, spacing, -spacing)
                    if sign[i] == 0.0:
                        got += _take_sign_across(
                            i, base + (k ^ (1 << a)), dist, sign, safety, spacing, mesh, x, x + step
                        )
                    if sign[i] == 0.0:
                        bit = (k >> a) & 1
                        face = 2 * a + bit
                        if across[face] == -2:
                            # the octet's level-1 node's neighbour across the face, and its children if it has any
                            across[face] = -1
                            nb = neighbours[parent[base] - row0, face]
                            if nb >= 0:
                                across[face] = child[nb]
                        if across[face] >= 0:
                            got += _take_sign_across(
                                i, across[face] + (k ^ (1 << a)), dist, sign, safety, spacing, mesh, x, x - step
                            )
    if got > 0:
        wp.atomic_add(changed, 0, got)


@wp.kernel(enable_backward=False)
def _apply_sign_kernel(
    first: int, dist: wp.array[wp.float32], sign: wp.array[wp.float32], values: wp.array[wp.float32]
):
    i = first + wp.tid()
    s = sign[i]
    if s == 0.0:
        s = 1.0
    values[i] = s * dist[i]


# No boxes, in the form of :func:`hole_caps`' result.
NO_BOXES = (np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0))


def box_arrays(boxes, device) -> list:
    """Warp arrays (lo, hi, radius) of boxes in the form of :func:`hole_caps`' result (None: no boxes)."""
    lo, hi, radius = NO_BOXES if boxes is None else boxes
    return [
        wp.array(np.asarray(lo, np.float32).reshape(-1, 3), dtype=wp.vec3, device=device),
        wp.array(np.asarray(hi, np.float32).reshape(-1, 3), dtype=wp.vec3, device=device),
        wp.array(np.asarray(radius, np.float32).reshape(-1), dtype=wp.float32, device=device),
    ]


@wp.kernel(enable_backward=False)
def _take_known_sign_kernel(
    first: int, where: wp.array[wp.int32], prev_values: wp.array[wp.float32], sign: wp.array[wp.float32]
):
    """Node ``first + tid`` found in an earlier build takes its sign."""
    i = first + wp.tid()
    j = where[i]
    if j >= 0:
        sign[i] = wp.where(prev_values[j] < 0.0, -1.0, 1.0)


@wp.kernel(enable_backward=False)
def _inherit_sign_kernel(
    coords: wp.array[wp.vec3i],
    parent: wp.array[wp.int32],
    lo: int,
    origin: wp.vec3,
    spacing: float,
    dist: wp.array[wp.float32],
    sign: wp.array[wp.float32],
    safety: float,
    winding: WindingArg,
    exact: int,
    cap_lo: wp.array[wp.vec3],
    cap_hi: wp.array[wp.vec3],
    cap_radius: wp.array[wp.float32],
    expansions: ExpansionArg,
    coarse_children: int,
):
    """A node takes its parent's sign when the two empty balls around them cover the segment between them (no
    surface can cross it); otherwise its sign stays 0 (undecided) for the caller's oracle. Near an open mesh's holes
    (``near_cap``) a segment may cross the jump of the winding number over a hole without meeting a triangle: there,
    for a mesh whose winding number is known exactly (``exact`` 1: ``winding`` in mode WINDING_EXACT), the parent
    must prove the sign (``sign_from_parent``); otherwise (the fast winding number alone) empty balls are a heuristic,
    which the band refinement of open meshes checks where it matters."""
    i = lo + wp.tid()
    p = parent[i]
    if sign[i] != 0.0 or p < 0:  # already known (a node kept from an earlier build of the same mesh), or the top
        return
    xi = node_center(origin, spacing, coords[i])
    xp = node_center(origin, 2.0 * spacing, coords[p])
    s = wp.length(xi - xp)
    if exact == 1:
        if near_cap(xi, cap_lo, cap_hi, cap_radius, s) or expansions.cert[p - expansions.first] != wp.uint8(0):
            sign[i] = sign_from_parent(winding, i, p, xi, xp, s, dist, sign, safety, expansions, coarse_children)
            return
    if (dist[i] + dist[p]) * safety > s:
        sign[i] = sign[p]


@wp.kernel(enable_backward=False)
def _parent_segment_kernel(
    nodes: wp.array[wp.int32],
    coords: wp.array[wp.vec3i],
    parent: wp.array[wp.int32],
    origin: wp.vec3,
    spacing: float,
    sign: wp.array[wp.float32],
    mesh: wp.uint64,
    cap_lo: wp.array[wp.vec3],
    cap_hi: wp.array[wp.vec3],
    cap_radius: wp.array[wp.float32],
):
    """A finest node left unset takes its parent's sign where the segment between them surely crosses no triangle,
    away from an open mesh's holes (there the winding number jumps without a triangle)."""
    i = nodes[wp.tid()]
    p = parent[i]
    if p < 0 or sign[p] == 0.0:
        return
    xi = node_center(origin, spacing, coords[i])
    xp = node_center(origin, 2.0 * spacing, coords[p])
    if near_cap(xi, cap_lo, cap_hi, cap_radius, wp.length(xi - xp)):
        return
    if segment_clear(mesh, xi, xp):
        sign[i] = sign[p]


# ---- host side: the top-down pass ----


def _winding_signs(
    winding: WindingArg, layout: dict, nodes_np: np.ndarray, k: int, lattice, sign, expand, reach: float = 0.8661
) -> None:
    """The oracle: the sign of each of ``nodes_np`` (indices of level ``k``'s nodes) from the winding number, with
    the coarse nodes' expansions when ``expand`` is (dist, ExpansionArg), see :func:`.winding.expand_winding_kernel`
    (valid within ``reach`` cells: their own cell's radius and a little). ``lattice``: (origin vec3, finest voxel
    size)."""
    if len(nodes_np) == 0:
        return
    coords = layout["coords"]
    device = coords.device
    nodes = wp.array(nodes_np.astype(np.int32), dtype=wp.int32, device=device)
    spacing = float(lattice[1] * 2**k)
    kernel = mesh_sign_kernel if expand is None else expand_winding_kernel

    def args(lo, n):
        if expand is None:
            return [winding, coords, nodes[lo : lo + n], lattice[0], spacing, sign]
        return [
            winding,
            coords,
            nodes[lo : lo + n],
            lattice[0],
            spacing,
            reach * spacing,
            expand[0],
            SIGN_SAFETY,
            sign,
            expand[1],
        ]

    launch_split(
        kernel,
        len(nodes_np),
        args,
        device,
        min_dim=EMIT_SPLIT_MIN_DIM,  # a winding number costs microseconds: split from a few thousand
        balance=True,  # winding numbers cost most near holes, which a Morton-ordered list bunches
    )


def _take_known_expansions(previous, prev_index, known, expansions, nodes) -> None:
    """The coarse nodes (``nodes``: from n0 to n) an earlier build has take its expansions (``known``), in place."""
    n0, n = nodes
    where = prev_index.numpy()
    renumber = np.full(int(previous.node_count), -1, dtype=np.int32)
    renumber[where[where >= 0]] = np.flatnonzero(where >= 0)
    renumber_wp = wp.array(renumber, dtype=wp.int32, device=expansions.cert.device)
    launch_split(
        take_known_expansion_kernel,
        n - n0,
        lambda s, _n: [s, prev_index, renumber_wp, known, expansions],
        expansions.cert.device,
    )


def sign_levels(
    winding: WindingArg,
    layout: dict,
    dist,
    neighbours,
    *,
    origin,
    voxel_size: float,
    hole_caps=None,
    previous=None,
    prev_index=None,
    known=None,
    timings: dict,
    coarse_known: bool = False,
):
    """Sign every node of a mesh's field, top-down, and return its signed values.

    The top level from a lattice of oracle seeds, spread between neighbours; every lower level from its parents, then
    from already signed neighbours (empty balls, then segments that cross no triangle); the oracle (the winding
    number) only for what is left. Near an open mesh's holes nothing spreads between neighbours, and a node takes
    its parent's sign only when the parent proves it (:func:`.winding.sign_from_parent`).

    Args:
        winding: The mesh's :class:`.winding.WindingArg` (its BVH, built with winding-number support, and boundary).
        layout: Every node's place (:func:`.layout.level_layout`).
        dist: (N,) float32 unsigned distances of every node.
        neighbours: (N - N0, 6) same-level neighbours of the coarse nodes (:func:`.distance.solve_levels`).
        origin, voxel_size: The field's lattice.
        hole_caps: (boxes lo, boxes hi, radii) of an open mesh's holes (:func:`.meshcheck.hole_caps`), near which
            signs do not spread; None for a closed mesh.
        previous, prev_index: An earlier field of the same mesh and domain and each node's index in it: matching
            nodes keep its signs.
        known: The expansions of that earlier build (the third result of this function), kept too.
        timings: ``signs`` seconds are added here.
        coarse_known: ``previous`` has every coarse node (a field refined on demand): only the finest are signed.
    Returns:
        ``(values, stats, expansions)``: (N,) float32 signed distances, ``{"sign_queries": winding numbers per level,
        "sign_sweeps": (empty-ball, segment) sweeps per level}``, and the coarse nodes' expansions (an
        :class:`.winding.ExpansionArg`, for ``known`` in a later build).
    """
    t0 = time.perf_counter()
    offsets, n, n0 = layout["offsets"], int(layout["offsets"][-1]), int(layout["offsets"][1])
    levels = len(offsets) - 1
    run = _Signing(winding, layout, dist, neighbours, origin, voxel_size, hole_caps)
    if winding.mode == WINDING_NONE:  # nothing enclosed: outside everywhere
        run.sign.fill_(1.0)
    elif previous is not None:
        launch_split(_take_known_sign_kernel, n, lambda s, _n: [s, prev_index, previous.values, run.sign], run.device)
    if run.exact and known is not None and known.cert.shape[0] > 0:
        _take_known_expansions(previous, prev_index, known, run.expansions, (n0, n))
    if levels > 1 and not coarse_known:
        run.top_level()
    for k in range(0 if coarse_known else levels - 2, -1, -1):
        run.from_parents(k)
    if levels > 1:
        run.spread(0, 0, n0)
    # Undecided finest nodes lie within about half a voxel of the surface, where the pseudo-normal sign is wrong near
    # open edges and where shells intersect or touch: they take their parent's sign across a segment that meets no
    # triangle, else pay the winding number.
    idx = run.across_to_parents(np.flatnonzero(run.sign.numpy()[:n0] == 0.0))
    run.oracle(idx, 0)
    run.oracle_counts[0] = len(idx)
    values = wp.empty(n, dtype=wp.float32, device=run.device)
    launch_split(_apply_sign_kernel, n, lambda start, _n: [start, dist, run.sign, values], run.device)
    timings["signs"] = timings.get("signs", 0.0) + time.perf_counter() - t0
    return values, {"sign_queries": run.oracle_counts, "sign_sweeps": run.sign_sweeps}, run.expansions


class _Signing:
    """The state :func:`sign_levels` signs a field with (the nodes' signs, 0 where unset), and its steps: the oracle,
    the spread between neighbours, the top level's seeds, a level from its parents."""

    def __init__(self, winding, layout, dist, neighbours, origin, voxel_size: float, hole_caps):
        self.winding, self.layout, self.dist, self.neighbours = winding, layout, dist, neighbours
        self.codes, self.coords, self.offsets = layout["codes"], layout["coords"], layout["offsets"]
        self.child, self.parent = layout["child"], layout["parent"]
        self.device = self.codes.device
        self.levels = len(self.offsets) - 1
        self.n, self.n0 = int(self.offsets[-1]), int(self.offsets[1])
        self.sign = wp.zeros(self.n, dtype=wp.float32, device=self.device)
        self.origin_v, self.voxel_size = wp.vec3(*(float(x) for x in origin)), voxel_size
        self.cap_args = box_arrays(hole_caps, self.device)
        self.mesh_id = int(winding.mesh)
        self.exact = winding.mode == WINDING_EXACT and hole_caps is not None
        self.expansions = expansion_arg(self.n0, self.n - self.n0 if self.exact else 0, self.device)
        self.oracle_counts, self.sign_sweeps = {}, {}

    def oracle(self, nodes_np, k, reach=0.8661):
        expand = (self.dist, self.expansions) if self.exact and k > 0 else None
        _winding_signs(
            self.winding, self.layout, nodes_np, k, (self.origin_v, self.voxel_size), self.sign, expand, reach
        )

    def across_to_parents(self, nodes_np) -> np.ndarray:
        """Of the finest ``nodes_np`` left unset, those still unset after taking their parents' signs across segments
        that cross no triangle (:func:`_parent_segment_kernel`): a field built on demand along a seam, in a ring on a
        large face, has its layer of nodes just off the face with no signed neighbour to spread from (a plate's, 20 k
        winding numbers; a full build spreads them from its rim)."""
        if not len(nodes_np) or self.mesh_id == 0 or self.levels < 2:
            return nodes_np
        nodes = wp.array(nodes_np.astype(np.int32), dtype=wp.int32, device=self.device)
        launch_split(
            _parent_segment_kernel,
            len(nodes_np),
            lambda lo, n: [nodes[lo : lo + n], self.coords, self.parent, self.origin_v, float(self.voxel_size)]
            + [self.sign, wp.uint64(self.mesh_id), *self.cap_args],
            self.device,
        )
        return nodes_np[self.sign.numpy()[nodes_np] == 0.0]

    def spread(self, k, lo, hi):
        """Signs spread between level ``k``'s neighbours (nodes ``lo`` to ``hi``); returns the nodes left unset."""
        changed = wp.zeros(1, dtype=wp.int32, device=self.device)
        # the finest level first spreads by empty balls alone, then across segments that cross no triangle, which
        # costs a box query each and so runs only once the cheap test is exhausted
        phases = [0, self.mesh_id]
        sweeps = {}
        for phase_mesh in phases:
            for sweep in range(MAX_SIGN_SWEEPS):  # noqa: B007 (the count is kept)
                changed.zero_()
                self._sweep(k, lo, hi, phase_mesh, sweep, changed)
                got = int(changed.numpy()[0])
                if got == 0:
                    break
                if phase_mesh != phases[-1] and (k == 0 or got < SIGN_SWEEP_SETTLED * (hi - lo)):
                    # the empty balls have settled (on the finest level one in-place sweep leaves a handful): the
                    # segments' phase signs the few nodes another sweep over the whole level would
                    break
            sweeps[phase_mesh] = sweep + 1
        self.sign_sweeps[k] = (sweeps[0], sweeps.get(self.mesh_id, 0))
        return lo + np.flatnonzero(self.sign.numpy()[lo:hi] == 0.0)

    def _sweep(self, k, lo, hi, phase_mesh, sweep, changed):
        """One sweep of the spread over level ``k`` (``phase_mesh`` 0: empty balls alone)."""
        common = [self.dist, self.sign]
        tail = [self.origin_v, *self.cap_args, wp.uint64(phase_mesh), changed]
        if k == 0:
            # in place from two threads: a sign only ever goes from unset to final, so races are harmless
            head = [self.codes, self.parent, self.child, self.neighbours, self.n0]
            launch_split(
                _propagate_sign_octet_kernel,
                (hi - lo) // 8,
                lambda start, span: [start, *head, *common, SIGN_SAFETY * 1.0, float(self.voxel_size), *tail]
                + [span, sweep % 2],
                self.device,
            )
            return
        # split the same way (racing increments from two threads still leave ``changed`` nonzero)
        spacing = float(self.voxel_size * 2**k)
        launch_split(
            _propagate_sign_kernel,
            hi - lo,
            lambda start, span: [self.neighbours, self.n0, lo + start, *common, SIGN_SAFETY, spacing, self.coords]
            + [*tail, span, sweep % 2],
            self.device,
        )

    def top_level(self):
        """The top level's signs: from a lattice of oracle seeds, spread between neighbours, the oracle for the rest.
        Across a hole of an open mesh the sign changes where no triangle is near, so empty balls prove nothing near
        it: signs spread only away from the holes' caps (``hole_caps``), the oracle decides the rest."""
        levels, offsets = self.levels, self.offsets
        top_lo, top_hi = int(offsets[levels - 1]), int(offsets[levels])
        nx, ny, nz = (int(d) for d in np.asarray(self.layout["top_dims"], dtype=np.int64))
        if self.exact:
            # near the holes nothing spreads: a lattice of seeds every other node expands far enough to decide its
            # neighbours by Taylor's theorem
            ix, iy, iz = (np.arange(0, m, 2) for m in (nx, ny, nz))
        else:
            ix, iy, iz = (np.arange(min(TOP_SEED_STRIDE // 2, m - 1), m, TOP_SEED_STRIDE) for m in (nx, ny, nz))
        seeds = top_lo + (ix[None, None, :] + nx * (iy[None, :, None] + ny * iz[:, None, None])).ravel()
        seeds = seeds[self.sign.numpy()[seeds] == 0.0]
        self.oracle(seeds, levels - 1, SEED_REACH)
        if self.exact:
            spacing = float(self.voxel_size * 2 ** (levels - 1))
            launch_split(
                sign_from_seed_kernel,
                top_hi - top_lo,
                lambda start, _n: [self.winding, self.coords, top_lo, start, wp.vec3i(nx, ny, nz), self.origin_v]
                + [spacing, self.dist, SIGN_SAFETY, self.sign, self.expansions, int(levels > 2)],
                self.device,
            )
        rest = self.spread(levels - 1, top_lo, top_hi)
        self.oracle(rest, levels - 1)
        self.oracle_counts[levels - 1] = len(seeds) + len(rest)

    def from_parents(self, k):
        """Level ``k``'s signs from its parents where they prove them, then (above the finest) spread and the
        oracle."""
        lo, hi = int(self.offsets[k]), int(self.offsets[k + 1])
        launch_split(
            _inherit_sign_kernel,
            hi - lo,
            lambda start, _n: [self.coords, self.parent, lo + start, self.origin_v, self.voxel_size * 2**k, self.dist]
            + [self.sign, SIGN_SAFETY, self.winding, int(self.exact), *self.cap_args, self.expansions, int(k >= 2)],
            self.device,
        )
        if k > 0:
            idx = self.spread(k, lo, hi)
            self.oracle(idx, k)
            self.oracle_counts[k] = len(idx)
