"""Kept loops that face each other with no voxel surface between them, zipped to each other.

Where two kept pieces of a mesh meet along borders that are near but not shared (a teapot's spout set against its
body, a scan's overlapping patches, the two sides of a crack too narrow for the voxel surface), every voxel vertex
there lies over kept faces and the voxel surface leaves nothing between the two borders: neither loop finds a voxel
loop to pair with (:mod:`.hybrid`). Such loops, left unpaired, are paired with each other instead (each with the
unpaired loop most of its vertices are nearest to, both ways), and the strip between them made as between a kept
loop and a voxel loop (:func:`.zipper.zip_loops`, the second loop walked against its faces). So are loops whose strip
with their voxel loop stretched (a scrap of voxel surface left between them: the cow's ears, 0.9945 -> 0.999 of what
should be kept). A strip that stretches (the loops part by more than the pairing's reach somewhere) is not taken: its
loops give up faces as before.
"""

from __future__ import annotations

import numpy as np

from .zipper import nearest_points, zip_loops


def _mutual_pairs(votes: np.ndarray) -> np.ndarray:
    """(P, 2) the label pairs (a, b), a < b, where b is a's most voted label and a is b's."""
    pairs, counts = np.unique(votes, axis=0, return_counts=True)
    order = np.lexsort((-counts, pairs[:, 0]))
    pairs = pairs[order]
    best = pairs[np.r_[True, pairs[1:, 0] != pairs[:-1, 0]]]  # each label's most voted other
    at = np.minimum(np.searchsorted(best[:, 0], best[:, 1]), len(best) - 1)  # b's row (rows sorted by label)
    back = np.where(best[at, 0] == best[:, 1], best[at, 1], -1)
    return best[(back == best[:, 0]) & (best[:, 0] < best[:, 1])]


def zip_twins(points, k_loops, unpaired, reach: float, near: float, device):
    """Zip the ``unpaired`` kept loops (labels of ``k_loops`` = ``(next, members, labels)``) that face each other
    (module docstring). Returns ``(tris, twinned)``: (F, 3) int32 the strips taken, and the labels of their loops."""
    nxt, members, labels = k_loops
    members = members[np.isin(labels[members], unpaired)]
    none = np.zeros((0, 3), dtype=np.int32), np.zeros(0, dtype=np.int64)
    if len(np.unique(labels[members])) < 2:
        return none
    at = points[members]
    near_other = nearest_points(at, at, reach, device, labels=(labels[members], labels[members]))
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
