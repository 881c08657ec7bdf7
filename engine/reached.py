"""Crease vertices that reached past their cube, checked against the operands' own surfaces.

Dual contouring keeps a vertex in its cube, except a crease or corner vertex whose planes meet outside it, which may
go up to ``dual.EMPTY_REACH`` voxels past a face whose neighbouring cube the surface does not cross: the tip of a
wedge more acute than the lattice resolves lies there (cube - bore's, cube | tilted cube's). Its planes are the
tangent planes of the closest points of its cube's nodes, unbounded: where two of them belong to faces that end
before they would meet (a thin part of the rocker arm meeting the cube), the tip they make is not on any surface,
and the vertex sits a voxel off the result. The exact answer is at hand for a field of meshes: the distance from the
vertex to its operands' triangles. A vertex more than ``PAST_VOXELS`` past its cube and farther than
``OFF_VOXELS`` from every operand's surface goes back into its cube (clamped, as any other vertex's minimiser is);
a true wedge tip lies on a surface (measured at /256: 0.07 voxel at most on the CAD pairs) and stays.
"""

from __future__ import annotations

import numpy as np

from .meshcheck import any_corner
from .octree import morton_decode_np
from .sources import closest_points

# Vertices this many voxels or less past their cube are not checked (they cannot be far off: a voxel's crossing).
PAST_VOXELS = 0.25
# A vertex past its cube that is farther than this many voxels from every operand's surface goes back into it.
OFF_VOXELS = 0.25


def pulled_back(field, surface: dict, cube_corners: np.ndarray, codes: np.ndarray, margin: float) -> dict:
    """``surface`` (:func:`.dual.contour_dual`'s, of the unplaced ``field``'s zero surface, its active cubes'
    ``cube_corners`` rows (M, 8) and the finest nodes' ``codes``) with the vertices that reached past their cube off
    every operand's surface clamped into their cube (``margin`` voxels in); the quads they are corners of split.
    ``surface["pulled_back"]``: how many."""
    verts, cells = surface["verts"], surface.get("cells")
    surface["pulled_back"] = 0
    if cells is None or not len(verts) or not field.sources:
        return surface
    h = float(field.voxel_size)
    creases = np.flatnonzero(surface["ranks"] == 2)  # only a crease vertex leaves its cube
    low = np.asarray(field.origin) + (morton_decode_np(codes[cube_corners[cells[creases], 0]]) + 0.5) * h
    local = (verts[creases] - low) / h
    past = np.maximum(-local, local - 1.0).max(axis=1)
    at = np.flatnonzero(past > PAST_VOXELS)
    rows, low, local = creases[at], low[at], local[at]
    if not len(rows):
        return surface
    points = verts[rows]
    nearest = np.full(len(rows), np.inf)
    for source in field.sources.values():
        if source is None or not len(source.tris):
            continue
        on = closest_points(source, points, field.device)
        found = np.flatnonzero(~np.isnan(on[:, 0]))
        nearest[found] = np.minimum(nearest[found], np.linalg.norm(points[found] - on[found], axis=1))
    far = nearest > OFF_VOXELS * h
    off = rows[far]
    if not len(off):
        return surface
    verts = verts.copy()
    verts[off] = (low[far] + np.clip(local[far], margin, 1.0 - margin) * h).astype(np.float32)
    moved = np.zeros(len(verts), dtype=bool)
    moved[off] = True
    whole = surface["whole"].copy()
    quads = surface["tris"][: 2 * len(whole)].reshape(-1, 6)
    whole[any_corner(moved, quads)] = 0
    return {**surface, "verts": verts, "whole": whole, "pulled_back": len(off)}
