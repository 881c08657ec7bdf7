"""Where a mesh passes through itself: the segments along which its triangles cross one another.

A shell that crosses itself (a teapot's spout through its body, two overlapping boxes given as one mesh, Suzanne's
eyes) has internal faces there, and its own field's surface turns along the crossing. Its faces are kept only a band
away from those segments, as from its other defects (:mod:`.keep`): a face that reaches the crossing is partly an
internal face, which the judge's samples a voxel apart could miss by a fraction of a voxel.

Written by hand: Warp's BVH finds the triangles whose boxes overlap each triangle, a kernel tests in float64 whether an
edge of either passes through the other's interior (triangles sharing a corner, and touching ones, do not count) and
lists the crossing pairs; numpy finds each pair's segment from the points where the edges pass through.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from .components import connected_components
from .parallel import launch_split

# Slots for the pairs of each triangle in the first pass (a triangle that crosses more is searched again).
PAIRS_ROOM = 4
# A search over this many triangles or more is split over the cores in balanced pieces: the queries that cost are the
# new faces' of a kept surface, which lie together (its uncrossing runs alone: plate - 4 bores 7.4 -> 5.1 ms, hex prism
# & sphere 7.1 -> 5.0).
PAIRS_SPLIT_MIN_DIM = 4096
# An edge passes through a triangle where it meets it this far inside its ends and the triangle's edges (a share of
# their lengths): touching is no crossing.
INSIDE = 1.0e-6


@wp.func
def _through(p: wp.vec3d, q: wp.vec3d, a: wp.vec3d, b: wp.vec3d, c: wp.vec3d) -> bool:
    """Whether the segment p-q meets triangle a-b-c at a point strictly inside both (Moller and Trumbore's test)."""
    d = q - p
    e1 = b - a
    e2 = c - a
    h = wp.cross(d, e2)
    det = wp.dot(e1, h)
    if wp.abs(det) <= wp.float64(1.0e-12) * wp.length(e1) * wp.length(e2) * wp.length(d):
        return False  # parallel, or degenerate
    s = p - a
    u = wp.dot(s, h) / det
    r = wp.cross(s, e1)
    v = wp.dot(d, r) / det
    t = wp.dot(e2, r) / det
    inside = wp.float64(INSIDE)
    one = wp.float64(1.0)
    return u > inside and v > inside and u + v < one - inside and t > inside and t < one - inside


@wp.func
def _corner(points: wp.array[wp.vec3], tris: wp.array2d[wp.int32], f: int, k: int) -> wp.vec3d:
    x = points[tris[f, k]]
    return wp.vec3d(wp.float64(x[0]), wp.float64(x[1]), wp.float64(x[2]))


@wp.func
def _crosses(points: wp.array[wp.vec3], tris: wp.array2d[wp.int32], f: int, g: int) -> bool:
    """Whether triangles ``f`` and ``g`` (sharing no corner) pass through each other."""
    for k in range(6):
        one = wp.where(k < 3, f, g)
        other = wp.where(k < 3, g, f)
        e = k % 3
        a = _corner(points, tris, other, 0)
        b = _corner(points, tris, other, 1)
        c = _corner(points, tris, other, 2)
        if _through(_corner(points, tris, one, e), _corner(points, tris, one, (e + 1) % 3), a, b, c):
            return True
    return False


@wp.kernel(enable_backward=False)
def _pairs_kernel(
    mesh: wp.uint64,
    points: wp.array[wp.vec3],
    tris: wp.array2d[wp.int32],
    rows: wp.array[wp.int32],
    member: wp.array[wp.uint8],
    which: wp.array[wp.int32],
    offset: int,
    room: int,
    count: wp.array[wp.int32],
    pairs: wp.array2d[wp.int32],
):
    """Per triangle ``f = which[i]``: how many triangles ``g`` of ``mesh`` (built on ``rows`` of ``tris``) sharing no
    corner with it it crosses, ``g > f`` where ``f`` is one of them too (``member``) (``count[i]``), the first ``room``
    of those pairs written to rows ``i * room`` on of ``pairs`` (one slot range a thread: no atomics across split
    launches)."""
    i = wp.tid() + offset
    f = which[i]
    lo = wp.min(wp.min(points[tris[f, 0]], points[tris[f, 1]]), points[tris[f, 2]])
    hi = wp.max(wp.max(points[tris[f, 0]], points[tris[f, 1]]), points[tris[f, 2]])
    query = wp.mesh_query_aabb(mesh, lo, hi)
    local = int(0)
    found = int(0)
    while wp.mesh_query_aabb_next(query, local):
        g = rows[local]
        if g == f or (member[f] != wp.uint8(0) and g < f):
            continue
        shared = False
        for a in range(3):
            for b in range(3):
                if tris[f, a] == tris[g, b]:
                    shared = True
        if not shared and _crosses(points, tris, f, g):
            if found < room:
                pairs[i * room + found, 0] = f
                pairs[i * room + found, 1] = g
            found += 1
    count[i] = found


def crossing_pairs(
    verts: np.ndarray, tris: np.ndarray, device, rows: np.ndarray | None = None, mesh=None
) -> np.ndarray:
    """(P, 2) int64 the pairs of triangles of a mesh ((V, 3), (T, 3) int) that pass through each other and share no
    corner (touching is no crossing), each pair once, in order of their first; with ``rows`` ((R,) ints), only the
    pairs with a triangle among those rows (the second of each pair). ``mesh``: Warp's mesh of all of them, where
    built already (no ``rows``)."""
    rows = np.arange(len(tris)) if rows is None else np.asarray(rows, dtype=np.int64)
    if not len(rows):
        return np.zeros((0, 2), dtype=np.int64)
    flat = np.ascontiguousarray(tris, dtype=np.int32)
    if mesh is None or len(rows) != len(tris):
        points_wp = wp.array(np.ascontiguousarray(verts, dtype=np.float32), dtype=wp.vec3, device=device)
        indices = wp.array(np.ascontiguousarray(flat[rows]).reshape(-1), dtype=wp.int32, device=device)
        mesh = wp.Mesh(points=points_wp, indices=indices)
    points_wp = mesh.points
    member = np.zeros(len(flat), dtype=np.uint8)
    member[rows] = 1
    args = [
        mesh.id,
        points_wp,
        wp.array(flat, dtype=wp.int32, device=device),
        wp.array(rows.astype(np.int32), dtype=wp.int32, device=device),
        wp.array(member, dtype=wp.uint8, device=device),
    ]
    # a triangle crossing more than its slots hold is searched again alone, with room for all of its pairs
    which = np.arange(len(flat), dtype=np.int32)
    count, pairs = _pairs_found(args, which, PAIRS_ROOM, device)
    over = np.flatnonzero(count > PAIRS_ROOM)
    found = _slots(which, count, pairs, PAIRS_ROOM)
    if len(over):
        again, more = _pairs_found(args, which[over], int(count[over].max()), device)
        found = np.concatenate([found, _slots(which[over], again, more, int(count[over].max()))])
        found = found[np.argsort(found[:, 0], kind="stable")]  # (in order of their first: each one's run as found)
    return found.astype(np.int64)


def _slots(which: np.ndarray, count: np.ndarray, pairs: np.ndarray, room: int) -> np.ndarray:
    """The pairs of each triangle of ``which`` whose slots hold them all (``count`` at most ``room``)."""
    rows = np.flatnonzero((count > 0) & (count <= room))
    held = pairs.reshape(len(which), room, 2)[rows]
    return held[np.arange(room)[None, :] < count[rows, None]]


def _pairs_found(args: list, which: np.ndarray, room: int, device) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_pairs_kernel` over the triangles ``which`` with ``room`` slots each: per triangle its count, and the
    slots."""
    n = len(which)
    which_wp = wp.array(np.ascontiguousarray(which, dtype=np.int32), dtype=wp.int32, device=device)
    count = wp.zeros(n, dtype=wp.int32, device=device)
    pairs = wp.empty((n * room, 2), dtype=wp.int32, device=device)
    inputs = lambda lo, _n: [*args, which_wp, lo, room, count, pairs]  # noqa: E731
    launch_split(_pairs_kernel, n, inputs, device, min_dim=PAIRS_SPLIT_MIN_DIM, balance=True)
    return count.numpy(), pairs.numpy()


def crossing_segments(verts: np.ndarray, tris: np.ndarray, device, shortest: float = 0.0, rows=None) -> np.ndarray:
    """(S, 2, 3) float32 the segments along which the triangles of a mesh ((V, 3), (T, 3) int; vertices at one
    position merged by the caller) pass through one another, one per crossing pair, those of crossing curves (the
    segments joined where they share an end: an edge of one triangle through another) at least ``shortest`` long
    (empty where none is); with ``rows``, only the pairs with a triangle among those rows (:func:`crossing_pairs`)."""
    pairs = crossing_pairs(verts, tris, device, rows)
    if not len(pairs):
        return np.zeros((0, 2, 3), dtype=np.float32)
    segments, ends = _segments(np.asarray(verts, dtype=np.float64), np.asarray(tris, dtype=np.int64), pairs)
    return segments[_curve_lengths(segments, ends, device) >= shortest].astype(np.float32)


def _segments(verts: np.ndarray, tris: np.ndarray, pairs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each crossing pair's segment, between the two points farthest apart where an edge of one triangle passes
    through the other (a transversal crossing has two), and (S, 2) int64 what each end is: the edge (its ends' key)
    and the triangle it passes through, as the neighbouring pair along the curve finds it too."""
    f, g = pairs[:, 0], pairs[:, 1]
    n, count = len(verts), len(tris)
    hits, found, names = [], [], []
    for one, other in ((f, g), (g, f)):
        a, b, c = (verts[tris[other, k]] for k in range(3))
        for k in range(3):
            u, w = tris[one, k], tris[one, (k + 1) % 3]
            point, ok = _edge_hits(verts[u], verts[w], a, b, c)
            hits.append(point)
            found.append(ok)
            names.append((np.minimum(u, w) * n + np.maximum(u, w)) * count + other)
    hits, found, names = np.stack(hits, axis=1), np.stack(found, axis=1), np.stack(names, axis=1)  # (S, 6, ...)
    rows = np.arange(len(pairs))
    first = np.argmax(found, axis=1)
    reach = np.where(found, np.linalg.norm(hits - hits[rows, first][:, None], axis=2), -1.0)
    last = np.argmax(reach, axis=1)
    segments = np.stack([hits[rows, first], hits[rows, last]], axis=1)
    return segments, np.stack([names[rows, first], names[rows, last]], axis=1)


def _curve_lengths(segments: np.ndarray, ends: np.ndarray, device) -> np.ndarray:
    """(S,) the length of the crossing curve each segment lies on: the segments joined through their shared ends."""
    _, node = np.unique(ends, return_inverse=True)
    node = node.reshape(-1, 2)
    curve = connected_components(int(node.max()) + 1, node[:, 0], node[:, 1], device)[node[:, 0]]
    length = np.linalg.norm(segments[:, 1] - segments[:, 0], axis=1)
    return np.bincount(curve, weights=length)[curve]


def _edge_hits(p, q, a, b, c) -> tuple[np.ndarray, np.ndarray]:
    """Where each segment p-q meets its triangle a-b-c (rows of (N, 3) each), and whether it does inside both."""
    d, e1, e2 = q - p, b - a, c - a
    h = np.cross(d, e2)
    det = np.einsum("ij,ij->i", e1, h)
    ok = np.abs(det) > 1e-12 * np.linalg.norm(e1, axis=1) * np.linalg.norm(e2, axis=1) * np.linalg.norm(d, axis=1)
    det = np.where(ok, det, 1.0)
    s = p - a
    r = np.cross(s, e1)
    u, v, t = np.einsum("ij,ij->i", s, h) / det, np.einsum("ij,ij->i", d, r) / det, np.einsum("ij,ij->i", e2, r) / det
    ok &= (u > INSIDE) & (v > INSIDE) & (u + v < 1.0 - INSIDE) & (t > INSIDE) & (t < 1.0 - INSIDE)
    return p + t[:, None] * d, ok
