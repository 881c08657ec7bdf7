"""High adaptivities contoured on the level above the finest: cells of 2 voxels, where nothing finer is lost.

From an adaptivity of 0.25 the merged surface strays up to 0.07 voxel and more from the field's surface
(:func:`.adaptive.tolerance`), and most cells merge into blocks of 4 and more voxels a side; contouring every finest
cell first, then merging them, costs 3-5 times the surface of adaptivity 0. Ju et al.'s octree simplification
starts from the octree's leaves; this starts one level up: the field's level 1 holds exact distances and closest
points as its finest does (each node a finest octet), so :func:`.meshing.sharp_surface` contours it as it contours the
finest (a quarter of the cubes, creases from the same exact tangent planes, measured Hausdorff p95 0.025-0.036 voxel
on the CAD pairs at /256 against 0.009-0.010 at the finest), and :func:`.adaptive.simplify` merges that surface's
cells (a level fewer: the same blocks in voxels).

The coarse surface is taken only where it is as good: closed (level 1 is a band of octets built around the finest
one, and a boolean prunes those farther than :data:`.prune.KEEP_BAND` voxels from its surface, which keeps every
corner of a level-1 cube the surface crosses where the values are distances; a chamfer's change faster, so a
level-1 cube near its seam may miss a corner, and the surface is open there until the nodes missing about it are
added from the operands' closest points, :func:`_with_missing_nodes`), and crossing every finest octet the finest
surface crosses (an octet whose eight nodes change sign, and no active coarse cube has it as a corner: a fin, a bump
or a hole thinner than the coarse cells, gone). Otherwise :func:`coarse_surface` returns None and the finest level
is contoured as at lower adaptivities.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from .contouring import lattice_surface, sharp_surface
from .meshcheck import open_vertices
from .octree import in_sorted, morton_decode_np, morton_encode_np
from .parallel import host_view
from .sources import closest_points

# Rounds of nodes added where level 1's surface is open before it is given up (one closed every case measured).
PATCH_ROUNDS = 2

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


def coarse_surface(field, iso: float) -> dict | None:
    """The sharp ``iso`` surface of the unplaced ``field``'s level 1 (:func:`.contouring.sharp_surface`; its open
    places patched, :func:`_with_missing_nodes`, PATCH_ROUNDS times at most), or None where it stays open or misses a
    finest octet the surface crosses (see the module)."""
    coarse = level_one(field)
    if coarse is None:
        return None
    surface, samples = sharp_surface(coarse, iso), None
    for patch in range(PATCH_ROUNDS + 1):
        if not len(surface["tris"]):
            return None
        open_at = [] if surface["closed"] else open_vertices(surface["tris"], len(surface["verts"]))
        if not len(open_at):
            break
        if patch == PATCH_ROUNDS:
            return None
        samples = _with_missing_nodes(field, coarse, samples, surface["verts"][open_at])
        surface = lattice_surface(coarse, *samples, iso)
    if _missed_octets(field, surface["cube_corners"], iso):
        return None
    return surface


def _with_missing_nodes(field, coarse, samples, points) -> tuple:
    """``samples`` (coords, values, codes, proj of the ``coarse`` level's nodes and of nodes added before; None: the
    level's own) with the nodes missing around the cubes of ``points`` added: the 4 x 4 x 4 nodes about each cube.
    A boolean prunes its finest octets farther than KEEP_BAND voxels from its surface, so a level-1 cube near a
    chamfered seam can miss a corner (with a band of 2.5, by plain booleans too: 3.3-3.8 voxels off the surface); its
    value is the distance to the closest point of the operand deciding there (:func:`.sources.closest_points`), signed
    as the field's (the field sampled)."""
    if samples is None:
        n1 = coarse.level_counts[0]
        codes = coarse.codes[:n1].numpy()
        samples = (morton_decode_np(codes), coarse.values[:n1].numpy(), codes, coarse.proj[:n1].numpy())
    coords, values, codes, proj = samples
    spacing = coarse.voxel_size
    cube = np.floor((np.asarray(points, dtype=np.float64) - coarse.origin) / spacing - 0.5).astype(np.int64)
    block = np.stack(np.meshgrid(*[np.arange(-1, 3)] * 3, indexing="ij"), axis=-1).reshape(-1, 3)
    near = (cube[:, None, :] + block[None]).reshape(-1, 3)
    near = near[(near >= 0).all(axis=1) & (near < coarse.fine_dims).all(axis=1)]
    near_codes = np.unique(morton_encode_np(near))  # (unique codes: rows would sort as records, far slower)
    near_codes = near_codes[~in_sorted(np.sort(codes), near_codes)]
    near = morton_decode_np(near_codes)
    centres = coarse.origin + (near + 0.5) * spacing
    value, grad = field.sample(centres.astype(np.float32), return_gradient=True)
    on = centres - value[:, None] * grad / np.maximum((grad.astype(np.float64) ** 2).sum(axis=1), 1e-12)[:, None]
    ids = field.source_ids(centres.astype(np.float32))
    for field_id, source in field.sources.items():
        rows = np.flatnonzero(ids == field_id)
        if source is not None and len(source.tris) and len(rows):
            exact = closest_points(source, centres[rows], field.device)
            found = ~np.isnan(exact[:, 0])
            on[rows[found]] = exact[found]
    distance = np.linalg.norm(centres - on, axis=1)
    value = np.where(value < 0.0, -distance, distance).astype(np.float32)
    offsets = ((on - centres) / spacing).astype(np.float16)
    return (
        np.concatenate([coords, near]), np.concatenate([values, value]), np.concatenate([codes, near_codes]),
        np.concatenate([proj, offsets]),
    )  # fmt: skip


def _missed_octets(field, cube_corners, iso: float) -> int:
    """How many finest octets change sign across their eight nodes without being a corner of an active coarse cube
    (``cube_corners``: (M, 8) level-1 node indices, and the nodes added past them)."""
    n1 = int(field.level_offsets[2] - field.level_offsets[1])
    device = field.device
    corners = host_view(np.ascontiguousarray(cube_corners, dtype=np.int32).reshape(-1), wp.int32, device)
    touched = wp.zeros(n1, dtype=wp.uint8, device=device)
    wp.launch(_touch_kernel, corners.shape[0] // 8, [corners, n1, touched], device=device)
    count = wp.zeros(1, dtype=wp.int32, device=device)
    wp.launch(_missed_kernel, n1, [field.values, field.child, touched, float(iso), count], device=device)
    return int(count.numpy()[0])


@wp.kernel(enable_backward=False)
def _touch_kernel(corners: wp.array[wp.int32], n1: int, touched: wp.array[wp.uint8]):
    """The level-1 nodes among cube ``i``'s 8 ``corners`` (nodes added past the level's ``n1`` left out) marked."""
    i = wp.tid()
    for k in range(8):
        c = corners[8 * i + k]
        if c < n1:
            touched[c] = wp.uint8(1)


@wp.kernel(enable_backward=False)
def _missed_kernel(
    values: wp.array[wp.float32],
    child: wp.array[wp.int32],
    touched: wp.array[wp.uint8],
    iso: float,
    count: wp.array[wp.int32],
):
    """Level-1 node ``i`` not ``touched`` whose finest octet (its first child ``child[i]`` and the 7 after it) is
    inside at one node and not at all, counted (one pass: numpy's eight column reductions took 1-1.5 ms)."""
    i = wp.tid()
    first = child[i]
    if first < 0 or touched[i] != wp.uint8(0):
        return
    low = values[first]
    high = low
    for k in range(1, 8):
        low = wp.min(low, values[first + k])
        high = wp.max(high, values[first + k])
    if low < iso and high >= iso:
        wp.atomic_add(count, 0, 1)
