"""Slivers cut across, never along: a thin source triangle's pieces as a strip between its two long edges.

A CAD cylinder's wall is a ring of slivers a voxel wide and the part long. Where a seam crosses the wall, the pieces
near it must be about a voxel long. Bisection (:func:`.refine.split_triangles`) halves a sliver's long edges, and the
quadrilateral left between the cuts takes a diagonal whose midpoint, at the next cut, lies inside the sliver: each
round adds points across the wall (a voxel-wide wall was cut into sixteen needles a twentieth of a voxel wide, and the
pieces judged, merged and straightened grew with them).

Here a sliver (no wider than the split size, several times longer than wide) has points only on its own edges: its
pieces are the strip that zips the points of its two long edges, ordered from its apex (the corner opposite its
shortest edge), with a fan onto any points its shortest edge holds. A partly keepable piece asks for the long edges'
segments that overlap it, on both sides, to be split at their midpoints; its neighbours across those edges take the
same points (the split's usual conformity), and the sliver is zipped again. Each cut adds one point on each long edge:
pieces stay a sliver's width wide however often it is cut.

Written by hand: the strip's zip is a merge of two sorted runs per sliver, done for all slivers at once in numpy.
"""

from __future__ import annotations

import numpy as np

from .refine import edge_of_new, split_triangles
from .trimeasures import triangle_measures

# A source triangle is cut as a strip when no wider than the split size and at least this many times as long.
SLIVER_ASPECT = 3.0
APEX, FIRST, SECOND, BASE = 0, 1, 2, 3  # a strip's sides: its apex, its two long edges from it, its shortest edge


def strip_parents(verts: np.ndarray, tris: np.ndarray, split_edge: float, measures=None) -> tuple:
    """``(strip, apex)``: (S,) bool which source triangles are cut as strips, and (S,) int64 each one's apex corner
    (0, 1, 2: the corner opposite its shortest edge). ``measures``: the triangles' :class:`.TriangleMeasures` where
    the caller has them."""
    measures = triangle_measures(verts, tris) if measures is None else measures
    lengths = measures.lengths  # edge k: corner k -> k + 1
    longest = lengths.max(axis=1)
    width = measures.doubled_areas / np.maximum(longest, 1e-300)
    strip = (width <= split_edge) & (longest > split_edge) & (longest >= SLIVER_ASPECT * width)
    apex = (np.argmin(lengths, axis=1) + 2) % 3
    return _among_strips(tris, strip, apex, len(verts)), apex


def _among_strips(tris: np.ndarray, strip: np.ndarray, apex: np.ndarray, n: int) -> np.ndarray:
    """``strip`` less the slivers whose long edges another triangle shares that is no strip (a sliver alone among a
    scan's triangles, where the cuts its neighbours take are better as bisection's), until every strip's long edges
    are shared with strips only (a cylinder's wall, a cap's fan). Only the slivers' long edges are looked up among
    the triangles' edges (a scan's thousand slivers among its 70 k triangles)."""
    rows = np.flatnonzero(strip)
    if not len(rows):
        return strip
    t = np.asarray(tris, dtype=np.int64)
    u = t[:, [1, 2, 0]]
    mark = np.zeros(n, dtype=bool)
    mark[t[rows]] = True
    near = np.flatnonzero((mark[t] & mark[u]).ravel())  # the edges both of whose ends are a sliver's corners
    keys = np.minimum(t.ravel()[near], u.ravel()[near]) * n + np.maximum(t.ravel()[near], u.ravel()[near])
    sliver_keys = np.minimum(t[rows], u[rows]) * n + np.maximum(t[rows], u[rows])
    k = np.arange(len(rows))
    long_keys = np.stack([sliver_keys[k, apex[rows]], sliver_keys[k, (apex[rows] + 2) % 3]], 1)
    edges = np.unique(long_keys)
    at = np.minimum(np.searchsorted(edges, keys), len(edges) - 1)
    hit = np.flatnonzero(edges[at] == keys)  # the triangles' edges that are a sliver's long edge
    face, edge = near[hit] // 3, at[hit]
    long_edge = np.searchsorted(edges, long_keys)
    for _ in range(len(rows) + 1):
        shared_with_other = np.zeros(len(edges), dtype=bool)
        shared_with_other[edge[~strip[face]]] = True
        keep = strip.copy()
        keep[rows] &= ~shared_with_other[long_edge].any(axis=1)
        if (keep == strip).all():
            return keep
        strip = keep
    return strip


def _places(verts, tris, parent, on, source_tris, apex) -> tuple[np.ndarray, np.ndarray]:
    """Per (piece, corner) of pieces of strip parents: its side (APEX, FIRST, SECOND, BASE; -1 for none) and its
    place along it: from the apex (0) to the far corner (1) on a long edge, from the first far corner on the base."""
    s = source_tris[parent]
    k = apex[parent]
    rows = np.arange(len(s))
    b, x, y = (s[rows, (k + j) % 3][:, None] for j in range(3))
    low, high = on[tris, 0], on[tris, 1]

    def along(e0, e1):
        return (low == np.minimum(e0, e1)) & (high == np.maximum(e0, e1))

    side = np.full(tris.shape, -1, dtype=np.int64)
    side[along(x, y)] = BASE
    side[along(b, x) | (tris == x)] = FIRST
    side[along(b, y) | (tris == y)] = SECOND
    side[tris == b] = APEX
    start = np.where(side == BASE, x, b)
    end = np.where(side == FIRST, x, y)
    # coordinate by coordinate (numpy reduces a 3-long axis several times slower), the sums in the same order
    along_d, length2 = 0.0, 0.0
    for j in range(3):  # the corners gathered, then widened (not the whole column: a scan's leaf has 35 k vertices)
        p0 = verts[start, j].astype(np.float64)
        d = verts[end, j].astype(np.float64) - p0
        along_d = along_d + (verts[tris, j].astype(np.float64) - p0) * d
        length2 = length2 + d * d
    t = along_d / np.maximum(length2, 1e-300)
    return side, np.where(side == APEX, 0.0, t)


def strip_requests(verts, tris, parent, on, source_tris, apex, strip, asked, long_edge: float):
    """The long edges' segments that the ``asked`` pieces of strip parents need split: every segment of either long
    edge of the piece's parent that overlaps the piece's span from the apex and is longer than ``long_edge``.

    Returns:
        ``(keys, rows, got)``: the segments' sorted keys (low * V + high), pieces holding them (for the split's
        neighbour search), and (T,) bool the asked pieces that get a segment split.
    """
    got = np.zeros(len(tris), dtype=bool)
    pieces = np.flatnonzero(strip[parent])
    ask = np.flatnonzero(asked[pieces])
    if not len(ask):
        return np.zeros(0, np.int64), np.zeros(0, np.int64), got
    side, t = _places(verts, tris[pieces], parent[pieces], on, source_tris, apex)
    segs = _segments(verts, tris[pieces], pieces, parent[pieces], side, t)
    group, lo_t, hi_t = segs["group"], segs["lo"], segs["hi"]
    span_lo = np.where(side[ask] >= 0, t[ask], np.inf).min(axis=1)
    span_hi = np.where(side[ask] == BASE, 1.0, np.where(side[ask] >= 0, t[ask], -np.inf)).max(axis=1)
    covered = np.zeros(len(group) + 1, dtype=np.int64)
    ranges = []
    for chain in (FIRST, SECOND):
        g = (parent[pieces[ask]] * 2 + chain - 1) * 4.0
        # a group's segments are sorted and do not overlap: those overlapping a span are a contiguous range
        first = np.searchsorted(group * 4.0 + hi_t, g + span_lo, side="right")
        last = np.searchsorted(group * 4.0 + lo_t, g + span_hi, side="left")
        ok = last > first
        np.add.at(covered, first[ok], 1)
        np.add.at(covered, last[ok], -1)
        ranges.append((first, last))
    chosen = (np.cumsum(covered[:-1]) > 0) & (segs["length"] > long_edge)
    count = np.r_[0, np.cumsum(chosen)]
    for first, last in ranges:
        got[pieces[ask]] |= count[np.maximum(last, first)] > count[first]
    return np.unique(segs["key"][chosen]), np.unique(segs["piece"][chosen]), got


def _segments(verts, tris, rows, parent, side, t) -> dict:
    """The pieces' edges along their strip parents' long edges, sorted by (parent, long edge, place): ``key``,
    ``piece`` (row), ``group`` (parent * 2 + long edge - 1), ``lo``/``hi`` places, ``length``."""
    n = len(verts)
    nxt = [1, 2, 0]
    a, b, sa, sb, ta, tb = tris, tris[:, nxt], side, side[:, nxt], t, t[:, nxt]
    out = {k: [] for k in ("key", "piece", "group", "lo", "hi", "length")}
    for chain in (FIRST, SECOND):
        on_it = ((sa == chain) | (sa == APEX)) & ((sb == chain) | (sb == APEX)) & ((sa == chain) | (sb == chain))
        r, k = np.nonzero(on_it)
        u, w = a[r, k], b[r, k]
        out["key"].append(np.minimum(u, w) * n + np.maximum(u, w))
        out["piece"].append(rows[r])
        out["group"].append(parent[r] * 2 + chain - 1)
        out["lo"].append(np.minimum(ta[r, k], tb[r, k]))
        out["hi"].append(np.maximum(ta[r, k], tb[r, k]))
        d = [verts[u, j].astype(np.float64) - verts[w, j] for j in range(3)]
        out["length"].append(np.sqrt((d[0] * d[0] + d[1] * d[1]) + d[2] * d[2]))  # as norm adds a 3-long axis
    out = {k: np.concatenate(v) for k, v in out.items()}
    order = np.lexsort((out["lo"], out["group"]))
    return {k: v[order] for k, v in out.items()}


def zipped(verts, tris, parent, on, source_tris, apex, redo):
    """The strip parents ``redo`` ((S,) bool) triangulated afresh from the points on their edges (the corners of their
    pieces ``tris``). Returns ``(tris, parent)`` of their new pieces, oriented as their source triangles, or of none
    where a piece has a corner off its parent's edges (left to the caller)."""
    rows = np.flatnonzero(redo[parent])
    side, t = _places(verts, tris[rows], parent[rows], on, source_tris, apex)
    p, v, side, t = np.repeat(parent[rows], 3), tris[rows].ravel(), side.ravel(), t.ravel()
    off = np.zeros(len(source_tris), dtype=bool)
    off[p[side < 0]] = True
    _, first = np.unique(p * (len(verts) + 1) + v, return_index=True)  # each (parent, point) once
    first = first[~off[p[first]] & (side[first] != APEX)]
    p, v, side, t = p[first], v[first], side[first], t[first]
    chain = side != BASE
    strips, strip_parent = zip_points(p[chain], v[chain], side[chain], t[chain], source_tris, apex)
    return _fanned(strips, strip_parent, p[~chain], v[~chain], t[~chain], source_tris, apex)


def zip_points(p, v, side, t, source_tris, apex):
    """The strips of the source triangles ``p`` from the points ``v`` on their long edges (``side`` FIRST or SECOND,
    ``t`` the place from the apex; each one's far corners at 1, its apex not listed), merged by their place: a first
    triangle (the apex, the first point of each), then one triangle per further point, on the latest point of each
    side. Returns ``(tris, parent)``."""
    order = np.lexsort((side, t, p))
    p, v, side = p[order], v[order], side[order]
    idx = np.arange(len(p))
    start = np.r_[True, p[1:] != p[:-1]]
    group_start = np.maximum.accumulate(np.where(start, idx, 0))
    one, two = (_first_in_group(side == s, start) for s in (FIRST, SECOND))
    last_one, last_two = (_latest_before(side == s, group_start) for s in (FIRST, SECOND))
    e = np.flatnonzero((idx != one) & (idx != two))
    before_one, before_two = np.maximum(last_one[e], one[e]), np.maximum(last_two[e], two[e])
    # a point of the first edge: (its predecessor, it, the second edge's latest); of the second: (the first edge's
    # latest, it, its predecessor)
    steps = np.stack([v[before_one], v[e], v[before_two]], axis=1)
    apex_of = source_tris[p[start], apex[p[start]]]
    firsts = np.stack([apex_of, v[one[start]], v[two[start]]], axis=1)
    return np.concatenate([firsts, steps]), np.concatenate([p[start], p[e]])


def _first_in_group(flag, start):
    """Per row: the first row of its group (runs beginning at ``start``) where ``flag`` holds."""
    idx = np.arange(len(flag))
    starts = np.flatnonzero(start)
    firsts = np.minimum.reduceat(np.where(flag, idx, len(flag)), starts)
    return np.repeat(firsts, np.diff(np.r_[starts, len(flag)]))


def _latest_before(flag, group_start):
    """Per row: the latest earlier row of its group where ``flag`` holds, -1 if none."""
    idx = np.arange(len(flag))
    latest = np.maximum.accumulate(np.r_[-1, np.where(flag, idx, -1)[:-1]])
    return np.where(latest >= group_start, latest, -1)


def _fanned(tris, parent, base_p, base_v, base_t, source_tris, apex):
    """The strips with the triangle on each one's shortest edge fanned over the points that edge holds."""
    if not len(base_p):
        return tris, parent
    k = apex[parent]
    x, y = source_tris[parent, (k + 1) % 3], source_tris[parent, (k + 2) % 3]
    held = np.zeros(len(source_tris), dtype=bool)
    held[base_p] = True
    rows = np.flatnonzero((tris == x[:, None]).any(axis=1) & (tris == y[:, None]).any(axis=1) & held[parent])
    tip = np.where((tris[rows] != x[rows, None]) & (tris[rows] != y[rows, None]), tris[rows], -1).max(axis=1)
    tip_of = np.full(len(source_tris), -1, dtype=np.int64)
    tip_of[parent[rows]] = tip
    order = np.lexsort((base_t, base_p))
    bp, bv = base_p[order], base_v[order]
    kb = apex[bp]
    xb, yb = source_tris[bp, (kb + 1) % 3], source_tris[bp, (kb + 2) % 3]
    first = np.r_[True, bp[1:] != bp[:-1]]
    last = np.r_[bp[1:] != bp[:-1], True]
    prev = np.where(first, xb, np.r_[-1, bv[:-1]])
    alive = np.ones(len(tris), dtype=bool)
    alive[rows] = False
    fans = [np.stack([prev, bv, tip_of[bp]], axis=1), np.stack([bv[last], yb[last], tip_of[bp[last]]], axis=1)]
    return np.concatenate([tris[alive], *fans]), np.concatenate([parent[alive], bp, bp[last]])


class Splitter:
    """A leaf's pieces split round after round (:func:`.refine.split_triangles`), its strip parents' pieces zipped
    (module docstring). Holds the source triangles' strip flags and apexes (``strips``, when found already: the
    :func:`strip_parents` of ``source_tris``) and each vertex's source edge (``on``)."""

    def __init__(self, verts: np.ndarray, source_tris: np.ndarray, split_edge: float, strips=None):
        self.source_tris = np.asarray(source_tris, dtype=np.int64)
        self.split_edge = float(split_edge)
        found = strips if strips is not None else strip_parents(verts, self.source_tris, self.split_edge)
        self.strip, self.apex = found
        self.on = np.repeat(np.arange(len(verts), dtype=np.int64)[:, None], 2, axis=1)

    def split(self, verts, tris, mark, parent, flip, status, ends, unknown: int, dropped: int):
        """Split the ``mark``ed pieces: ``(verts, tris, parent, flip, status, ends)`` after it. New pieces (of marked
        triangles, and zipped pieces that are no piece of before) get status ``unknown``; a marked strip piece with no
        segment left to split gets ``dropped``; the other pieces keep theirs."""
        strip_piece = self.strip[parent]
        keys, rows, got = strip_requests(
            verts, tris, parent, self.on, self.source_tris, self.apex, self.strip, mark & strip_piece, self.split_edge
        )
        status = status.copy()
        status[mark & strip_piece & ~got] = dropped
        plain = mark & ~strip_piece
        new_verts, new_tris, origin, new_ends = split_triangles(verts, tris, plain, self.split_edge, also=(keys, rows))
        self.on = np.concatenate([self.on, edge_of_new(self.on, new_ends[:, 0], new_ends[:, 1])])
        fresh = plain[origin]
        new_parent = parent[origin]
        redo = np.zeros(len(self.source_tris), dtype=bool)
        redo[new_parent[(new_tris >= len(verts)).any(axis=1)]] = True
        redo &= self.strip
        if redo.any():
            z_tris, z_parent = zipped(new_verts, new_tris, new_parent, self.on, self.source_tris, self.apex, redo)
            done = np.zeros(len(self.source_tris), dtype=bool)
            done[z_parent] = True
            stay = ~done[new_parent]
            z_origin, matched = _same_pieces(tris, parent, z_tris, z_parent, len(new_verts))
            new_tris = np.concatenate([new_tris[stay], z_tris])
            origin = np.concatenate([origin[stay], z_origin])
            fresh = np.concatenate([fresh[stay], ~matched])
        parent, flip, status = parent[origin], flip[origin], status[origin]
        status[fresh] = unknown
        return new_verts, new_tris, parent, flip, status, np.concatenate([ends, new_ends])


def _same_pieces(tris, parent, new_tris, new_parent, n: int) -> tuple[np.ndarray, np.ndarray]:
    """For each new piece: the row of ``tris`` with the same corners (its verdict holds), else a piece of the same
    parent; and whether it was found."""
    rep = np.full(int(max(parent.max(initial=0), new_parent.max(initial=0))) + 1, -1, dtype=np.int64)
    rep[parent] = np.arange(len(parent))
    origin = rep[new_parent]
    if n >= 1 << 21:  # corners packed 21 bits each
        return origin, np.zeros(len(new_tris), dtype=bool)

    def packed(t):
        s = np.sort(t, axis=1).astype(np.int64)
        return (s[:, 0] << 42) | (s[:, 1] << 21) | s[:, 2]

    old_keys, new_keys = packed(tris), packed(new_tris)
    order = np.argsort(old_keys)
    at = np.minimum(np.searchsorted(old_keys[order], new_keys), len(order) - 1)
    matched = old_keys[order][at] == new_keys
    origin = np.where(matched, order[at], origin)
    return origin, matched
