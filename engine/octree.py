"""Structure of the hierarchical sparse octree: Morton codes, sort/unique, levels, neighbours and the FIM solve.

Every level ``k`` (0 = finest) is a set of cells of edge ``voxel_size * 2**k`` whose integer coordinates are
relative to the field's domain origin, itself a multiple of the top spacing measured from the shared world origin
(Ren et al., Eq. 3). Cells come in complete octets, so every internal node has exactly 8 children; intermediate
levels are sorted by 64-bit Morton code, the top level is a dense grid in x-fastest order. These kernels are
device-agnostic: nothing here knows whether it runs on the CPU or on CUDA.
"""

from __future__ import annotations

import os
import threading
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import warp as wp

# Bits per axis in a Morton code: 21 * 3 = 63 bits fit a signed 64-bit key.
MORTON_BITS = 21
MAX_CELLS_PER_AXIS = 1 << MORTON_BITS
UNSET_DISTANCE = 1.0e30


# ---- launching ----

# Below this many threads a launch is not worth splitting across CPU cores.
SPLIT_MIN_DIM = 20_000
EMIT_SPLIT_MIN_DIM = 1_000
# Pieces per core of a balanced split launch, taken by the cores in turn as they finish one (each piece is a launch
# of its own, ~60 us of Python: only for long launches whose items cost unevenly), of at least BALANCE_MIN_PIECE items.
BALANCE_PIECES_PER_CORE = 4
BALANCE_MIN_PIECE = 1024


_helpers = None
_helpers_lock = threading.Lock()


def _helper_pool() -> ThreadPoolExecutor:
    """The threads that take pieces of split launches beside the caller's (starting a thread costs ~0.2 ms, more than
    many launches)."""
    global _helpers
    with _helpers_lock:
        if _helpers is None:
            # two builds may split launches at the same time (build_fields)
            _helpers = ThreadPoolExecutor(max_workers=2 * (os.cpu_count() or 1), thread_name_prefix="aasdf-split")
        return _helpers


def run_split(
    work,
    dim: int,
    device,
    *,
    parts: int | None = None,
    min_dim: int = SPLIT_MIN_DIM,
    balance: bool = False,
    own_threads: bool = False,
) -> None:
    """Call ``work(start, count)`` on consecutive pieces of [0, dim) from the caller's and one more Python thread per
    further CPU core (Warp CPU launches release the GIL), or from ``parts`` threads, one piece each; one call on CUDA
    or for small ``dim``. ``balance``: the work per item is uneven (items near an open mesh's holes, or far from the
    surface): each core takes the next of ``BALANCE_PIECES_PER_CORE`` pieces per core as it finishes one, so none
    waits for the other. The helper threads come from a pool, and whichever thread is free takes the next piece (so a
    busy pool only slows a split down); ``work`` that splits work itself needs ``own_threads`` (a thread started for
    each piece). The first error is re-raised in the caller."""
    if dim <= 0:
        return
    device = wp.get_device(device)
    threads_n = parts or os.cpu_count() or 1
    if device.is_cuda or threads_n < 2 or dim < min_dim:
        work(0, dim)
        return
    pieces = threads_n
    if balance and parts is None:
        pieces = min(threads_n * BALANCE_PIECES_PER_CORE, max(threads_n, dim // BALANCE_MIN_PIECE))
    bounds = np.linspace(0, dim, pieces + 1).astype(np.int64)
    errors = []
    taken = iter(range(pieces))
    lock = threading.Lock()

    def run():
        while not errors:
            with lock:
                k = next(taken, None)
            if k is None:
                return
            try:
                work(int(bounds[k]), int(bounds[k + 1] - bounds[k]))
            except Exception as err:  # re-raised below, in the caller's thread
                errors.append(err)

    if own_threads:
        threads = [threading.Thread(target=run) for _ in range(1, threads_n)]
        for t in threads:
            t.start()
        run()
        for t in threads:
            t.join()
    else:
        helpers = [_helper_pool().submit(run) for _ in range(1, threads_n)]
        run()
        for h in helpers:
            h.result()
    if errors:
        raise errors[0]


def run_tasks(tasks, device) -> None:
    """Call each of ``tasks`` (callables without arguments that launch independent work) from a Python thread of its
    own on the CPU, one after the other on CUDA. The first error is re-raised in the caller."""
    if wp.get_device(device).is_cuda or len(tasks) < 2 or (os.cpu_count() or 1) < 2:
        for task in tasks:
            task()
        return
    run_split(lambda k, _n: tasks[k](), len(tasks), device, parts=len(tasks), min_dim=0, own_threads=True)


def launch_split(
    kernel, dim: int, args, device, *, parts: int | None = None, min_dim: int = SPLIT_MIN_DIM, balance: bool = False
) -> None:
    """Launch ``kernel`` over [0, dim) — on the CPU, as one launch per core from as many Python threads.

    A Warp CPU launch runs on one thread but releases the GIL, so launches from two threads use two cores. ``args``
    is called with (start, count) and returns the launch's ``inputs`` list (slices of per-thread arrays, or an
    offset the kernel adds to its thread id). On CUDA, or for small launches, this is one ordinary launch.
    ``balance``: see :func:`run_split`.
    """
    if dim <= 0:
        return
    wp.load_module(kernel.module, device=device)  # compile (or load) once, before threads race for it
    run_split(
        lambda lo, n: wp.launch(kernel, dim=n, inputs=args(lo, n), device=device),
        dim,
        device,
        parts=parts,
        min_dim=min_dim,
        balance=balance,
    )


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


def mark_then_compact(kernel, dim: int, args, dims, device, end_bit: int = 63, check=None) -> wp.array:
    """Sorted unique octet codes marked by ``kernel`` (see :func:`count_then_emit`) called with ``emit=2``: item
    ``first + tid`` sets ``mask[x + dims.x * (y + dims.y * z)] = 1`` for each of its octets, ``mask`` being a uint8
    array of ``prod(dims)`` bytes passed after ``args`` (setting a byte to 1 from two threads is harmless); the kernel
    takes ``(first, *args, mask, offsets, emit, counts, codes)``. ``check(total)`` may refuse the count of unique
    octets before their codes are allocated."""
    nx, ny, nz = (int(d) for d in dims)
    mask = wp.zeros(nx * ny * nz, dtype=wp.uint8, device=device)
    none_i32 = wp.empty(1, dtype=wp.int32, device=device)
    none_i64 = wp.empty(1, dtype=wp.int64, device=device)
    launch_split(
        kernel,
        dim,
        lambda lo, n: [lo, *args, mask, none_i32, 2, none_i32, none_i64],
        device,
        min_dim=EMIT_SPLIT_MIN_DIM,
    )
    rows = ny * nz
    counts = wp.empty(rows, dtype=wp.int32, device=device)
    launch_split(
        _count_mask_rows_kernel, rows, lambda lo, n: [lo, mask, nx, counts], device, min_dim=EMIT_SPLIT_MIN_DIM
    )
    offsets, total = _exclusive_offsets(counts, check)
    codes = wp.empty(2 * total, dtype=wp.int64, device=device)  # the second half: the radix sort's buffer
    dims_v = wp.vec3i(nx, ny, nz)
    launch_split(
        _emit_mask_rows_kernel,
        rows,
        lambda lo, n: [lo, mask, dims_v, offsets, codes],
        device,
        min_dim=EMIT_SPLIT_MIN_DIM,
    )
    return _radix_sort(codes, total, end_bit)


@wp.kernel(enable_backward=False)
def _count_mask_rows_kernel(first: int, mask: wp.array[wp.uint8], nx: int, counts: wp.array[wp.int32]):
    """Set bytes in row ``first + tid`` (``nx`` consecutive bytes) of a mask."""
    r = first + wp.tid()
    base = r * nx
    n = int(0)
    for x in range(nx):
        n += int(mask[base + x])
    counts[r] = n


@wp.kernel(enable_backward=False)
def _emit_mask_rows_kernel(
    first: int, mask: wp.array[wp.uint8], dims: wp.vec3i, offsets: wp.array[wp.int32], codes: wp.array[wp.int64]
):
    """Morton codes of the set bytes of row ``first + tid`` of a (dims.x, dims.y, dims.z) x-fastest mask, from
    ``offsets[row]``."""
    r = first + wp.tid()
    base = r * dims[0]
    y = r % dims[1]
    z = r / dims[1]
    k = offsets[r]
    for x in range(dims[0]):
        if mask[base + x] != wp.uint8(0):
            codes[k] = morton_encode(wp.vec3i(x, y, z))
            k += 1


# ---- closest points on a mesh ----

# Warp's BVH closest-point search (``mesh_query_point_no_sign``), returning the point itself: the same traversal
# (nearest child first, boxes farther than the best distance so far skipped), without its per-triangle sliver test (a
# square root and a division each): a sliver's points are surface points like any other, and the finest level's own
# search tests every triangle too (Warp's closest-point routine keeps its result on the triangle, or yields NaN on a
# degenerate edge, which no comparison takes). About a fifth faster where a query tests many triangles (far from
# the surface).
_CLOSEST_POINT_SNIPPET = r"""
wp::Mesh m = wp::mesh_get(mesh);
int stack[BVH_QUERY_STACK_SIZE];
stack[0] = *m.bvh.root;
int count = 1;
float best = max_dist * max_dist;
float reach = best * shrink;
wp::vec4 out(x[0], x[1], x[2], -1.0f);
while (count) {
    const int node = stack[--count];
    wp::BVHPackedNodeHalf lower = wp::bvh_load_node(m.bvh.node_lowers, node);
    wp::BVHPackedNodeHalf upper = wp::bvh_load_node(m.bvh.node_uppers, node);
    if (wp::distance_to_aabb_sq(x, wp::vec3(lower.x, lower.y, lower.z), wp::vec3(upper.x, upper.y, upper.z)) > reach)
        continue;
    const int left = lower.i;
    const int right = upper.i;
    if (lower.b) {
        for (int c = left; c < right; c++) {
            const int t = wp::bvh_load_int(m.bvh.primitive_indices, c);
            const wp::vec3 p = m.points[wp::bvh_load_int(m.indices, t * 3 + 0)];
            const wp::vec3 q = m.points[wp::bvh_load_int(m.indices, t * 3 + 1)];
            const wp::vec3 r = m.points[wp::bvh_load_int(m.indices, t * 3 + 2)];
            const wp::vec2 b = wp::closest_point_to_triangle(p, q, r, x);
            const wp::vec3 y = b[0] * p + b[1] * q + (1.0f - b[0] - b[1]) * r;
            const float d = wp::length_sq(y - x);
            if (d < best) {
                best = d;
                reach = d * shrink;
                out = wp::vec4(y[0], y[1], y[2], d);
            }
        }
    } else {
        wp::BVHPackedNodeHalf ll = wp::bvh_load_node(m.bvh.node_lowers, left);
        wp::BVHPackedNodeHalf lu = wp::bvh_load_node(m.bvh.node_uppers, left);
        wp::BVHPackedNodeHalf rl = wp::bvh_load_node(m.bvh.node_lowers, right);
        wp::BVHPackedNodeHalf ru = wp::bvh_load_node(m.bvh.node_uppers, right);
        const float dl = wp::distance_to_aabb_sq(x, wp::vec3(ll.x, ll.y, ll.z), wp::vec3(lu.x, lu.y, lu.z));
        const float dr = wp::distance_to_aabb_sq(x, wp::vec3(rl.x, rl.y, rl.z), wp::vec3(ru.x, ru.y, ru.z));
        // the nearer child goes on the stack last, so it is searched first
        const bool left_first = dl < dr;
        const int far_node = left_first ? right : left;
        const int near_node = left_first ? left : right;
        if ((left_first ? dr : dl) < reach)
            stack[count++] = far_node;
        if ((left_first ? dl : dr) < reach)
            stack[count++] = near_node;
    }
}
return out;
"""


@wp.func_native(_CLOSEST_POINT_SNIPPET)
def _closest_point_native(mesh: wp.uint64, x: wp.vec3, max_dist: float, shrink: float) -> wp.vec4:
    """(closest point, squared distance) of ``x`` on the mesh within ``max_dist``; squared distance -1: none. Boxes
    farther than sqrt(``shrink``) times the best distance so far are skipped (1: the exact closest point)."""
    ...


# The same search returning the closest triangle's index in place of the squared distance (as a float: exact below
# 2**24 triangles, a neighbouring index above).
_CLOSEST_FACE_SNIPPET = _CLOSEST_POINT_SNIPPET.replace(
    "out = wp::vec4(y[0], y[1], y[2], d);", "out = wp::vec4(y[0], y[1], y[2], (float)t);"
)


@wp.func_native(_CLOSEST_FACE_SNIPPET)
def _closest_face_native(mesh: wp.uint64, x: wp.vec3, max_dist: float, shrink: float) -> wp.vec4:
    """(closest point, index of its triangle) of ``x`` on the mesh within ``max_dist``; index -1: none."""
    ...


@wp.func
def mesh_closest_face(mesh: wp.uint64, x: wp.vec3, max_dist: float):
    """(closest point on the mesh within ``max_dist`` of ``x``, or ``x``; its triangle, or -1). On a mesh of 2**24
    triangles or more the triangle may be one of the few next to it in the index (a triangle of the mesh still)."""
    r = _closest_face_native(mesh, x, max_dist, 1.0)
    return wp.vec3(r[0], r[1], r[2]), wp.min(int(r[3]), wp.mesh_get(mesh).indices.shape[0] / 3 - 1)


@wp.func
def mesh_near_point(mesh: wp.uint64, x: wp.vec3, max_dist: float, tolerance: float):
    """(found, a point of the mesh within ``max_dist`` of ``x`` no more than 1 + ``tolerance`` times as far as its
    closest point, or ``x``): boxes farther than the best distance so far over 1 + ``tolerance`` are skipped, far
    from the surface a fraction of the search."""
    r = _closest_point_native(mesh, x, max_dist, 1.0 / ((1.0 + tolerance) * (1.0 + tolerance)))
    if r[3] < 0.0:
        return False, x
    return True, wp.vec3(r[0], r[1], r[2])


@wp.func
def mesh_closest_point(mesh: wp.uint64, x: wp.vec3, max_dist: float):
    """(found, closest point on the mesh within ``max_dist`` of ``x``, or ``x``): Warp's closest-point query (the same
    result, see ``_CLOSEST_POINT_SNIPPET``)."""
    return mesh_near_point(mesh, x, max_dist, 0.0)


# ---- Morton codes ----


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
def morton_decode(m: wp.int64) -> wp.vec3i:
    return wp.vec3i(
        wp.int32(_compact_bits(m)),
        wp.int32(_compact_bits(m >> wp.int64(1))),
        wp.int32(_compact_bits(m >> wp.int64(2))),
    )


def morton_encode_np(coords: np.ndarray) -> np.ndarray:
    """Host twin of :func:`morton_encode`: (N,3) non-negative ints -> (N,) int64."""
    coords = np.asarray(coords, dtype=np.int64)
    out = np.zeros(len(coords), dtype=np.int64)
    for bit in range(MORTON_BITS):
        for axis in range(3):
            out |= ((coords[:, axis] >> bit) & 1) << (3 * bit + axis)
    return out


def morton_decode_np(codes: np.ndarray) -> np.ndarray:
    """Host twin of :func:`morton_decode`: (N,) int64 -> (N,3) int64."""
    codes = np.asarray(codes, dtype=np.int64)
    out = np.zeros((len(codes), 3), dtype=np.int64)
    for bit in range(MORTON_BITS):
        for axis in range(3):
            out[:, axis] |= ((codes >> (3 * bit + axis)) & 1) << bit
    return out


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


# ---- sort and unique ----


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


# ---- levels: parents, siblings, children ----


@wp.kernel(enable_backward=False)
def _shift_codes_kernel(first: int, codes: wp.array[wp.int64], shift: int, out: wp.array[wp.int64]):
    i = first + wp.tid()
    out[i] = codes[i] >> wp.int64(shift)


@wp.kernel(enable_backward=False)
def _expand_octets_kernel(
    first: int, octets: wp.array[wp.int64], codes: wp.array[wp.int64], coords: wp.array[wp.vec3i]
):
    """Each octet code (a parent) becomes its 8 children, in Morton order. Octet ``first + tid``."""
    i = first + wp.tid()
    base = octets[i] << wp.int64(3)
    for o in range(8):
        m = base | wp.int64(o)
        codes[8 * i + int(o)] = m
        coords[8 * i + int(o)] = morton_decode(m)


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
    """Node ``tid`` of a dense level in x-fastest order: its coordinates and Morton code."""
    i = wp.tid()
    c = wp.vec3i(i % dims[0], (i // dims[0]) % dims[1], i // (dims[0] * dims[1]))
    coords[i] = c
    codes[i] = morton_encode(c)


def dense_level(dims, codes: wp.array, coords: wp.array) -> None:
    """Coordinates and codes of a dense (nx, ny, nz) level in x-fastest order, written into ``codes``/``coords``."""
    n = int(np.prod(np.asarray(dims, dtype=np.int64)))
    if n:
        dims_v = wp.vec3i(*(int(d) for d in dims))
        wp.launch(_dense_level_kernel, dim=n, inputs=[dims_v, codes, coords], device=codes.device)


@wp.kernel(enable_backward=False)
def _link_octets_kernel(
    first: int,
    octets: wp.array[wp.int64],
    parent_index: wp.array[wp.int32],
    child_lo: int,
    parent_lo: int,
    top_dims: wp.vec3i,
    child: wp.array[wp.int32],
    parent: wp.array[wp.int32],
):
    """Octet ``first + tid`` of a level (its 8 nodes from ``child_lo``, in octet order) and the node it is the
    children of on the level above (from ``parent_lo``): there node 8 * ``parent_index`` + its octant, where that
    level is sparse (built from its parents' sorted codes, see :func:`parent_octets`), or its place in the dense top
    level (x fastest; ``parent_index`` empty)."""
    i = first + wp.tid()
    code = octets[i]
    p = int(0)
    if parent_index.shape[0] > 0:
        p = parent_lo + 8 * parent_index[i] + int(code & wp.int64(7))
    else:
        q = morton_decode(code)
        p = parent_lo + q[0] + top_dims[0] * (q[1] + top_dims[1] * q[2])
    child[p] = child_lo + 8 * i
    for o in range(8):
        parent[child_lo + 8 * i + o] = p


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
        if q[0] >= 0 and q[1] >= 0 and q[2] >= 0 and q[0] < dims[0] and q[1] < dims[1] and q[2] < dims[2]:
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


# ---- neighbours along each axis (Eq. 7) ----


@wp.kernel(enable_backward=False)
def _axis_keys_kernel(
    coords: wp.array[wp.vec3i], lo: int, axis: int, dims: wp.vec3i, keys: wp.array[wp.int64], vals: wp.array[wp.int32]
):
    i = wp.tid()
    c = coords[lo + i]
    a = axis
    b = (axis + 1) % 3
    d = (axis + 2) % 3
    # rows are dims[a] + 1 long, so the last node of a row and the first of the next are never one apart
    keys[i] = (wp.int64(c[d]) * wp.int64(dims[b]) + wp.int64(c[b])) * wp.int64(dims[a] + 1) + wp.int64(c[a])
    vals[i] = lo + i


@wp.kernel(enable_backward=False)
def _axis_neighbours_kernel(
    keys: wp.array[wp.int64],
    vals: wp.array[wp.int32],
    n: int,
    axis: int,
    row0: int,
    neighbours: wp.array2d[wp.int32],
):
    """In key order, consecutive keys one apart are neighbours along ``axis`` (rows are padded by one key, so a row's
    last node is never taken for the next row's first). Node ``i``'s row is ``i - row0``."""
    t = wp.tid()
    i = vals[t]
    if t + 1 < n:
        if keys[t + 1] == keys[t] + wp.int64(1):
            j = vals[t + 1]
            neighbours[i - row0, 2 * axis + 1] = j
            neighbours[j - row0, 2 * axis] = i


def level_neighbours(coords: wp.array, lo: int, hi: int, dims, neighbours: wp.array, row0: int = 0) -> None:
    """Fill the rows of nodes [lo, hi) of ``neighbours`` (int32, 6 columns, node ``i`` in row ``i - row0``) with their
    -x,+x,-y,+y,-z,+z same-level neighbours (Eq. 7), as node indices."""
    n = hi - lo
    if n == 0:
        return
    device = coords.device
    dims_v = wp.vec3i(*(int(d) for d in dims))
    total_bits = int(np.ceil(np.log2(float(np.prod(np.asarray(dims, dtype=np.float64) + 1.0)) + 2.0)))
    # the three axes write their own columns: on the CPU each sorts on a thread of its own
    wp.load_module(_axis_keys_kernel.module, device=device)

    def axis_pass(axis):
        keys = wp.empty(2 * n, dtype=wp.int64, device=device)
        vals = wp.empty(2 * n, dtype=wp.int32, device=device)
        wp.launch(_axis_keys_kernel, dim=n, inputs=[coords, lo, axis, dims_v], outputs=[keys, vals], device=device)
        wp.utils.radix_sort_pairs(keys, vals, n, end_bit=max(1, min(63, total_bits)))
        wp.launch(
            _axis_neighbours_kernel, dim=n, inputs=[keys, vals, n, axis, row0], outputs=[neighbours], device=device
        )

    run_tasks([lambda axis=axis: axis_pass(axis) for axis in range(3)], device)


# ---- distances: internal nodes from children, leaves by the fast iterative method ----


@wp.func
def node_center(origin: wp.vec3, spacing: float, c: wp.vec3i) -> wp.vec3:
    return origin + spacing * wp.vec3(float(c[0]) + 0.5, float(c[1]) + 0.5, float(c[2]) + 0.5)


@wp.kernel(enable_backward=False)
def _init_from_children_kernel(
    coords: wp.array[wp.vec3i],
    first_child: wp.array[wp.int32],
    lo: int,
    origin: wp.vec3,
    spacing: float,
    mesh: wp.uint64,
    max_dist: float,
    known: wp.array[wp.int32],
    octet_dist: wp.array[wp.float32],
    octet_proj: wp.array[wp.vec3],
    dist: wp.array[wp.float32],
    proj: wp.array[wp.vec3],
    source: wp.array[wp.int32],
):
    """Internal nodes are sources: the nearest of their children's projection points (Ren et al.), which with a
    mesh is then made exact by a BVH query bounded by that distance. Leaves start unset. Nodes marked ``known`` keep
    the values they were given. ``octet_dist``/``octet_proj`` (per octet of the level below, empty if none): exact
    closest points of octet centres already found (UNSET_DISTANCE where not), which are this level's node centres."""
    i = lo + wp.tid()
    if known[i] == 1:
        return
    c = first_child[i]
    if c < 0:
        dist[i] = UNSET_DISTANCE
        return
    x = node_center(origin, spacing, coords[i])
    best = float(UNSET_DISTANCE)
    best_j = c
    for o in range(8):
        j = c + o
        if dist[j] < UNSET_DISTANCE:
            dj = wp.length(x - proj[j])
            if dj < best:
                best = dj
                best_j = j
    dist[i] = best
    proj[i] = proj[best_j]
    source[i] = source[best_j]
    if octet_dist.shape[0] > 0:
        if octet_dist[c // 8] < UNSET_DISTANCE:
            dist[i] = octet_dist[c // 8]
            proj[i] = octet_proj[c // 8]
            return
    if mesh != wp.uint64(0):
        found, p = mesh_closest_point(mesh, x, wp.min(best * 1.0001 + spacing * 1.0e-4, max_dist))
        if found:
            d = wp.length(x - p)
            if d < best:
                dist[i] = d
                proj[i] = p


@wp.func
def _nearest_projection(
    x: wp.vec3,
    i: int,
    neighbours: wp.array2d[wp.int32],
    row0: int,
    in0: int,
    dist: wp.array[wp.float32],
    proj: wp.array[wp.vec3],
    source: wp.array[wp.int32],
):
    """The closest-point Eikonal update of node ``i`` (at ``x``): (distance, projection point, source) of the nearest
    projection point among its own and its face neighbours' (node ``j`` at entry ``j - in0``, its neighbours in row
    ``i - row0``); a neighbour's point must be nearer by a relative 1e-5 to win."""
    best = dist[i - in0]
    p = proj[i - in0]
    s = source[i - in0]
    for k in range(6):
        j = neighbours[i - row0, k]
        if j >= 0:
            if dist[j - in0] < UNSET_DISTANCE:
                dj = wp.length(x - proj[j - in0])
                if dj < best * 0.99999:
                    best = dj
                    p = proj[j - in0]
                    s = source[j - in0]
    return best, p, s


@wp.kernel(enable_backward=False)
def _fim_sweep_kernel(
    coords: wp.array[wp.vec3i],
    neighbours: wp.array2d[wp.int32],
    row0: int,
    nodes: wp.array[wp.int32],
    origin: wp.vec3,
    spacing: float,
    in0: int,
    dist_in: wp.array[wp.float32],
    proj_in: wp.array[wp.vec3],
    src_in: wp.array[wp.int32],
    out0: int,
    dist_out: wp.array[wp.float32],
    proj_out: wp.array[wp.vec3],
    src_out: wp.array[wp.int32],
    changed: wp.array[wp.int32],
):
    """One Jacobi sweep of the fast iterative method over a level's unknown leaves (``nodes``, one thread each): each
    takes the nearest projection point among its face neighbours (a closest-point Eikonal update); internal and
    known nodes stay fixed as sources (the caller keeps them in both buffers). Node ``i`` is entry ``i - in0`` of the
    inputs, ``i - out0`` of the outputs and row ``i - row0`` of ``neighbours``."""
    i = nodes[wp.tid()]
    best, p, s = _nearest_projection(
        node_center(origin, spacing, coords[i]), i, neighbours, row0, in0, dist_in, proj_in, src_in
    )
    if best < dist_in[i - in0]:
        wp.atomic_add(changed, 0, 1)
    dist_out[i - out0] = best
    proj_out[i - out0] = p
    src_out[i - out0] = s


@wp.kernel(enable_backward=False)
def _fim_ordered_sweep_kernel(
    coords: wp.array[wp.vec3i],
    first_child: wp.array[wp.int32],
    neighbours: wp.array2d[wp.int32],
    row0: int,
    lo: int,
    hi: int,
    reverse: int,
    origin: wp.vec3,
    spacing: float,
    dist: wp.array[wp.float32],
    proj: wp.array[wp.vec3],
    source: wp.array[wp.int32],
    known: wp.array[wp.int32],
    changed: wp.array[wp.int32],
):
    """The same update in place, one thread visiting the level's nodes in index order (``reverse``: backwards), so an
    update reaches the next nodes within the sweep (Gauss-Seidel): on the dense top level, whose index order is
    x-fastest, alternating directions converge in a few sweeps where Jacobi sweeps need one per cell of distance."""
    count = int(0)
    for t in range(hi - lo):
        i = lo + t
        if reverse == 1:
            i = hi - 1 - t
        if first_child[i] < 0 and known[i] == 0:
            best, p, s = _nearest_projection(
                node_center(origin, spacing, coords[i]), i, neighbours, row0, 0, dist, proj, source
            )
            if best < dist[i]:
                dist[i] = best
                proj[i] = p
                source[i] = s
                count += 1
    changed[0] = count


def _refine_leaves(coords, first_child, lo, n, origin_v, spacing, mesh_id, known, dist, proj, device, tolerance=0.0):
    """Closest points of a solved level's leaves (``_refine_leaves_kernel``), when there is a mesh."""
    if not mesh_id:
        return
    launch_split(
        _refine_leaves_kernel,
        n,
        lambda start, count: [
            coords,
            first_child,
            lo + start,
            origin_v,
            float(spacing),
            wp.uint64(mesh_id),
            known,
            dist,
            proj,
            float(tolerance),
        ],
        device,
        min_dim=EMIT_SPLIT_MIN_DIM,  # a BVH query per leaf: worth two threads from a few thousand
        balance=True,  # far from the surface a query costs more
    )


def solve_level(
    coords,
    first_child,
    neighbours,
    lo,
    hi,
    origin,
    spacing,
    dist,
    proj,
    source,
    mesh_id=0,
    known=None,
    max_sweeps=4096,
    octet_points=None,
    row0=0,
    ordered_sweeps=False,
    tolerance=0.0,
):
    """Initialise a level from its children (exactly from ``mesh_id`` when given) and run the fast iterative method
    until no leaf changes. Nodes flagged in ``known`` (N,) int32 keep their given distance and projection.
    ``octet_points``: (distances, closest points) of the octet centres of the level below, where already known.
    ``neighbours``: the level's rows of the table of :func:`level_neighbours` (node ``i`` in row ``i - row0``).
    ``ordered_sweeps``: on a CPU, sweep in place on one thread in alternating index order instead of Jacobi sweeps on
    both cores (far fewer sweeps where information travels far, as on the dense top level). ``tolerance``: relative
    error allowed to the leaves' closest points (0: exact)."""
    n = hi - lo
    if n == 0:
        return 0
    device = coords.device
    if known is None:
        known = wp.zeros(dist.shape[0], dtype=wp.int32, device=device)
    origin_v = wp.vec3(*origin)
    if octet_points is None:
        octet_points = (wp.empty(0, dtype=wp.float32, device=device), wp.empty(0, dtype=wp.vec3, device=device))
    launch_split(
        _init_from_children_kernel,
        n,
        lambda start, count: [
            coords,
            first_child,
            lo + start,
            origin_v,
            float(spacing),
            wp.uint64(mesh_id),
            4.0 * float(spacing),
            known,
            *octet_points,
            dist,
            proj,
            source,
        ],
        device,
    )
    if ordered_sweeps and device.is_cpu:
        # one CPU thread, in place, alternating directions (see _fim_ordered_sweep_kernel)
        changed = wp.zeros(1, dtype=wp.int32, device=device)
        sweeps = 0
        while sweeps < max_sweeps:
            wp.launch(
                _fim_ordered_sweep_kernel,
                dim=1,
                inputs=[coords, first_child, neighbours, row0, lo, hi, sweeps % 2, origin_v, float(spacing)],
                outputs=[dist, proj, source, known, changed],
                device=device,
            )
            sweeps += 1
            if int(changed.numpy()[0]) == 0:
                break
        _refine_leaves(coords, first_child, lo, n, origin_v, spacing, mesh_id, known, dist, proj, device, tolerance)
        return sweeps
    # only the unknown leaves change: the sweeps run over them alone
    free = (first_child[lo:hi].numpy() < 0) & (known[lo:hi].numpy() == 0)
    nodes = wp.array(lo + np.flatnonzero(free).astype(np.int32), dtype=wp.int32, device=device)
    # the second buffer of the Jacobi sweeps holds this level only (entry i - lo), every other node as in the first
    dist_b = wp.clone(dist[lo:hi])
    proj_b = wp.clone(proj[lo:hi])
    src_b = wp.clone(source[lo:hi])
    changed = wp.zeros(1, dtype=wp.int32, device=device)
    bufs = [(0, dist, proj, source), (lo, dist_b, proj_b, src_b)]
    sweeps = 0
    while sweeps < max_sweeps and nodes.shape[0] > 0:
        changed.zero_()
        src_bufs, dst_bufs = bufs[sweeps % 2], bufs[(sweeps + 1) % 2]
        # Jacobi sweeps read one buffer and write the other: both cores may take half each
        launch_split(
            _fim_sweep_kernel,
            nodes.shape[0],
            lambda start, count, src_bufs=src_bufs, dst_bufs=dst_bufs: [
                coords,
                neighbours,
                row0,
                nodes[start : start + count],
                origin_v,
                float(spacing),
                *src_bufs,
                *dst_bufs,
                changed,
            ],
            device,
        )
        sweeps += 1
        if int(changed.numpy()[0]) == 0:
            break
    if sweeps % 2 == 1:
        wp.copy(dist, dist_b, dest_offset=lo, count=n)
        wp.copy(proj, proj_b, dest_offset=lo, count=n)
        wp.copy(source, src_b, dest_offset=lo, count=n)
    _refine_leaves(coords, first_child, lo, n, origin_v, spacing, mesh_id, known, dist, proj, device, tolerance)
    return sweeps


@wp.kernel(enable_backward=False)
def _refine_leaves_kernel(
    coords: wp.array[wp.vec3i],
    first_child: wp.array[wp.int32],
    lo: int,
    origin: wp.vec3,
    spacing: float,
    mesh: wp.uint64,
    known: wp.array[wp.int32],
    dist: wp.array[wp.float32],
    proj: wp.array[wp.vec3],
    tolerance: float,
):
    """Closest point of a solved leaf, exact or within a relative ``tolerance`` (``mesh_near_point``): the FIM
    distance is an upper bound that caps the BVH search radius."""
    i = lo + wp.tid()
    if first_child[i] >= 0 or known[i] == 1:
        return
    x = node_center(origin, spacing, coords[i])
    found, p = mesh_near_point(mesh, x, dist[i] * 1.0001 + spacing * 1.0e-4, tolerance)
    if found:
        d = wp.length(x - p)
        if d < dist[i]:
            dist[i] = d
            proj[i] = p


# ---- signs, top-down ----


@wp.kernel(enable_backward=False)
def _inherit_sign_kernel(
    coords: wp.array[wp.vec3i],
    parent: wp.array[wp.int32],
    lo: int,
    origin: wp.vec3,
    spacing: float,
    dist: wp.array[wp.float32],
    sign: wp.array[wp.float32],
    safety: float,
    no_inherit: wp.array[wp.uint8],
):
    """A node takes its parent's sign when the two empty balls around them cover the segment between them (no
    surface can cross it); otherwise its sign stays 0 (undecided) for the caller's oracle. Near an open mesh's holes
    (``field.hole_caps``) a segment may cross the jump of the winding number over a hole without meeting a triangle:
    nodes flagged in ``no_inherit`` (empty: none) are left undecided there (``field.cap_sign_presets``), elsewhere near
    the holes this is a heuristic, which the band refinement of open meshes checks where it matters."""
    i = lo + wp.tid()
    p = parent[i]
    if sign[i] != 0.0:  # already known (a node kept from an earlier build of the same mesh, or preset)
        return
    if no_inherit.shape[0] > 0:
        if no_inherit[i] != wp.uint8(0):
            return
    if p >= 0:
        xi = node_center(origin, spacing, coords[i])
        xp = node_center(origin, 2.0 * spacing, coords[p])
        if (dist[i] + dist[p]) * safety > wp.length(xi - xp):
            sign[i] = sign[p]
