"""The quadric error function of dual contouring and the crease edges it finds, for :mod:`.dual`.

Warp functions that place a vertex at the minimiser of its tangent planes (Ju et al. 2002: relative to the mass
point, small eigenvalues truncated), kept in a box; the trilinear interpolant of a cube; and :func:`crease_edges`,
which picks the mesh edges along which the extracted surface folds.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from .marching import CORNER_OFFSETS

# Crease edges fold by more than this angle (degrees) between their two triangles' normals.
CREASE_ANGLE = 25.0


vec8 = wp.types.vector(length=8, dtype=wp.float32)


# A quadric in 10 floats: the upper triangle of A (a00, a01, a02, a11, a12, a22), then a vector and a constant. A sum
# of planes' terms (plane_terms) holds A^T A, A^T b and b.b; a vertex's quadric about itself (pack_quadric) holds A,
# the linear part r and the constant of E(x + d) = d^T A d + 2 d . r + E(x), per plane.
vec10 = wp.types.vector(length=10, dtype=wp.float32)


@wp.func
def plane_terms(n: wp.vec3, b: float):
    """What plane n.x = b adds to a sum of squared distances, as :data:`vec10`: n n^T (upper triangle), n b, b b."""
    return vec10(
        n[0] * n[0],
        n[0] * n[1],
        n[0] * n[2],
        n[1] * n[1],
        n[1] * n[2],
        n[2] * n[2],
        n[0] * b,
        n[1] * b,
        n[2] * b,
        b * b,
    )


@wp.func
def unpack_terms(s: vec10):
    """(A^T A, A^T b, b.b) of a sum of :func:`plane_terms`."""
    return wp.mat33(s[0], s[1], s[2], s[1], s[3], s[4], s[2], s[4], s[5]), wp.vec3(s[6], s[7], s[8]), s[9]


# Bit c of these is corner c's offset along x, y, z (CORNER_OFFSETS as integer constants, no table reads).
_BITS_X = int(sum(int(CORNER_OFFSETS[c][0]) << c for c in range(8)))
_BITS_Y = int(sum(int(CORNER_OFFSETS[c][1]) << c for c in range(8)))
_BITS_Z = int(sum(int(CORNER_OFFSETS[c][2]) << c for c in range(8)))


@wp.func
def cube_corner(c: int):
    """Local position of cube corner ``c`` (its ``CORNER_OFFSETS`` row)."""
    return wp.vec3(float((_BITS_X >> c) & 1), float((_BITS_Y >> c) & 1), float((_BITS_Z >> c) & 1))


# trilinear spells the corners out in this order (Warp's marching cubes order)
_TRILINEAR_ORDER = ((0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1))
if tuple(tuple(int(x) for x in row) for row in CORNER_OFFSETS) != _TRILINEAR_ORDER:
    raise ImportError("engine.quadric expects Warp's marching-cubes corner order")


@wp.func
def trilinear(v: vec8, p: wp.vec3):
    """Value and gradient of the trilinear interpolant of a cube's corner values ``v`` at local point ``p``."""
    x = p[0]
    y = p[1]
    z = p[2]
    d00 = v[1] - v[0]  # along x at (y, z) = (0, 0), (1, 0), (0, 1), (1, 1)
    d10 = v[2] - v[3]
    d01 = v[5] - v[4]
    d11 = v[6] - v[7]
    a00 = v[0] + x * d00
    a10 = v[3] + x * d10
    a01 = v[4] + x * d01
    a11 = v[7] + x * d11
    b0 = a00 + y * (a10 - a00)
    b1 = a01 + y * (a11 - a01)
    gx = (1.0 - z) * (d00 + y * (d10 - d00)) + z * (d01 + y * (d11 - d01))
    gy = (1.0 - z) * (a10 - a00) + z * (a11 - a01)
    return b0 + z * (b1 - b0), wp.vec3(gx, gy, b1 - b0)


@wp.func
def clip_line(x: wp.vec3, d: wp.vec3, lo: wp.vec3, hi: wp.vec3):
    """Parameter interval [s0, s1] of the line x + s d inside the box [lo, hi] (s0 > s1 when it misses)."""
    s0 = float(-1.0e30)
    s1 = float(1.0e30)
    for a in range(3):
        if wp.abs(d[a]) < 1.0e-8:
            if x[a] < lo[a] or x[a] > hi[a]:
                s0 = 1.0
                s1 = -1.0
        else:
            t0 = (lo[a] - x[a]) / d[a]
            t1 = (hi[a] - x[a]) / d[a]
            s0 = wp.max(s0, wp.min(t0, t1))
            s1 = wp.min(s1, wp.max(t0, t1))
    return wp.vec2(s0, s1)


@wp.func
def inside_box(x: wp.vec3, lo: wp.vec3, hi: wp.vec3):
    return x[0] >= lo[0] and x[0] <= hi[0] and x[1] >= lo[1] and x[1] <= hi[1] and x[2] >= lo[2] and x[2] <= hi[2]


@wp.func
def clamp_box(x: wp.vec3, lo: float, hi: float):
    return wp.vec3(wp.clamp(x[0], lo, hi), wp.clamp(x[1], lo, hi), wp.clamp(x[2], lo, hi))


@wp.func
def _eigenvector_for(
    a00: wp.float64,
    a01: wp.float64,
    a02: wp.float64,
    a11: wp.float64,
    a12: wp.float64,
    a22: wp.float64,
    lam: wp.float64,
):
    """Unit eigenvector of the symmetric matrix (a00 a01 a02; . a11 a12; . . a22) for its eigenvalue ``lam``, one of
    multiplicity 1: the largest cross product of two rows of A - lam I."""
    r0 = wp.vec3d(a00 - lam, a01, a02)
    r1 = wp.vec3d(a01, a11 - lam, a12)
    r2 = wp.vec3d(a02, a12, a22 - lam)
    v = wp.cross(r0, r1)
    best = wp.dot(v, v)
    c = wp.cross(r0, r2)
    if wp.dot(c, c) > best:
        v = c
        best = wp.dot(c, c)
    c = wp.cross(r1, r2)
    if wp.dot(c, c) > best:
        v = c
        best = wp.dot(c, c)
    if best <= wp.float64(0.0):
        return wp.vec3d(wp.float64(1.0), wp.float64(0.0), wp.float64(0.0))
    return v / wp.sqrt(best)


@wp.func
def _eigenvector_across(
    a00: wp.float64,
    a01: wp.float64,
    a02: wp.float64,
    a11: wp.float64,
    a12: wp.float64,
    a22: wp.float64,
    w: wp.vec3d,
    lam: wp.float64,
):
    """Unit eigenvector for eigenvalue ``lam`` orthogonal to the unit eigenvector ``w``: the null vector of A - lam I
    restricted to the plane orthogonal to ``w`` (a 2x2 problem, well posed even where ``lam`` is repeated)."""
    zero = wp.float64(0.0)
    u = wp.vec3d(zero)
    if wp.abs(w[0]) > wp.abs(w[1]):
        s = wp.float64(1.0) / wp.sqrt(w[0] * w[0] + w[2] * w[2])
        u = wp.vec3d(-w[2] * s, zero, w[0] * s)
    else:
        s = wp.float64(1.0) / wp.sqrt(w[1] * w[1] + w[2] * w[2])
        u = wp.vec3d(zero, w[2] * s, -w[1] * s)
    v = wp.cross(w, u)
    au = wp.vec3d(
        a00 * u[0] + a01 * u[1] + a02 * u[2], a01 * u[0] + a11 * u[1] + a12 * u[2], a02 * u[0] + a12 * u[1] + a22 * u[2]
    )
    av = wp.vec3d(
        a00 * v[0] + a01 * v[1] + a02 * v[2], a01 * v[0] + a11 * v[1] + a12 * v[2], a02 * v[0] + a12 * v[1] + a22 * v[2]
    )
    m00 = wp.dot(u, au) - lam
    m01 = wp.dot(u, av)
    m11 = wp.dot(v, av) - lam
    # the null vector (c, s) of [[m00, m01], [m01, m11]], from its larger row
    if wp.abs(m00) >= wp.abs(m11):
        if wp.abs(m00) + wp.abs(m01) > zero:
            return wp.normalize(m01 * u - m00 * v)
        return u
    if wp.abs(m11) + wp.abs(m01) > zero:
        return wp.normalize(m11 * u - m01 * v)
    return u


@wp.func
def eigen_sym3(m: wp.mat33):
    """Eigenvalues, largest first, and unit eigenvectors (e0, e1, e2, right-handed) of a symmetric 3x3 matrix, in
    closed form (the trigonometric solution of the characteristic cubic, then cross products: Eberly, "A robust
    eigensolver for 3x3 symmetric matrices", 2014), in double precision: accurate to float rounding of the largest
    eigenvalue, where Warp's ``eig3`` (four Jacobi sweeps in float) is off by up to 1e-4 of it and costs twice as
    much."""
    a00 = wp.float64(m[0, 0])
    a01 = wp.float64(m[0, 1])
    a02 = wp.float64(m[0, 2])
    a11 = wp.float64(m[1, 1])
    a12 = wp.float64(m[1, 2])
    a22 = wp.float64(m[2, 2])
    scale = wp.max(
        wp.max(wp.max(wp.abs(a00), wp.abs(a01)), wp.max(wp.abs(a02), wp.abs(a11))), wp.max(wp.abs(a12), wp.abs(a22))
    )
    ex = wp.vec3(1.0, 0.0, 0.0)
    ey = wp.vec3(0.0, 1.0, 0.0)
    ez = wp.vec3(0.0, 0.0, 1.0)
    if scale <= wp.float64(0.0):
        return wp.vec3(0.0), ex, ey, ez
    inv = wp.float64(1.0) / scale
    a00 = a00 * inv
    a01 = a01 * inv
    a02 = a02 * inv
    a11 = a11 * inv
    a12 = a12 * inv
    a22 = a22 * inv
    q = (a00 + a11 + a22) / wp.float64(3.0)
    b00 = a00 - q
    b11 = a11 - q
    b22 = a22 - q
    p = wp.sqrt(
        (b00 * b00 + b11 * b11 + b22 * b22 + wp.float64(2.0) * (a01 * a01 + a02 * a02 + a12 * a12)) / wp.float64(6.0)
    )
    if p <= wp.float64(1.0e-12):  # a multiple of the identity
        return wp.vec3(wp.float32(q * scale)), ex, ey, ez
    # det(B / p) / 2 = cos(3 angle), B = A - q I
    c00 = b11 * b22 - a12 * a12
    c01 = a01 * b22 - a12 * a02
    c02 = a01 * a12 - b11 * a02
    half_det = wp.clamp(
        (b00 * c00 - a01 * c01 + a02 * c02) / (wp.float64(2.0) * p * p * p), wp.float64(-1.0), wp.float64(1.0)
    )
    angle = wp.acos(half_det) / wp.float64(3.0)
    beta0 = wp.float64(2.0) * wp.cos(angle)  # largest
    beta2 = wp.float64(2.0) * wp.cos(angle + wp.float64(2.0943951023931954923))  # smallest
    l0 = q + p * beta0
    l1 = q - p * (beta0 + beta2)
    l2 = q + p * beta2
    e0 = wp.vec3d(wp.float64(0.0))
    e1 = wp.vec3d(wp.float64(0.0))
    e2 = wp.vec3d(wp.float64(0.0))
    if half_det >= wp.float64(0.0):  # the largest eigenvalue is the better separated one: its vector first
        e0 = _eigenvector_for(a00, a01, a02, a11, a12, a22, l0)
        e1 = _eigenvector_across(a00, a01, a02, a11, a12, a22, e0, l1)
        e2 = wp.cross(e0, e1)
    else:
        e2 = _eigenvector_for(a00, a01, a02, a11, a12, a22, l2)
        e1 = _eigenvector_across(a00, a01, a02, a11, a12, a22, e2, l1)
        e0 = wp.cross(e1, e2)
    d = wp.vec3(wp.float32(l0 * scale), wp.float32(l1 * scale), wp.float32(l2 * scale))
    return d, wp.vec3(e0), wp.vec3(e1), wp.vec3(e2)


@wp.func
def solve_in_cube(
    ata: wp.mat33, rhs: wp.vec3, mass: wp.vec3, cutoff: float, lo: float, hi: float, wide_lo: wp.vec3, wide_hi: wp.vec3
):
    """Minimiser of |A x - b|^2 near the mass point (``rhs = A^T b - A^T A mass``): the truncated pseudo-inverse
    solution if it lies in the box [wide_lo, wide_hi]; else the solution line of the two largest eigenvalues clipped
    to that box; else the point of rank 1 clamped to the cube [lo, hi]^3. Returns (x, rank used, 0 where that is
    the last because the crease missed the box, else 1)."""
    d, e0, e1, e2 = eigen_sym3(ata)
    top = d[0]
    x = mass
    if top <= 0.0:
        return clamp_box(x, lo, hi), 0, 1
    rank = int(1)
    if d[1] > cutoff * top:
        rank = 2
    if d[2] > cutoff * top:
        rank = 3
    x1 = mass + e0 * (wp.dot(e0, rhs) / top)
    x2 = x1
    if rank >= 2:
        x2 = x1 + e1 * (wp.dot(e1, rhs) / d[1])
    x3 = x2
    if rank == 3:
        x3 = x2 + e2 * (wp.dot(e2, rhs) / d[2])
        if inside_box(x3, wp.vec3(lo), wp.vec3(hi)):
            return x3, 3, 1
    if rank >= 2:
        # the crease line through the cube, else through the box that reaches into the empty neighbours: the point
        # nearest the mass point within the middle half of the part inside, so that the crease vertices of
        # neighbouring cubes never crowd together at the face between them
        s = clip_line(x2, e2, wp.vec3(0.0), wp.vec3(1.0))
        if s[0] > s[1]:
            s = clip_line(x2, e2, wide_lo, wide_hi)
        if s[0] <= s[1]:
            quarter = 0.25 * (s[1] - s[0])
            t = wp.clamp(0.0, s[0] + quarter, s[1] - quarter)
            return x2 + t * e2, 2, 1
    return clamp_box(x1, lo, hi), 1, wp.where(rank == 1, 1, 0)


@wp.func
def is_smooth(ata: wp.mat33, normal_sum: wp.vec3, min_cos: float, smooth_cos: float, cutoff: float):
    """Whether a quadric is of rank 1: all its (heavy) normals within ``smooth_cos`` of the first, or, for sure, the
    planes' spread about their mean normal small (the mean normal's Rayleigh quotient bounds the largest eigenvalue
    from below, the trace less it the other two from above)."""
    if min_cos >= smooth_cos:
        return True
    mean = wp.normalize(normal_sum)
    lam = wp.dot(mean, ata * mean)
    return ata[0, 0] + ata[1, 1] + ata[2, 2] - lam <= cutoff * lam


@wp.func
def solve_smooth(ata: wp.mat33, rhs: wp.vec3, mass: wp.vec3, normal_sum: wp.vec3):
    """The rank-1 minimiser when all normals nearly agree: the mass point moved along their mean normal."""
    e0 = wp.normalize(normal_sum)
    lam = wp.dot(e0, ata * e0)
    if lam <= 0.0:
        return mass
    return mass + e0 * (wp.dot(e0, rhs) / lam)


@wp.func
def pack_quadric(ata: wp.mat33, atb: wp.vec3, btb: float, x: wp.vec3, w: float):
    """The quadric of planes (sum of squared distances |A x - b|^2: ``ata`` = A^T A, ``atb`` = A^T b, ``btb`` =
    b.b) about ``x``, times ``w`` (one over the number of planes), as :data:`vec10`."""
    grad = ata * x - atb
    ex = wp.dot(x, ata * x) - 2.0 * wp.dot(x, atb) + btb
    q = vec10()
    q[0] = ata[0, 0] * w
    q[1] = ata[0, 1] * w
    q[2] = ata[0, 2] * w
    q[3] = ata[1, 1] * w
    q[4] = ata[1, 2] * w
    q[5] = ata[2, 2] * w
    q[6] = grad[0] * w
    q[7] = grad[1] * w
    q[8] = grad[2] * w
    q[9] = wp.max(ex * w, 0.0)
    return q


@wp.func
def fold_cos(a: wp.vec3, b: wp.vec3, c: wp.vec3, d: wp.vec3):
    """Cosine of the angle between triangles ``a b c`` and ``a c d`` (-1 where either is degenerate)."""
    n1 = wp.cross(b - a, c - a)
    n2 = wp.cross(c - a, d - a)
    den = wp.length(n1) * wp.length(n2)
    return wp.where(den > 0.0, wp.dot(n1, n2) / wp.max(den, 1.0e-30), -1.0)


@wp.func
def quadric_at(q: vec10, d: wp.vec3):
    """Mean squared distance (in voxels^2) to a vertex's planes of the point ``d`` voxels from it (``q`` from
    :func:`pack_quadric`)."""
    x = d[0]
    y = d[1]
    z = d[2]
    quad = q[0] * x * x + q[3] * y * y + q[5] * z * z + 2.0 * (q[1] * x * y + q[2] * x * z + q[4] * y * z)
    return quad + 2.0 * (x * q[6] + y * q[7] + z * q[8]) + q[9]


def _normals(verts, tris) -> np.ndarray:
    """(T, 3) float64 unnormalised normals of triangles ``tris`` (the cross product written out: numpy's ``cross``
    costs twice as much on a few thousand rows)."""
    p = np.asarray(verts)[tris].astype(np.float64)  # (gathered first: converting every vertex cost as much again)
    e1, e2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
    return np.stack(
        [
            e1[:, 1] * e2[:, 2] - e1[:, 2] * e2[:, 1],
            e1[:, 2] * e2[:, 0] - e1[:, 0] * e2[:, 2],
            e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0],
        ],
        axis=1,
    )


def crease_edges(verts, tris, ranks, angle: float = CREASE_ANGLE, *, folds: bool = False):
    """The edges of a closed mesh along which it folds at a reconstructed crease.

    Args:
        verts: (V, 3) float vertex positions.
        tris: (T, 3) int triangles of a closed, consistently oriented mesh.
        ranks: (V,) int quadric ranks from :func:`contour_dual` (2 or more: on a crease or corner).
        angle: Smallest angle (degrees) between the two triangles' normals.
        folds: Also return each edge's angle.
    Returns:
        (E, 2) int32 vertex index pairs (smaller index first), each an edge of ``tris`` between two crease or corner
        vertices whose triangles' normals differ by more than ``angle``; with ``folds`` also (E,) float64 that angle
        (degrees).
    """
    tris = np.asarray(tris)
    feature = np.asarray(ranks) >= 2
    none = np.zeros((0, 2), dtype=np.int32)
    if len(tris) == 0 or not feature.any():
        return (none, np.zeros(0)) if folds else none
    # the triangle sides between two feature vertices, each undirected edge seen from both of its triangles (only the
    # triangles with two feature corners are looked at, a few percent of them)
    on = feature.view(np.uint8)[tris]
    candidates = np.flatnonzero(on[:, 0] + on[:, 1] + on[:, 2] >= 2)
    corners = tris[candidates]
    following = corners[:, [1, 2, 0]]
    keep = (feature[corners] & feature[following]).ravel()
    a, b = corners.ravel()[keep].astype(np.int64), following.ravel()[keep].astype(np.int64)
    face = np.repeat(candidates, 3)[keep]
    low, high = np.minimum(a, b), np.maximum(a, b)
    code = low * np.int64(len(verts)) + high
    order = np.argsort(code)
    twin = np.flatnonzero(code[order][1:] == code[order][:-1])  # an edge's two sides, next to each other sorted
    if len(twin) == 0:
        return (none, np.zeros(0)) if folds else none
    first, second = order[twin], order[twin + 1]
    na, nb = _normals(verts, tris[face[first]]), _normals(verts, tris[face[second]])
    cos = np.einsum("ij,ij->i", na, nb) / np.maximum(np.linalg.norm(na, axis=1) * np.linalg.norm(nb, axis=1), 1e-300)
    at = cos < np.cos(np.radians(angle))
    fold = first[at]
    edges = np.stack([low[fold], high[fold]], axis=1).astype(np.int32)
    return (edges, np.degrees(np.arccos(np.clip(cos[at], -1.0, 1.0)))) if folds else edges


vec8i = wp.types.vector(length=8, dtype=wp.int32)


@wp.func
def corner_plane(d: wp.vec3, corner: wp.vec3, value: float, iso: float, inv: float, tolerance: float, near: float):
    """A cube corner's plane (cube coordinates: voxels from the cube's minimum corner; ``d`` from the node's closest
    point to the node, in voxels): unit normal (outward) and offset where the node's value is its distance to its
    closest point, else a zero normal; the weight it keeps when damped (the direction to a closest point is noise
    close to the surface, :data:`.dual.HERMITE_NEAR`); state 1 (a plane), 0 (Hermite data does not hold) or -1 (the
    node lies on the surface: no direction)."""
    q = corner - d
    dl = wp.length(d)
    r = value + iso
    good = wp.abs(dl - wp.abs(r) * inv) <= tolerance
    k = wp.where(dl > 1.0e-4, wp.where(good, wp.where(r < 0.0, -1.0, 1.0) / dl, 0.0), 0.0)
    n = k * d
    state = wp.where(dl <= 1.0e-4, -1, wp.where(good, 1, 0))
    return n, wp.dot(n, q) + iso * inv, wp.min(1.0, (dl / near) * (dl / near)), state


@wp.func
def opposed_planes(normals: wp.types.matrix(shape=(8, 3), dtype=float), state: vec8i, ends: int):
    """The least cosine between the normals of two of the corners ``ends`` (bits) with planes (``state`` 1,
    :func:`corner_plane`); 1 with fewer than two: near -1, the corners' closest points lie on both sides of a part
    thinner than the cube."""
    out = float(1.0)
    for a in range(8):
        if (ends >> a) & 1 == 1 and state[a] == 1:
            n = wp.vec3(normals[a, 0], normals[a, 1], normals[a, 2])
            for b in range(a + 1, 8):
                if (ends >> b) & 1 == 1 and state[b] == 1:
                    out = wp.min(out, wp.dot(n, wp.vec3(normals[b, 0], normals[b, 1], normals[b, 2])))
    return out


@wp.func
def wide_box(
    below: wp.array[wp.uint8], cube_of_node: wp.array[wp.int32], ids: vec8i, lo: float, hi: float, reach: float
):
    """The box a crease or corner vertex may reach into: ``reach`` past each face of the cube (its corners ``ids``)
    whose neighbouring cube the surface does not cross."""
    wide_lo = wp.vec3(lo)
    wide_hi = wp.vec3(hi)
    for a in range(3):
        if below[ids[0] * 3 + a] == wp.uint8(0):
            wide_lo[a] = lo - reach
        if cube_of_node[ids[wp.where(a == 0, 1, wp.where(a == 1, 3, 4))]] < 0:
            wide_hi[a] = hi + reach
    return wide_lo, wide_hi


@wp.func
def through_cube(sums: vec10, mass: wp.vec3, cutoff: float, lo: float, hi: float, wide_lo: wp.vec3, wide_hi: wp.vec3):
    """The crease or corner of the planes ``sums`` (those through the cube) and its rank where it lies in the box, else
    rank 0."""
    ata, atb, btb = unpack_terms(sums)
    x, rank, own = solve_in_cube(ata, atb - ata * mass, mass, cutoff, lo, hi, wide_lo, wide_hi)
    return x, wp.where(own == 1 and rank >= 2, rank, 0)
