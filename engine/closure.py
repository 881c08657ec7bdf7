"""The octets a boolean's surface needs around it, found from its computed values (a blend over a boolean result).

A boolean keeps the finest octets its operands' brackets put within a band of its surface (:func:`.prune.prune_octets`):
every corner of a cube the surface crosses lies within that band of it while the values read are as Lipschitz as the
operands' fields. An operand that is itself a blended boolean is read off coarse leaves a few voxels from its surface
(its nodes' closest points are its own operands', and its leaves span the kinks of its blend) up to two voxels off
its nodes' values: a chamfer over a chamfered union (two balls chamfered by 8 voxels, then a box) read so had a
corner 3.4 voxels from a crossing a voxel and a half away, its octet pruned, and its cube (so the surface) open. So
where an operand is a blended boolean, or the boolean blends a boolean, the surface's octets are found from the
values computed (:func:`surface_gaps`) and every octet around them the result lacks is added, until none is lacking.
The lacking octets are found in Warp (a binary search of the kept ones per neighbour); the few rounds that add some
merge them on the host.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from . import octree, parallel
from .expression import widest_blend

# The 27 steps to an octet and those about it (x slowest: :func:`_step`'s slots).
_STEPS = np.stack(np.meshgrid(*(np.arange(-1, 2),) * 3, indexing="ij"), axis=-1).reshape(27, 3)


def needs_closure(a, b, blend: float) -> bool:
    """Whether a boolean of ``a`` and ``b`` (blended by ``blend``) reads a blended boolean, or blends a boolean: its
    values may stray from its brackets by more than its band allows (module docstring)."""
    inner = [getattr(f, "expression", None) for f in (a, b)]
    booleans = [e for e in inner if e is not None]
    return bool(booleans) and (blend > 0.0 or any(widest_blend(e) > 0.0 for e in booleans))


@wp.func
def _step(slot: int) -> wp.vec3i:
    """Slot ``slot`` of 27 (x slowest): its step (-1, 0 or 1 per axis)."""
    return wp.vec3i(slot // 9 - 1, (slot // 3) % 3 - 1, slot % 3 - 1)


@wp.kernel(enable_backward=False)
def _gaps_kernel(
    first: int, octets: wp.array[wp.int64], values: wp.array[wp.float32], dims: wp.vec3i, out: wp.array[wp.int32]
):
    """Per octet, which of the octets about its nodes at an end of a crossed edge are not among ``octets``
    (:func:`surface_gaps`): bit ``slot`` of 27 (:func:`_step`)."""
    i = first + wp.tid()
    out[i] = _lacking(octets, values, dims, i)


@wp.kernel(enable_backward=False)
def _gaps_at_kernel(
    first: int,
    rows: wp.array[wp.int32],
    octets: wp.array[wp.int64],
    values: wp.array[wp.float32],
    dims: wp.vec3i,
    out: wp.array[wp.int32],
):
    """:func:`_gaps_kernel` at the octets of index ``rows`` alone."""
    i = rows[first + wp.tid()]
    out[i] = _lacking(octets, values, dims, i)


@wp.func
def _lacking(octets: wp.array[wp.int64], values: wp.array[wp.float32], dims: wp.vec3i, i: int) -> int:
    """:func:`_gaps_kernel` for octet ``i``."""
    n = octets.shape[0]
    ends = int(0)
    for k in range(8):  # edges within the octet
        for axis in range(3):
            if (values[8 * i + k] < 0.0) != (values[8 * i + (k ^ (1 << axis))] < 0.0):
                ends = ends | (1 << k)
    c = octree.morton_decode(octets[i])
    for axis in range(3):  # edges to the octets beside it
        for side in range(2):
            q = c
            q[axis] = q[axis] + 2 * side - 1
            if octree.in_grid(q, dims):
                j = octree.find_key(octets, 0, n, octree.morton_encode(q))
                if j >= 0:
                    for k in range(8):
                        partner = 8 * j + (k ^ (1 << axis))
                        if ((k >> axis) & 1) == side and (values[8 * i + k] < 0.0) != (values[partner] < 0.0):
                            ends = ends | (1 << k)
    want = int(0)
    for k in range(8):  # each end's octant: the octets towards its corner
        if (ends >> k) & 1 == 1:
            for o in range(1, 8):
                dx = (o & 1) * (2 * (k & 1) - 1)
                dy = ((o >> 1) & 1) * (2 * ((k >> 1) & 1) - 1)
                dz = ((o >> 2) & 1) * (2 * ((k >> 2) & 1) - 1)
                want = want | (1 << ((dx + 1) * 9 + (dy + 1) * 3 + dz + 1))
    lacking = int(0)
    for slot in range(27):
        if (want >> slot) & 1 == 1:
            q = c + _step(slot)
            if octree.in_grid(q, dims):
                if octree.find_key(octets, 0, n, octree.morton_encode(q)) < 0:
                    lacking = lacking | (1 << slot)
    return lacking


def surface_gaps(octets: wp.array, values: wp.array, oct_dims, rows: np.ndarray | None = None) -> np.ndarray:
    """Sorted codes of the octets within the grid of ``oct_dims`` that the surface of a result with finest
    ``octets`` (sorted codes) and ``values`` (per finest node, child ``i % 8`` of octet ``i // 8``, its bits x, y, z)
    needs and it lacks. A node at an end of a lattice edge the surface crosses (its two nodes of opposite signs, in
    one octet or in two beside each other) is a corner of the cubes about it, whose other corners lie within a step
    of it: in the octets of its octant (the 7 beside its octet towards its corner of it). Only about the octets of
    index ``rows`` when given."""
    n, device = octets.shape[0], octets.device
    out = wp.zeros(n, dtype=wp.int32, device=device)
    dims = wp.vec3i(*(int(d) for d in oct_dims))
    if rows is None:
        parallel.launch_split(_gaps_kernel, n, lambda lo, _k: [lo, octets, values, dims, out], device)
    elif len(rows):
        at = wp.array(rows.astype(np.int32), dtype=wp.int32, device=device)
        parallel.launch_split(_gaps_at_kernel, len(rows), lambda lo, _k: [lo, at, octets, values, dims, out], device)
    lacking = out.numpy()
    rows = np.flatnonzero(lacking)  # (few: the octets beside a gap)
    if not len(rows):
        return np.zeros(0, dtype=np.int64)
    bits = (lacking[rows, None] >> np.arange(27)) & 1 == 1
    row, slot = np.nonzero(bits)
    coords = octree.morton_decode_np(octets.numpy()[rows[row]]) + _STEPS[slot]
    return np.unique(octree.morton_encode_np(coords))


def closed(finest: dict, prune, values_of, oct_dims, rounds: int) -> tuple[dict, dict]:
    """``finest`` (the pruning's kept octets and what the combination reads of them: ``octets``, ``a_first`` and
    ``b_first`` Warp arrays, ...) with the octets its surface lacks (:func:`surface_gaps`) added, found from the
    finest values (``values_of(finest)``: a dict of per-node Warp arrays, ``values`` among them) for up to ``rounds``
    rounds; ``prune(codes, band=inf)`` gives what the combination reads of added octets. Returns the new ``finest``
    and its finest nodes' arrays (in its octets' order), each octet's computed once."""
    done = values_of(finest)
    gaps = surface_gaps(finest["octets"], done["values"], oct_dims)
    if not len(gaps):  # (the rule: nothing lacking, nothing copied)
        return finest, done
    keys, device = ("octets", "a_first", "b_first"), finest["octets"].device
    dtypes = {key: array.dtype for key, array in done.items()}
    kept = {key: finest[key].numpy() for key in keys}
    nodes = {key: array.numpy() for key, array in done.items()}
    for _ in range(rounds):
        more = prune(wp.array(gaps, dtype=wp.int64, device=device), band=np.inf)
        theirs = values_of(more)
        order = np.argsort(np.concatenate([kept["octets"], gaps]), kind="stable")
        rows = (8 * order[:, None] + np.arange(8)).ravel()  # each octet's 8 children follow it
        kept = {key: np.concatenate([kept[key], more[key].numpy()])[order] for key in keys}
        nodes = {key: np.concatenate([nodes[key], theirs[key].numpy()])[rows] for key in nodes}
        values = wp.array(nodes["values"], dtype=wp.float32, device=device)
        octets = wp.array(kept["octets"], dtype=wp.int64, device=device)
        gaps = surface_gaps(octets, values, oct_dims, _about(kept["octets"], gaps, oct_dims))
        if not len(gaps):
            break
    finest = {**finest, **{key: wp.array(kept[key], device=device) for key in keys}}
    return finest, {key: wp.array(nodes[key], dtype=dtypes[key], device=device) for key in nodes}


def _about(octets: np.ndarray, added: np.ndarray, oct_dims) -> np.ndarray:
    """Indices in ``octets`` (sorted codes) of the ``added`` ones and of those beside them: where a round's octets
    may show new crossings."""
    coords = (octree.morton_decode_np(added)[:, None, :] + _STEPS[None]).reshape(-1, 3)
    coords = coords[((coords >= 0) & (coords < np.asarray(oct_dims))).all(axis=1)]
    codes = np.unique(octree.morton_encode_np(coords))
    index = np.minimum(np.searchsorted(octets, codes), len(octets) - 1)
    return index[octets[index] == codes]
