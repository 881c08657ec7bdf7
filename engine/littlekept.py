"""Booleans whose operands' faces are the result's surface almost nowhere: remeshed, not joined.

Where the operands' surfaces lie within the band of each other nearly everywhere (a mesh united with its own copy
moved by a voxel or two), the judge keeps a few scattered faces in a sea of new surface. Joining them costs what a
join costs where much is kept: the strips, the coarsening of the whole voxel surface about them, the crossing faces
tiled again and the faces judged again clear of those left (rocker arm ∪ its copy moved by 1.9 voxels at /256: 2.1 s
against 0.32 s for the remeshed surface, for 2.3 % of the area kept in islands of a few faces, which carry no UV
layout or topology worth the cost). Where the faces judged kept are under MIN_KEPT_SHARE of the operands' area and
of the result's, :func:`.hybrid.kept_surface` takes the voxel surface instead, as the remeshed result has it: at
adaptivity 0 as it is (made coarse where flat and its crossings tiled, the rocker arm's copy moved a voxel or two took
240-260 ms more than the remeshed surface's 32-43 ms), at an adaptivity coarse where flat as a join's new faces are.
It says so in ``stats["kept_fallback"]`` (a fallback chosen, not a join failed: ``join_failed`` stays False; the
add-on tells the user why nothing was kept).
"""

from __future__ import annotations

import numpy as np

from .assembly import uncovered
from .edges import surface_edges
from .meshcheck import triangle_areas

# The share of the judged meshes' area, and of the result's, under which the judged faces are not joined.
MIN_KEPT_SHARE = 0.05

LITTLE_KEPT = "the operands' faces are its surface almost nowhere"


def little_kept(judged: list, verts, tris) -> bool:
    """Whether the triangles ``judged`` kept (:func:`.keep.kept_triangles`' answer) cover under MIN_KEPT_SHARE of
    the judged meshes' area and of theirs and the voxel surface's (``verts``, ``tris``, the same frame) together: little
    of the operands is kept, and it is little of the result (a small intersection of large meshes keeps little of them
    but is mostly their faces; an offset less a ball keeps much of the ball in a surface mostly the offset's). Along the
    seams alone the voxel surface is the seams' only: the kept share of the result is then the larger."""
    areas = [triangle_areas(leaf["verts"], leaf["tris"]) for leaf in judged]  # (each piece's, once)
    kept = sum(float(area[leaf["kept"]].sum()) for area, leaf in zip(areas, judged, strict=True))
    if kept >= MIN_KEPT_SHARE * sum(float(area.sum()) for area in areas):
        return False  # (much of the operands kept: the voxel surface's area is not needed)
    return kept < MIN_KEPT_SHARE * (kept + float(triangle_areas(verts, tris).sum()))


def whole_along_seams(judged: list, verts, tris, voxel: float, device) -> bool:
    """Whether a voxel surface made along the seams alone (``verts``, ``tris``) is the whole result's: closed, and
    about every triangle ``judged`` kept (a part of the result far from every seam, an operand apart from the
    others, has no voxel surface made there, and the surface about the others is closed without it)."""
    if surface_edges(tris, len(verts), device) is None:  # (not closed: 6 ms where the edges' sort took 35)
        return False
    kept = [leaf["verts"][leaf["tris"][leaf["kept"]]].astype(np.float64).mean(axis=1) for leaf in judged]
    centres = np.concatenate(kept) if kept else np.zeros((0, 3))
    return not uncovered(verts, tris, centres, voxel, device)
