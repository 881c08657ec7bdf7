"""Where an open mesh's surface crosses its holes, away from every triangle.

Across a hole the winding number jumps from inside to outside with no triangle near, so the finest band around the
triangles does not hold that part of the surface. Before the first build, :func:`cap_lattices` decides inside or
outside at the octet centres around each hole's cap and adds the octets on either side of that surface to the finest
level. After a build, :func:`sign_change_octets` looks for the zero set leaving the band near the caps, and the build
refines what it finds in another round.
"""

from __future__ import annotations

import itertools
from typing import TYPE_CHECKING

import numpy as np
import warp as wp

from . import octree, parallel
from .geometry import near_cap, segment_clear, winding_number
from .octree import find_key, morton_decode, morton_encode, node_center
from .sampling import FieldArg, inside_domain, locate_leaf, node_coords, top_cell
from .signs import box_arrays
from .winding import WINDING_ACCURACY, WindingArg, mesh_sign_kernel, side_of

if TYPE_CHECKING:
    from .field import AdaptiveField

# Octets around the caps of an open mesh's holes whose centres' winding numbers locate the surface across the holes
# before the first build, and the most such octets per band octet that is worth (beyond it, a hole about as large
# as the mesh, the refinement rounds find that surface from the coarse signs instead).
CAP_LATTICE_MARGIN = 1


CAP_LATTICE_MAX_RATIO = 1.0


# ... and the least part of a box's octets that surface must cross, as seen from cells twice their size, for the box
# to be sampled (Suzanne's eyes: 0.2 %, holes of the bunny and the teapot: 10-30 %)
CAP_LATTICE_MIN_SHEET = 0.02


@wp.kernel(enable_backward=False)
def _segments_clear_kernel(mesh: wp.uint64, p: wp.array[wp.vec3], q: wp.array[wp.vec3], clear: wp.array[wp.uint8]):
    """Whether each segment p[i] q[i] surely meets no triangle (``segment_clear``)."""
    i = wp.tid()
    clear[i] = wp.where(segment_clear(mesh, p[i], q[i]), wp.uint8(1), wp.uint8(0))


@wp.kernel(enable_backward=False)
def _band_gap_kernel(
    start: int,
    f: FieldArg,
    near_lo: wp.array[wp.vec3],
    near_hi: wp.array[wp.vec3],
    near_radius: wp.array[wp.float32],
    margin: float,
    region: wp.array[wp.uint8],
    capacity: int,
    count: wp.array[wp.int32],
    out: wp.array[wp.int64],
):
    """Octets next to the finest band whose covering coarse leaf has another sign than a node of the band octet
    beside them: a marching cube straddling the zero set there would be incomplete. One thread per band octet
    (8 consecutive finest nodes, octet ``start + tid``), only where the ``near`` boxes' bound (``near_cap``) fails
    within ``margin`` when ``margin >= 0``, and only in the top cells flagged in ``region`` (empty: all); found octet
    codes are appended to ``out``."""
    t = start + wp.tid()
    first = 8 * t
    octet = morton_decode(f.codes[first] >> wp.int64(3))
    size = 2.0 * f.voxel_size
    c = f.origin + size * wp.vec3(float(octet[0]) + 0.5, float(octet[1]) + 0.5, float(octet[2]) + 0.5)
    if not _in_region(f, region, c):
        return
    if margin >= 0.0 and not near_cap(c, near_lo, near_hi, near_radius, margin):
        return
    for o in range(27):
        if o != 13:
            d = wp.vec3i(o % 3 - 1, (o // 3) % 3 - 1, o // 9 - 1)
            q = c + size * wp.vec3(float(d[0]), float(d[1]), float(d[2]))
            if inside_domain(f, q):
                nb = locate_leaf(f, q)
                if nb[1] > 0:
                    other = f.values[nb[0]] < 0.0
                    # only this octet's nodes on the side facing the neighbour share marching cubes with it
                    differs = int(0)
                    for n in range(8):
                        facing = int(1)
                        for a in range(3):
                            bit = (n >> a) & 1
                            if (d[a] > 0 and bit == 0) or (d[a] < 0 and bit == 1):
                                facing = int(0)
                        if facing == 1 and (f.values[first + n] < 0.0) != other:
                            differs = int(1)
                    if differs == 1:
                        slot = wp.atomic_add(count, 0, 1)
                        if slot < capacity:
                            out[slot] = morton_encode(octet + d)


@wp.kernel(enable_backward=False)
def _sign_change_kernel(
    start: int,
    f: FieldArg,
    node_level: wp.array[wp.int32],
    near_lo: wp.array[wp.vec3],
    near_hi: wp.array[wp.vec3],
    near_radius: wp.array[wp.float32],
    margin: float,
    region: wp.array[wp.uint8],
    marks: wp.array[wp.int32],
):
    """Mark coarse leaves that have a coarse face neighbour of the opposite sign: the zero set crosses them.
    Coarse node ``start + tid``; only where the ``near`` boxes' bound (``near_cap``) fails within ``margin`` when
    ``margin >= 0``, and only in the top cells flagged in ``region`` (empty: all)."""
    t = start + wp.tid()
    i = f.fine_count + t
    marks[t] = 0
    if f.child[t] >= 0:
        return
    s = f.voxel_size * float(1 << node_level[i])
    c = node_center(f.origin, s, node_coords(f, i))
    if not _in_region(f, region, c):
        return
    if margin >= 0.0 and not near_cap(c, near_lo, near_hi, near_radius, margin):
        return
    inside = f.values[i] < 0.0
    for k in range(6):
        # probe just across the face centre: the leaf found there touches this one
        d = wp.vec3(0.0)
        step = 0.5 * s + 0.25 * f.voxel_size
        d[k // 2] = wp.where(k % 2 == 0, -step, step)
        q = c + d
        if inside_domain(f, q):
            nb = locate_leaf(f, q)
            # sign changes next to the finest band are the band-gap kernel's business
            if nb[1] > 0 and (f.values[nb[0]] < 0.0) != inside:
                marks[t] = 1


@wp.kernel(enable_backward=False)
def _octet_side_kernel(
    start: int, mesh: wp.uint64, origin: wp.vec3, size: float, codes: wp.array[wp.int64], inside: wp.array[wp.uint8]
):
    """Whether the centre of octet ``codes[start + tid]`` (edge ``size``) is inside by the fast winding number (the
    sign oracle's first guess, see :func:`.winding.inside_sign`)."""
    t = start + wp.tid()
    o = morton_decode(codes[t])
    c = origin + size * wp.vec3(float(o[0]) + 0.5, float(o[1]) + 0.5, float(o[2]) + 0.5)
    inside[t] = wp.where(side_of(winding_number(mesh, c, WINDING_ACCURACY)) < 0.0, wp.uint8(1), wp.uint8(0))


@wp.kernel(enable_backward=False)
def _crossed_octet_kernel(
    start: int,
    f: FieldArg,
    codes: wp.array[wp.int64],
    inside: wp.array[wp.uint8],
    dims: wp.vec3i,
    keep: wp.array[wp.uint8],
):
    """Whether octet ``codes[start + tid]`` (sorted codes, ``inside`` or not at their centres) has a neighbour (faces,
    edges or corners) on the other side: one of ``codes``, or another octet by the sign of the leaf or node of ``f``
    holding its centre."""
    t = start + wp.tid()
    o = morton_decode(codes[t])
    own = inside[t]
    keep[t] = wp.uint8(0)
    size = 2.0 * f.voxel_size
    for k in range(27):
        nb = o + wp.vec3i(k % 3 - 1, (k // 3) % 3 - 1, k // 9 - 1)
        if k != 13 and nb[0] >= 0 and nb[1] >= 0 and nb[2] >= 0 and nb[0] < dims[0] and nb[1] < dims[1]:
            if nb[2] < dims[2]:
                j = find_key(codes, 0, codes.shape[0], morton_encode(nb))
                other = own
                if j >= 0:
                    other = inside[j]
                else:
                    q = f.origin + size * wp.vec3(float(nb[0]) + 0.5, float(nb[1]) + 0.5, float(nb[2]) + 0.5)
                    if inside_domain(f, q):
                        other = wp.where(f.values[locate_leaf(f, q)[0]] < 0.0, wp.uint8(1), wp.uint8(0))
                if other != own:
                    keep[t] = wp.uint8(1)
                    break


@wp.func
def _in_region(f: FieldArg, region: wp.array[wp.uint8], x: wp.vec3) -> bool:
    """Whether the top-level cell holding ``x`` is flagged in ``region`` (one byte per top cell; empty: all are)."""
    if region.shape[0] == 0:
        return True
    return region[top_cell(f, x)] != wp.uint8(0)


def changed_top_cells(octets: np.ndarray, top_dims, levels: int) -> np.ndarray:
    """(top_dims) bool: the top-level cells a refinement round that adds ``octets`` (codes, and the octets next to
    them) may change, and their neighbours. The round changes nodes only in the top cells holding the added octets
    (their parents, siblings and ancestors), every node elsewhere keeps its value and sign, and a sign change
    involves a changed node and a face neighbour (or an octet next to it): the next check needs to look only there."""
    top_dims = np.asarray(top_dims, dtype=np.int64)
    cells = octree.morton_decode_np(octets) >> (levels - 2)  # octets are level-1 cells
    hit = np.zeros(top_dims + 4, dtype=bool)  # a margin of two cells: the octets next to them, then the neighbours
    hit[tuple((cells + 2).T)] = True
    grown = np.zeros_like(hit)
    for offset in itertools.product((-2, -1, 0, 1, 2), repeat=3):
        grown |= np.roll(hit, offset, axis=(0, 1, 2))
    return grown[2:-2, 2:-2, 2:-2]


def sign_change_octets(field: AdaptiveField, near=None, region=None, winding=None) -> np.ndarray:
    """Octet codes the finest level lacks where the zero set leaves it: every coarse leaf whose face neighbour has
    the opposite sign, and every octet next to the band whose covering coarse leaf has another sign than a band node
    beside it (so every marching cube that straddles the zero set is complete).

    ``near``: boxes (lo (K, 3), hi (K, 3), radius (K,)) as from :func:`hole_caps`, outside which the zero set runs
    only through the band (no sign change away from a triangle): only leaves and octets within reach of them are
    checked (none for K = 0). None checks everywhere. ``region``: (top_dims) bool, the top-level cells whose leaves
    and octets are checked (None: all). ``winding``: the mesh's :class:`.winding.WindingArg`, to keep only the
    octets of those leaves next to where the fast winding number crosses +-1/2 (:func:`_crossed_codes`); None:
    all their octets.

    Returns:
        (M,) int64 sorted unique octet codes."""
    n_coarse = field.node_count - field.level_counts[0]
    if n_coarse == 0:
        return np.zeros(0, dtype=np.int64)
    if near is not None and len(near[2]) == 0:
        return np.zeros(0, dtype=np.int64)
    top, h = field.top_spacing, field.voxel_size
    # Signs are compared between a leaf's centre and a face neighbour's (reached 0.5 s + h / 4 across a face), or an
    # octet's node and the centre of the leaf one octet away: every point of either segment lies within
    # sqrt(3) / 2 top + max(top / 2 + h / 4, 2 sqrt(3) h) of the leaf's or octet's centre (5 % slack).
    reach = 1.05 * (0.866 * top + max(0.5 * top + 0.25 * h, 3.465 * h))
    # one byte per top cell, x fastest as in the kernels (none: check everywhere)
    flags = np.zeros(0, np.uint8) if region is None else np.asarray(region, np.uint8).T.reshape(-1)
    near_args = [
        *box_arrays(near, field.device),
        -1.0 if near is None else reach,
        wp.array(flags, dtype=wp.uint8, device=field.device),
    ]
    levels_np = field.level_of_nodes()
    marks = wp.empty(n_coarse, dtype=wp.int32, device=field.device)
    arg = field.arg()
    node_level = wp.array(levels_np, dtype=wp.int32, device=field.device)
    parallel.launch_split(
        _sign_change_kernel, n_coarse, lambda lo, n: [lo, arg, node_level, *near_args, marks], field.device
    )
    n_octets = field.level_counts[0] // 8
    # each part of the split launch appends to its own buffer (CPU launches have no cross-thread atomics)
    parts = {}

    def gather_part(lo, n):
        capacity = max(1024, n // 4)
        while True:
            count = wp.zeros(1, dtype=wp.int32, device=field.device)
            gaps = wp.empty(capacity, dtype=wp.int64, device=field.device)
            wp.launch(_band_gap_kernel, dim=n, inputs=[lo, arg, *near_args, capacity, count, gaps], device=field.device)
            found = int(count.numpy()[0])
            if found <= capacity:
                parts[lo] = gaps.numpy()[:found]
                return
            capacity = found

    parallel.load_modules([_band_gap_kernel.module], field.device)
    parallel.run_split(gather_part, n_octets, field.device, balance=True)  # only octets near the holes cost
    gap_octets = np.unique(np.concatenate([parts[k] for k in sorted(parts)] or [np.zeros(0, np.int64)]))
    n0 = field.level_counts[0]
    marked = n0 + np.flatnonzero(marks.numpy())
    if len(marked) == 0:
        return gap_octets
    coords = octree.morton_decode_np(field.codes.numpy()[marked])
    lv = levels_np[marked]
    out = []
    for k in np.unique(lv):
        n = 2 ** (int(k) - 1)  # octets per axis in a level-k cell
        base = coords[lv == k] * n
        grid = np.stack(np.meshgrid(*([np.arange(n)] * 3), indexing="ij"), axis=-1).reshape(-1, 3)
        out.append((base[:, None, :] + grid[None, :, :]).reshape(-1, 3))
    codes = octree.morton_encode_np(np.concatenate(out))
    if winding is not None:
        codes = _crossed_codes(field, winding, codes)
    return np.union1d(codes, gap_octets)


def _crossed_codes(field, winding, octet_codes: np.ndarray) -> np.ndarray:
    """The codes of the octets of marked leaves (``octet_codes``) next to where w crosses +-1/2: inside or outside at
    their centres by the fast winding number, at the octets around them by the sign of the leaf or node holding
    their centres; kept are those with a neighbour (faces, edges or corners) on the other side. The rest of a leaf
    need not be finest, and what this misses the next round finds (beetle /256: 43,657 octets -> 18,807, finest nodes
    708,912 -> 513,960, still two rounds)."""
    device = field.device
    dims = np.asarray(field.top_dims, dtype=np.int64) * 2 ** (field.levels - 2)
    codes = octree.sort_unique(wp.array(octet_codes, dtype=wp.int64, device=device), end_bit=3 * octree.code_bits(dims))
    inside = wp.empty(codes.shape[0], dtype=wp.uint8, device=device)
    parallel.launch_split(
        _octet_side_kernel,
        codes.shape[0],
        lambda lo, n: [lo, winding.mesh, wp.vec3(*field.origin), 2.0 * field.voxel_size, codes, inside],
        device,
        min_dim=parallel.EMIT_SPLIT_MIN_DIM,  # a winding number each
        balance=True,
    )
    keep = wp.empty(codes.shape[0], dtype=wp.uint8, device=device)
    arg = field.arg()
    dims_v = wp.vec3i(*(int(d) for d in dims))
    parallel.launch_split(
        _crossed_octet_kernel, codes.shape[0], lambda lo, n: [lo, arg, codes, inside, dims_v, keep], device
    )
    return codes.numpy()[keep.numpy() == 1]


# One of each pair of opposite steps to the 26 neighbours of a cell.
_FORWARD_STEPS = [np.array(d) for d in itertools.product((-1, 0, 1), repeat=3) if d > (0, 0, 0)]


def _merge_boxes(first: np.ndarray, last: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Integer boxes (K, 3) inclusive, overlapping ones replaced by the box around them until none overlap (loops
    of one hole, or holes close together, are sampled once)."""
    boxes = [(a, b) for a, b in zip(first, last, strict=True)]
    merged = True
    while merged:
        merged = False
        for i in range(len(boxes)):
            for j in range(i + 1, len(boxes)):
                (a, b), (c, d) = boxes[i], boxes[j]
                if np.all(a <= d) and np.all(c <= b):
                    boxes[i] = (np.minimum(a, c), np.maximum(b, d))
                    del boxes[j]
                    merged = True
                    break
            if merged:
                break
    return np.array([a for a, _ in boxes]), np.array([b for _, b in boxes])


def _inside_at(winding: WindingArg, cells: np.ndarray, origin, size: float, device) -> np.ndarray:
    """(M,) bool: whether the centres of the cells (M, 3) of edge ``size`` are inside the mesh (the sign oracle's
    kernel, on every cell)."""
    sign = wp.empty(len(cells), dtype=wp.float32, device=device)
    cells_wp = wp.array(cells.astype(np.int32), dtype=wp.vec3i, device=device)
    every = wp.array(np.arange(len(cells), dtype=np.int32), dtype=wp.int32, device=device)
    parallel.launch_split(
        mesh_sign_kernel,
        len(cells),
        lambda start, n: [winding, cells_wp, every[start : start + n], wp.vec3(*origin), float(size), sign],
        device,
        min_dim=parallel.EMIT_SPLIT_MIN_DIM,  # a winding number each
        balance=True,  # cells near the mesh cost more
    )
    return sign.numpy() < 0.0


def _box_cells(first, last) -> np.ndarray:
    """(M, 3) cells of the box [first, last] (inclusive), in C order of (x, y, z)."""
    return np.argwhere(np.ones(np.asarray(last) - first + 1, dtype=bool)) + first


def _changes(grid: np.ndarray) -> np.ndarray:
    """Pairs (P, 2, 3) of 26-neighbour cells of a bool grid with different values."""
    pairs = []
    for step in _FORWARD_STEPS:
        ends = tuple(slice(max(0, -d), n - max(0, d)) for d, n in zip(step, grid.shape, strict=True))
        starts = tuple(slice(max(0, d), n - max(0, -d)) for d, n in zip(step, grid.shape, strict=True))
        at = np.argwhere(grid[ends] != grid[starts]) + np.maximum(0, -step)
        pairs.append(np.stack([at, at + step], axis=1))
    return np.concatenate(pairs)


def _clear_pairs(mesh_id, pairs: np.ndarray, origin, size: float, device) -> np.ndarray:
    """The pairs of cells (P, 2, 3) whose centres (cells of edge ``size``) are joined by a segment that surely
    meets no triangle."""
    if len(pairs) == 0:
        return pairs
    centres = (origin + size * (pairs + 0.5)).astype(np.float32)
    clear = wp.empty(len(pairs), dtype=wp.uint8, device=device)
    p, q = (wp.array(np.ascontiguousarray(centres[:, k]), dtype=wp.vec3, device=device) for k in (0, 1))
    parallel.launch_split(
        _segments_clear_kernel,
        len(pairs),
        lambda s, n: [wp.uint64(mesh_id), p[s : s + n], q[s : s + n], clear[s : s + n]],
        device,
        min_dim=parallel.EMIT_SPLIT_MIN_DIM,  # a box query each
        balance=True,  # pairs next to the mesh test many triangles
    )
    return pairs[clear.numpy() == 1]


def cap_lattices(winding: WindingArg, caps, origin, octet_dims, octet: float, band_count: int, device):
    """Where an open mesh's surface crosses its holes, from inside or outside (:class:`.winding.WindingArg`) at the
    centres of octets (the level-1 nodes) around each hole's cap: that surface spans the hole's boundary, where the
    boundary's solid angle is 2 pi, inside the hull of the boundary and so inside the cap's box. The box's octets and
    ``CAP_LATTICE_MARGIN`` more around it are sampled (overlapping boxes as one), where cells twice their size,
    sampled first, find enough of that surface (``CAP_LATTICE_MIN_SHEET``). Sampling only the octets of those cells
    that change sides, and the cells next to them, still sampled 64-91 % of the octets on Suzanne and the bunny: the
    triangles in a box change sides too.

    Returns ``{"lattices": [(first octet (3,), inside (nx, ny, nz) bool)], "sheet": sorted codes of the octets on
    either side of 0.5 from a neighbour (faces, edges or corners) with no triangle between their centres}``, or None
    when no box is sampled or the boxes hold more than ``CAP_LATTICE_MAX_RATIO`` octets per band octet
    (``band_count``)."""
    lo, hi, _radius = caps
    origin = np.asarray(origin, dtype=np.float64)
    top = np.asarray(octet_dims, dtype=np.int64) - 1
    first = np.clip(np.floor((np.asarray(lo) - origin) / octet).astype(np.int64) - CAP_LATTICE_MARGIN, 0, top)
    last = np.clip(np.ceil((np.asarray(hi) - origin) / octet).astype(np.int64) + CAP_LATTICE_MARGIN, 0, top)
    first, last = _merge_boxes(first, last)
    if (last - first + 1).prod(axis=1).sum() > CAP_LATTICE_MAX_RATIO * band_count:
        return None
    lattices, sheet = [], []
    for corner, end in zip(first, last, strict=True):
        # cells of two octets first, an eighth of the cost: a box where they find little of that surface (a hole
        # mostly filled, its surface within the triangles' band) is left to the refinement rounds, which it would
        # rarely need
        c0, c1 = corner // 2, end // 2
        coarse = _inside_at(winding, _box_cells(c0, c1), origin, 2 * octet, device).reshape(c1 - c0 + 1)
        found = _clear_pairs(winding.mesh, _changes(coarse) + c0, origin, 2 * octet, device)
        # a sheet of cells twice an octet's size is about 4 octets to each of its cells
        if 4 * len(np.unique(found.reshape(-1, 3), axis=0)) < CAP_LATTICE_MIN_SHEET * (end - corner + 1).prod():
            continue
        grid = _inside_at(winding, _box_cells(corner, end), origin, octet, device).reshape(end - corner + 1)
        lattices.append((corner, grid))
        sheet.append(_clear_pairs(winding.mesh, _changes(grid) + corner, origin, octet, device).reshape(-1, 3))
    if not lattices:
        return None
    codes = octree.morton_encode_np(np.concatenate(sheet))
    return {"lattices": lattices, "sheet": np.unique(codes)}
