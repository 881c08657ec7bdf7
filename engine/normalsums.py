"""Faces' normals summed at their corners, in one Warp launch.

The join (:mod:`.hybrid`) reads the voxel surface's way at each of its vertices, and the adaptivity (:mod:`.adaptive`)
each cluster's, as the sums of the (area-weighted) normals of the faces about them. In numpy that is a gather, a
cross product, a repeat and a bincount per column: 17-30 ms for 100-160 k triangles, where one thread a face adding
its normal to its corners takes a few. The sums are float64, added face by face and corner by corner as numpy's
bincount adds them (on the CPU the same order, so the same sums; on a GPU the atomic additions' order varies).
Written by hand: a scatter-add is one of the few things Warp has no primitive for.
"""

from __future__ import annotations

import numpy as np
import warp as wp


@wp.kernel(enable_backward=False)
def _triangle_sums_kernel(
    points: wp.array(dtype=wp.vec3),
    tris: wp.array2d(dtype=wp.int32),
    first: int,
    out: wp.array(dtype=wp.vec3d),
):
    f = wp.tid()
    a, b, c = tris[f, 0], tris[f, 1], tris[f, 2]
    n = wp.cross(points[b] - points[a], points[c] - points[a])
    m = wp.vec3d(wp.float64(n[0]), wp.float64(n[1]), wp.float64(n[2]))
    wp.atomic_add(out, a - first, m)
    wp.atomic_add(out, b - first, m)
    wp.atomic_add(out, c - first, m)


@wp.kernel(enable_backward=False)
def _quad_sums_kernel(
    points: wp.array(dtype=wp.vec3d),
    corners: wp.array2d(dtype=wp.int32),
    out: wp.array(dtype=wp.vec3d),
):
    f = wp.tid()
    p0, p1, p2, p3 = corners[f, 0], corners[f, 1], corners[f, 2], corners[f, 3]
    n = wp.cross(points[p2] - points[p0], points[p3] - points[p1])
    wp.atomic_add(out, p0, n)
    wp.atomic_add(out, p1, n)
    wp.atomic_add(out, p2, n)
    wp.atomic_add(out, p3, n)


def triangle_normal_sums(points: np.ndarray, tris: np.ndarray, first: int = 0, device=None) -> np.ndarray:
    """(N, 3) float32: at each of ``points`` (N, 3) float32, the sum of the normals (``cross(b - a, c - a)``, float32:
    twice the area) of the triangles ``tris`` (T, 3) at it; zeros for points of none. The triangles use points from
    ``first`` on only."""
    out = np.zeros((len(points), 3), dtype=np.float32)
    typed = (points, np.float32, wp.vec3)
    out[first:] = _summed(_triangle_sums_kernel, typed, tris, len(points) - first, device, first)
    return out


def quad_normal_sums(points: np.ndarray, corners: np.ndarray, device=None) -> np.ndarray:
    """(N, 3) float64: at each of ``points`` (N, 3), the sum of the normals of the polygons ``corners`` (P, 4) at
    it (a quad's diagonals' cross product; a triangle given with its last corner repeated counts there twice)."""
    return _summed(_quad_sums_kernel, (points, np.float64, wp.vec3d), corners, len(points), device)


def _summed(kernel, points: tuple, corners: np.ndarray, n: int, device, *options) -> np.ndarray:
    """(n, 3) float64 the sums ``kernel`` adds up over the faces ``corners`` (``points``: the array, its numpy and
    Warp types; ``options`` go between the faces and the sums)."""
    sums = wp.zeros(n, dtype=wp.vec3d, device=device)
    if len(corners):
        values, np_type, wp_type = points
        inputs = [
            wp.array(np.ascontiguousarray(values, dtype=np_type), dtype=wp_type, device=device),
            wp.array(np.ascontiguousarray(corners, dtype=np.int32), dtype=wp.int32, device=device),
            *(int(x) for x in options),
            sums,
        ]
        wp.launch(kernel, dim=len(corners), inputs=inputs, device=device)
    return sums.numpy()
