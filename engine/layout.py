"""Where every node of a field goes, before any value is computed: its levels' octets, codes and links.

:func:`level_layout` places every node of a field from its finest octets (Ren et al., Eq. 6: each level above holds
the parents of the level below and their siblings, sorted by Morton code; the top level is dense, x fastest) and links
parents and children; :func:`match_levels` finds each node in an earlier field of the same domain (a refinement keeps
the nodes found before). Built on :mod:`.octree`'s codes and sorts; nothing here knows of meshes or values, or whether
it runs on the CPU or on CUDA.
"""

from __future__ import annotations

import time

import numpy as np
import warp as wp

from . import parallel
from .octree import code_bits, dense_level, expand_octets, find_key, morton_decode, parent_octets


@wp.kernel(enable_backward=False)
def _link_octets_kernel(
    first: int,
    octets: wp.array[wp.int64],
    parent_index: wp.array[wp.int32],
    child_lo: int,
    parent_lo: int,
    top_dims: wp.vec3i,
    child: wp.array[wp.int32],
    child_base: int,
    parent: wp.array[wp.int32],
):
    """Octet ``first + tid`` of a level (its 8 nodes from ``child_lo``, in octet order) and the node it is the
    children of on the level above (from ``parent_lo``): there node 8 * ``parent_index`` + its octant, where that
    level is sparse (built from its parents' sorted codes, see :func:`parent_octets`), or its place in the dense top
    level (x fastest; ``parent_index`` empty). The parent's link goes to ``child[p - child_base]``; ``parent``
    empty: no links up."""
    i = first + wp.tid()
    code = octets[i]
    p = int(0)
    if parent_index.shape[0] > 0:
        p = parent_lo + 8 * parent_index[i] + int(code & wp.int64(7))
    else:
        q = morton_decode(code)
        p = parent_lo + q[0] + top_dims[0] * (q[1] + top_dims[1] * q[2])
    child[p - child_base] = child_lo + 8 * i
    if parent.shape[0] > 0:
        for o in range(8):
            parent[child_lo + 8 * i + o] = p


@wp.kernel(enable_backward=False)
def _match_level_kernel(
    first: int,
    codes: wp.array[wp.int64],
    lo: int,
    prev_codes: wp.array[wp.int64],
    prev_lo: int,
    prev_hi: int,
    where: wp.array[wp.int32],
):
    """Where octet ``first + tid`` of the level at ``lo`` (8 consecutive nodes, sorted by code) is in the sorted range
    [prev_lo, prev_hi) of ``prev_codes`` (a level of complete octets too): its nodes' indices there, or -1."""
    i = lo + 8 * (first + wp.tid())
    j = find_key(prev_codes, prev_lo, prev_hi, codes[i])
    for o in range(8):
        where[i + o] = wp.where(j >= 0, j + o, -1)


def match_levels(codes: wp.array, offsets, previous) -> wp.array:
    """For every node (levels at ``offsets``) its index in ``previous`` (an earlier field of the same domain and
    levels), level by level, or -1: (N,) int32 on the device. Levels below the top are complete octets sorted by code
    (matched octet by octet); the dense top level (when ``offsets`` reach it) is the same grid in both."""
    where = wp.empty(codes.shape[0], dtype=wp.int32, device=codes.device)
    for k in range(len(offsets) - 1):
        lo, hi = int(offsets[k]), int(offsets[k + 1])
        ks = previous.level_slice(k)
        if k == previous.levels - 1:
            where[lo:hi].assign(np.arange(ks.start, ks.stop, dtype=np.int32))
            continue
        parallel.launch_split(
            _match_level_kernel,
            (hi - lo) // 8,
            lambda s, _n, lo=lo, ks=ks: [s, codes, lo, previous.codes, ks.start, ks.stop, where],
            codes.device,
        )
    return where


def _levels_above(level_octets: list, top_dims, levels: int) -> tuple[list, list]:
    """The octets of the levels above ``level_octets`` (finest first) up to the one below the dense top, each the
    parents of the one below (sorted by code: they come in order), and each level's parents' index among them."""
    fine_dims = np.asarray(top_dims, dtype=np.int64) * 2 ** (levels - 1)
    octets, index = [], []
    for k in range(len(level_octets), levels - 1):
        below = (level_octets + octets)[-1]
        up, up_index = parent_octets(
            below, 1, end_bit=3 * code_bits((fine_dims >> k) * 2), presorted=True, return_index=True
        )
        octets.append(up)
        index.append(up_index)
    return octets, index


def upper_levels(above: wp.array, top_dims, levels: int) -> tuple[list, list]:
    """Level 1's octets ``above`` and the octets of the levels above them, with each one's parents' index (the
    coarse part of :func:`level_layout`, the same for every refinement of a field built on demand)."""
    octets, index = _levels_above([None, above], top_dims, levels)
    return [above, *octets], index


def level_layout(
    octets, top_dims, levels: int, device, timings: dict | None = None, *, lean: bool = False, above=None
) -> dict:
    """Where every node of a field goes, before any value is computed.

    The finest level is the children of ``octets`` (sorted unique octet codes), or with ``octets`` None (and
    ``levels`` 1) the dense top level itself. Each level above holds the parents of the level below and their
    siblings (Eq. 6), sorted by code; the top level is dense. Returns ``codes`` and ``coords`` of all levels in one
    pair of arrays (finest first), the level ``offsets``, each node's first ``child`` and ``parent`` (-1: none), and
    ``top_dims``. ``lean``: only what a finished field keeps (codes, and child links of the coarse nodes alone, as
    ``AdaptiveField.child``); ``coords`` and ``parent`` are None: 16 bytes a node less at the peak of a boolean.
    ``above``: level 1's octets (sorted unique codes, holding the parent of every one of ``octets``) instead of the
    parents of ``octets``: a field refined on demand keeps the level-1 nodes of its whole band while its finest
    octets are a part of it (:mod:`.ondemand`); or :func:`upper_levels` of them, found once for every refinement.
    """
    t0 = time.perf_counter()
    top_dims = np.asarray(top_dims, dtype=np.int64)
    level_octets = [] if octets is None else [octets]
    parent_index = []  # per octet of a level, its parent's octet among the next level's (all but the last)
    if above is not None and levels > 2:
        upper, upper_index = above if isinstance(above, tuple) else upper_levels(above, top_dims, levels)
        index = np.searchsorted(upper[0].numpy(), octets.numpy() >> 3).astype(np.int32)
        level_octets += upper
        parent_index += [wp.array(index, dtype=wp.int32, device=device), *upper_index]
    else:
        more, more_index = _levels_above(level_octets, top_dims, levels)
        level_octets += more
        parent_index += more_index
    parent_index.append(wp.empty(0, dtype=wp.int32, device=device))  # the dense top level: by coordinates
    sizes = [8 * o.shape[0] for o in level_octets] + [int(np.prod(top_dims))]
    offsets = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
    n = int(offsets[-1])
    codes = wp.empty(n, dtype=wp.int64, device=device)
    coords = wp.empty(0 if lean else n, dtype=wp.vec3i, device=device)
    for k, o in enumerate(level_octets):
        lo, hi = int(offsets[k]), int(offsets[k + 1])
        expand_octets(o, codes[lo:hi], coords[lo:hi] if not lean else coords)
    dense_level(top_dims, codes[int(offsets[-2]) :], coords[int(offsets[-2]) :] if not lean else coords)
    child_base = int(offsets[1]) if lean else 0  # lean: the finest level has no children to link
    child = wp.full(n - child_base, -1, dtype=wp.int32, device=device)
    parent = wp.full(0 if lean else n, -1, dtype=wp.int32, device=device)
    dims_v = wp.vec3i(*(int(d) for d in top_dims))
    for k, o in enumerate(level_octets):
        parallel.launch_split(
            _link_octets_kernel,
            o.shape[0],
            lambda start, _n, k=k, o=o: [
                start,
                o,
                parent_index[k],
                int(offsets[k]),
                int(offsets[k + 1]),
                dims_v,
                child,
                child_base,
                parent,
            ],
            device,
        )
    if timings is not None:
        timings["levels_structure"] = timings.get("levels_structure", 0.0) + time.perf_counter() - t0
    return {
        "codes": codes,
        "coords": None if lean else coords,
        "offsets": offsets,
        "child": child,
        "parent": None if lean else parent,
        "top_dims": top_dims,
    }
