"""The sides of a closed mesh's faces from a few winding numbers: each face's inside behind it and outside ahead.

The kept faces' judge reads each face's own side (:func:`.ondemand.own_sides`): whether the mesh's inside lies half a
voxel behind the face and its outside as far ahead. On a field built on demand that reading comes from the mesh's
winding number at both points, two evaluations a face (about 2 us each on this CPU: 60-100 ms on the bench's 13-36 k
triangle meshes). A closed mesh's winding number is an integer off its triangles, and it changes along a segment
only where the segment passes through a triangle (:func:`.geometry.segment_crossings` counts those passes, signed,
or says it cannot tell: a segment through an edge, a vertex or grazing a plane). So:

1. the point ahead of each face and the one ahead of each neighbour (across a shared edge) have the same winding
   number where the segment between them passes through no triangle: the faces joined so fall into components, and
   one exact winding number per component gives every face's point ahead;
2. the point behind a face has the winding number ahead plus the crossings from ahead to behind (the face itself
   and any other the segment passes through);
3. where either count cannot be told, the winding number is evaluated at the point itself.

The sides are those the two evaluations give, to the integer: the winding numbers are the same integers. Written by
hand: the propagation is this module's own (Warp gives the BVH queries and the winding numbers).
"""

from __future__ import annotations

import numpy as np
import warp as wp

from .components import connected_components, edge_neighbours
from .geometry import CROSSINGS_UNKNOWN, segment_crossings, winding_number
from .parallel import launch_split
from .winding import WINDING_ACCURACY, WINDING_CLOSED, WindingArg, exact_winding


@wp.kernel(enable_backward=False)
def _crossings_kernel(
    mesh: wp.uint64, p: wp.array[wp.vec3], q: wp.array[wp.vec3], offset: int, out: wp.array[wp.int32]
):
    """Per segment ``p[i] q[i]``: the signed passes through the mesh's triangles (or CROSSINGS_UNKNOWN)."""
    i = wp.tid() + offset
    out[i] = segment_crossings(mesh, p[i], q[i])


@wp.kernel(enable_backward=False)
def _winding_kernel(f: WindingArg, x: wp.array[wp.vec3], offset: int, out: wp.array[wp.int32]):
    """Per point: the closed mesh's winding number there (an integer, :func:`.winding.exact_winding`)."""
    i = wp.tid() + offset
    w = exact_winding(f, x[i], winding_number(f.mesh, x[i], WINDING_ACCURACY))
    out[i] = int(wp.floor(w + 0.5))


def closed_sides(winding, tris: np.ndarray, front: np.ndarray, back: np.ndarray, device) -> np.ndarray | None:
    """(T,) int8 each face's side (+1 inside behind and outside ahead, -1 the other way round, 0 both on one side)
    from the winding numbers at its points ``front`` and ``back`` ((T, 3) float32, the mesh's frame) of a closed mesh
    (``winding``: its :class:`.winding.WindingArg`, ``tris`` (T, 3) its faces' corners, for their neighbours); None
    where the mesh is not closed (its winding number is no integer)."""
    if winding.mode != WINDING_CLOSED or not len(tris):
        return None
    front, back = (np.ascontiguousarray(x, dtype=np.float32) for x in (front, back))
    tris = np.asarray(tris, dtype=np.int64)
    a, b = edge_neighbours(tris, int(tris.max()) + 1)
    same = _crossings(winding.mesh, front[a], front[b], device) == 0
    label = connected_components(len(tris), a[same], b[same], device)
    roots, at = np.unique(label, return_inverse=True)
    ahead = _windings(winding, front[roots], device)[at]
    through = _crossings(winding.mesh, front, back, device)
    behind = ahead + through
    unknown = np.flatnonzero(through == CROSSINGS_UNKNOWN)
    behind[unknown] = _windings(winding, back[unknown], device)
    inside_ahead, inside_behind = ahead != 0, behind != 0
    return np.where(inside_ahead == inside_behind, 0, np.where(inside_behind, 1, -1)).astype(np.int8)


def _crossings(mesh: wp.uint64, p: np.ndarray, q: np.ndarray, device) -> np.ndarray:
    out = wp.empty(len(p), dtype=wp.int32, device=device)
    if len(p):
        p_wp, q_wp = (wp.array(x, dtype=wp.vec3, device=device) for x in (p, q))
        launch_split(_crossings_kernel, len(p), lambda lo, _n: [mesh, p_wp, q_wp, lo, out], device)
    return out.numpy().astype(np.int64)


def _windings(winding, x: np.ndarray, device) -> np.ndarray:
    out = wp.empty(len(x), dtype=wp.int32, device=device)
    if len(x):
        x_wp = wp.array(np.ascontiguousarray(x, dtype=np.float32), dtype=wp.vec3, device=device)
        launch_split(_winding_kernel, len(x), lambda lo, _n: [winding, x_wp, lo, out], device)
    return out.numpy().astype(np.int64)
