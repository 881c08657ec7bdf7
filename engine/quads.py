"""Quads of the dual surface: each crossed lattice edge's quad kept whole where splitting it changes nothing.

Dual contouring (:mod:`.dual`) makes one quad per crossed lattice edge and writes it as two triangles (rows 2q and
2q + 1, split along the diagonal its vertices' planes fit best). Most of those quads are nearly planar and convex:
either diagonal gives the same surface, so they are polygons of their own, as Blender's Voxel Remesh writes them. A
quad stays two triangles where the split matters:

* its two triangles fold by more than :data:`QUAD_ANGLE` degrees across either diagonal (a crease or corner runs
  through it: every reconstructed crease edge folds by more, or it is twisted), or one split turns a triangle over
  (a non-convex quad);
* it is split around a tunnel's vertex (:func:`.meshcheck.open_tunnels`).

The test runs in ``dual._quads_kernel``, where the quad's corners are at hand (``whole``).

A quad kept whole starts at an end of the diagonal it was split along, so triangulating the polygons again (fans,
:func:`triangulate`) gives the same triangles back. The polygons
share their edges exactly as the triangles do (a merged pair only loses its inner diagonal), so they are as closed
and as 2-manifold as the triangles.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from .parallel import host_view, launch_split

# Largest angle (degrees) between the two triangles of a quad, along either diagonal, for it to stay one polygon:
# well below the crease angle (quadric.CREASE_ANGLE, 25), so no reconstructed crease runs through a polygon; above
# the bend of a quad on a sphere of 4 voxels' radius.
QUAD_ANGLE = 20.0


def merge_pairs(tris, whole) -> tuple[np.ndarray, np.ndarray]:
    """Polygons of a dual surface: the quads flagged ``whole`` kept whole, first, then the other triangles in order.

    Args:
        tris: (T, 3) int triangles; for q < len(whole) rows 2q and 2q + 1 are the halves of quad q0 q1 q2 q3, split
            along q0-q2 (``q0 q1 q2``, ``q0 q2 q3``) or along q1-q3 (``q0 q1 q3``, ``q1 q2 q3``); the rows after
            them are triangles of their own.
        whole: (Q,) uint8 per quad (``dual.contour_dual``): 0 to leave it split, 1 or 2 to keep it whole (split
            along q0-q2 or q1-q3).
    Returns:
        ``faces`` (C,) int32 corner vertices, face after face, and ``sizes`` (P,) int32 corners per face (4 or 3).
        A quad starts at an end of its diagonal (``q0 q1 q2 q3`` or ``q1 q2 q3 q0``): its fan is its two rows.
    """
    tris = np.ascontiguousarray(tris, dtype=np.int32).reshape(-1, 3)
    whole = np.ascontiguousarray(whole, dtype=np.uint8)
    n_quads, rest = len(whole), len(tris) - 2 * len(whole)
    kept = whole != 0
    before = np.cumsum(kept, dtype=np.int32) - kept  # whole quads before each quad
    n_whole = int(np.count_nonzero(kept))
    faces = np.empty(4 * n_whole + 3 * (2 * (n_quads - n_whole) + rest), dtype=np.int32)
    sizes = np.empty(n_whole + 2 * (n_quads - n_whole) + rest, dtype=np.int32)
    if n_quads:
        _on_host(_merge_pairs_kernel, n_quads, [tris.reshape(-1), whole, before], n_whole, [faces, sizes])
    faces[len(faces) - 3 * rest :] = tris[2 * n_quads :].reshape(-1)
    sizes[len(sizes) - rest :] = 3
    return faces, sizes


def triangulate(faces, sizes) -> np.ndarray:
    """(T, 3) int32 fans of polygons (``faces`` (C,) corners, ``sizes`` (P,)): each polygon ``a b c ...`` as
    ``a b c``, ``a c d``, ... (a quad of :func:`merge_pairs` gives back its two rows)."""
    faces = np.ascontiguousarray(faces, dtype=np.int32)
    sizes = np.ascontiguousarray(sizes, dtype=np.int32)
    count = np.maximum(sizes - 2, 0)
    tri_start = (np.cumsum(count) - count).astype(np.int32)
    corner_start = (np.cumsum(sizes) - sizes).astype(np.int32)
    out = np.empty((int(count.sum()), 3), dtype=np.int32)
    if len(sizes):
        _on_host(_fans_kernel, len(sizes), [faces, sizes, corner_start, tri_start], 0, [out.reshape(-1)])
    return out


def _on_host(kernel, n: int, inputs: list, value: int, outputs: list) -> None:
    """Launch a host ``kernel`` over ``n`` rows of numpy arrays (read and written in place) on the CPU's cores: the
    polygons are the extraction's host arrays whatever the field's device, and numpy's gathers of their corners took
    5-10 ms on a 150 k-triangle surface (the kernels 0.6)."""
    cpu = wp.get_device("cpu")
    args = [host_view(a, wp.dtype_from_numpy(a.dtype), cpu) for a in inputs + outputs]
    k = len(inputs)
    launch_split(kernel, n, lambda lo, _n: [*args[:k], value, lo, *args[k:]], cpu)


@wp.kernel(enable_backward=False)
def _merge_pairs_kernel(
    tris: wp.array[wp.int32],
    whole: wp.array[wp.uint8],
    before: wp.array[wp.int32],
    n_whole: int,
    offset: int,
    faces: wp.array[wp.int32],
    sizes: wp.array[wp.int32],
):
    """Quad ``q``'s polygon: whole at row ``before[q]``, else its two rows after all whole quads. A whole quad's
    corners in its two rows ``a b c``, ``d e f``: split along q0-q2 (``q0 q1 q2``, ``q0 q2 q3``) ``a b c f``, along
    q1-q3 (``q0 q1 q3``, ``q1 q2 q3``) ``d e f a``."""
    q = wp.tid() + offset
    r = 6 * q
    k = before[q]
    w = int(whole[q])
    if w == 0:
        s = q - k  # split quads before this one
        o = 4 * n_whole + 6 * s
        for j in range(6):
            faces[o + j] = tris[r + j]
        sizes[n_whole + 2 * s] = 3
        sizes[n_whole + 2 * s + 1] = 3
    else:
        o = 4 * k
        first = wp.where(w == 1, 0, 3)
        for j in range(3):
            faces[o + j] = tris[r + first + j]
        faces[o + 3] = tris[r + wp.where(w == 1, 5, 0)]
        sizes[k] = 4


@wp.kernel(enable_backward=False)
def _fans_kernel(
    faces: wp.array[wp.int32],
    sizes: wp.array[wp.int32],
    corner_start: wp.array[wp.int32],
    tri_start: wp.array[wp.int32],
    unused: int,
    offset: int,
    out: wp.array[wp.int32],
):
    """Polygon ``p``'s fan about its first corner, from row ``tri_start[p]``."""
    p = wp.tid() + offset
    c = corner_start[p]
    t = 3 * tri_start[p]
    for k in range(sizes[p] - 2):
        out[t + 3 * k] = faces[c]
        out[t + 3 * k + 1] = faces[c + k + 1]
        out[t + 3 * k + 2] = faces[c + k + 2]


# A kept surface's per-face arrays (:func:`.hybrid.kept_surface`).
KEPT_FACE_KEYS = ("tris", "kept", "field_id", "triangle_id", "corner_bary", "voxel_face")


def quad_halves_first(surface: dict) -> dict:
    """A kept surface with its new faces that are both halves of one quad of its voxel surface (``voxel_face`` 2q and
    2q + 1) first, each pair as rows ``a b c``, ``a c d`` (so a writer can join them as :func:`triangulate` split
    them); ``quads``: how many pairs."""
    voxel_face = surface["voxel_face"]
    if _in_order(surface["tris"], voxel_face):  # (a voxel surface as extracted: its rows as they are)
        return {**surface, "quads": len(voxel_face[voxel_face >= 0]) // 2}
    rows = np.flatnonzero(voxel_face >= 0)
    rows = rows[np.argsort(voxel_face[rows], kind="stable")]
    quad = voxel_face[rows] // 2
    start = np.flatnonzero(quad[1:] == quad[:-1])
    first, second = rows[start], rows[start + 1]
    turn_first, turn_second = _quad_turns(surface["tris"][first], surface["tris"][second])
    whole = (turn_first >= 0) & (turn_second >= 0)
    first, second, turn_first, turn_second = first[whole], second[whole], turn_first[whole], turn_second[whole]
    rest = np.ones(len(surface["tris"]), dtype=bool)
    rest[first] = rest[second] = False
    order = np.r_[np.stack([first, second], axis=1).ravel(), np.flatnonzero(rest)]
    pairs = 2 * len(first)  # only the pairs' rows turn (the rest keep their corners as they are)
    turn = np.stack([turn_first, turn_second], axis=1).ravel()
    corners = (turn[:, None] + np.arange(3)) % 3
    out = dict(surface)
    for key in KEPT_FACE_KEYS:
        out[key] = surface[key][order]
    out["tris"][:pairs] = np.take_along_axis(out["tris"][:pairs], corners, axis=1)
    out["corner_bary"][:pairs] = np.take_along_axis(out["corner_bary"][:pairs], corners[:, :, None], axis=1)
    out["quads"] = len(first)
    return out


def _in_order(tris: np.ndarray, voxel_face: np.ndarray) -> bool:
    """Whether the rows of a surface are already as :func:`quad_halves_first` orders them: rows 2q and 2q + 1 the
    halves ``a b c``, ``a c d`` of quad q (four corners apart) up to some 2Q, no other row a quad's half (a voxel
    surface as :func:`triangulate` splits its quads, where nothing was kept: 48 ms to gather again 167 k rows in the
    order they have)."""
    halves = int(np.count_nonzero(voxel_face >= 0))
    if halves % 2 or not np.array_equal(voxel_face[:halves], np.arange(halves)):
        return False
    (a, b, c), (a2, c2, d) = tris[0:halves:2].T, tris[1:halves:2].T
    return bool(((a == a2) & (c == c2) & (a != b) & (a != c) & (b != c) & (d != a) & (d != b) & (d != c)).all())


def _quad_turns(t1: np.ndarray, t2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """How far to turn each pair's corners to read ``a b c`` and ``a c d`` (two triangles sharing the edge a-c, the
    same way round); -1 where they are not such a pair."""
    shared = (t1[:, :, None] == t2[:, None, :]).any(axis=2)  # (Q, 3) corners of t1 also in t2
    b = np.argmin(shared, axis=1)  # the corner of t1 not in t2
    turn1 = (b - 1) % 3
    abc = np.take_along_axis(t1, (turn1[:, None] + np.arange(3)) % 3, axis=1)
    at_a = t2 == abc[:, :1]
    turn2 = np.argmax(at_a, axis=1)
    acd = np.take_along_axis(t2, (turn2[:, None] + np.arange(3)) % 3, axis=1)
    ok = (shared.sum(axis=1) == 2) & at_a.any(axis=1) & (acd[:, 1] == abc[:, 2])
    return np.where(ok, turn1, -1), np.where(ok, turn2, -1)


def polygon_edges(faces, sizes) -> np.ndarray:
    """(C, 2) int64 directed edges of polygons: each corner to the next corner of its face."""
    faces = np.asarray(faces, dtype=np.int64)
    sizes = np.asarray(sizes, dtype=np.int64)
    start = np.repeat(np.cumsum(sizes) - sizes, sizes)
    within = np.arange(len(faces)) - start
    nxt = start + (within + 1) % np.repeat(sizes, sizes)
    return np.stack([faces, faces[nxt]], axis=1)
