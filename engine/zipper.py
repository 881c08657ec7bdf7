"""The join of kept faces and the voxel surface: one closed surface out of the two, sharing vertices along the seam.

The kept triangles (:mod:`.keep`) and the voxel surface of the whole result overlap wherever faces are kept. The
voxel surface gives up every face with a corner *over* the kept faces (within a voxel of them, its closest point on
them not on their border, its surface facing their way: the far side of a part thinner than a voxel is not over the
near side's faces), so that it ends just beyond their border; the gap between the two borders, a voxel or
less wide, is closed by a strip of triangles between each border loop of the kept faces and the loop of the voxel
surface that faces it (the shorter-diagonal advance of mesh zippering, Turk and Levoy 1994, steered by where along
the voxel loop the kept loop's next vertex lies: a kept border that zigzags across slivers, three times the voxel
loop's length, or runs a long straight edge, stays in step), whose corners are the two loops' own vertices: no new
vertex, no T-junction. A loop that cannot be paired (a hole of one kept triangle that the voxel surface does not
reach, an island of the voxel surface left over the kept faces), or whose strip stretches where the two loops part
(a kept finger narrower than a voxel, which the voxel surface does not follow), gives up the kept faces or voxel
faces at it, and the pairing runs again.

Written by hand: no library joins a triangle soup to a surface along borders it has to find first; the loops are
walked in a kernel, a thread per loop pair, the rest is numpy and Warp's BVH and hash-grid queries.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from .components import connected_components
from .edgehash import EdgeCounts, directed_edges
from .geometry import closest_on_triangle, triangle_frame
from .parallel import EMIT_SPLIT_MIN_DIM, host_view, launch_split

# A voxel-surface vertex is over the kept faces within this many voxels of them.
OVER_VOXELS = 1.0
# The grid that finds the kept faces near the voxel surface (:func:`faces_near`) has at most this many cells a side.
NEAR_GRID = 32
# Border loops are paired through vertices within this many voxels of each other.
PAIR_VOXELS = 4.0
# A strip stretches where the loops run farther apart than this many voxels.
STRETCH_VOXELS = 4.0
# Rounds of giving up faces at loops that cannot be paired before the join is abandoned.
MAX_ROUNDS = 12
# Rounds in which a stretched strip gives up only the kept faces where it stretches, before its whole loop's.
LOCAL_ROUNDS = 1
# A loop failing again gives up this many rings of kept faces around it (a small kept piece: all of it): one (a
# low-polygon mesh's three rings are a third of its area).
WIDEN_RINGS = 1


# ---- the voxel surface over the kept faces ----
@wp.func
def _segment_distance(p: wp.vec3, a: wp.vec3, b: wp.vec3) -> float:
    d = b - a
    t = wp.clamp(wp.dot(p - a, d) / wp.max(wp.dot(d, d), 1.0e-30), 0.0, 1.0)
    return wp.length(p - (a + t * d))


@wp.func
def _facing_tie(kept: wp.uint64, p: wp.vec3, way: wp.vec3, u: float, margin: float) -> bool:
    """Whether a kept face as near to ``p`` as ``u`` (within ``margin``) faces ``way``: where the nearest point lies on
    an edge or a corner, the face the query returns among those that share it is the BVH's choice, and a point is over
    the kept faces where any of them faces its way (the verdict the same whichever BVH holds them)."""
    r = u + margin
    query = wp.mesh_query_aabb(kept, p - wp.vec3(r), p + wp.vec3(r))
    f = int(0)
    while wp.mesh_query_aabb_next(query, f):
        n = wp.mesh_eval_face_normal(kept, f)
        if wp.dot(way, n) >= 0.0:
            a = wp.mesh_eval_position(kept, f, 1.0, 0.0)
            b = wp.mesh_eval_position(kept, f, 0.0, 1.0)
            c = wp.mesh_eval_position(kept, f, 0.0, 0.0)
            edges, inward, lengths, unit = triangle_frame(a, b, c)
            if wp.length(p - closest_on_triangle(p, a, b, c, edges, inward, lengths, unit)) <= r:
                return True
    return False


@wp.kernel(enable_backward=False)
def _over_kernel(
    kept: wp.uint64,
    border: wp.uint64,
    border_a: wp.array[wp.vec3],
    border_b: wp.array[wp.vec3],
    points: wp.array[wp.vec3],
    normals: wp.array[wp.vec3],
    reach: float,
    margin: float,
    over: wp.array[wp.uint8],
):
    """Whether each point lies over the kept faces: within ``reach`` of them, its closest point not on their border
    (every border segment farther than that closest point by ``margin``) unless it lies exactly on them (faces on the
    lattice's planes put voxel vertices on the border's corners: their faces stayed, doubling kept ones), and its
    surface facing the way the kept face there does (``normals``, when given: another sheet a voxel off, the far side
    of a thin part, is not over it)."""
    i = wp.tid()
    p = points[i]
    over[i] = wp.uint8(0)
    q = wp.mesh_query_point_no_sign(kept, p, reach)
    if not q.result:
        return
    u = wp.length(p - wp.mesh_eval_position(kept, q.face, q.u, q.v))
    if normals.shape[0] > 0:
        if wp.dot(normals[i], wp.mesh_eval_face_normal(kept, q.face)) < 0.0 and not _facing_tie(
            kept, p, normals[i], u, margin
        ):
            return
    if u == 0.0:  # (exactly on a kept face: over it, border or not)
        over[i] = wp.uint8(1)
        return
    r = u + margin
    query = wp.bvh_query_aabb(border, p - wp.vec3(r), p + wp.vec3(r))
    s = int(0)
    while wp.bvh_query_next(query, s):
        if _segment_distance(p, border_a[s], border_b[s]) <= r:
            return
    over[i] = wp.uint8(1)


def border_halves(tris: np.ndarray, n_verts: int) -> np.ndarray:
    """(B, 2) int64 the directed edges (as the faces list them) whose reverse no face lists: a surface's border."""
    if not len(tris):
        return np.zeros((0, 2), dtype=np.int64)
    a, b, _, _ = directed_edges(tris, n_verts)
    open_ = EdgeCounts(a, b, n_verts).reverses() == 0
    return np.stack([a[open_], b[open_]], axis=1)


def vertices_over(points, kept_tris, border, candidates, voxel: float, device, normals=None) -> np.ndarray:
    """(N,) bool: which of the ``candidates`` (indices of ``points``) lie over the kept faces ``kept_tris`` (whose
    border edges are ``border``), within ``OVER_VOXELS`` of them, and with ``normals`` ((N, 3) per point: its surface's
    way) facing the way the kept face nearest them does; every other point False."""
    over_all = np.zeros(len(points), dtype=bool)
    if not len(kept_tris) or not len(candidates):
        return over_all
    kept_verts = points
    reach, margin = OVER_VOXELS * voxel, 1e-3 * voxel
    near = np.ascontiguousarray(kept_tris, dtype=np.int32)
    if len(near) > len(candidates):  # a BVH of those near the points alone (fewer points: their grid costs more)
        near = near[faces_near(kept_verts, near, points[candidates], reach)]
    if not len(near):
        return over_all
    mesh = wp.Mesh(
        points=wp.array(kept_verts, dtype=wp.vec3, device=device),
        indices=wp.array(near.reshape(-1), dtype=wp.int32, device=device),
    )
    a = np.ascontiguousarray(kept_verts[border[:, 0]], dtype=np.float32)
    b = np.ascontiguousarray(kept_verts[border[:, 1]], dtype=np.float32)
    if not len(border):  # a closed kept surface: nothing is its border (a far-away segment stands in)
        a = b = np.full((1, 3), 1e30, dtype=np.float32)
    a_wp, b_wp = wp.array(a, dtype=wp.vec3, device=device), wp.array(b, dtype=wp.vec3, device=device)
    bvh = wp.Bvh(
        wp.array(np.minimum(a, b), dtype=wp.vec3, device=device),
        wp.array(np.maximum(a, b), dtype=wp.vec3, device=device),
    )
    pts = wp.array(np.ascontiguousarray(points[candidates], dtype=np.float32), dtype=wp.vec3, device=device)
    over = wp.empty(len(candidates), dtype=wp.uint8, device=device)
    ways = np.zeros((0, 3), np.float32) if normals is None else np.ascontiguousarray(normals[candidates], np.float32)
    ways = wp.array(ways, dtype=wp.vec3, device=device)
    launch_split(
        _over_kernel,
        len(candidates),
        lambda lo, n: [
            *(mesh.id, bvh.id, a_wp, b_wp, pts[lo : lo + n], ways[lo : lo + n] if ways.shape[0] else ways),
            *(reach, margin, over[lo : lo + n]),
        ],
        device,
        min_dim=EMIT_SPLIT_MIN_DIM,  # (a BVH query each: the join runs alone, the other core is free)
    )
    over_all[candidates] = over.numpy().astype(bool)
    return over_all


@wp.kernel(enable_backward=False)
def _near_faces_kernel(
    verts: wp.array[wp.vec3],
    tris: wp.array[wp.int32],
    table: wp.array3d[wp.int32],
    low: wp.vec3,
    size: float,
    reach: float,
    offset: int,
    near: wp.array[wp.uint8],
):
    """Whether triangle ``t``'s box, grown by ``reach``, meets a cell of the grid (``low``, cells of ``size``) that
    holds a point: the count in its cells off the summed-volume ``table`` (dims + 1 a side, 0 first)."""
    t = wp.tid() + offset
    a = verts[tris[3 * t]]
    b = verts[tris[3 * t + 1]]
    c = verts[tris[3 * t + 2]]
    lo = wp.min(wp.min(a, b), c) - wp.vec3(reach) - low
    hi = wp.max(wp.max(a, b), c) + wp.vec3(reach) - low
    first = wp.vec3i(0)
    last = wp.vec3i(0)
    for k in range(3):
        n = table.shape[k] - 1
        first[k] = wp.clamp(int(wp.floor(lo[k] / size)), 0, n)
        last[k] = wp.clamp(int(wp.floor(hi[k] / size)) + 1, 0, n)
    x0, y0, z0 = first[0], first[1], first[2]
    x1, y1, z1 = last[0], last[1], last[2]
    count = table[x1, y1, z1] - table[x0, y1, z1] - table[x1, y0, z1] - table[x1, y1, z0]
    count += table[x0, y0, z1] + table[x0, y1, z0] + table[x1, y0, z0] - table[x0, y0, z0]
    near[t] = wp.uint8(wp.where(count > 0, 1, 0))


def faces_near(verts: np.ndarray, tris: np.ndarray, points: np.ndarray, reach: float) -> np.ndarray:
    """(T,) bool a superset of the triangles ``tris`` ((T, 3) int32 of ``verts``) within ``reach`` of any of
    ``points``: those whose box, grown by ``reach``, meets a cell of a coarse grid (at most NEAR_GRID cells a side)
    that holds a point (:func:`_near_faces_kernel`, on the CPU's cores). A join's kept faces lie mostly far from the
    seams' voxel surface, and Warp builds a mesh's BVH on one thread (0.3-0.4 us a triangle here): a BVH of those near
    it alone is built in a fraction of the time."""
    if not len(points) or not len(tris):
        return np.zeros(len(tris), dtype=bool)
    pts = np.asarray(points, dtype=np.float32)
    low = pts.min(axis=0) - np.float32(reach)
    size = max(2.0 * reach, float((pts.max(axis=0) - low).max()) / NEAR_GRID, 1e-30)
    cell = np.floor((pts - low) / np.float32(size)).astype(np.int64)
    dims = cell.max(axis=0) + 1
    table = np.zeros(dims + 1, dtype=np.int32)
    table[1:, 1:, 1:][cell[:, 0], cell[:, 1], cell[:, 2]] = 1
    table = np.ascontiguousarray(table.cumsum(axis=0).cumsum(axis=1).cumsum(axis=2), dtype=np.int32)
    cpu = wp.get_device("cpu")
    near = np.zeros(len(tris), dtype=np.uint8)
    verts, flat = np.ascontiguousarray(verts, dtype=np.float32), np.ascontiguousarray(tris, dtype=np.int32).reshape(-1)
    args = [
        host_view(verts, wp.vec3, cpu),
        host_view(flat, wp.int32, cpu),
        host_view(table, wp.int32, cpu),
        wp.vec3(*low.tolist()),
        float(size),
        float(reach),
    ]  # fmt: skip
    out = host_view(near, wp.uint8, cpu)
    launch_split(_near_faces_kernel, len(tris), lambda lo, _n: [*args, lo, out], cpu)
    return near.view(bool)


# ---- border loops ----
def pinched(halves: np.ndarray, n_verts: int) -> np.ndarray:
    """(V,) bool: vertices where more than one border edge starts (two border loops touch there)."""
    return np.bincount(halves[:, 0], minlength=n_verts) > 1


def loop_labels(nxt: np.ndarray, members: np.ndarray, device=None) -> np.ndarray:
    """Label of each vertex's loop under the permutation ``nxt`` of ``members`` (the least member of its loop; -1 for
    vertices on a path that does not close: one that reaches a vertex not a member), as the connected components
    (:func:`.components.connected_components`, in Warp) of the edges from each member to its next."""
    label = np.full(len(nxt), -1, dtype=np.int64)
    if not len(members):
        return label
    root = connected_components(len(nxt), members, nxt[members], device)
    open_ = np.zeros(len(nxt), dtype=bool)
    ends = nxt[members]
    member = np.zeros(len(nxt), dtype=bool)
    member[members] = True
    open_[root[ends[~member[ends]]]] = True  # a path's end is no member: its piece is no loop
    label[members] = np.where(open_[root[members]], -1, root[members])
    return label


def vertex_components(tris: np.ndarray, n_verts: int, device=None) -> np.ndarray:
    """(n_verts,) int64 the connected piece of each vertex through the triangles' edges (its least vertex; an unused
    vertex is a piece of its own): :func:`.components.connected_components` over the edges."""
    t = np.asarray(tris, dtype=np.int64).reshape(-1, 3)
    return connected_components(n_verts, t.ravel(), t[:, [1, 2, 0]].ravel(), device)


@wp.kernel(enable_backward=False)
def _nearest_kernel(
    grid: wp.uint64,
    cloud: wp.array[wp.vec3],
    cloud_label: wp.array[wp.int64],
    points: wp.array[wp.vec3],
    point_label: wp.array[wp.int64],
    radius: float,
    nearest: wp.array[wp.int32],
):
    """The nearest point of ``cloud`` to each point whose label is not the point's, within ``radius`` (-1: none)."""
    i = wp.tid()
    p = points[i]
    best = radius
    found = int(-1)
    query = wp.hash_grid_query(grid, p, radius)
    j = int(0)
    while wp.hash_grid_query_next(query, j):
        if cloud_label[j] != point_label[i]:
            d = wp.length(cloud[j] - p)
            if d < best:
                best = d
                found = j
    nearest[i] = found


# Cells a side of the hash grid the nearest points are found in (its table, not a bound on the points): a table of
# 128^3 cells took 12 ms to make, 64^3 0.2 ms, and the loops' points number thousands.
HASH_CELLS = 64


def nearest_points(cloud: np.ndarray, points: np.ndarray, radius: float, device, labels=None) -> np.ndarray:
    """(N,) int32 index of the nearest of ``cloud`` (M, 3) to each point within ``radius`` (-1: none); with
    ``labels`` = (the cloud's (M,), the points' (N,)), the nearest with another label than the point's."""
    if not len(cloud) or not len(points):
        return np.full(len(points), -1, dtype=np.int32)
    if labels is None:  # no point's label is any of the cloud's
        labels = (np.zeros(len(cloud), dtype=np.int64), np.full(len(points), -1, dtype=np.int64))
    grid = wp.HashGrid(*(HASH_CELLS,) * 3, device=device)
    cloud_wp = wp.array(np.ascontiguousarray(cloud, dtype=np.float32), dtype=wp.vec3, device=device)
    grid.build(cloud_wp, radius)
    pts = wp.array(np.ascontiguousarray(points, dtype=np.float32), dtype=wp.vec3, device=device)
    cloud_label, point_label = (wp.array(np.ascontiguousarray(x, dtype=np.int64), device=device) for x in labels)
    out = wp.empty(len(points), dtype=wp.int32, device=device)
    inputs = [grid.id, cloud_wp, cloud_label, pts, point_label, float(radius), out]
    wp.launch(_nearest_kernel, len(points), inputs=inputs, device=device)
    return out.numpy()


def teeth(tris, alive, halves, n_verts: int) -> np.ndarray:
    """(F,) bool: the faces ``alive`` with two edges on their border (``halves``, :func:`border_halves`): a tooth of
    the voxel loop, which the strip beside it would fold over."""
    at = np.zeros(n_verts, dtype=bool)
    at[np.asarray(halves).ravel()] = True
    rows = np.flatnonzero(alive & at[tris[:, 0]] & at[tris[:, 1]] & at[tris[:, 2]])
    out = np.zeros(len(tris), dtype=bool)
    if not len(rows) or not len(halves):
        return out
    t = np.asarray(tris[rows], dtype=np.int64)
    border = np.sort(halves[:, 0].astype(np.int64) * n_verts + halves[:, 1])
    count = np.zeros(len(rows), dtype=np.int64)
    for k in range(3):
        edge = t[:, k] * n_verts + t[:, (k + 1) % 3]
        count += border[np.minimum(np.searchsorted(border, edge), len(border) - 1)] == edge
    out[rows[count >= 2]] = True
    return out


# ---- the strip ----
# Q is searched this many vertices ahead for the vertex nearest P's next one (a kept border's longest straight run
# is a few tens of voxels, the voxel loop's edges about one), and no farther than this many past the nearest so far.
AHEAD = 128
PAST = 4
# A vertex of Q nearer than this many voxels to P's next one is where Q's walk ahead may stop.
NEAR_VOXELS = 2.0


@wp.func
def _gap(points: wp.array[wp.vec3], p: int, pn: int, q: int, qn: int) -> float:
    """How far apart the two loops run at a step: the nearer of Q's vertex to P's edge and P's vertex to Q's edge."""
    a = _segment_distance(points[q], points[p], points[pn])
    b = _segment_distance(points[p], points[q], points[qn])
    return wp.min(a, b)


@wp.func
def _steps_ahead(
    points: wp.array[wp.vec3], q_next: wp.array[wp.int32], q: int, left: int, target: wp.vec3, near: float
) -> wp.vec2:
    """How many vertices ahead of ``q`` along Q (at most ``left``) the one nearest ``target`` is, and how far it is
    from it: the first minimum of the distance within ``near`` of it, walking on until ``PAST`` vertices have not come
    nearer (a minimum farther than ``near`` is a wiggle of Q, or Q's detour around a kept island it passes first: the
    walk goes on)."""
    best = wp.length(points[q] - target)
    best_t = int(0)
    walk = q
    for t in range(1, wp.min(left, AHEAD) + 1):
        walk = q_next[walk]
        d = wp.length(points[walk] - target)
        if d < best:
            best = d
            best_t = t
        if t - best_t >= PAST and best <= near:
            break
    return wp.vec2(float(best_t), best)


@wp.kernel(enable_backward=False)
def _zip_kernel(
    points: wp.array[wp.vec3],
    p_next: wp.array[wp.int32],
    q_next: wp.array[wp.int32],
    p_start: wp.array[wp.int32],
    q_any: wp.array[wp.int32],
    p_count: wp.array[wp.int32],
    q_count: wp.array[wp.int32],
    first: wp.array[wp.int32],
    near: float,
    tris: wp.array[wp.vec3i],
    gaps: wp.array[wp.float32],
):
    """One strip per loop pair: P walks a kept border loop as its faces list it, Q the voxel surface's loop against
    its faces' direction, from the Q vertex nearest P's start. Each step advances P while its next vertex is nearest
    Q's current one (:func:`_steps_ahead` 0: a zigzag of P, or a long straight edge's end, does not drag Q along or
    get left behind), Q while the vertex nearest P's next one lies two or more ahead, else the shorter diagonal."""
    k = wp.tid()
    p = p_start[k]
    n = p_count[k]
    m = q_count[k]
    # Q's start: its vertex nearest P's
    q = q_any[k]
    best = wp.length(points[q] - points[p])
    walk = q_next[q]
    for _ in range(m):
        d = wp.length(points[walk] - points[p])
        if d < best:
            best = d
            q = walk
        walk = q_next[walk]
    i = int(0)
    j = int(0)
    out = first[k]
    for _ in range(n + m):
        pn = p_next[p]
        qn = q_next[q]
        advance_p = j == m
        if i < n and j < m:
            found = _steps_ahead(points, q_next, q, m - j, points[pn], near)
            ahead = int(found[0])
            if found[1] > near and i + 1 < n:  # P's next is off Q: Q goes no farther than P's next but one needs
                ahead = wp.min(ahead, int(_steps_ahead(points, q_next, q, m - j, points[p_next[pn]], near)[0]))
            advance_p = ahead == 0
            if ahead == 1:
                advance_p = wp.length(points[pn] - points[q]) < wp.length(points[p] - points[qn])
        gaps[out] = _gap(points, p, pn, q, qn)
        if advance_p:
            tris[out] = wp.vec3i(pn, p, q)
            p = pn
            i += 1
        else:
            tris[out] = wp.vec3i(q, qn, p)
            q = qn
            j += 1
        out += 1


def zip_loops(points, p_next, q_next, p_start, q_any, p_count, q_count, device, near: float = np.inf):
    """The strips between paired loops (see :func:`_zip_kernel`): ``(tris, gaps)``, (sum of the loops' lengths, 3)
    int32 and per triangle float32 how far apart the two loops run there (:func:`_gap`). ``points`` and the
    ``*_next`` permutations index one vertex array; ``near``: see :func:`_steps_ahead`."""
    counts = np.asarray(p_count, dtype=np.int64) + np.asarray(q_count, dtype=np.int64)
    first = np.zeros(len(counts), dtype=np.int32)
    np.cumsum(counts[:-1], out=first[1:])
    out = wp.empty(int(counts.sum()), dtype=wp.vec3i, device=device)
    gaps = wp.empty(int(counts.sum()), dtype=wp.float32, device=device)
    if len(counts):

        def arr(values):
            return wp.array(np.ascontiguousarray(values, dtype=np.int32), dtype=wp.int32, device=device)

        wp.launch(
            _zip_kernel,
            len(counts),
            inputs=[
                wp.array(np.ascontiguousarray(points, dtype=np.float32), dtype=wp.vec3, device=device),
                *(arr(x) for x in (p_next, q_next, p_start, q_any, p_count, q_count, first)),
                float(min(near, 1e30)),
                out,
                gaps,
            ],
            device=device,
        )
    return out.numpy().reshape(-1, 3).astype(np.int32), gaps.numpy()


# Passes of :func:`unfolded` (each over every other pair of steps, then the others).
UNFOLD_PASSES = 2


def unfolded(points, strips: np.ndarray, counts, n_kept: int) -> np.ndarray:
    """``strips`` (:func:`zip_loops`: each loop pair's steps in turn, ``counts`` of them) with each two steps that fold
    over each other (facing opposite ways: a vertex of one loop inside the other's triangle, where the walk took the
    step the next one folds back over) flipped across the quadrilateral they make, when the flipped pair folds not:
    the strip's borders are the same, its diagonal the other one (between a kept vertex, below ``n_kept``, and a voxel
    one)."""
    tris = np.asarray(strips, dtype=np.int64).copy()
    p = np.asarray(points, dtype=np.float64)
    within = np.ones(max(len(tris) - 1, 0), dtype=bool)  # steps i and i + 1 of one strip
    within[(np.cumsum(counts) - 1)[:-1]] = False
    for parity in (0, 1) * UNFOLD_PASSES:
        normals = _normals(p, tris.T)
        folds = np.einsum("ij,ij->i", normals[:-1], normals[1:]) < 0.0
        i = np.flatnonzero(folds & within)
        i = i[i % 2 == parity]
        a, b = tris[i], tris[i + 1]
        # a = (x, u, w) and b = (y, w, u): x and y the corners the two do not share
        x_at = (~(a[:, :, None] == b[:, None, :]).any(axis=2)).argmax(axis=1)
        y_at = (~(b[:, :, None] == a[:, None, :]).any(axis=2)).argmax(axis=1)
        rows = np.arange(len(i))
        x, u, w = a[rows, x_at], a[rows, (x_at + 1) % 3], a[rows, (x_at + 2) % 3]
        y = b[rows, y_at]
        shared = (b[rows, (y_at + 1) % 3] == w) & (b[rows, (y_at + 2) % 3] == u) & (x != y)
        mixed = (x < n_kept) != (y < n_kept)
        flip = shared & mixed
        flip[flip] = np.einsum("ij,ij->i", _normals(p, (x, u, y))[flip], _normals(p, (y, w, x))[flip]) >= 0.0
        tris[i[flip]] = np.stack([x, u, y], axis=1)[flip]
        tris[i[flip] + 1] = np.stack([y, w, x], axis=1)[flip]
    return tris.astype(np.asarray(strips).dtype)


def _normals(p: np.ndarray, corners) -> np.ndarray:
    """(N, 3) the normals of the triangles of ``corners`` (three index arrays)."""
    a, b, c = (p[k] for k in corners)
    return np.cross(b - a, c - a)
