"""A field's surface as a mesh: the extraction (sharp dual contouring or marching cubes), then the polygons.

:meth:`.field.AdaptiveField.to_mesh` runs these steps: the finest level's active cubes (from an adaptivity of 0.25,
those of the level above where that loses nothing finer: :mod:`.coarse`) contoured in the field's own frame
(:func:`.dual.contour_dual`, or marching cubes), its crease edges, the cells merged where the surface is flat enough
for the adaptivity asked (:mod:`.adaptive`), the surface placed in the world, and its quads kept whole where they are
planar (:mod:`.quads`) when polygons are asked for.
"""

from __future__ import annotations

import numpy as np

from .adaptive import simplify
from .coarse import COARSE_FROM, coarse_surface
from .contouring import sharp_surface
from .extract import extract_octree_level, extract_surface
from .meshcheck import open_vertices
from .quadric import crease_edges
from .quads import merge_pairs, triangulate


def field_mesh(field, iso: float, *, sharp: bool, creases: bool, quads: bool, adaptivity: float, regions=None) -> dict:
    """The ``iso`` surface of ``field`` (see ``AdaptiveField.to_mesh``): extracted, simplified and paired into quads
    in the field's own frame, then placed.

    Returns:
        dict: ``verts`` (V, 3) float32; ``tris`` (T, 3) int32, or with ``quads`` ``faces`` (C,) int32 and ``sizes``
        (P,) int32 polygons (quads first); ``creases`` (E, 2) int32; ``closed``: False where a level off the surface
        left the finest band (an edge in one triangle).
    """
    frame = field.in_frame()
    scale = 1.0 if field.placement is None else field.placement.scale
    coarse = coarse_surface(frame, iso / scale) if sharp and adaptivity >= COARSE_FROM else None
    if coarse is not None:  # (:mod:`.coarse`)
        surface = coarse
    elif sharp:
        surface = sharp_surface(frame, iso / scale)
    else:
        verts, tris = marching_cubes(frame, iso / scale)
        surface = {"verts": verts, "tris": tris, "ranks": None, "whole": np.zeros(0, np.uint8)}
    closed = iso == 0.0 or not len(open_vertices(surface["tris"], len(surface["verts"])))  # (see ``to_mesh``)
    found = sharp and (creases or adaptivity > 0.0) and len(surface["tris"])
    crease, fold = (
        crease_edges(surface["verts"], surface["tris"], surface["ranks"], folds=True) if found else (None, None)
    )
    out = {"verts": surface["verts"], "creases": np.zeros((0, 2), np.int32) if crease is None else crease}
    if not quads and adaptivity <= 0.0:
        out["tris"] = surface["tris"]
        return _placed(field, {**out, "closed": closed})
    out["faces"], out["sizes"] = merge_pairs(surface["tris"], surface["whole"])
    if adaptivity > 0.0 and sharp and len(out["sizes"]):
        coarser = int(coarse is not None)
        out = simplify(frame, {**out, "ranks": surface["ranks"], "folds": fold}, adaptivity, regions, coarser=coarser)
    if not quads:
        out["tris"] = triangulate(out.pop("faces"), out.pop("sizes"))
    return _placed(field, {**out, "closed": closed})


def _placed(field, out: dict) -> dict:
    """A surface extracted in the field's own frame, placed (``Placement.place_surface``; polygons turned over
    about their first corner, so their fans stay the triangles turned over)."""
    if field.placement is None:
        return out
    if "tris" in out:
        out["verts"], out["tris"] = field.placement.place_surface(out["verts"], out["tris"])
        return out
    out["verts"] = field.placement.to_world(out["verts"]).astype(np.float32)
    if field.placement.mirrors:
        sizes = out["sizes"].astype(np.int64)
        start = np.repeat(np.cumsum(sizes) - sizes, sizes)
        within = np.arange(len(out["faces"])) - start
        out["faces"] = out["faces"][start + (np.repeat(sizes, sizes) - within) % np.repeat(sizes, sizes)]
    return out


def marching_cubes(field, iso: float):
    """Marching cubes on an unplaced field's finest level: ``verts``, ``tris``."""
    n0 = field.level_counts[0]
    if field.levels == 1:  # the dense top level is the finest: no octets to walk
        return extract_surface(
            field.coords.numpy(), field.values.numpy(), origin=field.origin, spacing=field.voxel_size, iso=iso
        )
    codes, values = field.codes[:n0], field.values[:n0]
    return extract_octree_level(codes, values, field.tree, origin=field.origin, spacing=field.voxel_size, iso=iso)
