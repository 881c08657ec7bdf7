"""Flatness of vertex components (:mod:`.adaptive`'s step 2) in Warp: the plane (or line) fitted through each
component's vertices, and whether every vertex lies within a tolerance of it.

Four launches over the members and the components replace a dozen whole-array passes of numpy (the moments'
sums, the batched eigenvectors, the distances): the moments are summed about a vertex of each component (no
cancellation of large coordinates), the covariance's eigenvectors (closed form) give the fitted plane's normal (the
smallest eigenvalue's) and a fitted line's direction (the largest's).
"""

from __future__ import annotations

import numpy as np
import warp as wp

from . import parallel


@wp.func
def _component(cluster: wp.array(dtype=wp.int32), comp: wp.array(dtype=wp.int32), i: int) -> int:
    """The component vertex ``i`` is tested in (its cluster's), -1 for none."""
    k = cluster[i]
    if k < 0:
        return -1
    return comp[k]


@wp.kernel(enable_backward=False)
def _last_member_kernel(
    cluster: wp.array(dtype=wp.int32), comp: wp.array(dtype=wp.int32), last: wp.array(dtype=wp.int32)
):
    i = wp.tid()
    c = _component(cluster, comp, i)
    if c >= 0:
        wp.atomic_max(last, c, i)


@wp.kernel(enable_backward=False)
def _sum_moments_kernel(
    points: wp.array(dtype=wp.vec3d),
    cluster: wp.array(dtype=wp.int32),
    comp: wp.array(dtype=wp.int32),
    last: wp.array(dtype=wp.int32),
    count: wp.array(dtype=wp.float64),
    first: wp.array(dtype=wp.vec3d),
    square: wp.array(dtype=wp.vec3d),
    cross: wp.array(dtype=wp.vec3d),
):
    i = wp.tid()
    c = _component(cluster, comp, i)
    if c < 0:
        return
    d = points[i] - points[last[c]]
    wp.atomic_add(count, c, wp.float64(1.0))
    wp.atomic_add(first, c, d)
    wp.atomic_add(square, c, wp.cw_mul(d, d))
    wp.atomic_add(cross, c, wp.vec3d(d[0] * d[1], d[0] * d[2], d[1] * d[2]))


@wp.func
def _eigenvector(c: wp.mat33d, value: wp.float64, scale: wp.float64) -> wp.vec3d:
    """The eigenvector of the symmetric ``c`` for its eigenvalue ``value``: the longest cross product of two rows of
    c - value I; zero where the eigenvalue is a double one (every cross product below ``scale``)."""
    r0 = wp.vec3d(c[0, 0] - value, c[0, 1], c[0, 2])
    r1 = wp.vec3d(c[1, 0], c[1, 1] - value, c[1, 2])
    r2 = wp.vec3d(c[2, 0], c[2, 1], c[2, 2] - value)
    best = wp.cross(r0, r1)
    v = wp.cross(r0, r2)
    if wp.dot(v, v) > wp.dot(best, best):
        best = v
    v = wp.cross(r1, r2)
    if wp.dot(v, v) > wp.dot(best, best):
        best = v
    if wp.length(best) <= scale:
        return wp.vec3d(0.0, 0.0, 0.0)
    return wp.normalize(best)


@wp.func
def _perpendicular(v: wp.vec3d) -> wp.vec3d:
    """A unit vector perpendicular to the unit ``v``."""
    other = wp.vec3d(1.0, 0.0, 0.0)
    if wp.abs(v[0]) > 0.8:
        other = wp.vec3d(0.0, 1.0, 0.0)
    return wp.normalize(wp.cross(v, other))


@wp.kernel(enable_backward=False)
def _fit_axes_kernel(
    count: wp.array(dtype=wp.float64),
    first: wp.array(dtype=wp.vec3d),
    square: wp.array(dtype=wp.vec3d),
    cross: wp.array(dtype=wp.vec3d),
    mean: wp.array(dtype=wp.vec3d),
    normal: wp.array(dtype=wp.vec3d),
    direction: wp.array(dtype=wp.vec3d),
):
    c = wp.tid()
    if count[c] == wp.float64(0.0):
        return  # a component not tested
    m = first[c] / count[c]
    s = square[c] / count[c]
    x = cross[c] / count[c]
    xy = x[0] - m[0] * m[1]
    xz = x[1] - m[0] * m[2]
    yz = x[2] - m[1] * m[2]
    cov = wp.mat33d(s[0] - m[0] * m[0], xy, xz, xy, s[1] - m[1] * m[1], yz, xz, yz, s[2] - m[2] * m[2])
    # the smallest and largest eigenvalues in closed form (Smith 1961)
    one, two, three = wp.float64(1.0), wp.float64(2.0), wp.float64(3.0)
    q = (cov[0, 0] + cov[1, 1] + cov[2, 2]) / three
    a0, a1, a2 = cov[0, 0] - q, cov[1, 1] - q, cov[2, 2] - q
    p = wp.sqrt((a0 * a0 + a1 * a1 + a2 * a2 + two * (xy * xy + xz * xz + yz * yz)) / wp.float64(6.0))
    n = wp.vec3d(0.0, 0.0, 1.0)
    d = wp.vec3d(1.0, 0.0, 0.0)
    if p > wp.float64(0.0):
        b = wp.mat33d(a0, xy, xz, xy, a1, yz, xz, yz, a2) / p
        phi = wp.acos(wp.clamp(wp.determinant(b) / two, -one, one)) / three
        scale = wp.float64(1.0e-9) * p * p
        n = _eigenvector(cov, q + two * p * wp.cos(phi + two * wp.float64(wp.pi) / three), scale)
        d = _eigenvector(cov, q + two * p * wp.cos(phi), scale)
        if wp.length(n) == wp.float64(0.0):
            n = _perpendicular(d)  # a line: any plane through it
        if wp.length(d) == wp.float64(0.0):
            d = _perpendicular(n)  # a disk: any line through it
    mean[c] = m
    normal[c] = n
    direction[c] = d


@wp.kernel(enable_backward=False)
def _flag_far_kernel(
    points: wp.array(dtype=wp.vec3d),
    cluster: wp.array(dtype=wp.int32),
    comp: wp.array(dtype=wp.int32),
    on_line: wp.array(dtype=wp.int8),
    last: wp.array(dtype=wp.int32),
    mean: wp.array(dtype=wp.vec3d),
    normal: wp.array(dtype=wp.vec3d),
    direction: wp.array(dtype=wp.vec3d),
    tol: wp.float64,
    far: wp.array(dtype=wp.int8),
):
    i = wp.tid()
    c = _component(cluster, comp, i)
    if c < 0:
        return
    d = points[i] - points[last[c]] - mean[c]
    dist = wp.abs(wp.dot(d, normal[c]))
    if on_line[i] != wp.int8(0):
        dist = wp.length(d - wp.dot(d, direction[c]) * direction[c])
    if dist > tol:
        far[c] = wp.int8(1)


def far_components(points, cluster, comp, on_line, m: int, tol: float, device=None) -> np.ndarray:
    """(m,) bool: the components with a vertex farther than ``tol`` from the plane fitted through their vertices
    (least squares, the moments summed about the component's last vertex), or with ``on_line`` from the line.

    Args:
        points: (V, 3) float64 vertex positions (or a Warp vec3d array of them).
        cluster: (V,) int the cluster of each vertex, -1 for none.
        comp: (K,) int the component each cluster is tested in, in 0 .. m - 1, or -1 for none.
        on_line: (V,) bool: the vertex's component is measured against its fitted line (a crease's).
        m: Number of components.
        tol: Largest distance allowed.
        device: Warp device (default: the current one).
    """
    device = wp.get_device(device)
    if not isinstance(points, wp.array):
        points = wp.array(np.ascontiguousarray(points, dtype=np.float64), dtype=wp.vec3d, device=device)
    if not isinstance(on_line, wp.array):
        on_line = wp.array(np.asarray(on_line, dtype=np.int8), dtype=wp.int8, device=device)
    n = len(points)
    if not n or not m:
        return np.zeros(m, dtype=bool)
    wp_cluster = wp.array(np.asarray(cluster, dtype=np.int32), dtype=wp.int32, device=device)
    wp_comp = wp.array(np.asarray(comp, dtype=np.int32), dtype=wp.int32, device=device)
    last = wp.full(m, -1, dtype=wp.int32, device=device)
    wp.launch(_last_member_kernel, dim=n, inputs=[wp_cluster, wp_comp, last], device=device)
    sums = [wp.zeros(m, dtype=wp.float64, device=device)]
    sums += [wp.zeros(m, dtype=wp.vec3d, device=device) for _ in range(3)]
    shared = [points, wp_cluster, wp_comp]
    wp.launch(_sum_moments_kernel, dim=n, inputs=[*shared, last, *sums], device=device)
    axes = [wp.zeros(m, dtype=wp.vec3d, device=device) for _ in range(3)]
    fitted = [*sums, *axes]  # each component's own: split over the CPU's cores
    parallel.launch_split(_fit_axes_kernel, m, lambda lo, k: [x[lo : lo + k] for x in fitted], device)
    far = wp.zeros(m, dtype=wp.int8, device=device)
    wp.launch(_flag_far_kernel, dim=n, inputs=[*shared, on_line, last, *axes, wp.float64(tol), far], device=device)
    return far.numpy().astype(bool)
