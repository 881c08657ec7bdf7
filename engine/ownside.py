"""A face's side of its own mesh's field: inside behind it and outside in front, an internal face, a thin part, or
a wall of a gap narrower than the field sees.

The judge (:mod:`.keep`, :mod:`.judging`) keeps a triangle only where its own field crosses it from inside to outside,
read a little in front of and behind it (:func:`side_at`): both sides inside is an internal face of overlapping or
self-intersecting shells (not kept); both outside, a part thinner than the field sees (it faces the way most of the
mesh does, :func:`outward`). Where two parts of one mesh face each other across a gap narrower than the voxel
(Suzanne's ears and head: 0.1-1.3 voxel apart), the field closes the gap and both sides of its walls read inside too:
taken for internal faces, they were dropped, their holes filled with voxel surface that cannot follow the gap, and the
join gave faces up about them. A wall of such a gap is told apart by the mesh itself (:func:`gap_side`): a ray
from it along its normal meets a face turned back towards it within two offsets, and the gap's middle is outside
every shell of the mesh (the faces a ray from there crosses, counted +1 leaving a shell and -1 entering one, sum to 0
or less: the winding number along the ray of closed, consistently turned shells). A face inside another shell (an
internal one) fails that count. For a mesh inside out, every face's way is taken reversed.
"""

from __future__ import annotations

import numpy as np
import warp as wp

# Faces a ray from a gap's middle is followed through at most (more: taken as inside).
GAP_CROSSINGS = 64
# The face met in front must turn back towards the ray at least this much (cosine).
FACING = 0.2
# A ray starts this many voxels past the face it leaves.
TINY_VOXELS = 1e-3


@wp.func
def gap_along(mesh: wp.uint64, x: wp.vec3, d: wp.vec3, reach: float, tiny: float, turn: int) -> bool:
    """Whether along the unit ``d`` from ``x`` the mesh leaves a gap (see the module): a face turned back within
    ``reach``, the gap's middle outside every shell (``tiny``: how far a ray starts past a face; ``turn``: 1 for a
    mesh whose faces face outward, -1 for one inside out: every face's way reversed)."""
    if mesh == wp.uint64(0):
        return False
    way = float(turn)
    hit = wp.mesh_query_ray(mesh, x + tiny * d, d, reach)
    if not hit.result or way * wp.dot(hit.normal, d) > -FACING * wp.length(hit.normal):
        return False
    origin = x + (tiny + 0.5 * hit.t) * d
    winding = int(0)
    for _k in range(GAP_CROSSINGS):
        q = wp.mesh_query_ray(mesh, origin, d, 1.0e6)
        if not q.result:
            return winding <= 0
        winding += wp.where(way * wp.dot(q.normal, d) > 0.0, 1, -1)
        origin = origin + (q.t + tiny) * d
    return False


@wp.func
def gap_side(mesh: wp.uint64, x: wp.vec3, n: wp.vec3, front: float, back: float, offset: float, tiny: float, turn: int):
    """The side of a face read internal (both sides inside, ``front`` and ``back`` read ``offset`` along its unit
    normal ``n`` and against it) where it is the wall of a gap narrower than the field sees: 1 with the gap in front
    (the side read there lies less than ``offset`` inside), -1 with it behind (an inside-out face), else 0."""
    if front > -offset and gap_along(mesh, x, n, 2.0 * offset, tiny, turn):
        return 1
    if back > -offset and gap_along(mesh, x, -n, 2.0 * offset, tiny, turn):
        return -1
    return 0


@wp.kernel(enable_backward=False)
def _gap_sides_kernel(
    mesh: wp.uint64,
    points: wp.array[wp.vec3],
    normals: wp.array[wp.vec3],
    front: wp.array[wp.float32],
    back: wp.array[wp.float32],
    offset: float,
    tiny: float,
    turn: int,
    out: wp.array[wp.int8],
):
    i = wp.tid()
    out[i] = wp.int8(gap_side(mesh, points[i], normals[i], front[i], back[i], offset, tiny, turn))


def side_at(leaf, points, normals, offset: float, rays=None, tiny: float = 0.0, turn: int = 1) -> np.ndarray:
    """(N,) +1 where the leaf's field grows across each point along its normal (inside ``offset`` behind it, outside
    as far in front), -1 where it falls (an inside-out face), 0 where both sides are clearly inside (by a quarter of
    ``offset`` or more: an internal face), THIN where both are clearly outside (a part thinner than the field sees).
    Near a crease of the mesh one side reads near 0 (interpolation across the crease): that counts by the difference
    of the two. With ``rays`` (its mesh's BVH), a face read internal that is the wall of a gap of the mesh narrower
    than the field sees has its side towards the gap (:func:`gap_side`; ``turn``: -1 for a mesh inside out)."""
    front = leaf.sample(points + offset * normals, method="linear")
    back = leaf.sample(points - offset * normals, method="linear")
    clear = 0.25 * offset
    internal, thin = np.maximum(front, back) < -clear, np.minimum(front, back) > clear
    side = np.where(thin, THIN, np.where(internal, 0, np.where(front >= back, 1, -1))).astype(np.int8)
    rows = np.flatnonzero(internal)
    if rays is not None and len(rows):
        device = leaf.device
        out = wp.empty(len(rows), dtype=wp.int8, device=device)
        arrays = [(points, wp.vec3), (normals, wp.vec3), (front, wp.float32), (back, wp.float32)]
        inputs = [wp.array(np.ascontiguousarray(a[rows], dtype=np.float32), dtype=t, device=device) for a, t in arrays]
        wp.launch(
            _gap_sides_kernel,
            dim=len(rows),
            inputs=[rays.id, *inputs, float(offset), float(tiny), int(turn), out],
            device=device,
        )
        side[rows] = out.numpy()
    return side


# :func:`side_at` where both sides of a face read outside: a part of the mesh thinner than the field sees (a cow's
# ear, a beetle's leg), whose faces face the way most of the mesh's area does (:func:`outward`).
THIN = 2


def outward(side: np.ndarray, area: np.ndarray) -> int:
    """+1 where most of a mesh's area (its triangles' ``side`` and ``area``) faces its outside, -1 where it is inside
    out."""
    return 1 if area[side == 1].sum() >= area[side == -1].sum() else -1
