"""How often each of some integer keys occurs among others, through a hash table in Warp.

The join of kept faces to the voxel surface asks, several times a round, which directed edges of a mesh of a hundred
thousand faces have their reverse, or repeat: sorting the edge keys and searching the reverses in them took 0.13 s
for 0.5 M edges here, an open-addressing table (linear probing, slots claimed by compare-and-swap so that CUDA
threads can insert side by side) 0.03 s. Written by hand: Warp has sorts and scans but no hash table.
"""

from __future__ import annotations

import numpy as np
import warp as wp

_EMPTY = wp.constant(wp.int64(-1))


@wp.func
def _slot(key: wp.int64, mask: wp.int64) -> wp.int64:
    """The first slot to probe for ``key`` (Fibonacci hashing: the high bits of the key times 2^64 / phi)."""
    h = wp.uint64(key) * wp.uint64(0x9E3779B97F4A7C15)
    return wp.int64(h >> wp.uint64(20)) & mask


@wp.kernel(enable_backward=False)
def _insert_kernel(
    keys: wp.array(dtype=wp.int64), mask: wp.int64, table: wp.array(dtype=wp.int64), counts: wp.array(dtype=wp.int32)
):
    i = wp.tid()
    key = keys[i]
    s = _slot(key, mask)
    while True:
        held = wp.atomic_cas(table, int(s), _EMPTY, key)
        if held == _EMPTY or held == key:
            wp.atomic_add(counts, int(s), 1)
            return
        s = (s + wp.int64(1)) & mask


@wp.kernel(enable_backward=False)
def _count_kernel(
    queries: wp.array(dtype=wp.int64),
    mask: wp.int64,
    table: wp.array(dtype=wp.int64),
    counts: wp.array(dtype=wp.int32),
    out: wp.array(dtype=wp.int32),
):
    i = wp.tid()
    key = queries[i]
    s = _slot(key, mask)
    while True:
        held = table[int(s)]
        if held == key:
            out[i] = counts[int(s)]
            return
        if held == _EMPTY:
            out[i] = 0
            return
        s = (s + wp.int64(1)) & mask


class KeyCounts:
    """The keys (non-negative int64) in a table; :meth:`of` tells how often each query occurs among them."""

    def __init__(self, keys: np.ndarray, device="cpu"):
        keys = np.ascontiguousarray(keys, dtype=np.int64)
        self.device = wp.get_device(device)
        size = 1 << max(int(np.ceil(np.log2(2 * len(keys) + 1))), 4)  # at most half full: short probes
        self.mask = wp.int64(size - 1)
        self.table = wp.full(size, -1, dtype=wp.int64, device=self.device)
        self.counts = wp.zeros(size, dtype=wp.int32, device=self.device)
        if len(keys):
            keys_wp = wp.array(keys, dtype=wp.int64, device=self.device)
            wp.launch(_insert_kernel, len(keys), inputs=[keys_wp, self.mask, self.table, self.counts], device=device)

    def of(self, queries: np.ndarray) -> np.ndarray:
        """(N,) int32 how many of the keys equal each query."""
        queries = np.ascontiguousarray(queries, dtype=np.int64)
        if not len(queries):
            return np.zeros(0, dtype=np.int32)
        out = wp.empty(len(queries), dtype=wp.int32, device=self.device)
        q = wp.array(queries, dtype=wp.int64, device=self.device)
        wp.launch(_count_kernel, len(queries), inputs=[q, self.mask, self.table, self.counts, out], device=self.device)
        return out.numpy()


def directed_edges(tris: np.ndarray, n_verts: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(a, b, keys, reverses)``: each face's directed edges (corner k -> k + 1), face after face, and their keys
    ``a * n + b`` and ``b * n + a`` (int64)."""
    t = np.asarray(tris, dtype=np.int64)
    a, b = t.ravel(), t[:, [1, 2, 0]].ravel()
    return a, b, a * n_verts + b, b * n_verts + a
