"""Connected components of a graph given by its edges, in Warp: union-find with lock-free hooking.

Each edge finds its ends' roots (halving the paths it walks) and hooks the larger under the smaller with a
compare-and-swap (retrying from the new roots when another edge hooked one first), then each node points at its
root. A root only ever hooks under a smaller one, so every component's root is its smallest node, whatever the order
the edges run in (on the CPU one after the other, on CUDA side by side). Two launches replace numpy's rounds of
hooking and pointer jumping, each a few passes over every node and edge.
"""

from __future__ import annotations

import numpy as np
import warp as wp


@wp.func
def _root(parent: wp.array(dtype=wp.int32), node: wp.int32) -> wp.int32:
    """The root above ``node``, the path there halved on the way (each node passed set to its grandparent: only
    ever an ancestor, never a root changed, so other threads' walks and hooks stay valid)."""
    x = node
    up = parent[x]
    while up != x:
        grand = parent[up]
        if grand != up:
            parent[x] = grand
        x = grand
        up = parent[x]
    return x


@wp.kernel(enable_backward=False)
def _hook_edges_kernel(
    a: wp.array(dtype=wp.int32),
    b: wp.array(dtype=wp.int32),
    rank: wp.array(dtype=wp.int32),
    up_to: wp.int32,
    parent: wp.array(dtype=wp.int32),
):
    i = wp.tid()
    if rank.shape[0] > 0:
        if rank[i] > up_to:
            return
    ra = _root(parent, a[i])
    rb = _root(parent, b[i])
    while ra != rb:
        low = wp.min(ra, rb)
        high = wp.max(ra, rb)
        if wp.atomic_cas(parent, high, high, low) == high:
            break
        ra = _root(parent, high)  # another edge hooked ``high`` first: carry on from the roots now
        rb = _root(parent, low)


@wp.kernel(enable_backward=False)
def _point_at_roots_kernel(parent: wp.array(dtype=wp.int32)):
    i = wp.tid()
    parent[i] = _root(parent, wp.int32(i))


def connected_components(n: int, a, b, device=None, *, rank=None, up_to: int = 0) -> np.ndarray:
    """(n,) int64 the smallest node of each node's connected component over the edges ``a``-``b``.

    Args:
        n: Number of nodes.
        a, b: (E,) int nodes in 0 .. n - 1, the ends of each edge.
        device: Warp device (default: the current one).
        rank: Optional (E,) int: only the edges whose rank is at most ``up_to`` join their ends.
    """
    if not len(a):
        return np.arange(n)
    device = wp.get_device(device)
    parent = wp.array(np.arange(n, dtype=np.int32), dtype=wp.int32, device=device)
    ends = [_int32(x, device) for x in (a, b, np.zeros(0) if rank is None else rank)]
    wp.launch(_hook_edges_kernel, dim=len(ends[0]), inputs=[*ends, int(up_to), parent], device=device)
    wp.launch(_point_at_roots_kernel, dim=n, inputs=[parent], device=device)
    return parent.numpy().astype(np.int64)


def _int32(values, device) -> wp.array:
    """``values`` as a Warp int32 array (on the CPU the int32 numpy array's own memory, not a copy)."""
    return wp.array(np.ascontiguousarray(values, dtype=np.int32), dtype=wp.int32, device=device, copy=False)


def edge_neighbours(tris: np.ndarray, n_verts: int) -> tuple[np.ndarray, np.ndarray]:
    """The pairs of faces of ``tris`` ((F, 3) int, corners below ``n_verts``) that share an edge, by corner index (on
    a non-manifold edge, its faces one after another)."""
    tris = np.asarray(tris, dtype=np.int64)
    a, b = tris.ravel(), tris[:, [1, 2, 0]].ravel()
    key = np.minimum(a, b) * n_verts + np.maximum(a, b)
    order = np.argsort(key, kind="stable")
    same = key[order][1:] == key[order][:-1]
    face = order // 3
    return face[:-1][same], face[1:][same]
