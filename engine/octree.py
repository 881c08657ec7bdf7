"""Structure of the hierarchical sparse octree: Morton codes, sort/unique, levels and links.

Every level ``k`` (0 = finest) is a set of cells of edge ``voxel_size * 2**k`` whose integer coordinates are
relative to the field's domain origin, itself a multiple of the top spacing measured from the shared world origin
(Ren et al., Eq. 3). Cells come in complete octets, so every internal node has exactly 8 children; intermediate
levels are sorted by 64-bit Morton code, the top level is a dense grid in x-fastest order (:mod:`.layout` places every
node of a field from its finest octets and links parents and children; same-level face neighbours are
:mod:`.neighbours`'). These kernels know nothing of meshes or values, and
nothing here knows whether it runs on the CPU or on CUDA.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from .parallel import EMIT_SPLIT_MIN_DIM, launch_split

# Bits per axis in a Morton code: 21 * 3 = 63 bits fit a signed 64-bit key.
MORTON_BITS = 21


MAX_CELLS_PER_AXIS = 1 << MORTON_BITS


def count_then_emit(kernel, dim: int, args, device, check=None) -> wp.array:
    """Run a two-pass "count, then write at scanned offsets" kernel; return the int64 codes it writes.

    ``kernel`` takes ``(first, *args, offsets, emit, counts, codes)`` and handles item ``first + tid``: with ``emit=0``
    it writes that item's count, with ``emit=1`` its codes from ``offsets[item]``. Both passes are split over the CPU
    cores. ``check(total)`` may refuse the total before allocation.
    """
    counts = wp.empty(dim, dtype=wp.int32, device=device)
    dummy = wp.empty(1, dtype=wp.int64, device=device)
    # items (triangles, cells) each enumerate many octets: worth splitting from a few thousand on
    launch_split(kernel, dim, lambda lo, n: [lo, *args, counts, 0, counts, dummy], device, min_dim=EMIT_SPLIT_MIN_DIM)
    offsets, total = _exclusive_offsets(counts, check)
    codes = wp.empty(total, dtype=wp.int64, device=device)
    launch_split(kernel, dim, lambda lo, n: [lo, *args, offsets, 1, counts, codes], device, min_dim=EMIT_SPLIT_MIN_DIM)
    return codes


def _exclusive_offsets(counts: wp.array, check=None) -> tuple[wp.array, int]:
    """Where each item's output starts (exclusive scan of ``counts``) and the total, which ``check(total)`` may refuse
    before anything that size is allocated."""
    counts_np = counts.numpy().astype(np.int64)
    total = int(counts_np.sum())
    if check is not None:
        check(total)
    offsets = np.concatenate([[0], np.cumsum(counts_np)[:-1]]).astype(np.int32)
    return wp.array(offsets, dtype=wp.int32, device=counts.device), total


# Octet grids up to this many cells are de-duplicated in a dense byte mask (one byte per octet) instead of by sorting
# every (item, octet) pair: small items (triangles of about a voxel) each enumerate a few dozen octets, mostly the
# same as their neighbours'.
MASK_MAX_CELLS = 1 << 28


def mark_octets(kernel, dim: int, args, mask: wp.array, device) -> None:
    """Run ``kernel`` (see :func:`count_then_emit`) with ``emit=2``: item ``first + tid`` sets ``mask[x + dims.x * (y
    + dims.y * z)] = 1`` for each of its octets (setting a byte to 1 from two threads is harmless); the kernel takes
    ``(first, *args, mask, offsets, emit, counts, codes)``."""
    none_i32 = wp.empty(1, dtype=wp.int32, device=device)
    none_i64 = wp.empty(1, dtype=wp.int64, device=device)
    launch_split(
        kernel,
        dim,
        lambda lo, n: [lo, *args, mask, none_i32, 2, none_i32, none_i64],
        device,
        min_dim=EMIT_SPLIT_MIN_DIM,
    )


def compact_mask(mask: wp.array, dims, device, end_bit: int = 63, check=None) -> wp.array:
    """Sorted codes of the set bytes of a uint8 mask of ``prod(dims)`` bytes (x-fastest). ``check(total)`` may refuse
    the count before the codes are allocated."""
    nx, ny, nz = (int(d) for d in dims)
    rows = ny * nz
    # the mask's whole 64-bit words, the same memory (a Warp allocation is aligned far beyond 8 bytes)
    words = wp.array(ptr=mask.ptr, dtype=wp.uint64, shape=(mask.shape[0] // 8,), device=mask.device)
    counts = wp.empty(rows, dtype=wp.int32, device=device)
    launch_split(
        _count_mask_rows_kernel, rows, lambda lo, n: [lo, mask, words, nx, counts], device, min_dim=EMIT_SPLIT_MIN_DIM
    )
    offsets, total = _exclusive_offsets(counts, check)
    codes = wp.empty(2 * total, dtype=wp.int64, device=device)  # the second half: the radix sort's buffer
    dims_v = wp.vec3i(nx, ny, nz)
    launch_split(
        _emit_mask_rows_kernel,
        rows,
        lambda lo, n: [lo, mask, words, dims_v, offsets, codes],
        device,
        min_dim=EMIT_SPLIT_MIN_DIM,
    )
    return _radix_sort(codes, total, end_bit)


def mark_then_compact(kernel, dim: int, args, dims, device, end_bit: int = 63, check=None) -> wp.array:
    """Sorted unique octet codes marked by ``kernel`` in a byte per octet of a (dims) grid (:func:`mark_octets`, then
    :func:`compact_mask`)."""
    mask = wp.zeros(int(np.prod([int(d) for d in dims])), dtype=wp.uint8, device=device)
    mark_octets(kernel, dim, args, mask, device)
    return compact_mask(mask, dims, device, end_bit, check)


@wp.kernel(enable_backward=False)
def _count_mask_rows_kernel(
    first: int, mask: wp.array[wp.uint8], words: wp.array[wp.uint64], nx: int, counts: wp.array[wp.int32]
):
    """Set bytes (each 0 or 1) in row ``first + tid`` (``nx`` consecutive bytes) of a mask; ``words`` the same memory
    as 64-bit words, read 8 bytes at a time where the row covers a whole word (the bytes' sum in the top byte of the
    word times 0x0101010101010101)."""
    r = first + wp.tid()
    x = r * nx
    end = x + nx
    n = int(0)
    while x < end and (x % 8 != 0 or end - x < 8):
        n += int(mask[x])
        x += 1
    while end - x >= 8:
        n += int((words[x / 8] * wp.uint64(0x0101010101010101)) >> wp.uint64(56))
        x += 8
    while x < end:
        n += int(mask[x])
        x += 1
    counts[r] = n


@wp.kernel(enable_backward=False)
def _emit_mask_rows_kernel(
    first: int,
    mask: wp.array[wp.uint8],
    words: wp.array[wp.uint64],
    dims: wp.vec3i,
    offsets: wp.array[wp.int32],
    codes: wp.array[wp.int64],
):
    """Morton codes of the set bytes of row ``first + tid`` of a (dims.x, dims.y, dims.z) x-fastest mask, from
    ``offsets[row]``; whole 64-bit words of zeros (``words``: the same memory) skipped at once."""
    r = first + wp.tid()
    base = r * dims[0]
    y = r % dims[1]
    z = r / dims[1]
    k = offsets[r]
    x = int(0)
    while x < dims[0]:
        i = base + x
        if i % 8 == 0 and dims[0] - x >= 8:
            if words[i / 8] == wp.uint64(0):
                x += 8
                continue
        if mask[i] != wp.uint8(0):
            codes[k] = morton_encode(wp.vec3i(x, y, z))
            k += 1
        x += 1


@wp.func
def _spread_bits(v: wp.int64) -> wp.int64:
    x = v & wp.int64(0x1FFFFF)
    x = (x | (x << wp.int64(32))) & wp.int64(0x1F00000000FFFF)
    x = (x | (x << wp.int64(16))) & wp.int64(0x1F0000FF0000FF)
    x = (x | (x << wp.int64(8))) & wp.int64(0x100F00F00F00F00F)
    x = (x | (x << wp.int64(4))) & wp.int64(0x10C30C30C30C30C3)
    x = (x | (x << wp.int64(2))) & wp.int64(0x1249249249249249)
    return x


@wp.func
def _compact_bits(v: wp.int64) -> wp.int64:
    x = v & wp.int64(0x1249249249249249)
    x = (x | (x >> wp.int64(2))) & wp.int64(0x10C30C30C30C30C3)
    x = (x | (x >> wp.int64(4))) & wp.int64(0x100F00F00F00F00F)
    x = (x | (x >> wp.int64(8))) & wp.int64(0x1F0000FF0000FF)
    x = (x | (x >> wp.int64(16))) & wp.int64(0x1F00000000FFFF)
    x = (x | (x >> wp.int64(32))) & wp.int64(0x1FFFFF)
    return x


@wp.func
def morton_encode(c: wp.vec3i) -> wp.int64:
    """Interleave (x, y, z) with x in bit 0: the low 3 bits of a child's code are its octant in the parent."""
    return (
        _spread_bits(wp.int64(c[0]))
        | (_spread_bits(wp.int64(c[1])) << wp.int64(1))
        | (_spread_bits(wp.int64(c[2])) << wp.int64(2))
    )


@wp.func
def in_grid(q: wp.vec3i, dims: wp.vec3i) -> bool:
    """Whether cell ``q`` lies within a grid of ``dims`` cells."""
    return q[0] >= 0 and q[1] >= 0 and q[2] >= 0 and q[0] < dims[0] and q[1] < dims[1] and q[2] < dims[2]


@wp.func
def morton_decode(m: wp.int64) -> wp.vec3i:
    return wp.vec3i(
        wp.int32(_compact_bits(m)),
        wp.int32(_compact_bits(m >> wp.int64(1))),
        wp.int32(_compact_bits(m >> wp.int64(2))),
    )


# :func:`_spread_bits`' masks after shifts of 32, 16, 8, 4 and 2 (:func:`_compact_bits` the other way), for the host
# twins below: six passes over the array an axis, against one a bit (63).
_MASKS = (0x1F00000000FFFF, 0x1F0000FF0000FF, 0x100F00F00F00F00F, 0x10C30C30C30C30C3, 0x1249249249249249)


def morton_encode_np(coords: np.ndarray) -> np.ndarray:
    """Host twin of :func:`morton_encode`: (N,3) non-negative ints -> (N,) int64 (a kernel on the CPU's cores from
    HOST_KERNEL_FROM rows)."""
    coords = np.ascontiguousarray(coords, dtype=np.int64).reshape(-1, 3)
    if len(coords) >= HOST_KERNEL_FROM:
        out = np.empty(len(coords), dtype=np.int64)
        _on_host(_encode_host_kernel, coords, out)
        return out
    out, x, t = (np.zeros(len(coords), dtype=np.int64) for _ in range(3))
    for axis in range(3):
        np.bitwise_and(coords[:, axis], MAX_CELLS_PER_AXIS - 1, out=x)
        for shift, mask in zip((32, 16, 8, 4, 2), _MASKS, strict=True):
            _step(x, t, np.left_shift, shift, mask)
        out |= x << axis
    return out


def morton_decode_np(codes: np.ndarray) -> np.ndarray:
    """Host twin of :func:`morton_decode`: (N,) int64 -> (N,3) int64 (a kernel on the CPU's cores from
    HOST_KERNEL_FROM codes)."""
    codes = np.ascontiguousarray(codes, dtype=np.int64).reshape(-1)
    if len(codes) >= HOST_KERNEL_FROM:
        out = np.empty((len(codes), 3), dtype=np.int64)
        _on_host(_decode_host_kernel, codes, out)
        return out
    out, t = np.empty((3, len(codes)), dtype=np.int64), np.empty(len(codes), dtype=np.int64)
    for axis in range(3):
        np.bitwise_and(codes >> axis, _MASKS[-1], out=out[axis])
        for shift, mask in zip((2, 4, 8, 16, 32), _MASKS[-2::-1] + (MAX_CELLS_PER_AXIS - 1,), strict=True):
            _step(out[axis], t, np.right_shift, shift, mask)
    return np.ascontiguousarray(out.T)


# Host arrays of this many rows or more are encoded and decoded by a kernel on the CPU (numpy's 15 passes an axis took
# 57 ns a code, the kernel 10 on one core).
HOST_KERNEL_FROM = 4096


def _on_host(kernel, source: np.ndarray, out: np.ndarray) -> None:
    """Launch a host twin's ``kernel`` from ``source`` into ``out`` (numpy arrays, read and written in place) on the
    CPU's cores."""
    cpu = wp.get_device("cpu")
    args = [wp.array(a, dtype=wp.int64, device=cpu, copy=False) for a in (source, out)]
    launch_split(kernel, len(source), lambda lo, _n: [args[0], lo, args[1]], cpu)


@wp.kernel(enable_backward=False)
def _encode_host_kernel(coords: wp.array2d[wp.int64], offset: int, out: wp.array[wp.int64]):
    """:func:`morton_encode` of each row (its low 21 bits an axis, as numpy's passes take them)."""
    i = wp.tid() + offset
    out[i] = morton_encode(wp.vec3i(wp.int32(coords[i, 0]), wp.int32(coords[i, 1]), wp.int32(coords[i, 2])))


@wp.kernel(enable_backward=False)
def _decode_host_kernel(codes: wp.array[wp.int64], offset: int, out: wp.array2d[wp.int64]):
    """:func:`morton_decode` of each code."""
    i = wp.tid() + offset
    c = morton_decode(codes[i])
    out[i, 0] = wp.int64(c[0])
    out[i, 1] = wp.int64(c[1])
    out[i, 2] = wp.int64(c[2])


def _step(x: np.ndarray, t: np.ndarray, shifted, shift: int, mask: int) -> None:
    """``x = (x | shifted(x, shift)) & mask`` in place (``t`` scratch)."""
    shifted(x, shift, out=t)
    x |= t
    x &= mask


@wp.func
def lower_bound(keys: wp.array[wp.int64], lo: int, hi: int, key: wp.int64) -> int:
    """First index in [lo, hi) whose key is >= ``key`` (keys sorted ascending)."""
    a = lo
    b = hi
    while a < b:
        mid = (a + b) // 2
        if keys[mid] < key:
            a = mid + 1
        else:
            b = mid
    return a


@wp.func
def find_key(keys: wp.array[wp.int64], lo: int, hi: int, key: wp.int64) -> int:
    """Index of ``key`` in the sorted range [lo, hi), or -1."""
    i = lower_bound(keys, lo, hi, key)
    if i < hi:
        if keys[i] == key:
            return i
    return -1


@wp.kernel(enable_backward=False)
def _mark_unique_kernel(first: int, keys: wp.array[wp.int64], flags: wp.array[wp.int32]):
    i = first + wp.tid()
    if i == 0:
        flags[i] = 1
    elif keys[i] != keys[i - 1]:
        flags[i] = 1
    else:
        flags[i] = 0


@wp.kernel(enable_backward=False)
def _compact_unique_kernel(
    first: int,
    keys: wp.array[wp.int64],
    flags: wp.array[wp.int32],
    slots: wp.array[wp.int32],
    out: wp.array[wp.int64],
    index: wp.array[wp.int32],
):
    """Key ``first + tid`` to its slot if it is the first of its run; its run's slot to ``index`` (when not empty)."""
    i = first + wp.tid()
    if flags[i] == 1:
        out[slots[i]] = keys[i]
    if index.shape[0] > 0:
        index[i] = slots[i] + flags[i] - 1


def _radix_sort(work_keys: wp.array, n: int, end_bit: int) -> wp.array:
    """The first ``n`` int64 keys of ``work_keys`` (which has room for 2 n: the sort's buffer) sorted in place on
    their low ``end_bit`` bits; returns that sorted view."""
    if n == 0:
        return wp.empty(0, dtype=wp.int64, device=work_keys.device)
    if n > 1:
        values = wp.empty(2 * n, dtype=wp.int32, device=work_keys.device)  # the payload is not used
        wp.utils.radix_sort_pairs(work_keys, values, n, end_bit=max(1, min(63, end_bit)))
    return work_keys[:n]


def sort_unique(keys: wp.array, end_bit: int = 63, *, presorted: bool = False, return_index: bool = False):
    """Sorted unique values of an int64 array (radix sort, mark first occurrences, exclusive scan, compact);
    ``presorted``: the keys are already non-decreasing, only duplicates go, and ``return_index`` also returns where
    each key went: ``(unique, index)`` with ``unique[index[i]] == keys[i]`` (int32)."""
    n = keys.shape[0]
    device = keys.device
    if return_index and not presorted:
        raise ValueError("sort_unique returns indices only for presorted keys")
    if n == 0:
        out = wp.empty(0, dtype=wp.int64, device=device)
        return (out, wp.empty(0, dtype=wp.int32, device=device)) if return_index else out
    if presorted:
        sorted_keys = keys
    else:
        work_keys = wp.empty(2 * n, dtype=wp.int64, device=device)
        wp.copy(work_keys, keys, count=n)
        sorted_keys = _radix_sort(work_keys, n, end_bit)
    flags = wp.empty(n, dtype=wp.int32, device=device)
    launch_split(_mark_unique_kernel, n, lambda lo, _n: [lo, sorted_keys, flags], device)
    slots = wp.empty(n, dtype=wp.int32, device=device)
    wp.utils.array_scan(flags, slots, inclusive=False)
    count = int(slots.numpy()[-1] + flags.numpy()[-1])
    out = wp.empty(count, dtype=wp.int64, device=device)
    index = wp.empty(n if return_index else 0, dtype=wp.int32, device=device)
    launch_split(_compact_unique_kernel, n, lambda lo, _n: [lo, sorted_keys, flags, slots, out, index], device)
    return (out, index) if return_index else out


def merge_unique(*parts: wp.array, end_bit: int = 63) -> wp.array:
    """Sorted unique codes of all ``parts`` (int64 code arrays on one device) together."""
    total = sum(p.shape[0] for p in parts)
    merged = wp.empty(total, dtype=wp.int64, device=parts[0].device)
    at = 0
    for p in parts:
        if p.shape[0]:
            wp.copy(merged, p, dest_offset=at, count=p.shape[0])
        at += p.shape[0]
    return sort_unique(merged, end_bit=end_bit)


@wp.kernel(enable_backward=False)
def _shift_codes_kernel(first: int, codes: wp.array[wp.int64], shift: int, out: wp.array[wp.int64]):
    i = first + wp.tid()
    out[i] = codes[i] >> wp.int64(shift)


@wp.kernel(enable_backward=False)
def _expand_octets_kernel(
    first: int, octets: wp.array[wp.int64], codes: wp.array[wp.int64], coords: wp.array[wp.vec3i]
):
    """Each octet code (a parent) becomes its 8 children, in Morton order (``coords`` empty: codes alone). Octet
    ``first + tid``."""
    i = first + wp.tid()
    base = octets[i] << wp.int64(3)
    for o in range(8):
        m = base | wp.int64(o)
        codes[8 * i + int(o)] = m
        if coords.shape[0] > 0:
            coords[8 * i + int(o)] = morton_decode(m)


@wp.kernel(enable_backward=False)
def _decode_kernel(first: int, codes: wp.array[wp.int64], step: int, coords: wp.array[wp.vec3i]):
    i = first + wp.tid()
    coords[i] = morton_decode(codes[step * i])


def decode_codes(codes: wp.array, step: int = 1) -> wp.array:
    """(N,) vec3i lattice coordinates of (N,) int64 Morton codes (every ``step``-th)."""
    n = (codes.shape[0] + step - 1) // step
    coords = wp.empty(n, dtype=wp.vec3i, device=codes.device)
    launch_split(_decode_kernel, n, lambda lo, _n: [lo, codes, int(step), coords], codes.device)
    return coords


def expand_octets(octets: wp.array, codes: wp.array | None = None, coords: wp.array | None = None):
    """Children of every parent code: (8M,) int64 codes sorted when ``octets`` is, and (8M,) vec3i coordinates
    (written into ``codes``/``coords`` when given)."""
    n = octets.shape[0]
    codes = wp.empty(8 * n, dtype=wp.int64, device=octets.device) if codes is None else codes
    coords = wp.empty(8 * n, dtype=wp.vec3i, device=octets.device) if coords is None else coords
    if n:
        launch_split(_expand_octets_kernel, n, lambda lo, _n: [lo, octets, codes, coords], octets.device)
    return codes, coords


def parent_octets(codes: wp.array, levels_up: int, end_bit: int, *, presorted: bool = False, return_index=False):
    """Unique codes ``levels_up`` levels above (Eq. 6 with ``levels_up=2``: grandparents whose 8 children are the
    parents and their siblings). ``presorted``: ``codes`` ascend, and so do their shifted codes: no sort needed; then
    ``return_index`` also returns each code's parent's index in the result (see :func:`sort_unique`)."""
    shifted = wp.empty_like(codes)
    if codes.shape[0]:
        launch_split(
            _shift_codes_kernel, codes.shape[0], lambda lo, _n: [lo, codes, 3 * levels_up, shifted], codes.device
        )
    return sort_unique(shifted, end_bit=end_bit, presorted=presorted, return_index=return_index)


@wp.kernel(enable_backward=False)
def _dense_level_kernel(dims: wp.vec3i, codes: wp.array[wp.int64], coords: wp.array[wp.vec3i]):
    """Node ``tid`` of a dense level in x-fastest order: its coordinates (``coords`` empty: none) and Morton code."""
    i = wp.tid()
    c = wp.vec3i(i % dims[0], (i // dims[0]) % dims[1], i // (dims[0] * dims[1]))
    if coords.shape[0] > 0:
        coords[i] = c
    codes[i] = morton_encode(c)


def dense_level(dims, codes: wp.array, coords: wp.array) -> None:
    """Coordinates and codes of a dense (nx, ny, nz) level in x-fastest order, written into ``codes``/``coords``."""
    n = int(np.prod(np.asarray(dims, dtype=np.int64)))
    if n:
        dims_v = wp.vec3i(*(int(d) for d in dims))
        wp.launch(_dense_level_kernel, dim=n, inputs=[dims_v, codes, coords], device=codes.device)


@wp.kernel(enable_backward=False)
def _dilate_octets_kernel(octets: wp.array[wp.int64], radius: int, dims: wp.vec3i, out: wp.array[wp.int64]):
    """Every octet within ``radius`` octets (a cube) of a stored one; out of range ones repeat the centre."""
    t = wp.tid()
    c = morton_decode(octets[t])
    w = 2 * radius + 1
    for n in range(w * w * w):
        d = wp.vec3i(n % w - radius, (n // w) % w - radius, n // (w * w) - radius)
        q = c + d
        code = octets[t]
        if in_grid(q, dims):
            code = morton_encode(q)
        out[t * w * w * w + n] = code


def dilate_octets(octets: wp.array, dims, end_bit: int) -> wp.array:
    """Sorted unique octet codes within one octet (a 3x3x3 block) of ``octets``, inside ``dims`` octets."""
    grown = wp.empty(octets.shape[0] * 27, dtype=wp.int64, device=octets.device)
    wp.launch(
        _dilate_octets_kernel,
        dim=octets.shape[0],
        inputs=[octets, 1, wp.vec3i(*(int(d) for d in dims))],
        outputs=[grown],
        device=octets.device,
    )
    return sort_unique(grown, end_bit=end_bit)


@wp.func
def node_center(origin: wp.vec3, spacing: float, c: wp.vec3i) -> wp.vec3:
    return origin + spacing * wp.vec3(float(c[0]) + 0.5, float(c[1]) + 0.5, float(c[2]) + 0.5)


# ---- a field's levels: layout, matching between builds ----


def in_sorted(keys: np.ndarray, values: np.ndarray) -> np.ndarray:
    """(len(values),) bool: whether each value is one of the sorted ``keys``."""
    if len(keys) == 0:
        return np.zeros(len(values), dtype=bool)
    return keys[np.minimum(np.searchsorted(keys, values), len(keys) - 1)] == values


# How many of an octet's six face neighbours kept keep it too (:func:`filled_notches`).
NOTCH_NEIGHBOURS = 3


@wp.kernel(enable_backward=False)
def _kept_neighbours_kernel(
    offset: int, codes: wp.array[wp.int64], kept: wp.array[wp.int64], count: wp.array[wp.int32]
):
    """How many of octet ``codes[i]``'s six face neighbours are among the sorted ``kept`` codes."""
    i = wp.tid() + offset
    c = morton_decode(codes[i])
    found = int(0)
    for k in range(6):
        q = wp.vec3i(c[0], c[1], c[2])
        q[k // 2] = q[k // 2] + 1 - 2 * (k % 2)
        if q[0] >= 0 and q[1] >= 0 and q[2] >= 0:
            if find_key(kept, 0, kept.shape[0], morton_encode(q)) >= 0:
                found += 1
    count[i] = found


def filled_notches(codes: np.ndarray, keep: np.ndarray, device=None) -> np.ndarray:
    """``keep`` (N,) bool over octet ``codes`` with the octets it leaves out that have NOTCH_NEIGHBOURS or more of
    their six face neighbours kept taken too (one pass): a region of octets kept by a distance test closed at its
    pinholes and at notches an octet wide along its edge (a boolean along its seams kept the rocker arm's octets within
    6 voxels of its copy placed 5.12 voxels off, and the surface made there had a hole a voxel across, which no kept
    face bordered: its join ran out of rounds). Each octet left out looks its neighbours up among the kept ones,
    sorted: a binary search each, in Warp (24 k octets about a sphere, 1.4-2.2 ms at any share kept; numpy's counts
    took 0.9 ms at 1 % kept, 4.7 at 19 %, 10.9 at 49 %: the bunny's seams 11 ms a call)."""
    out = keep.copy()
    n_kept = int(np.count_nonzero(keep))
    if not n_kept or n_kept == len(keep):
        return out
    device = wp.get_device(device)
    rows = np.flatnonzero(~keep)
    left = wp.array(np.ascontiguousarray(codes[rows], dtype=np.int64), dtype=wp.int64, device=device)
    kept = wp.array(np.sort(codes[keep]).astype(np.int64), dtype=wp.int64, device=device)
    count = wp.empty(len(rows), dtype=wp.int32, device=device)
    args = lambda lo, n: [lo, left, kept, count]  # noqa: E731
    launch_split(_kept_neighbours_kernel, len(rows), args, device, min_dim=EMIT_SPLIT_MIN_DIM)
    out[rows[count.numpy() >= NOTCH_NEIGHBOURS]] = True
    return out


def add_octets(octets: wp.array, extra: np.ndarray, octet_dims, end_bit: int) -> wp.array:
    """Sorted unique octet codes: ``octets`` (sorted codes) and ``extra`` with one octet around each (the zero set
    across a hole leaves coarse leaves in a sheet, and what is added next to it would otherwise show up as new sign
    changes)."""
    device = octets.device
    grown = dilate_octets(wp.array(extra, dtype=wp.int64, device=device), octet_dims, end_bit=end_bit)
    merged = wp.empty(octets.shape[0] + grown.shape[0], dtype=wp.int64, device=device)
    wp.copy(merged, octets, count=octets.shape[0])
    wp.copy(merged, grown, dest_offset=octets.shape[0], count=grown.shape[0])
    return sort_unique(merged, end_bit=end_bit)


def code_bits(dims) -> int:
    return max(1, int(np.ceil(np.log2(float(np.max(dims)) + 1.0))))
