"""Mesh extraction from the sparse sample lattice of an adaptive field.

The finest octree level stores signed distances at cell centres, which form a sparse subset of a regular integer
lattice: a thin band around the surface inside a possibly huge domain. :func:`extract_surface` polygonises the dual
cubes of that lattice (cube ``c`` has the samples ``c + {0, 1}^3`` as corners) without ever allocating a dense grid:
samples are packed into sorted 64-bit keys, a Warp kernel finds each cube's seven other corners by galloping search,
and only complete cubes whose corners change sign are polygonised by the core of Warp's sparse marching cubes (its
tables, its passes run here split over the CPU cores), with the samples themselves as the cubes' shared corners
(Warp's public ``sparse_marching_cubes_from_cells`` would sort eight corner codes per cube to find them again: ~2x
the time and memory; it remains the fallback for other Warp versions). Vertices are shared between cubes, so the
mesh is watertight wherever the zero set stays inside the band.
:func:`extract_octree_level` does the same on a field's finest level as stored (Morton order, complete octets):
each cube's corners come from its octet's +x/+y/+z neighbour octets, found through the tree's child links, so
nothing is sorted and nothing leaves the device. ``bench/extract_compare.py`` measures this against scikit-image's
marching cubes run on dense 16^3 blocks.
"""

from __future__ import annotations

import numpy as np
import warp as wp
import warp.geometry

from .marching import CORNER_OFFSETS, HAS_SHARED_CORNER_CORE, empty_mesh, iso_nudge, polygonise
from .octree import decode_codes, morton_decode
from .parallel import EMIT_SPLIT_MIN_DIM, launch_split

# The seven other corners in ascending key order (corner slot, then its offset). Keys are
# i * stride_x + j * stride_y + k with stride_x > stride_y + 1 > 2, so lexicographic (i, j, k) order is key order.
_SEARCH_SLOTS = tuple(sorted(range(1, 8), key=lambda c: CORNER_OFFSETS[c].tolist()))


_SEARCH_OFFSETS = tuple(tuple(int(x) for x in CORNER_OFFSETS[c]) for c in _SEARCH_SLOTS)


# Keys pack (i, j, k) relative to the minimum into one int64, so the lattice may span at most this many points per axis.
_MAX_SPAN = 2**20


@wp.func
def _gallop_lower_bound(keys: wp.array[wp.int64], start: wp.int32, target: wp.int64):
    """First index ``>= start`` whose key is ``>= target`` in sorted ``keys`` (``len(keys)`` if none).

    Gallops forward from ``start`` before bisecting, so a neighbour a few entries away (the common case for the +z and
    +y corners) costs a few reads instead of a full binary search.

    Args:
        keys: (N,) int64, strictly increasing.
        start: First index to consider; every key before it must be ``< target``.
        target: Key to look for.
    Returns:
        int32 index in ``[start, N]``.
    """
    n = keys.shape[0]
    lo = start
    hi = start
    step = wp.int32(1)
    while hi < n:
        if keys[hi] >= target:
            break
        lo = hi + 1
        hi = start + step
        step = step * 2
    if hi > n:
        hi = n
    while lo < hi:
        mid = lo + (hi - lo) // 2
        if keys[mid] < target:
            lo = mid + 1
        else:
            hi = mid
    return lo


@wp.kernel(enable_backward=False)
def _find_cube_corners_kernel(
    first: int,
    keys: wp.array[wp.int64],
    values: wp.array[wp.float32],
    stride_x: wp.int64,
    stride_y: wp.int64,
    emit: int,
    active_scan: wp.array[wp.int32],
    active: wp.array[wp.int32],
    cube_corners: wp.array2d[wp.int32],
):
    """Find the 8 corner samples of the cube whose minimum corner is sample ``i``.

    A cube is active when all 8 corners exist and its values have both signs (``< 0`` and ``>= 0``, the convention of
    Warp's marching cubes). One thread per sample; the 7 searches gallop forward in ascending key order. Run twice:
    with ``emit=0`` it flags the active cubes, with ``emit=1`` it searches again for the active ones only and writes
    their corners to their compacted row (so no (N, 8) table is ever held).

    Args:
        first: Sample of thread 0 (launches may cover part of the samples).
        keys: (N,) int64 sorted sample keys ``i * stride_x + j * stride_y + k`` (relative to the minimum).
        values: (N,) float32 values minus the level, in key order, none exactly 0.
        stride_x: Key step of +1 in i.
        stride_y: Key step of +1 in j (+1 in k is 1).
        emit: 0 to flag, 1 to write corners.
        active_scan: (N,) int32 inclusive prefix sum of ``active`` (read with ``emit=1``).
        active: (N,) int32, written with ``emit=0``: 1 for a complete cube whose corners change sign, else 0.
        cube_corners: (M, 8) int32 output with ``emit=1``: sample index of each active cube's corners, in
            ``CUBE_CORNER_OFFSETS`` order.
    """
    i = first + wp.tid()
    if emit == 1:
        if active[i] == 0:
            return
    n = keys.shape[0]
    key = keys[i]
    row = int(0)
    if emit == 1:
        row = active_scan[i] - 1
        cube_corners[row, 0] = i
    else:
        active[i] = 0
    negative = wp.where(values[i] < 0.0, 1, 0)
    pos = i + 1
    for c in range(7):
        target = (
            key
            + wp.int64(wp.static(_SEARCH_OFFSETS[c][0])) * stride_x
            + wp.int64(wp.static(_SEARCH_OFFSETS[c][1])) * stride_y
            + wp.int64(wp.static(_SEARCH_OFFSETS[c][2]))
        )
        pos = _gallop_lower_bound(keys, pos, target)
        if pos >= n:
            return
        if keys[pos] != target:
            return
        if emit == 1:
            cube_corners[row, wp.static(_SEARCH_SLOTS[c])] = pos
        negative += wp.where(values[pos] < 0.0, 1, 0)
    if emit == 0 and negative > 0 and negative < 8:
        active[i] = 1


@wp.kernel(enable_backward=False)
def _gather_active_cubes_kernel(
    cube_corners: wp.array2d[wp.int32],
    keys: wp.array[wp.int64],
    values: wp.array[wp.float32],
    lo: wp.vec3i,
    stride_x: wp.int64,
    stride_y: wp.int64,
    cells: wp.array[wp.vec3i],
    corner_values: wp.array2d[wp.float32],
):
    """Minimum-corner lattice coordinates (decoded from corner 0's key) and corner values of each active cube.

    Args:
        cube_corners: (M, 8) int32 corner sample indices from ``_find_cube_corners_kernel``.
        keys: (N,) int64 sorted sample keys.
        values: (N,) float32 values minus the level, in key order.
        lo: Lattice coordinates of key 0.
        stride_x: Key step of +1 in i.
        stride_y: Key step of +1 in j.
        cells: (M,) vec3i output, lattice coordinates of each active cube's minimum corner.
        corner_values: (M, 8) float32 output, the active cubes' corner values in ``CUBE_CORNER_OFFSETS`` order.
    """
    o = wp.tid()
    key = keys[cube_corners[o, 0]]
    ci = key / stride_x
    rem = key - ci * stride_x
    cj = rem / stride_y
    ck = rem - cj * stride_y
    cells[o] = lo + wp.vec3i(wp.int32(ci), wp.int32(cj), wp.int32(ck))
    for c in range(8):
        corner_values[o, c] = values[cube_corners[o, c]]


@wp.kernel(enable_backward=False)
def _used_corner_points_kernel(
    first: int,
    used: wp.array[wp.int32],
    used_scan: wp.array[wp.int32],
    keys: wp.array[wp.int64],
    values: wp.array[wp.float32],
    stride_x: wp.int64,
    stride_y: wp.int64,
    base: wp.vec3,
    spacing: float,
    points: wp.array[wp.vec3],
    point_values: wp.array[wp.float32],
):
    """Position (``base`` is the world position of key 0) and value of used sample ``first + tid``, at its compacted
    index."""
    i = first + wp.tid()
    if used[i] == 0:
        return
    out = used_scan[i] - 1
    key = keys[i]
    ci = key / stride_x
    rem = key - ci * stride_x
    cj = rem / stride_y
    ck = rem - cj * stride_y
    points[out] = base + spacing * wp.vec3(float(ci), float(cj), float(ck))
    point_values[out] = values[i]


# For node k of an octet (bits x, y, z) and cube corner c: which of the octet's +x/+y/+z neighbour octets (bits) holds
# the corner, and which child of it the corner is.
# Bit c of _CORNER_BITS_X/Y/Z is corner c's offset along that axis.
_CORNER_BITS_X = int(sum(int(CORNER_OFFSETS[c][0]) << c for c in range(8)))


_CORNER_BITS_Y = int(sum(int(CORNER_OFFSETS[c][1]) << c for c in range(8)))


_CORNER_BITS_Z = int(sum(int(CORNER_OFFSETS[c][2]) << c for c in range(8)))


@wp.func
def _octet_first_node(
    child: wp.array[wp.int32], fine_count: int, top_offset: int, top_dims: wp.vec3i, levels: int, q: wp.vec3i
) -> int:
    """First finest node of the octet at octet coordinates ``q`` (level-1 lattice), or -1 when the tree has none there:
    the top cell holding it, then the child links down to level 1 (children in Morton order; ``child`` holds the
    coarse nodes' links, node ``i`` at ``i - fine_count``)."""
    shift = levels - 2
    top = wp.vec3i(q[0] >> shift, q[1] >> shift, q[2] >> shift)
    for a in range(3):
        if q[a] < 0 or top[a] >= top_dims[a]:
            return -1
    node = top_offset + top[0] + top_dims[0] * (top[1] + top_dims[1] * top[2])
    for s in range(shift):
        first = child[node - fine_count]
        if first < 0:
            return -1
        b = shift - 1 - s
        node = first + ((q[0] >> b) & 1) + 2 * ((q[1] >> b) & 1) + 4 * ((q[2] >> b) & 1)
    return child[node - fine_count]


@wp.kernel(enable_backward=False)
def _octet_cube_corners_kernel(
    first: int,
    codes: wp.array[wp.int64],
    child: wp.array[wp.int32],
    fine_count: int,
    top_offset: int,
    top_dims: wp.vec3i,
    levels: int,
    values: wp.array[wp.float32],
    emit: int,
    neighbours: wp.array2d[wp.int32],
    active_scan: wp.array[wp.int32],
    active: wp.array[wp.int32],
    cube_corners: wp.array2d[wp.int32],
):
    """``_find_cube_corners_kernel`` on an octree's finest level (Morton-sorted, in complete octets): one thread per
    octet. With ``emit=0`` it finds the octet's 7 neighbours towards +x/+y/+z (first node, or -1) into
    ``neighbours`` through the tree's child links, and flags the active cubes whose minimum corner is one of its 8
    nodes; with ``emit=1`` it writes those cubes' corners, taken from the 8 octets by index arithmetic."""
    t = first + wp.tid()
    base = 8 * t
    nb = wp.vector(-1, -1, -1, -1, -1, -1, -1, -1, length=8, dtype=int)
    nb[0] = base
    if emit == 0:
        octet = morton_decode(codes[base] >> wp.int64(3))
        for d in range(1, 8):
            q = octet + wp.vec3i(d & 1, (d >> 1) & 1, (d >> 2) & 1)
            neighbours[t, d - 1] = _octet_first_node(child, fine_count, top_offset, top_dims, levels, q)
    for d in range(1, 8):
        nb[d] = neighbours[t, d - 1]
    nodes = int(8)  # not unrolled (compile time)
    for k in range(nodes):
        i = base + k
        if emit == 0 or active[i] == 1:
            complete = int(1)
            negative = int(0)
            row = int(0)
            if emit == 1:
                row = active_scan[i] - 1
            for c in range(8):
                # the corner's position in the 4x4x4 nodes of the octet and its +x/+y/+z neighbours
                sx = (k & 1) + ((_CORNER_BITS_X >> c) & 1)
                sy = ((k >> 1) & 1) + ((_CORNER_BITS_Y >> c) & 1)
                sz = ((k >> 2) & 1) + ((_CORNER_BITS_Z >> c) & 1)
                o = nb[(sx >> 1) | ((sy >> 1) << 1) | ((sz >> 1) << 2)]
                if o < 0:
                    complete = 0
                else:
                    j = o + ((sx & 1) | ((sy & 1) << 1) | ((sz & 1) << 2))
                    negative += wp.where(values[j] < 0.0, 1, 0)
                    if emit == 1:
                        cube_corners[row, c] = j
            if emit == 0:
                active[i] = wp.where(complete == 1 and negative > 0 and negative < 8, 1, 0)


@wp.kernel(enable_backward=False)
def _shift_nudge_kernel(values: wp.array[wp.float32], iso: float, nudge: float, out: wp.array[wp.float32]):
    """``values - iso``, entries within ``nudge`` of 0 pushed to ``-nudge`` / ``+nudge`` (see ``_nudge_values``)."""
    i = wp.tid()
    v = values[i] - iso
    if wp.abs(v) < nudge:
        v = wp.where(v < 0.0, -nudge, nudge)
    out[i] = v


@wp.kernel(enable_backward=False)
def _used_node_points_kernel(
    first: int,
    used: wp.array[wp.int32],
    used_scan: wp.array[wp.int32],
    codes: wp.array[wp.int64],
    lo: wp.vec3i,
    values: wp.array[wp.float32],
    base: wp.vec3,
    spacing: float,
    points: wp.array[wp.vec3],
    point_values: wp.array[wp.float32],
):
    """``_used_corner_points_kernel`` from lattice coordinates (``base``: world position of lattice point ``lo``)."""
    i = first + wp.tid()
    if used[i] == 0:
        return
    out = used_scan[i] - 1
    c = morton_decode(codes[i]) - lo
    points[out] = base + spacing * wp.vec3(float(c[0]), float(c[1]), float(c[2]))
    point_values[out] = values[i]


def octree_level_cubes(codes, values, tree, *, origin, spacing, iso=0.0):
    """The active cubes of an octree's finest level as it is stored (see :func:`extract_octree_level`): each cube's
    corners come from its octet's neighbours (``_octet_cube_corners_kernel``), so nothing is sorted.

    Returns:
        ``None`` when no complete cube changes sign, else a dict: ``cube_corners`` (M, 8) int32 Warp array of node
        indices (``CORNER_OFFSETS`` order), ``shifted`` (N,) float32 Warp array of the values minus ``iso`` with
        entries within the nudge of 0 pushed off it, ``lo`` (3,) int64 lattice minimum of the level.
    """
    n = codes.shape[0]
    if n == 0:
        return None
    device = codes.device
    child, fine_count, top_offset, top_dims, levels = tree
    tree_args = [child, int(fine_count), int(top_offset), wp.vec3i(*(int(d) for d in top_dims)), int(levels)]
    origin = np.asarray(origin, dtype=np.float64)
    spacing = float(spacing)
    # each octet spans its first node's coordinates plus 0 or 1 on every axis: the first nodes bound the level
    # (column by column: numpy reduces an (N, 3) array along its first axis several times slower)
    first_nodes = decode_codes(codes, step=8).numpy()
    lo = np.array([first_nodes[:, k].min() for k in range(3)], dtype=np.int64)
    hi = np.array([first_nodes[:, k].max() + 1 for k in range(3)], dtype=np.int64)
    nudge = iso_nudge(origin, lo, hi, spacing)
    shifted = wp.empty(n, dtype=wp.float32, device=device)
    launch_split(
        _shift_nudge_kernel, n, lambda s, c: [values[s : s + c], float(iso), nudge, shifted[s : s + c]], device
    )
    active = wp.empty(n, dtype=wp.int32, device=device)
    active_scan = wp.empty(n, dtype=wp.int32, device=device)
    no_corners = wp.empty((0, 8), dtype=wp.int32, device=device)
    neighbours = wp.empty((n // 8, 7), dtype=wp.int32, device=device)
    launch_split(
        _octet_cube_corners_kernel,
        n // 8,
        lambda s, c: [s, codes, *tree_args, shifted, 0, neighbours, active_scan, active, no_corners],
        device,
        min_dim=EMIT_SPLIT_MIN_DIM,  # an octet's neighbours searched each
    )
    wp.utils.array_scan(active, active_scan, inclusive=True)
    n_cubes = int(active_scan[-1:].numpy()[0])
    if n_cubes == 0:
        return None
    cube_corners = wp.empty((n_cubes, 8), dtype=wp.int32, device=device)
    launch_split(
        _octet_cube_corners_kernel,
        n // 8,
        lambda s, c: [s, codes, *tree_args, shifted, 1, neighbours, active_scan, active, cube_corners],
        device,
        min_dim=EMIT_SPLIT_MIN_DIM,
    )
    return {"cube_corners": cube_corners, "shifted": shifted, "lo": lo}


def extract_octree_level(codes, values, tree, *, origin, spacing, iso=0.0):
    """:func:`extract_surface` for an octree's finest level as it is stored: Warp arrays of Morton codes and
    values (signed distances, finite; Morton order, in complete octets of 8 consecutive nodes), all on one device, and
    ``tree`` = (the coarse nodes' child links, the finest level's node count, index of the dense top level's first
    node, its dims, number of levels >= 2; ``AdaptiveField.tree``) to find neighbour octets by. Same mesh as
    ``extract_surface(coords, values, ...)``, found without leaving the device: each cube's corners come from its
    octet's neighbours (``_octet_cube_corners_kernel``), so nothing is sorted.

    Returns and raises as :func:`extract_surface` (no ValueError: the level is valid by construction).
    """
    cubes = octree_level_cubes(codes, values, tree, origin=origin, spacing=spacing, iso=iso)
    if cubes is None:
        return empty_mesh()
    device = codes.device
    origin = np.asarray(origin, dtype=np.float64)
    spacing = float(spacing)
    n, lo, shifted = codes.shape[0], cubes["lo"], cubes["shifted"]
    if not HAS_SHARED_CORNER_CORE:  # another Warp version: through the generic path
        return extract_surface(
            decode_codes(codes).numpy(), shifted.numpy(), origin=origin, spacing=spacing, iso=0.0, device=device
        )
    point_inputs = [codes, wp.vec3i(*(int(x) for x in lo)), shifted]
    verts_wp, indices_wp = polygonise(
        cubes["cube_corners"], n, _used_node_points_kernel, point_inputs, lo, origin, spacing
    )
    if indices_wp.shape[0] == 0:
        return empty_mesh()
    verts = verts_wp.numpy().astype(np.float32, copy=False).reshape(-1, 3)
    tris = indices_wp.numpy().astype(np.int32, copy=False).reshape(-1, 3)
    return verts, tris


def _shared_corner_surface(keys_wp, values_wp, cube_corners, lo, origin, spacing, strides):
    """Marching cubes whose corners are the samples themselves: each sample is one shared corner, so no sort is needed
    to find which cubes share a corner (Warp's public entry point sorts 8 codes per cube). Returns Warp arrays
    (vertices, flat triangle indices)."""
    point_inputs = [keys_wp, values_wp, wp.int64(strides[0]), wp.int64(strides[1])]
    return polygonise(cube_corners, keys_wp.shape[0], _used_corner_points_kernel, point_inputs, lo, origin, spacing)


def _sorted_corner_surface(keys_wp, values_wp, cube_corners, lo, origin, spacing, strides):
    """The same through Warp's public ``sparse_marching_cubes_from_cells`` (cube positions and corner values)."""
    device = keys_wp.device
    n_cubes = cube_corners.shape[0]
    cells = wp.empty(n_cubes, dtype=wp.vec3i, device=device)
    corner_values = wp.empty((n_cubes, 8), dtype=wp.float32, device=device)
    wp.launch(
        _gather_active_cubes_kernel,
        dim=n_cubes,
        inputs=[
            cube_corners,
            keys_wp,
            values_wp,
            wp.vec3i(*(int(x) for x in lo)),
            wp.int64(strides[0]),
            wp.int64(strides[1]),
        ],
        outputs=[cells, corner_values],
        device=device,
    )
    return warp.geometry.sparse_marching_cubes_from_cells(
        cells,
        corner_values,
        origin=tuple(float(x) for x in origin + 0.5 * spacing),
        cell_width=spacing,
        threshold=0.0,
        device=device,
    )


def _validate(coords, values, origin, spacing, iso) -> tuple[np.ndarray, np.ndarray, np.ndarray, float, float]:
    """Check and normalise the arguments of :func:`extract_surface`; see there for the rules."""
    coords = np.asarray(coords)
    if coords.ndim != 2 or coords.shape[1] != 3:
        raise ValueError(f"Expected 'coords' of shape (N, 3), but got {coords.shape}.")
    if coords.size and not np.issubdtype(coords.dtype, np.integer):
        raise TypeError(f"Expected integer 'coords', but got dtype {coords.dtype}.")
    if coords.dtype != np.int32:
        int32 = np.iinfo(np.int32)
        if coords.size and (coords.min() < int32.min or coords.max() > int32.max):
            raise ValueError("Expected 'coords' within the int32 range, but got values outside it.")
        coords = coords.astype(np.int32)
    values = np.asarray(values, dtype=np.float64)
    if values.shape != (len(coords),):
        raise ValueError(f"Expected 'values' of shape ({len(coords)},) to match 'coords', but got {values.shape}.")
    bad = np.count_nonzero(~np.isfinite(values))
    if bad:
        raise ValueError(f"Expected finite 'values', but got {bad} non-finite entries.")
    origin = np.asarray(origin, dtype=np.float64)
    if origin.shape != (3,):
        raise ValueError(f"Expected 'origin' of shape (3,), but got {origin.shape}.")
    if not np.all(np.isfinite(origin)):
        raise ValueError(f"Expected a finite 'origin', but got {origin.tolist()}.")
    spacing = float(spacing)
    if not (np.isfinite(spacing) and spacing > 0.0):
        raise ValueError(f"Expected a positive 'spacing', but got {spacing}.")
    iso = float(iso)
    if not np.isfinite(iso):
        raise ValueError(f"Expected a finite 'iso', but got {iso}.")
    return coords, values, origin, spacing, iso


def _nudge_values(values: np.ndarray, iso: float, nudge: float) -> np.ndarray:
    """Return ``values - iso`` as float32 with every entry at least ``nudge`` away from zero.

    Entries in ``(-nudge, nudge)`` become ``-nudge`` when negative and ``+nudge`` otherwise, so exact zeros join the
    outside, matching the ``>= iso`` test of Warp's marching cubes, and no sample changes side.
    """
    shifted = values - iso
    shifted = np.where(np.abs(shifted) < nudge, np.where(shifted < 0.0, -nudge, nudge), shifted)
    return shifted.astype(np.float32)


def lattice_cubes(coords, values, *, origin, spacing, iso, device=None):
    """The active cubes of a sparse set of lattice samples (validated as by :func:`extract_surface`): samples packed
    into sorted 64-bit keys, each cube's other corners found by galloping search.

    Returns:
        ``None`` when no complete cube changes sign, else a dict: ``keys`` (N,) int64 and ``shifted`` (N,) float32
        (values minus ``iso``, nudged off 0) Warp arrays in key order, ``order`` (N,) int64 sample index of each key
        (``None`` when the samples came in key order), ``cube_corners`` (M, 8) int32 Warp array of key indices,
        ``lo`` (3,) int64 lattice minimum, ``strides`` (key step in i, in j).
    """
    if len(coords) == 0:
        return None
    device = wp.get_device(device)

    # Pack (i, j, k) into int64 keys and sort; a field that emits its samples in key order skips the sort.
    lo = np.array([coords[:, axis].min() for axis in range(3)], dtype=np.int64)
    hi = np.array([coords[:, axis].max() for axis in range(3)], dtype=np.int64)
    if int((hi - lo).max()) >= _MAX_SPAN:
        raise ValueError(
            f"Expected 'coords' spanning fewer than 2**20 lattice points per axis, but got {(hi - lo + 1).tolist()}."
        )
    span = hi - lo + 2  # one spare slot per axis: a search for c + 1 past the maximum can never alias
    stride_y = int(span[2])
    stride_x = int(span[1]) * stride_y
    keys = (coords[:, 0] - lo[0]).astype(np.int64) * stride_x
    keys += (coords[:, 1] - lo[1]).astype(np.int64) * stride_y
    keys += coords[:, 2] - lo[2]
    order = None
    if not np.all(keys[1:] > keys[:-1]):
        order = np.argsort(keys)
        keys, values = keys[order], values[order]
        duplicates = np.count_nonzero(keys[1:] == keys[:-1])
        if duplicates:
            raise ValueError(f"Expected unique 'coords', but got {duplicates} repeated samples.")

    nudge = iso_nudge(origin, lo, hi, spacing)
    shifted = _nudge_values(values, iso, nudge)

    # Find the complete cubes whose corners change sign and gather their corner values.
    n = len(keys)
    keys_wp = wp.array(keys, dtype=wp.int64, device=device)
    values_wp = wp.array(shifted, dtype=wp.float32, device=device)
    active = wp.empty(n, dtype=wp.int32, device=device)
    active_scan = wp.empty(n, dtype=wp.int32, device=device)
    strides = (wp.int64(stride_x), wp.int64(stride_y))
    no_corners = wp.empty((0, 8), dtype=wp.int32, device=device)
    launch_split(
        _find_cube_corners_kernel,
        n,
        lambda start, _count: [start, keys_wp, values_wp, *strides, 0, active_scan, active, no_corners],
        device,
    )
    wp.utils.array_scan(active, active_scan, inclusive=True)
    n_cubes = int(active_scan[-1:].numpy()[0])
    if n_cubes == 0:
        return None
    cube_corners = wp.empty((n_cubes, 8), dtype=wp.int32, device=device)
    launch_split(
        _find_cube_corners_kernel,
        n,
        lambda start, _count: [start, keys_wp, values_wp, *strides, 1, active_scan, active, cube_corners],
        device,
    )
    return {
        "keys": keys_wp,
        "shifted": values_wp,
        "order": order,
        "cube_corners": cube_corners,
        "lo": lo,
        "strides": (stride_x, stride_y),
    }


def extract_surface(coords, values, *, origin, spacing, iso=0.0, device=None) -> tuple[np.ndarray, np.ndarray]:
    """Marching cubes over a sparse set of samples on a regular lattice.

    Sample ``(i, j, k)`` sits at ``origin + ((i, j, k) + 0.5) * spacing`` (the cell centres of the finest octree
    level). Only the dual cubes whose 8 corner samples ``c + {0, 1}^3`` all exist are polygonised, so the result is
    watertight whenever every cube the ``iso`` level set passes through is complete: for a distance field, a band
    holding every sample with ``|values - iso| < 2 * spacing`` is enough (such a cube's corners lie within
    ``sqrt(3) * spacing`` of the surface). No dense grid is allocated: memory and time grow with ``N``.

    Samples within ``1e-3 * spacing`` of ``iso`` are pushed to that distance (keeping their side; values equal to
    ``iso`` count as outside), so no vertex lands on a sample and no triangle collapses.

    Args:
        coords: (N, 3) integer array-like of unique lattice coordinates (may be negative, must fit in int32).
        values: (N,) float array-like of signed distances at the samples, negative inside.
        origin: (3,) float array-like, world position of the lattice's cell (0, 0, 0) minimum corner.
        spacing: Positive lattice spacing in world units.
        iso: Level to extract.
        device: Warp device for the kernels; ``None`` uses Warp's current device.
    Returns:
        ``verts`` (V, 3) float32 world positions and ``tris`` (F, 3) int32 indices: each vertex shared by all its
        triangles and used by at least one, counter-clockwise seen from outside (normals point towards values above
        ``iso``). Both are empty, with shapes (0, 3), when no complete cube crosses ``iso``.
    Raises:
        ValueError: If ``coords`` is not (N, 3), has duplicates or leaves the int32 range; if ``values`` is not (N,)
            or not finite; if ``origin`` is not a finite (3,); if ``spacing`` is not positive; if ``iso`` is not
            finite; or if the coordinates span too many lattice points to pack into 64-bit keys.
        TypeError: If ``coords`` is not an integer array.
        AasdfError: If the lattice lies so far from the world origin that float32 vertices cannot resolve 1/32 of
            ``spacing`` there.
    """
    coords, values, origin, spacing, iso = _validate(coords, values, origin, spacing, iso)
    cubes = lattice_cubes(coords, values, origin=origin, spacing=spacing, iso=iso, device=device)
    if cubes is None:
        return empty_mesh()
    keys_wp, values_wp, cube_corners, lo = cubes["keys"], cubes["shifted"], cubes["cube_corners"], cubes["lo"]
    stride_x, stride_y = cubes["strides"]
    surface = _sorted_corner_surface if not HAS_SHARED_CORNER_CORE else _shared_corner_surface
    verts_wp, indices_wp = surface(keys_wp, values_wp, cube_corners, lo, origin, spacing, (stride_x, stride_y))
    if indices_wp.shape[0] == 0:
        return empty_mesh()
    verts = verts_wp.numpy().astype(np.float32, copy=False).reshape(-1, 3)
    tris = indices_wp.numpy().astype(np.int32, copy=False).reshape(-1, 3)
    return verts, tris
