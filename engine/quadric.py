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
def solve_in_cube(
    ata: wp.mat33, rhs: wp.vec3, mass: wp.vec3, cutoff: float, lo: float, hi: float, wide_lo: wp.vec3, wide_hi: wp.vec3
):
    """Minimiser of |A x - b|^2 near the mass point (``rhs = A^T b - A^T A mass``): the truncated pseudo-inverse
    solution if it lies in the box [wide_lo, wide_hi]; else the solution line of the two largest eigenvalues clipped
    to that box; else the point of rank 1 clamped to the cube [lo, hi]^3. Returns (x, rank used)."""
    q, d = wp.eig3(ata)
    # order the eigenvalues, largest first
    i0 = int(0)
    i2 = int(0)
    for k in range(3):
        if d[k] > d[i0]:
            i0 = k
        if d[k] < d[i2]:
            i2 = k
    if i0 == i2:
        i2 = (i0 + 1) % 3
    i1 = 3 - i0 - i2
    top = d[i0]
    x = mass
    if top <= 0.0:
        return clamp_box(x, lo, hi), 0
    e0 = wp.vec3(q[0, i0], q[1, i0], q[2, i0])
    e1 = wp.vec3(q[0, i1], q[1, i1], q[2, i1])
    e2 = wp.vec3(q[0, i2], q[1, i2], q[2, i2])
    rank = int(1)
    if d[i1] > cutoff * top:
        rank = 2
    if d[i2] > cutoff * top:
        rank = 3
    x1 = mass + e0 * (wp.dot(e0, rhs) / top)
    x2 = x1
    if rank >= 2:
        x2 = x1 + e1 * (wp.dot(e1, rhs) / d[i1])
    x3 = x2
    if rank == 3:
        x3 = x2 + e2 * (wp.dot(e2, rhs) / d[i2])
        if inside_box(x3, wp.vec3(lo), wp.vec3(hi)):
            return x3, 3
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
            return x2 + t * e2, 2
    x = x1
    if rank >= 2:
        rank = 1
    return clamp_box(x, lo, hi), rank


@wp.func
def solve_smooth(ata: wp.mat33, rhs: wp.vec3, mass: wp.vec3, normal_sum: wp.vec3):
    """The rank-1 minimiser when all normals nearly agree: the mass point moved along their mean normal."""
    e0 = wp.normalize(normal_sum)
    lam = wp.dot(e0, ata * e0)
    if lam <= 0.0:
        return mass
    return mass + e0 * (wp.dot(e0, rhs) / lam)


@wp.func
def quadric_at(
    quadrics: wp.array[wp.mat33], linear: wp.array[wp.vec4], verts: wp.array[wp.vec3], v: int, y: wp.vec3, inv: float
):
    """Mean squared distance (in voxels^2) of point ``y`` to vertex ``v``'s planes."""
    d = (y - verts[v]) * inv
    r = linear[v]
    return wp.dot(d, quadrics[v] * d) + 2.0 * (d[0] * r[0] + d[1] * r[1] + d[2] * r[2]) + r[3]


def crease_edges(verts, tris, ranks, angle: float = CREASE_ANGLE) -> np.ndarray:
    """The edges of a closed mesh along which it folds at a reconstructed crease.

    Args:
        verts: (V, 3) float vertex positions.
        tris: (T, 3) int triangles of a closed, consistently oriented mesh.
        ranks: (V,) int quadric ranks from :func:`contour_dual` (2 or more: on a crease or corner).
        angle: Smallest angle (degrees) between the two triangles' normals.
    Returns:
        (E, 2) int32 vertex index pairs (smaller index first), each an edge of ``tris`` between two crease or corner
        vertices whose triangles' normals differ by more than ``angle``.
    """
    tris = np.asarray(tris, dtype=np.int64)
    feature = np.asarray(ranks) >= 2
    if len(tris) == 0 or not feature.any():
        return np.zeros((0, 2), dtype=np.int32)
    # the triangle sides between two feature vertices, each undirected edge seen from both of its triangles
    candidates = np.flatnonzero(feature[tris].sum(axis=1) >= 2)
    sides = np.stack([tris[candidates], np.roll(tris[candidates], -1, axis=1)], axis=-1).reshape(-1, 2)
    face = np.repeat(candidates, 3)
    keep = feature[sides[:, 0]] & feature[sides[:, 1]]
    sides, face = sides[keep], face[keep]
    key = np.sort(sides, axis=1)
    code = key[:, 0] * np.int64(len(verts)) + key[:, 1]
    order = np.argsort(code, kind="stable")
    code, key, face = code[order], key[order], face[order]
    pair = np.flatnonzero(code[1:] == code[:-1])
    if len(pair) == 0:
        return np.zeros((0, 2), dtype=np.int32)
    v = np.asarray(verts, dtype=np.float64)
    fa, fb = face[pair], face[pair + 1]
    na = np.cross(v[tris[fa, 1]] - v[tris[fa, 0]], v[tris[fa, 2]] - v[tris[fa, 0]])
    nb = np.cross(v[tris[fb, 1]] - v[tris[fb, 0]], v[tris[fb, 2]] - v[tris[fb, 0]])
    cos = np.einsum("ij,ij->i", na, nb) / np.maximum(np.linalg.norm(na, axis=1) * np.linalg.norm(nb, axis=1), 1e-300)
    fold = cos < np.cos(np.radians(angle))
    return key[pair[fold]].astype(np.int32)
