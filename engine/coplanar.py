"""Faces of two operands that lie in one plane: kept once, where the result's surface is theirs.

Boxes set side by side, a slot cut with its cutter's top flush with the part's, a block stacked on another: CAD
booleans are full of faces that coincide with another operand's faces. The judge (:mod:`.keep`) keeps a face only
where every other surface is farther than the band, and there the other surface is at distance 0: every such face was
given up and remeshed (two boxes side by side: 4,200 triangles where the exact union has 28, in 0.8 s).

Here a coincident face is read as what it is. For a sample of a face of one operand:

- the other operand's triangles that lie in the face's plane (every corner within ``COPLANAR_VOXELS`` of it) are no
  *other* surface: its distance to the other operand is to its nearest triangle out of that plane (where such a face
  ends, the other operand's surface leaves the plane: that is the seam, and the band keeps clear of it as of any);
- where the sample lies on such a triangle, the other operand's sign there is tied to the face's own: the same where
  both face one way, the opposite where they face each other (touching solids); the expression is evaluated with
  the other operand's value moving with the face's own (:func:`tied_values`).

So a face crosses the result's surface where the expression changes sign with both operands at once (a union's or an
intersection's faces facing one way, a difference's faces touching from outside), and is internal where it does not
(a difference's flush faces, a union's touching ones). Where two operands' faces coincide and both cross, the face of
the operand first in the expression is kept and the other's is taken for within the band (none is kept twice).

Seams are read only where the kept faces change hands: where the first operand's face ends in the plane and the
later one's goes on (each keeps a band from there: the later one from the earlier face's end, the earlier one from
its own faces out of the plane that the later face goes on past), and where another surface of the result comes
near. The other operand's walls that lie inside the result (a box's end wall inside the box beside it:
:func:`internal_triangles`) and its triangles flush on the operand's own (a wall both share: :func:`flush_triangles`)
are no surface there, and a tie to a face inside the result (one that only touches along an edge) no place where
faces change hands.

Only triangles that some other operand's triangle lies in the plane of and overlaps (:func:`coplanar_triangles`, a
BVH query a triangle: 4 ms for the bunny's 69 k triangles against spot), and where the expression can cross with
both, are read so, sample by sample (:meth:`.keep._Judge.judge`); every other triangle is judged as before, bit for
bit. The flush and internal triangles are found once a judge, and skipped without a closest point.

Written by hand: a nearest-triangle query that skips triangles by their plane is a few lines over Warp's BVH boxes.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from .expression import evaluate_signs
from .geometry import closest_on_triangle, triangle_frame
from .parallel import launch_split
from .samples import triangle_samples

# A triangle lies in a face's plane where each of its corners is this many voxels or less off it (float rounding of
# a placement is about 1e-7 of the coordinates; a voxel is about 4e-3 of the operands' size at /256).
COPLANAR_VOXELS = 1e-3
# :func:`coplanar_triangles`' bits, and the sign a leaf tied so takes (:func:`tied_values`).
TIED_SAME, TIED_OPPOSITE = 1, 2
# A triangle's nearest point lying flush on the operand's own faces counts as flush where its surface this many voxels
# about it does too, where it goes on (:func:`_flush_about`).
FLUSH_STEP_VOXELS = 0.5
TIES = ((TIED_SAME, 2), (TIED_OPPOSITE, -2))
# :func:`unflushed` gives the mesh itself (its readings skipping by the flags) where at most one triangle in this many
# is skipped.
FEW_SKIPPED = 16
# :func:`internal_triangles` reads samples this many voxels apart before those a voxel apart.
COARSE_SAMPLES = 8.0


@wp.func
def _in_plane(mesh: wp.uint64, g: int, a: wp.vec3, n: wp.vec3, eps: float) -> bool:
    """Whether triangle ``g`` of ``mesh`` lies in the plane through ``a`` with unit normal ``n`` (within ``eps``)."""
    inside = True
    for k in range(3):
        if wp.abs(wp.dot(n, wp.mesh_get_point(mesh, 3 * g + k) - a)) > eps:
            inside = False
    return inside


@wp.func
def _closest_on(mesh: wp.uint64, g: int, p: wp.vec3):
    """(the point of triangle ``g`` of ``mesh`` closest to ``p``, the triangle's unit normal)."""
    a = wp.mesh_get_point(mesh, 3 * g)
    b = wp.mesh_get_point(mesh, 3 * g + 1)
    c = wp.mesh_get_point(mesh, 3 * g + 2)
    edges, inward, lengths, n = triangle_frame(a, b, c)
    return closest_on_triangle(p, a, b, c, edges, inward, lengths, n), n


@wp.func
def _on_own(own: wp.uint64, q: wp.vec3, m: wp.vec3, eps: float) -> bool:
    """Whether point ``q`` (on a triangle of unit normal ``m``) lies on a triangle of ``own`` in that triangle's
    plane: there the two surfaces coincide (a wall of one operand flush with the other's), no other surface. (Any
    such triangle: on an edge of ``own`` the nearest may be the other face at the edge.)"""
    if own == wp.uint64(0) or wp.length(m) == 0.0:
        return False
    pad = wp.vec3(eps, eps, eps)
    query = wp.mesh_query_aabb(own, q - pad, q + pad)
    t = int(0)
    while wp.mesh_query_aabb_next(query, t):
        if _in_plane(own, t, q, m, eps):
            on, _n = _closest_on(own, t, q)
            if wp.length(q - on) <= eps:
                return True
    return False


@wp.func
def _flush_about(mesh: wp.uint64, own: wp.uint64, q: wp.vec3, m: wp.vec3, eps: float, step: float) -> bool:
    """Whether ``mesh``'s surface about its point ``q`` (on a triangle of unit normal ``m``) lies flush on ``own``:
    ``q`` does, and so does every point ``step`` from it in that plane along two axes where ``mesh`` goes on (one that
    only touches ``own`` along an edge, or goes on past ``own``'s face there, is not flush)."""
    if not _on_own(own, q, m, eps):
        return False
    e1 = wp.normalize(wp.cross(m, wp.where(wp.abs(m[0]) < 0.9, wp.vec3(1.0, 0.0, 0.0), wp.vec3(0.0, 1.0, 0.0))))
    e2 = wp.cross(m, e1)
    for k in range(4):
        o = q + step * wp.where(k < 2, e1, e2) * wp.where(k % 2 == 0, 1.0, -1.0)
        if _on_own(mesh, o, m, eps) and not _on_own(own, o, m, eps):
            return False
    return True


@wp.kernel(enable_backward=False)
def _touching_kernel(
    mesh: wp.uint64,
    verts: wp.array[wp.vec3],
    tris: wp.array2d[wp.int32],
    eps: float,
    out: wp.array[wp.uint8],
):
    """Per triangle: bit 1 where a triangle of ``mesh`` whose box overlaps its own lies in its plane facing its way,
    bit 2 where one faces the other way."""
    t = wp.tid()
    a = verts[tris[t, 0]]
    b = verts[tris[t, 1]]
    c = verts[tris[t, 2]]
    m = wp.cross(b - a, c - a)
    if wp.length(m) == 0.0:
        return
    n = wp.normalize(m)
    pad = wp.vec3(eps, eps, eps)
    query = wp.mesh_query_aabb(mesh, wp.min(wp.min(a, b), c) - pad, wp.max(wp.max(a, b), c) + pad)
    g = int(0)
    bits = int(0)
    while wp.mesh_query_aabb_next(query, g):
        if _in_plane(mesh, g, a, n, eps):
            ga = wp.mesh_get_point(mesh, 3 * g)
            m = wp.cross(wp.mesh_get_point(mesh, 3 * g + 1) - ga, wp.mesh_get_point(mesh, 3 * g + 2) - ga)
            bits = bits | wp.where(wp.dot(m, n) >= 0.0, 1, 2)
    out[t] = wp.uint8(bits)


def coplanar_triangles(verts: np.ndarray, tris: np.ndarray, meshes: list, voxel: float, device) -> list:
    """Per mesh of ``meshes`` (the other operands' BVHs; None for the operand itself and one without a mesh): None,
    or (T,) uint8 per triangle (world ``verts``, ``tris``): bit 1 where a triangle of the mesh overlapping its box
    lies in its plane facing its way (``TIED_SAME``), bit 2 the other way (``TIED_OPPOSITE``); None where no triangle
    has either."""
    if not len(tris) or all(m is None for m in meshes):
        return [None] * len(meshes)
    v = wp.array(np.ascontiguousarray(verts, dtype=np.float32), dtype=wp.vec3, device=device)
    t = wp.array(np.ascontiguousarray(tris, dtype=np.int32), dtype=wp.int32, device=device)
    found = []
    for mesh in meshes:
        bits = None if mesh is None else _touching(mesh, v, t, COPLANAR_VOXELS * voxel, device)
        found.append(bits if bits is not None and bits.any() else None)
    return found


def _touching(mesh, verts: wp.array, tris: wp.array, eps: float, device) -> np.ndarray:
    """:func:`_touching_kernel` of ``tris`` (on ``verts``) against ``mesh``: (T,) uint8."""
    out = wp.empty(tris.shape[0], dtype=wp.uint8, device=device)
    launch_split(
        _touching_kernel,
        tris.shape[0],
        lambda lo, k: [mesh.id, verts, tris[lo : lo + k], eps, out[lo : lo + k]],
        device,
    )
    return out.numpy()


@wp.kernel(enable_backward=False)
def _flush_kernel(mesh: wp.uint64, own: wp.uint64, eps: float, rows: wp.array[wp.int32], out: wp.array[wp.uint8]):
    """Per triangle ``rows[tid]`` of ``mesh``: 1 where its corners and centre lie on triangles of ``own`` in its
    plane (all of it flush with ``own``: a wall both share), else 0."""
    g = rows[wp.tid()]
    a = wp.mesh_get_point(mesh, 3 * g)
    b = wp.mesh_get_point(mesh, 3 * g + 1)
    c = wp.mesh_get_point(mesh, 3 * g + 2)
    m = wp.cross(b - a, c - a)
    flush = int(0)
    if wp.length(m) > 0.0:
        m = wp.normalize(m)
        flush = 1
        for k in range(4):
            q = wp.where(k == 3, (a + b + c) / 3.0, wp.mesh_get_point(mesh, 3 * g + k % 3))
            if not _on_own(own, q, m, eps):
                flush = 0
    out[wp.tid()] = wp.uint8(flush)


def flush_triangles(mesh, own, voxel: float, device, near=None) -> np.ndarray:
    """(G,) uint8 per triangle of ``mesh`` (a BVH): 1 where it lies flush on ``own``'s triangles in its plane
    (:func:`_flush_kernel`; none where ``own`` is None); with ``near`` ((G,) bool), only those triangles are looked
    at (the rest 0)."""
    count = mesh.indices.shape[0] // 3
    out = np.zeros(count, dtype=np.uint8)
    rows = np.arange(count, dtype=np.int32) if near is None else np.flatnonzero(near).astype(np.int32)
    if own is None or not len(rows):
        return out
    found = wp.empty(len(rows), dtype=wp.uint8, device=device)
    w_rows = wp.array(rows, dtype=wp.int32, device=device)
    eps = COPLANAR_VOXELS * voxel
    launch_split(
        _flush_kernel, len(rows), lambda lo, k: [mesh.id, own.id, eps, w_rows[lo : lo + k], found[lo : lo + k]], device
    )
    out[rows] = found.numpy()
    return out


@wp.kernel(enable_backward=False)
def _near_kernel(mesh: wp.uint64, corners: wp.array[wp.vec3], pad: float, out: wp.array[wp.uint8]):
    """Per triangle ``tid`` (corners ``3 tid`` to ``3 tid + 2``): every triangle of ``mesh`` whose box overlaps its
    box grown by ``pad`` marked 1 in ``out``."""
    t = wp.tid()
    a = corners[3 * t]
    b = corners[3 * t + 1]
    c = corners[3 * t + 2]
    grow = wp.vec3(pad, pad, pad)
    query = wp.mesh_query_aabb(mesh, wp.min(wp.min(a, b), c) - grow, wp.max(wp.max(a, b), c) + grow)
    g = int(0)
    while wp.mesh_query_aabb_next(query, g):
        out[g] = wp.uint8(1)


def triangles_near(mesh, corners: np.ndarray, reach: float, device) -> np.ndarray:
    """(G,) bool the triangles of ``mesh`` (a BVH) whose boxes come within ``reach`` of the boxes of the triangles
    ``corners`` (T, 3, 3): every triangle a query from a point of those within ``reach`` can meet."""
    out = wp.zeros(mesh.indices.shape[0] // 3, dtype=wp.uint8, device=device)
    if len(corners):
        points = wp.array(np.ascontiguousarray(corners, dtype=np.float32).reshape(-1, 3), dtype=wp.vec3, device=device)
        wp.launch(_near_kernel, dim=len(corners), inputs=[mesh.id, points, float(reach), out], device=device)
    return out.numpy() > 0


@wp.kernel(enable_backward=False)
def _readings_kernel(
    mesh: wp.uint64,
    surface: wp.uint64,
    own: wp.uint64,
    flush: wp.array[wp.uint8],
    points: wp.array[wp.vec3],
    normals: wp.array[wp.vec3],
    reaches: wp.array[wp.float32],
    eps: float,
    step: float,
    earlier: int,
    across: int,
    distance: wp.array[wp.float32],
    tie: wp.array[wp.int8],
    live: wp.array[wp.uint8],
):
    """Per point (on a face of unit normal ``normals``): the distance to the nearest triangle of ``mesh`` out of the
    face's plane whose surface about its nearest point does not lie flush on ``own`` (its reach where farther), +1 /
    -1 where it lies on a triangle in the face's plane facing the same / the other way (0 where on none), and 1 where
    such a triangle is not one ``flush`` skips (one inside the result: a face that only touches the point's along
    an edge, and goes on out of the result). ``surface``: ``mesh``'s triangles that ``flush`` does not skip (0:
    none), searched over the reach; the triangles the point lies on are looked for in a box of ``eps`` about it."""
    i = wp.tid()
    p = points[i]
    n = normals[i]
    reach = reaches[i]
    side = int(0)
    alive = int(0)
    tight = wp.vec3(eps, eps, eps)
    on = wp.mesh_query_aabb(mesh, p - tight, p + tight)
    g = int(0)
    while wp.mesh_query_aabb_next(on, g):
        if alive != 0 or (side != 0 and flush[g] != wp.uint8(0)) or not _in_plane(mesh, g, p, n, eps):
            continue  # (a tie found already, or one that this one cannot make live)
        q, m = _closest_on(mesh, g, p)
        if wp.length(p - q) <= eps:
            side = wp.where(wp.dot(m, n) >= 0.0, 1, -1)
            alive = wp.where(flush[g] == wp.uint8(0), 1, alive)
    best = reach
    pad = wp.vec3(reach, reach, reach)
    if surface != wp.uint64(0):
        near = wp.mesh_query_aabb(surface, p - pad, p + pad)
        h = int(0)
        while wp.mesh_query_aabb_next(near, h):
            if (surface == mesh and flush[h] != wp.uint8(0)) or _in_plane(surface, h, p, n, eps):
                continue  # (``mesh`` itself as its ``surface``: the few triangles ``flush`` skips, skipped here)
            q, m = _closest_on(surface, h, p)
            d = wp.length(p - q)
            if d < best and not _flush_about(mesh, own, q, m, eps, step):
                # (``across``: only where ``own``'s face in the point's plane goes on past it)
                if across == 0 or _on_own(own, q + step * wp.normalize(q - p + 1.0e-30 * n), n, eps):
                    best = d
    if earlier != 0 and side == 0:  # off an earlier operand's face in the plane: where it ends, so does what it keeps
        beside = wp.mesh_query_aabb(mesh, p - pad, p + pad)
        f = int(0)
        while wp.mesh_query_aabb_next(beside, f):
            if _in_plane(mesh, f, p, n, eps):
                e, _m = _closest_on(mesh, f, p)
                best = wp.min(best, wp.length(p - e))
    distance[i] = best
    tie[i] = wp.int8(side)
    live[i] = wp.uint8(alive)


def unflushed(mesh, flush: np.ndarray, device):
    """``mesh``'s triangles that ``flush`` ((G,) uint8, :func:`flush_triangles` and any other to skip) does not skip,
    as a BVH on the same points: ``mesh`` itself where it skips none, or few (at most one in FEW_SKIPPED: the
    readings skip those by their flags, where a BVH built anew costs more than the queries gain: 3.4 ms for the
    rocker arm's 20 k triangles), None where it skips all."""
    keep = np.asarray(flush) == 0
    if FEW_SKIPPED * int(np.count_nonzero(~keep)) <= len(keep):
        return mesh
    if not keep.any():
        return None
    indices = mesh.indices.numpy().reshape(-1, 3)[keep].ravel()
    return wp.Mesh(points=mesh.points, indices=wp.array(indices, dtype=wp.int32, device=device))


def coplanar_readings(
    mesh, own, flush, points, normals, reach, voxel: float, device, earlier=False, across=False, surface=False
):
    """For each point (N, 3) on a face of unit normal ``normals`` (N, 3) of the mesh ``own`` (its BVH, or None): (N,)
    float32 its distance to ``mesh``'s nearest triangle out of the face's plane and not flush with ``own`` where
    nearest (up to its ``reach``, (N,) or one for all: its candidates are the triangles in a box of that size;
    ``flush``: (G,) uint8, numpy or Warp, :func:`flush_triangles` of ``mesh`` on ``own`` and any other triangle to
    skip), (N,) int8 its tie: +1 / -1 where it lies on a triangle of ``mesh`` in that plane facing the face's way /
    the other way, else 0, and (N,) bool whether one such triangle is not one ``flush`` skips.
    With ``earlier`` (``mesh`` is an operand before ``own``'s in the expression, whose faces are kept where both
    coincide), its triangles in the plane that a point is off count as a surface: where that operand's face ends in
    the plane, ``own``'s face takes over, a seam. With ``across``, a triangle out of the plane counts only where
    ``own``'s face in the point's plane goes on past it (half a voxel on from its nearest point, away from the
    point): where ``mesh``'s face ends and ``own``'s goes on. ``surface``: :func:`unflushed` of ``mesh`` and
    ``flush``, where the caller has it (False: made here)."""
    n = len(points)
    if surface is False:
        surface = unflushed(mesh, flush.numpy() if isinstance(flush, wp.array) else flush, device)
    flush = wp.array(flush, dtype=wp.uint8, device=device) if isinstance(flush, np.ndarray) else flush
    pts = wp.array(np.ascontiguousarray(points, dtype=np.float32), dtype=wp.vec3, device=device)
    nrm = wp.array(np.ascontiguousarray(normals, dtype=np.float32), dtype=wp.vec3, device=device)
    reaches = wp.array(np.broadcast_to(np.asarray(reach, np.float32), (n,)).copy(), dtype=wp.float32, device=device)
    distance = wp.empty(n, dtype=wp.float32, device=device)
    tie = wp.empty(n, dtype=wp.int8, device=device)
    live = wp.empty(n, dtype=wp.uint8, device=device)
    eps = COPLANAR_VOXELS * voxel
    meshes = (mesh.id, wp.uint64(0) if surface is None else surface.id, wp.uint64(0) if own is None else own.id)
    launch_split(
        _readings_kernel,
        n,
        lambda lo, k: [
            *meshes, flush, pts[lo : lo + k], nrm[lo : lo + k],
            *(reaches[lo : lo + k], eps, FLUSH_STEP_VOXELS * voxel, int(earlier), int(across)),
            *(distance[lo : lo + k], tie[lo : lo + k], live[lo : lo + k]),
        ],
        device,
    )  # fmt: skip
    return distance.numpy(), tie.numpy(), live.numpy() > 0


def tied_values(signs: list, index: int, own: float) -> list:
    """The leaves' values for evaluating an expression at samples of leaf ``index`` whose value is ``own``: each other
    leaf's sign (-1, 0, +1), or where it is tied to the leaf (+2 / -2: its face in the plane, one way or the other,
    :func:`coplanar_readings`), ``own`` / ``-own``."""
    values, done = [], {}  # (one array may stand for many leaves: those outside everywhere, converted once)
    for j, s in enumerate(signs):
        if j == index:
            values.append(np.full(len(s), own, np.float32))
        elif id(s) in done:
            values.append(done[id(s)])
        else:
            f = s.astype(np.float32)
            tied = np.abs(f) == 2.0
            done[id(s)] = np.where(tied, 0.5 * f * own, f).astype(np.float32) if tied.any() else f
            values.append(done[id(s)])
    return values


def tied_to_earlier(signs: list, index: int) -> np.ndarray:
    """(N,) bool the samples of leaf ``index`` where a leaf before it in the expression is tied to it (its face in
    the plane: kept by that leaf, if by any)."""
    out = np.zeros(len(signs[index]), dtype=bool)
    for s in signs[:index]:
        out |= np.abs(s) == 2
    return out


def source_verts_near(leaf, tris: np.ndarray) -> np.ndarray:
    """(T, 3, 3) the world corners of the rows ``tris`` of a mesh leaf's triangles."""
    source = next(iter(leaf.world_sources().values()))
    return source.verts[source.tris[np.asarray(tris)]] if len(tris) else np.zeros((0, 3, 3), np.float32)


def internal_triangles(leaves: list, j: int, expression, near: np.ndarray, flush, voxel: float) -> np.ndarray:
    """(G,) uint8 1 for leaf ``j``'s triangles ``near`` ((G,) bool: those within reach of a judged leaf's faces in
    other leaves' planes, :func:`triangles_near`), not ``flush``, that lie inside the result, no part of them its
    surface (a box's end wall inside the box beside it): at samples a voxel apart and a voxel in from their edges,
    every other leaf's sign is clear (a quarter voxel off its surface) and the expression does not cross with
    ``j``'s. Such a wall is no surface where it meets a face in the plane. Samples ``COARSE_SAMPLES`` voxels apart
    are read first: most candidates are faces of the result, and one crossing sample tells (two boxes side by side:
    34 k samples a voxel apart, 100 ms, against some hundreds)."""
    source = next(iter(leaves[j].world_sources().values()))
    out = np.zeros(len(source.tris), dtype=np.uint8)
    rows = np.flatnonzero((flush == 0) & near)
    for spacing in (COARSE_SAMPLES * voxel, voxel):
        if not len(rows):
            break
        crossed = _crossed_somewhere(leaves, j, expression, source, rows, spacing, voxel)
        rows = rows[~crossed]
    out[rows] = 1
    return out


def _crossed_somewhere(leaves: list, j: int, expression, source, rows, spacing: float, voxel: float) -> np.ndarray:
    """(R,) bool per triangle ``rows`` of leaf ``j``'s world ``source``: at one of its samples ``spacing`` apart and
    a voxel in from its edges, a leaf's value lies within a quarter voxel of its surface or the expression crosses
    with ``j``'s (see :func:`internal_triangles`)."""
    corners = source.verts[source.tris[rows]]
    device = leaves[j].device
    points, first = triangle_samples(source.verts, source.tris[rows], np.full(len(rows), spacing), device)
    owner = np.r_[np.repeat(np.arange(len(rows)), 3), np.repeat(np.arange(len(rows)), np.diff(first))]
    points = np.concatenate([corners.reshape(-1, 3), points[len(source.verts) :]])
    towards = corners.mean(axis=1)[owner] - points  # each sample a voxel in, towards its triangle's centre
    length = np.linalg.norm(towards, axis=1, keepdims=True)
    points = (points + towards * np.minimum(1.0, voxel / np.maximum(length, 1e-30))).astype(np.float32)
    signs, clear = [], np.ones(len(points), dtype=bool)
    for k, leaf in enumerate(leaves):
        values = leaf.sample(points, method="linear") if k != j else np.full(len(points), -1.0, np.float32)
        clear &= (np.abs(values) > 0.25 * voxel) | (k == j)
        signs.append(np.sign(values).astype(np.int8))
    tiny = 1e-3 * voxel
    inside = evaluate_signs(expression, tied_values(signs, j, -tiny))
    outside = evaluate_signs(expression, tied_values(signs, j, tiny))
    crosses = ((inside < 0) != (outside < 0)) | ~clear
    return np.bincount(owner, weights=crosses, minlength=len(rows)) > 0
