"""A field's sharp surface: the dual contouring (:func:`.dual.contour_dual`) of its finest level's active cubes, or of
given samples on that lattice, with the crease vertices that reached past their cube off every operand's surface
pulled back (:func:`.reached.pulled_back`)."""

from __future__ import annotations

import numpy as np
import warp as wp

from .dual import CELL_MARGIN, contour_dual
from .extract import lattice_cubes, octree_level_cubes
from .marching import empty_mesh
from .reached import pulled_back


def sharp_surface(field, iso: float) -> dict:
    """The dual contouring of an unplaced field's finest-level active cubes: :func:`.dual.contour_dual`'s dict with
    the cubes' (M, 8) ``cube_corners`` node indices, or an empty surface."""
    n0 = field.level_counts[0]
    if field.levels == 1:
        arrays = (field.coords.numpy(), field.values.numpy(), field.codes.numpy(), field.proj.numpy())
        return lattice_surface(field, *arrays, iso)
    codes, values, proj = field.codes[:n0], field.values[:n0], field.proj[:n0]
    cubes = octree_level_cubes(codes, values, field.tree, origin=field.origin, spacing=field.voxel_size, iso=iso)
    if cubes is None:
        return _empty()
    corners = cubes["cube_corners"]
    surface = contour_dual(
        corners, cubes["shifted"], codes, proj, origin=field.origin, spacing=field.voxel_size, iso=iso
    )
    surface["cube_corners"] = corners.numpy()
    if iso != 0.0:  # (an offset's vertices lie off every operand's surface)
        return surface
    return pulled_back(field, surface, surface["cube_corners"], codes.numpy(), CELL_MARGIN)


def lattice_surface(field, coords, values, codes, proj, iso: float) -> dict:
    """:func:`sharp_surface` of samples on the lattice of an unplaced ``field``'s finest level: (N, 3) int
    ``coords``, (N,) float ``values``, (N,) int64 Morton ``codes`` and (N, 3) float16 ``proj`` (each closest point's
    offset from its sample in spacings, as a field keeps it), in any order; ``cube_corners`` are sample indices."""
    cubes = lattice_cubes(
        coords, np.asarray(values, dtype=np.float64), origin=field.origin, spacing=field.voxel_size, iso=iso,
        device=field.device,
    )  # fmt: skip
    if cubes is None:
        return _empty()
    order = np.arange(len(codes)) if cubes["order"] is None else cubes["order"]
    codes = np.asarray(codes, dtype=np.int64)[order]
    codes_wp = wp.array(codes, dtype=wp.int64, device=field.device)
    proj_wp = wp.array(np.ascontiguousarray(np.asarray(proj)[order]), dtype=wp.vec3h, device=field.device)
    corners = cubes["cube_corners"]
    surface = contour_dual(
        corners, cubes["shifted"], codes_wp, proj_wp, origin=field.origin, spacing=field.voxel_size, iso=iso
    )
    sorted_corners = corners.numpy()
    surface["cube_corners"] = order[sorted_corners]
    if iso != 0.0:
        return surface
    return pulled_back(field, surface, sorted_corners, codes, CELL_MARGIN)


def _empty() -> dict:
    verts, tris = empty_mesh()
    empty = {"ranks": np.zeros(0, np.int32), "whole": np.zeros(0, np.uint8), "cube_corners": np.zeros((0, 8), np.int64)}
    return {"verts": verts, "tris": tris, **empty}
