"""Kept loops that face each other with no voxel surface between them, zipped to each other.

Where two kept pieces of a mesh meet along borders that are near but not shared (a teapot's spout set against its
body, a scan's overlapping patches, the two sides of a crack too narrow for the voxel surface), every voxel vertex
there lies over kept faces and the voxel surface leaves nothing between the two borders: neither loop finds a voxel
loop to pair with (:mod:`.hybrid`). Such loops, left unpaired, are paired with each other instead (each with the
unpaired loop most of its vertices are nearest to, both ways), and the strip between them made as between a kept
loop and a voxel loop (:func:`.zipper.zip_loops`, the second loop walked against its faces). A strip that stretches
(the loops part by more than the pairing's reach somewhere) is not taken: its loops give up faces as before.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from .zipper import zip_loops


@wp.kernel(enable_backward=False)
def _nearest_other_kernel(
    grid: wp.uint64,
    cloud: wp.array[wp.vec3],
    cloud_label: wp.array[wp.int64],
    radius: float,
    nearest: wp.array[wp.int32],
):
    """The nearest point of ``cloud`` to each of its points with another label, within ``radius`` (-1: none)."""
    i = wp.tid()
    p = cloud[i]
    best = radius
    found = int(-1)
    query = wp.hash_grid_query(grid, p, radius)
    j = int(0)
    while wp.hash_grid_query_next(query, j):
        if cloud_label[j] != cloud_label[i]:
            d = wp.length(cloud[j] - p)
            if d < best:
                best = d
                found = j
    nearest[i] = found


def _nearest_other(points: np.ndarray, labels: np.ndarray, radius: float, device) -> np.ndarray:
    """(N,) int32: for each of ``points``, the nearest one with another label within ``radius`` (-1: none)."""
    grid = wp.HashGrid(128, 128, 128, device=device)
    cloud = wp.array(np.ascontiguousarray(points, dtype=np.float32), dtype=wp.vec3, device=device)
    grid.build(cloud, radius)
    out = wp.empty(len(points), dtype=wp.int32, device=device)
    label = wp.array(np.ascontiguousarray(labels, dtype=np.int64), dtype=wp.int64, device=device)
    wp.launch(_nearest_other_kernel, len(points), inputs=[grid.id, cloud, label, float(radius), out], device=device)
    return out.numpy()


def _mutual_pairs(votes: np.ndarray) -> np.ndarray:
    """(P, 2) the label pairs (a, b), a < b, where b is a's most voted label and a is b's."""
    pairs, counts = np.unique(votes, axis=0, return_counts=True)
    order = np.lexsort((-counts, pairs[:, 0]))
    pairs = pairs[order]
    best = pairs[np.r_[True, pairs[1:, 0] != pairs[:-1, 0]]]  # each label's most voted other
    of = dict(zip(best[:, 0].tolist(), best[:, 1].tolist(), strict=True))
    back = np.array([of.get(b, -1) for b in best[:, 1].tolist()], dtype=np.int64)
    return best[(back == best[:, 0]) & (best[:, 0] < best[:, 1])]


def zip_twins(points, k_loops, unpaired, reach: float, near: float, device):
    """Zip the ``unpaired`` kept loops (labels of ``k_loops`` = ``(next, members, labels)``) that face each other
    (module docstring). Returns ``(tris, twinned)``: (F, 3) int32 the strips taken, and the labels of their loops."""
    nxt, members, labels = k_loops
    members = members[np.isin(labels[members], unpaired)]
    none = np.zeros((0, 3), dtype=np.int32), np.zeros(0, dtype=np.int64)
    if len(np.unique(labels[members])) < 2:
        return none
    near_other = _nearest_other(points[members], labels[members], reach, device)
    has = near_other >= 0
    if not has.any():
        return none
    votes = np.stack([labels[members[has]], labels[members[near_other[has]]]], axis=1)
    pairs = _mutual_pairs(votes)
    if not len(pairs):
        return none
    prev = np.arange(len(nxt), dtype=np.int64)
    prev[nxt[members]] = members
    count = np.bincount(labels[members], minlength=len(points))
    p_count, q_count = count[pairs[:, 0]], count[pairs[:, 1]]
    tris, gaps = zip_loops(points, nxt, prev, pairs[:, 0], pairs[:, 1], p_count, q_count, device, near)
    first = np.r_[0, np.cumsum(p_count + q_count)[:-1]]
    ok = np.maximum.reduceat(gaps, first) <= reach
    taken = np.repeat(ok, p_count + q_count)
    return tris[taken], pairs[ok].ravel()
