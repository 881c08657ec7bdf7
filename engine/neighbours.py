"""Same-level face neighbours of an octree level (Ren et al., Eq. 7): the table the fast iterative method sweeps over.

A level small enough for a dense grid of node indices (``DENSE_NEIGHBOUR_CELLS``, 4 bytes a cell) writes its nodes
into one and reads each node's six neighbours back. A larger level made of octets (every level but the dense top: 8
siblings in a row, in Morton order) finds each octet's six face-adjacent octets by binary search of their codes: three
of a node's neighbours are its siblings, the other three the same child of those octets. Any other sorts its nodes by
a key per axis (rows padded by one so that a row's last node is never the next row's first) and pairs keys one apart.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from . import parallel
from .octree import in_grid, morton_decode, morton_encode
from .parallel import run_tasks

# Levels with at most this many cells find their neighbours through a dense grid (8 MB), larger ones by sorting.
DENSE_NEIGHBOUR_CELLS = 1 << 21


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


@wp.kernel(enable_backward=False)
def _grid_neighbours_kernel(
    coords: wp.array[wp.vec3i],
    lo: int,
    dims: wp.vec3i,
    fill: int,
    grid: wp.array[wp.int32],
    row0: int,
    neighbours: wp.array2d[wp.int32],
):
    """``fill`` 1: node ``lo + tid`` written into the level's dense grid; 0: its 6 face neighbours read from it."""
    i = lo + wp.tid()
    c = coords[i]
    if fill == 1:
        grid[c[0] + dims[0] * (c[1] + dims[1] * c[2])] = i
        return
    for k in range(6):
        q = c
        q[k // 2] = q[k // 2] + 2 * (k % 2) - 1
        if in_grid(q, dims):
            j = grid[q[0] + dims[0] * (q[1] + dims[1] * q[2])]
            if j >= 0:
                neighbours[i - row0, k] = j


@wp.func
def _octet_at(codes: wp.array[wp.int64], lo: int, n_octets: int, octet: wp.int64) -> int:
    """The first node of the octet with code ``octet`` of the ``n_octets`` (sorted) from node ``lo``, or -1."""
    a = int(0)
    b = n_octets
    while a < b:
        m = (a + b) // 2
        if (codes[lo + 8 * m] >> wp.int64(3)) < octet:
            a = m + 1
        else:
            b = m
    if a < n_octets:
        if (codes[lo + 8 * a] >> wp.int64(3)) == octet:
            return lo + 8 * a
    return -1


@wp.kernel(enable_backward=False)
def _octet_neighbours_kernel(
    codes: wp.array[wp.int64], lo: int, n_octets: int, first: int, octet_dims: wp.vec3i, row0: int,
    neighbours: wp.array2d[wp.int32],
):  # fmt: skip
    """Octet ``first + tid``'s nodes' six face neighbours: siblings within it, else the same child (the bit of that
    axis flipped) of the octet across the face."""
    t = first + wp.tid()
    base = lo + 8 * t
    at = morton_decode(codes[base] >> wp.int64(3))
    for face in range(6):
        axis = face // 2
        up = face % 2  # 1: the +axis side
        q = at
        q[axis] = q[axis] + 2 * up - 1
        across = int(-1)
        if q[axis] >= 0 and q[axis] < octet_dims[axis]:
            across = _octet_at(codes, lo, n_octets, morton_encode(q))
        for k in range(8):
            bit = (k >> axis) & 1
            j = int(-1)
            if bit != up:  # the sibling on that side
                j = base + (k ^ (1 << axis))
            elif across >= 0:
                j = across + (k ^ (1 << axis))
            if j >= 0:
                neighbours[base + k - row0, face] = j


def level_neighbours(
    coords: wp.array, lo: int, hi: int, dims, neighbours: wp.array, row0: int = 0, codes: wp.array | None = None
) -> None:
    """Fill the rows of nodes [lo, hi) of ``neighbours`` (int32, 6 columns, node ``i`` in row ``i - row0``, -1 kept
    where none) with their -x,+x,-y,+y,-z,+z same-level neighbours (Eq. 7), as node indices: through a dense grid of
    the level when it has at most ``DENSE_NEIGHBOUR_CELLS`` cells (no sort); else, given the level's ``codes`` (a level
    of octets), octet by octet (module docstring), or by axis-wise key sorting."""
    n = hi - lo
    if n == 0:
        return
    device = coords.device
    dims_v = wp.vec3i(*(int(d) for d in dims))
    if codes is not None and int(np.prod(np.asarray(dims, dtype=np.int64))) > DENSE_NEIGHBOUR_CELLS:
        octet_dims = wp.vec3i(*(int(d + 1) // 2 for d in dims))
        parallel.launch_split(
            _octet_neighbours_kernel,
            n // 8,
            lambda start, _k: [codes, lo, n // 8, start, octet_dims, row0, neighbours],
            device,
        )
        return
    if int(np.prod(np.asarray(dims, dtype=np.int64))) <= DENSE_NEIGHBOUR_CELLS:
        grid = wp.full(int(np.prod(np.asarray(dims, dtype=np.int64))), -1, dtype=wp.int32, device=device)
        for fill in (1, 0):
            parallel.launch_split(
                _grid_neighbours_kernel,
                n,
                lambda start, k, fill=fill: [coords, lo + start, dims_v, fill, grid, row0, neighbours],
                device,
            )
        return
    total_bits = int(np.ceil(np.log2(float(np.prod(np.asarray(dims, dtype=np.float64) + 1.0)) + 2.0)))
    # the three axes write their own columns: on the CPU each sorts on a thread of its own
    parallel.load_modules([_axis_keys_kernel.module], device)

    def axis_pass(axis):
        keys = wp.empty(2 * n, dtype=wp.int64, device=device)
        vals = wp.empty(2 * n, dtype=wp.int32, device=device)
        wp.launch(_axis_keys_kernel, dim=n, inputs=[coords, lo, axis, dims_v], outputs=[keys, vals], device=device)
        wp.utils.radix_sort_pairs(keys, vals, n, end_bit=max(1, min(63, total_bits)))
        wp.launch(
            _axis_neighbours_kernel, dim=n, inputs=[keys, vals, n, axis, row0], outputs=[neighbours], device=device
        )

    run_tasks([lambda axis=axis: axis_pass(axis) for axis in range(3)], device)
