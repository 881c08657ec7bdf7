"""A second join where the first gave kept faces up: the operands' triangles judged again, kept clear of the places
where it failed, so that only a band about each is new surface.

The join (:func:`.hybrid.hybrid_surface`) gives up whole kept faces where it cannot pair a border loop: every kept
face at the loop, or near a voxel loop that has no kept loop to pair with (a hole a voxel across in the voxel surface
where a thin part or a crossing of a shell with itself leaves the two surfaces a voxel apart). On a scan the faces are
smaller than a voxel and little is lost; on a low-polygon mesh one face can be tens of voxels across (Suzanne's are
about five voxels wide), and giving a handful up takes a tenth of its surface. Here the vertices the faces were given
up at become defects of every operand for a second judge (:func:`.keep.kept_triangles`' ``avoid``): the faces there
are split like faces at a seam, their far parts kept, and the new surface about those places is a band wide, as along
a seam; the second join is kept when it keeps more area than the first. It costs a judge and a join more, so it is
tried only where the large faces given up are a sizeable share of what was kept (``REJOIN_SHARE``).
"""

from __future__ import annotations

import numpy as np

from .keep import kept_triangles
from .meshcheck import triangle_areas


def kept_area(surface: dict) -> float:
    """The area of a joined surface's kept faces."""
    verts = np.asarray(surface["verts"], dtype=np.float64)
    return float(triangle_areas(verts, np.asarray(surface["tris"])[surface["kept"]]).sum())


def joined_again(field, surface: dict, join, judged: list, avoid=None) -> tuple[dict, np.ndarray]:
    """``surface`` (a :func:`.hybrid.hybrid_surface` of ``field``'s ``judged`` triangles, judged clear of the points
    ``avoid`` (P, 3), with its ``trouble``), or, where its join gave up large kept faces of ``REJOIN_SHARE`` of its kept
    area or more (``PER_POINT_VOXELS`` a point they were given up at), the surface ``join(judged)`` makes of the
    triangles judged again clear of those points too (and of the next join's, while each keeps more area than the last
    and gives up ``AGAIN_SHARE``, up to ``REJOINS`` times) that keeps the most area (``stats["rejoined"]``: how many
    points its judge kept clear of); with the points its judge kept clear of."""
    trouble = surface.pop("trouble", NO_TROUBLE)
    avoid = np.zeros((0, 3), np.float32) if avoid is None else np.asarray(avoid, dtype=np.float32).reshape(-1, 3)
    best, best_avoid = surface, avoid
    best["stats"]["rejoined"] = len(avoid)
    if not len(trouble["points"]):  # (most joins: nothing given up, nothing to measure)
        return best, best_avoid
    best_area = kept_area(surface)
    per_point = trouble["area"] / len(trouble["points"]) / field.voxel_size**2
    if per_point < PER_POINT_VOXELS:  # faces hardly larger than what a second judge clears about each point
        return best, best_avoid
    for k in range(REJOINS):
        if not len(trouble["points"]) or trouble["area"] < (AGAIN_SHARE if k else REJOIN_SHARE) * best_area:
            break
        avoid = np.concatenate([avoid, trouble["points"]])
        judged = kept_triangles(field, avoid=avoid, previous=judged)  # a leaf far from them as it was
        surface = join(judged)
        trouble = surface.pop("trouble", NO_TROUBLE)
        if surface["stats"]["kept_fallback"] or kept_area(surface) <= best_area:
            break
        best, best_area, best_avoid = surface, kept_area(surface), avoid
        best["stats"]["rejoined"] = len(avoid)
    return best, best_avoid


# What a join that fell back to the voxel surface alone reports.
NO_TROUBLE = {"points": np.zeros((0, 3), np.float32), "area": 0.0}
# Joins after the first, each judging the triangles clear of every earlier one's trouble.
REJOINS = 3
# A join is tried again where the large kept faces it gave up are at least this share of the area it kept, and
# PER_POINT_VOXELS square voxels or more a point they were given up at (a second judge clears a disc of about 16 about
# each): a low-polygon mesh's (Suzanne with a ball: 7 %, 40), a scan's larger faces near its holes (the beetle's
# 1.3 %, 10: 0.986 -> 0.992 of what should be kept, for a judge and a join more), not a scan's faces smaller than
# the disc (the cow's 0.01 %, 6), and again while the last join gave up AGAIN_SHARE.
REJOIN_SHARE = 0.01
PER_POINT_VOXELS = 8.0
AGAIN_SHARE = 0.003
