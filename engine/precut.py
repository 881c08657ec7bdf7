"""Slivers cut in one pass where a seam will need them: the cuts bisection reaches round after round, found from the
distances read along each sliver.

A bore's wall is a ring of slivers a voxel wide and the part long, each crossing the seams near its ends. The judge
(:mod:`.keep`) halves a partly keepable piece and judges the halves again, so a sliver 200 voxels long takes eight
rounds of splitting and judging to reach pieces a voxel long at the seam: 0.12-0.16 s for the 512 triangles of a
128-sided bore, against 0.03 s for the 13 k triangles of the fandisk it goes through. Here each sliver the first
round left partly keepable is read once, a voxel apart along its middle: how far the other leaves' surfaces are, read
off their fields, and its own defects. The dyadic intervals of its length that the judge would find partly keepable
and not keepable (judged from the nearest and farthest readings in each, widened by half the readings' spacing, against
the band and the interval's own slack) are halved down to the split size, and the sliver is cut at their ends on both
long edges in one go, its neighbours across those edges taking the same points. The judge then judges the pieces, and
its rounds go on where a prediction fell short. The readings are a prediction's, and the judge's own (off the meshes)
decide: off the meshes, the fandisk's bore's 24 k took 25-33 ms of its judge's 90-100; off the fields, 2-3.

The cuts are points bisection would make (dyadic places on each long edge), so the kept pieces merge back as theirs
do (``ends``: each point's neighbours on its edge, the midpoint's ends).

Written by hand: the intervals are a few numpy passes per level over all slivers at once.
"""

from __future__ import annotations

import numpy as np

from .otherleaves import NEAR_BOX_VOXELS
from .slivers import FIRST, SECOND, zip_points
from .sources import mesh_distances

# Readings along a sliver's middle, this many of the judge's least sample spacings apart.
READ_SPACINGS = 1.0


def cut_strips(judge, splitter, verts: np.ndarray, unknown: np.ndarray, split_edge: float):
    """The source triangles' strips (``splitter``'s) left ``unknown`` by the first round, cut where the judge's rounds
    would cut them (module docstring).

    Args:
        judge: The leaf's judge (:mod:`.keep`): its ``band``, ``spacing``, ``slack``, ``slack_of(size)`` and
            ``margins(points, reach)`` (:func:`predicted_margins`).
        splitter: The leaf's :class:`.slivers.Splitter`; its vertices' source edges (``on``) grow with the cuts.
        verts: (V, 3) float32 the source's vertices; unknown: (S,) bool per source triangle; split_edge: as there.
    Returns:
        None where nothing is cut, else ``(verts, tris, rows, ends)``: the vertices with the cuts appended, the
        pieces (source triangles not cut, then the pieces of those cut), the source triangle each lies in, and (V', 2)
        int64 each vertex's ends (-1 for the source's: :func:`.refine.merge_kept`).
    """
    rows = np.flatnonzero(unknown & splitter.strip)
    if not len(rows):
        return None
    source, apex = splitter.source_tris, splitter.apex
    k = apex[rows]
    b, x, y = source[rows, k], source[rows, (k + 1) % 3], source[rows, (k + 2) % 3]
    sliver, place = _cut_places(judge, verts.astype(np.float64), (b, x, y), split_edge)
    if not len(sliver):
        return None
    points = _edge_points(verts, (b, x, y), sliver, place)
    new_verts, ends = points["verts"], points["ends"]
    splitter.on = np.concatenate([splitter.on, points["on"]])
    p, v, side, t = _strip_points(source, apex, splitter.strip, points, len(verts))
    tris, parent = zip_points(p, v, side, t, source, apex)
    cut = np.zeros(len(source), dtype=bool)
    cut[parent] = True
    whole = np.flatnonzero(~cut)
    n = len(verts)
    return (
        np.concatenate([verts, new_verts]),
        np.concatenate([source[whole], tris]),
        np.concatenate([whole, parent]),
        np.concatenate([np.full((n, 2), -1, dtype=np.int64), ends]),
    )


def _cut_places(judge, verts: np.ndarray, corners, split_edge: float) -> tuple[np.ndarray, np.ndarray]:
    """``(sliver, place)``: the cuts of each sliver (apex, far corners ``corners``), places from its apex in (0, 1)."""
    b, x, y = (verts[c] for c in corners)
    length = np.maximum(np.linalg.norm(x - b, axis=1), np.linalg.norm(y - b, axis=1))
    spacing = READ_SPACINGS * judge.spacing
    count = np.maximum(np.ceil(length / spacing), 1).astype(np.int64)
    first = np.r_[0, np.cumsum(count)[:-1]]
    owner = np.repeat(np.arange(len(b)), count)
    at = (np.arange(owner.size) - first[owner] + 0.5) / count[owner]
    middle = b[owner] + at[:, None] * (0.5 * (x + y) - b)[owner]
    reach = judge.band + float(judge.slack_of(length.max())) + spacing + judge.slack
    margin = judge.margins(middle.astype(np.float32), reach).astype(np.float64)
    # a reading stands for the half-spacing about it; across the sliver the judge's own slack covers the rest (widened
    # by its half-width too, 822 pieces of the fandisk's bore were kept against 762, in the same time)
    blur = 0.5 * length / count
    partly_at = judge.band + judge.slack
    cuts = ([], [])
    s, lo, hi = np.arange(len(b)), np.zeros(len(b)), np.ones(len(b))
    while len(s):
        size = (hi - lo) * length[s]
        a = np.clip(np.floor(lo * count[s] - 0.5), 0, count[s] - 1).astype(np.int64)
        z = np.clip(np.ceil(hi * count[s] - 0.5), 0, count[s] - 1).astype(np.int64)
        least, most = _range_extremes(margin, first[s] + a, z - a + 1)
        slack = judge.slack_of(size)
        keepable = least - blur[s] > judge.band + slack
        partly = most + blur[s] + judge.partly_slack(slack) > partly_at
        split = ~keepable & partly & (size > split_edge)
        mid = 0.5 * (lo + hi)
        cuts[0].append(s[split])
        cuts[1].append(mid[split])
        s, lo, hi = np.r_[s[split], s[split]], np.r_[lo[split], mid[split]], np.r_[mid[split], hi[split]]
    return np.concatenate(cuts[0]), np.concatenate(cuts[1])


def predicted_margins(judge, points: np.ndarray, reach: float) -> np.ndarray:
    """(N,) float32 about how far the nearest of the other leaves' surfaces and the leaf's own defects is from each
    point (N, 3) float32, up to ``reach``: the other leaves' values read off their fields (linear), its defects' mesh
    distances (module docstring: a prediction, the same whichever path the judge takes)."""
    margin, indexed = np.full(len(points), reach, dtype=np.float32), judge.near.index(points)
    pad = reach + NEAR_BOX_VOXELS * judge.voxel
    near = judge.near.near(
        indexed, pad
    )  # (a closed clean mesh's leaf near its box alone: :class:`.otherleaves.NearRows`)
    others = [j for j in np.flatnonzero(near) if j != judge.index]
    read = judge.near.read_together(judge.reads, indexed, others, pad, reach, distances=False)
    for j in others:
        at, values, _ = read.get(j) or (judge.near.rows(j, indexed, pad), None, None)
        values = judge.leaves[j].sample(points[at], method="linear") if values is None else values
        margin[at] = np.minimum(margin[at], np.abs(values))
    if judge.defect_mesh is not None:
        margin = np.minimum(margin, mesh_distances(judge.defect_mesh, points, reach, judge.device))
    return margin


def _range_extremes(values: np.ndarray, first: np.ndarray, count: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The least and the largest of ``values[first:first + count]`` for each range (count >= 1)."""
    starts = np.r_[0, np.cumsum(count)[:-1]]
    at = np.repeat(first - starts, count) + np.arange(int(count.sum()))
    return np.minimum.reduceat(values[at], starts), np.maximum.reduceat(values[at], starts)


def _edge_points(verts: np.ndarray, corners, sliver: np.ndarray, place: np.ndarray) -> dict:
    """The cuts as points on the slivers' two long edges, one vertex per edge and place: ``verts`` (M, 3) float32,
    ``edge`` (M,) the edge key (low * V + high), ``low_place`` (M,) the place from the low end, ``on`` (M, 2) the
    edge's ends, ``ends`` (M, 2) each point's neighbours among the edge's points (its place's dyadic parent's ends)."""
    n = len(verts)
    b, x, y = corners
    start = np.r_[b[sliver], b[sliver]]
    end = np.r_[x[sliver], y[sliver]]
    place = np.r_[place, place]
    low, high = np.minimum(start, end), np.maximum(start, end)
    low_place = np.where(start == low, place, 1.0 - place)
    key = low * n + high
    keys, group = np.unique(key, return_inverse=True)
    code = np.unique(group * 4.0 + low_place)  # group, then place: exact (dyadic places, few edges)
    group = np.floor(code / 4.0).astype(np.int64)
    low_place = code - 4.0 * group
    lo, hi = keys[group] // n, keys[group] % n
    v64 = verts.astype(np.float64)
    points = v64[lo] + low_place[:, None] * (v64[hi] - v64[lo])
    step = _dyadic_step(low_place)
    ids = n + np.arange(len(code))

    def vertex_at(where):
        found = np.minimum(np.searchsorted(code, group * 4.0 + where), len(code) - 1)
        return np.where(where <= 0.0, lo, np.where(where >= 1.0, hi, ids[found]))

    return {
        "verts": points.astype(np.float32),
        "edge": keys[group],
        "low_place": low_place,
        "on": np.stack([lo, hi], axis=1),
        "ends": np.stack([vertex_at(low_place - step), vertex_at(low_place + step)], axis=1),
    }


def _dyadic_step(place: np.ndarray) -> np.ndarray:
    """(M,) 2^-l for each dyadic place j / 2^l in (0, 1) (j odd): the half-width of the interval it halves."""
    step = np.zeros(len(place))
    for level in range(1, 64):
        scaled = place * 2.0**level
        new = (step == 0.0) & (scaled == np.floor(scaled))
        step[new] = 2.0**-level
        if (step > 0.0).all():
            break
    return step


def _strip_points(source: np.ndarray, apex: np.ndarray, strip: np.ndarray, points: dict, n: int):
    """``(p, v, side, t)`` for :func:`.slivers.zip_points`: every strip parent with a cut on a long edge (the cut
    slivers and their neighbours across those edges), its far corners and the cuts on its long edges (``n``: the
    source's vertex count, the cuts numbered after them)."""
    rows = np.flatnonzero(strip)
    k = apex[rows]
    b = source[rows, k]
    edges = np.unique(points["edge"])
    parts = []
    for side, far in ((FIRST, source[rows, (k + 1) % 3]), (SECOND, source[rows, (k + 2) % 3])):
        key = np.minimum(b, far) * n + np.maximum(b, far)
        held = np.isin(key, edges)
        parts.append((rows[held], key[held], b[held], far[held], side))
    touched = np.unique(np.concatenate([part[0] for part in parts]))
    out = ([], [], [], [])
    order = np.argsort(points["edge"], kind="stable")
    point_edge = points["edge"][order]
    for side, turn in ((FIRST, 1), (SECOND, 2)):
        out[0].append(touched)  # the far corner, at 1
        far = source[touched, (apex[touched] + turn) % 3]
        out[1].append(far)
        out[2].append(np.full(len(touched), side))
        out[3].append(np.ones(len(touched)))
    for parent, key, apex_vertex, far, side in parts:
        first = np.searchsorted(point_edge, key, side="left")
        last = np.searchsorted(point_edge, key, side="right")
        count = last - first
        at = np.repeat(first - np.r_[0, np.cumsum(count)[:-1]], count) + np.arange(int(count.sum()))
        which = order[at]
        reversed_ = np.repeat(apex_vertex > far, count)  # the apex is the edge's high end: places run the other way
        low_place = points["low_place"][which]
        out[0].append(np.repeat(parent, count))
        out[1].append(n + which)
        out[2].append(np.full(len(which), side))
        out[3].append(np.where(reversed_, 1.0 - low_place, low_place))
    return tuple(np.concatenate(column) for column in out)
