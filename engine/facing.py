"""A new face's source read again where the triangle its node found does not lie the face's way.

A face of a field's surface takes its source from the finest node holding its centre: the operand whose value decides
there and the triangle of that node's closest point (:func:`.sources.face_sources_of`). Along a crease, the nodes
about it lie as near the triangles on both sides, and a face lying flat on one side takes the other side's triangle
as often as not (a remeshed box with a material per side: 0.2-2.7 % of its faces, along every edge, in the wrong
side's material; cube - bore's seam band at /128: 155 of the 764 new faces on the box's planes took the bore's). So a
face whose normal lies farther than FACING_DEGREES from its triangle's plane is read again: the triangle of any
operand nearest its centre (a face on a side's plane lies on that side's triangles, and a crease's other side is a
fraction of a voxel away at least), the node's where it is as near.

Written by hand: one kernel flags the faces, and Warp's BVH finds the nearest triangles of those alone (the faces
along the creases: 0.5-3.3 % of the remeshed bench pairs' faces).
"""

from __future__ import annotations

import numpy as np
import warp as wp

from .geometry import mesh_closest_face
from .parallel import EMIT_SPLIT_MIN_DIM, host_view, launch_split

# A face whose normal is farther than this (degrees) from its source triangle's, either way, is read again (under
# CREASE_ANGLE, 25: a crease's other side is always farther).
FACING_DEGREES = 20.0

# The nearest triangle is looked for within this many voxels of a face's centre (a face lies within a fraction of one
# of its source's surface), and replaces the node's only where nearer by more than TIE_VOXELS.
REACH_VOXELS = 2.0
TIE_VOXELS = 1e-3


@wp.kernel(enable_backward=False)
def _nearest_kernel(
    mesh: wp.uint64,
    points: wp.array[wp.vec3],
    reach: float,
    offset: int,
    face: wp.array[wp.int32],
    distance: wp.array[wp.float32],
):
    """The mesh's triangle nearest each point within ``reach`` (-1 where none) and how far it is."""
    i = wp.tid() + offset
    foot, t = mesh_closest_face(mesh, points[i], reach)
    face[i] = t
    distance[i] = wp.where(t >= 0, wp.length(points[i] - foot), reach)


def facing_sources(field, verts: np.ndarray, tris: np.ndarray, ids: np.ndarray, node_tri: np.ndarray) -> None:
    """Read again, in place, the source (``ids``: operand per face; ``node_tri``: its index into that operand's
    source triangles, -1 where unknown) of the faces ``tris`` of ``verts`` (the field's own frame) whose normal does
    not lie its triangle's way (the module docstring): the nearest triangle of any operand to the face's centre."""
    doubtful = _doubtful(field, verts, tris, ids, node_tri)
    if not len(doubtful):
        return
    centres = verts[tris[doubtful]].astype(np.float64).mean(axis=1).astype(np.float32)
    reach = REACH_VOXELS * float(field.voxel_size)
    points = wp.array(centres, dtype=wp.vec3, device=field.device)
    best = np.full(len(doubtful), np.inf)
    own = np.full(len(doubtful), np.inf)  # how far the node's own operand's nearest triangle is, and which it is
    own_tri = node_tri[doubtful].copy()
    chosen_id, chosen_tri = ids[doubtful].copy(), node_tri[doubtful].copy()
    for field_id, source in field.sources.items():
        if source is None or not len(source.tris):
            continue
        face, distance = _nearest(source, points, reach, field.device)
        found = face >= 0
        mine = found & (ids[doubtful] == field_id)
        own[mine], own_tri[mine] = distance[mine], face[mine]
        better = found & (distance < best)
        best[better] = distance[better]
        chosen_id[better], chosen_tri[better] = field_id, face[better]
    # the node's operand keeps the face where its nearest triangle is as near as the nearest found (a tie)
    keep = own <= best + TIE_VOXELS * float(field.voxel_size)
    node_tri[doubtful] = np.where(keep, own_tri, chosen_tri)
    ids[doubtful] = np.where(keep, ids[doubtful], chosen_id)


@wp.kernel(enable_backward=False)
def _doubtful_kernel(
    verts: wp.array[wp.vec3],
    tris: wp.array[wp.int32],
    ids: wp.array[wp.int32],
    node_tri: wp.array[wp.int32],
    field_id: int,
    points: wp.array[wp.vec3],
    indices: wp.array[wp.int32],
    limit: float,
    offset: int,
    doubtful: wp.array[wp.uint8],
):
    """Per face of operand ``field_id`` whose node's triangle is known: whether its normal and that triangle's
    (``points``, ``indices``: the operand's source) are farther apart than the angle whose cosine is ``limit``."""
    i = wp.tid() + offset
    t = node_tri[i]
    if ids[i] != field_id or t < 0:
        return
    a = verts[tris[3 * i]]
    mine = wp.cross(verts[tris[3 * i + 1]] - a, verts[tris[3 * i + 2]] - a)
    p = points[indices[3 * t]]
    theirs = wp.cross(points[indices[3 * t + 1]] - p, points[indices[3 * t + 2]] - p)
    if wp.abs(wp.dot(mine, theirs)) < limit * wp.length(mine) * wp.length(theirs):
        doubtful[i] = wp.uint8(1)


def _doubtful(field, verts, tris, ids, node_tri) -> np.ndarray:
    """The faces whose node's triangle is known and whose normal lies farther than FACING_DEGREES from its."""
    device, n = field.device, len(tris)
    flags = wp.zeros(n, dtype=wp.uint8, device=device)
    verts_wp = host_view(np.ascontiguousarray(verts, dtype=np.float32), wp.vec3, device)
    tris_wp = host_view(np.ascontiguousarray(tris, dtype=np.int32).ravel(), wp.int32, device)
    ids_wp, node_wp = host_view(ids, wp.int32, device), host_view(node_tri, wp.int32, device)
    limit = float(np.cos(np.radians(FACING_DEGREES)))
    for field_id, source in field.sources.items():
        if source is None or not len(source.tris):
            continue
        points, indices = source.arrays(device)
        head = [verts_wp, tris_wp, ids_wp, node_wp, int(field_id), points, indices, limit]
        launch_split(_doubtful_kernel, n, lambda lo, k, head=head: [*head, lo, flags], device)
    return np.flatnonzero(flags.numpy())


def _nearest(source, points: wp.array, reach: float, device) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_nearest_kernel` of ``source``'s triangles at ``points``: (N,) local triangle (-1: none), distance."""
    n = points.shape[0]
    face = wp.empty(n, dtype=wp.int32, device=device)
    distance = wp.empty(n, dtype=wp.float32, device=device)
    mesh = source.bvh(device)
    launch_split(
        _nearest_kernel,
        n,
        lambda lo, k: [mesh.id, points, float(reach), lo, face, distance],
        device,
        min_dim=EMIT_SPLIT_MIN_DIM,  # a BVH query each
    )
    return face.numpy(), distance.numpy()
