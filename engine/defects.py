"""A mesh operand's own defects, as the kept faces' judge (:mod:`.keep`) measures distances to them: open,
non-manifold and inconsistently oriented edges, repeated triangles, the curves along which the mesh passes through
itself, and points a join gave kept faces up at (:mod:`.rejoin`), each as flat triangles of one mesh whose BVH the
judge's samples query.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from .meshcheck import defect_edge_kinds
from .selfcross import crossing_segments
from .sources import mesh_distances

AXES = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], dtype=np.float32)


def repeated_triangles(tris: np.ndarray, n_verts: int) -> np.ndarray:
    """(T,) bool: the triangles whose corners another triangle repeats (in any order): one key per sorted corner
    triple where three indices fit in 63 bits (numpy's unique over rows sorts them as bytes, 8x slower), else the
    rows themselves."""
    if n_verts**3 < 2**63:  # the duplicated keys found in a sort of the keys (no inverse permutation)
        a, b, c = (tris[:, k].astype(np.int64) for k in range(3))
        low, high = np.minimum(np.minimum(a, b), c), np.maximum(np.maximum(a, b), c)
        key = (low * n_verts + (a + b + c - low - high)) * n_verts + high
        ordered = np.sort(key)
        repeated = ordered[1:][ordered[1:] == ordered[:-1]]
        return np.isin(key, repeated) if len(repeated) else np.zeros(len(key), dtype=bool)
    corners = np.sort(tris, axis=1).astype(np.int64)
    _, inverse, counts = np.unique(corners, axis=0, return_inverse=True, return_counts=True)
    return counts[inverse.reshape(-1)] > 1


# Where a mesh passes through itself along a curve at least this many voxels long, its faces stay a band from it as from
# its other defects (a face reaching it is partly inside: kept, overlapping boxes given as one mesh kept pieces of
# their faces up to 0.64 voxel inside each other). Shorter ones are pokes under the field's resolution: as defects
# they cost the beetle 6 % of what it kept, through the join, while its gaps' walls were taken for internal faces;
# Suzanne's of 2-3 voxels, left out at 3, made 82 of its 163 crossing pairs (the beetle's of 2-3 voxels change nothing).
CROSSING_VOXELS = 2.0


def own_defects(verts: np.ndarray, tris: np.ndarray, shortest: float | None, device, near=None) -> tuple:
    """A mesh's defects (judged with vertices at one position merged): ``(repeated, points, parts, beyond_holes)``:
    (T,) bool the triangles repeating another triangle's corners (never kept), and the defects as triangles to measure
    distances to: each open, non-manifold or inconsistently oriented edge and each segment along which the mesh passes
    through itself (:func:`.selfcross.crossing_segments`, on curves at least ``shortest`` long, with a triangle of
    ``near`` ((T,) bool, :func:`near_internal`; None: any); ``shortest`` None: not looked for) as a flat triangle
    ``a b b``, each repeated triangle as itself (``points`` (P, 3) float32, ``parts`` (D, 3) int32; empty when the mesh
    has none); and whether it has a defect other than a hole's edge. A triangle at a hole's edge keeps its parts
    farther than the band from that edge, one the mesh passes through farther than the band from the crossing."""
    welded_verts, welded, bad, open_edge = defect_edge_kinds(verts, tris)
    repeated = repeated_triangles(welded, len(welded_verts))
    points = np.asarray(welded_verts, dtype=np.float32)
    rows = None if near is None else np.flatnonzero(near[~repeated])
    crossings = (
        np.zeros((0, 2, 3), np.float32)
        if shortest is None
        else crossing_segments(points, welded[~repeated], device, shortest, rows)
    )
    ends = np.arange(len(points), len(points) + 2 * len(crossings)).reshape(-1, 2)
    points = np.concatenate([points, crossings.reshape(-1, 3)])
    segments = np.concatenate([bad, ends])
    # a segment as a sliver: its ends and its midpoint a hair off the line (the BVH's point query skips flat triangles)
    a, b = points[segments[:, 0]].astype(np.float64), points[segments[:, 1]].astype(np.float64)
    off = np.zeros_like(a)
    off[np.arange(len(a)), np.argmin(np.abs(b - a), axis=1)] = 1e-5 * np.linalg.norm(b - a, axis=1)
    mids = np.arange(len(points), len(points) + len(segments))
    slivers = np.stack([segments[:, 0], segments[:, 1], mids], axis=1)
    parts = np.concatenate([slivers, welded[repeated]]).astype(np.int32)
    beyond_holes = bool(repeated.any() or not open_edge.all() or len(crossings))
    return repeated, np.concatenate([points, (0.5 * (a + b) + off).astype(np.float32)]), parts, beyond_holes


def near_internal(verts: np.ndarray, tris: np.ndarray, measures, internal: np.ndarray, shortest: float, device):
    """(T,) bool the triangles a crossing curve at least ``shortest`` long may pass through, given the ``internal``
    ones ((T,) bool: their own inside on both sides, :mod:`.ownside`): those whose centre lies within two of the
    mesh's longest edges and ``shortest`` of an internal triangle. A mesh passes through itself only where some part
    of it lies inside the rest: along such a curve the triangles past it read internal, and the ones across it touch
    them. (Searched over the whole mesh, a scan of 278 k triangles with one triangle misread internal took 0.33 s.)

    ``measures``: the triangles' :class:`.trimeasures.TriangleMeasures`."""
    reach = 2.0 * float(measures.lengths.max()) + shortest
    mesh = wp.Mesh(
        points=wp.array(np.ascontiguousarray(verts, dtype=np.float32), dtype=wp.vec3, device=device),
        indices=wp.array(np.ascontiguousarray(tris[internal], dtype=np.int32).ravel(), dtype=wp.int32, device=device),
    )
    return mesh_distances(mesh, measures.centres, 2.0 * reach, device) <= reach


def octahedra(points: np.ndarray, radius: float) -> tuple[np.ndarray, np.ndarray]:
    """An octahedron of ``radius`` about each point, as ``(verts, tris)``: a point kept clear of by a BVH's
    distances (they skip flat triangles), farther by at most ``radius`` than the point itself."""
    corners = (points[:, None, :] + radius * AXES[None]).reshape(-1, 3).astype(np.float32)
    faces = np.array([[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]])
    return corners, (faces[None] + 6 * np.arange(len(points))[:, None, None]).reshape(-1, 3).astype(np.int32)


def defects_and(defect_mesh, avoid, radius: float, device):
    """A mesh of a leaf's defects (``defect_mesh``, or None) and of octahedra about the ``avoid`` points."""
    points, parts = octahedra(np.asarray(avoid, dtype=np.float32).reshape(-1, 3), radius)
    if defect_mesh is not None:
        own_points, own_parts = defect_mesh.points.numpy(), defect_mesh.indices.numpy().reshape(-1, 3)
        points, parts = np.concatenate([own_points, points]), np.concatenate([own_parts, parts + len(own_points)])
    return wp.Mesh(
        points=wp.array(points, dtype=wp.vec3, device=device),
        indices=wp.array(parts.reshape(-1).astype(np.int32), dtype=wp.int32, device=device),
    )
