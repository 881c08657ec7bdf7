"""High adaptivities contoured on the level above the finest: cells of 2 voxels, where nothing finer is lost.

From an adaptivity of 0.25 the merged surface strays up to 0.07 voxel and more from the field's surface
(:func:`.adaptive.tolerance`), and most cells merge into blocks of 4 and more voxels a side; contouring every finest
cell first, then merging them, costs 3-5 times the surface of adaptivity 0. Ju et al.'s octree simplification
starts from the octree's leaves; this starts one level up: the field's level 1 holds exact distances and closest
points as its finest does (each node a finest octet), so :func:`.meshing.sharp_surface` contours it as it contours the
finest (a quarter of the cubes, creases from the same exact tangent planes, measured Hausdorff p95 0.025-0.036 voxel
on the CAD pairs at /256 against 0.009-0.010 at the finest), and :func:`.adaptive.simplify` merges that surface's
cells (a level fewer: the same blocks in voxels).

The coarse surface is taken only where it is as good: closed and 2-manifold (level 1 is a band of octets built around
the finest one, and may leave a cube incomplete where the finest band is thin), and crossing every finest octet the
finest surface crosses (an octet whose eight nodes change sign, and no active coarse cube has it as a corner: a fin,
a bump or a hole thinner than the coarse cells, gone). Otherwise :func:`coarse_surface` returns None and the finest
level is contoured as at lower adaptivities.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from .meshcheck import edge_table

# Adaptivities from this one on are contoured on level 1: the tolerance is 0.072 voxel there (0.22 at 0.5), 2.5-4
# times the coarse surface's Hausdorff p95, and its merged surface is nearer the exact one with fewer polygons than the
# finest's (cube - bore at 0.25: 7,273 polygons at p95 0.064 voxel against 9,891 at 0.078; fandisk - cylinder 5,060
# at 0.073 against 5,751 at 0.080); at 0.1 (0.023 voxel) it would be the coarse surface's error that counts.
COARSE_FROM = 0.25


def level_one(field):
    """The unplaced ``field`` without its finest level: its level 1 as the finest (cells of twice the voxel), the
    same nodes, values, closest points and sources (an ``AdaptiveField``, built as ``field``'s type: this module is
    imported by the field's own); None when that would leave the dense top level alone."""
    if field.levels < 3:
        return None
    offsets = field.level_offsets
    n0, n1 = int(offsets[1]), int(offsets[2] - offsets[1])
    child = field.child.numpy()[n1:]  # the links of level 2 and above, into level 1 and above
    child = np.where(child >= 0, child - n0, -1).astype(np.int32)
    return type(field)(
        voxel_size=2.0 * field.voxel_size,
        levels=field.levels - 1,
        origin=field.origin,
        top_dims=field.top_dims,
        level_offsets=offsets[1:] - n0,
        codes=field.codes[n0:],
        values=field.values[n0:],
        proj=field.proj[n0:],
        child=wp.array(child, dtype=wp.int32, device=field.device),
        source=field.source[n0:] if field.source.shape[0] else field.source,
        field_ids=field.field_ids,
        device=field.device,
        stats=field.stats,
        sources=field.sources,
    )


def coarse_surface(field, iso: float, contour) -> dict | None:
    """The sharp ``iso`` surface of the unplaced ``field``'s level 1 (``contour``: :func:`.meshing.sharp_surface`,
    given the coarse field and ``iso``; it returns the active cubes' ``cube_corners`` among its keys), or None where
    it is not closed and 2-manifold or misses a finest octet the surface crosses (see the module)."""
    coarse = level_one(field)
    if coarse is None:
        return None
    surface = contour(coarse, iso)
    if not len(surface["tris"]) or not _closed(surface["tris"], len(surface["verts"])):
        return None
    if _missed_octets(field, surface["cube_corners"], iso):
        return None
    return {**surface, "field": coarse}


def _closed(tris, n: int) -> bool:
    """Every edge of ``tris`` in two triangles, opposite ways."""
    table = edge_table(tris, n)
    return bool((table["faces"] == 2).all() and (table["forward"] == 1).all())


def _missed_octets(field, cube_corners, iso: float) -> int:
    """How many finest octets change sign across their eight nodes without being a corner of an active coarse cube
    (``cube_corners``: (M, 8) level-1 node indices)."""
    n0, n1 = int(field.level_offsets[1]), int(field.level_offsets[2] - field.level_offsets[1])
    values = field.values[:n0].numpy().reshape(-1, 8)
    inside = values < np.float32(iso)
    crossed = inside.any(axis=1) & ~inside.all(axis=1)  # per octet
    first = field.child.numpy()[:n1]  # each level-1 node's first child: its octet times 8, or -1
    octet_node = np.flatnonzero(first >= 0)
    crossing = np.zeros(n1, dtype=bool)
    crossing[octet_node] = crossed[first[octet_node] // 8]
    touched = np.zeros(n1, dtype=bool)
    touched[np.asarray(cube_corners).ravel()] = True
    return int(np.count_nonzero(crossing & ~touched))
