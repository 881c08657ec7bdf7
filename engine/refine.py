"""Splitting an operand's large triangles where a seam crosses them, so that their far parts can be kept.

A CAD part's faces are a few large triangles: a bore through a plate lies within the band of every triangle of the
plate's top, so none could be kept whole. The triangles that are partly keepable are split, conformingly, until the
pieces are no larger than a voxel or two; their neighbours take the new vertices on their shared edges (red-green
refinement: a triangle splits in two, three or four by how many of its edges are split), so the mesh stays free of
T-junctions. Each piece remembers its original triangle (``parent``), whose attributes it keeps.

Written by hand: the templates are a few lines of numpy over all triangles at once, no mesh library needed.
"""

from __future__ import annotations

import numpy as np

from .meshcheck import any_corner, compacted


# ---- splitting ----
def split_triangles(verts: np.ndarray, tris: np.ndarray, split: np.ndarray, long_edge: float = np.inf, also=None):
    """Split the longest edge of each ``split`` triangle at its midpoint, in every triangle that has that edge
    (longest-edge bisection, Rivara's: pieces keep their shape where splitting every edge would keep a sliver's). A
    sliver's other long edges are split with it (every edge longer than ``long_edge`` and than twice its triangle's
    shortest): it is cut across into pieces as wide as it is, where bisecting its longest edge alone makes narrower
    slivers of it.

    Args:
        verts: (V, 3) float32; tris: (T, 3) int64; split: (T,) bool; long_edge: float; also: optional ``(keys,
            rows)``: more edges to split (sorted keys low * V + high) and triangles that hold them.
    Returns:
        ``(verts, tris, origin, ends)``: the vertices with the midpoints appended, the new triangles, (T',) int64 the
        triangle of ``tris`` each new one lies in, and (M, 2) int64 the edge each midpoint splits.
    """
    t = np.asarray(tris, dtype=np.int64)
    n = len(verts)
    rows = np.flatnonzero(split)
    marked_keys = _edges_to_split(verts, t[rows], long_edge)
    if also is not None:  # more edges, and triangles that hold them
        marked_keys, rows = np.union1d(marked_keys, also[0]), np.union1d(rows, also[1])
    mids = _midpoints(t, rows, marked_keys, n)
    lo, hi = marked_keys // n, marked_keys % n
    new_verts = (0.5 * (verts[lo].astype(np.float64) + verts[hi].astype(np.float64))).astype(np.float32)
    pattern = (mids[:, 0] >= 0).astype(np.int64) + (mids[:, 1] >= 0) + (mids[:, 2] >= 0)
    none = np.flatnonzero(pattern == 0)
    parts, origin = [t[none]], [none]
    # one split edge: turned to be edge 0
    one = np.flatnonzero(pattern == 1)
    if len(one):
        k = np.argmax(mids[one] >= 0, axis=1)
        v, m = _turned(t[one], k), _turned(mids[one], k)
        _emit(parts, origin, one, [(v[:, 0], m[:, 0], v[:, 2]), (m[:, 0], v[:, 1], v[:, 2])])
    # two split edges: the unsplit one turned to be edge 2
    two = np.flatnonzero(pattern == 2)
    if len(two):
        k = (np.argmin(mids[two] >= 0, axis=1) + 1) % 3
        v, m = _turned(t[two], k), _turned(mids[two], k)
        _emit(
            parts,
            origin,
            two,
            [(m[:, 0], v[:, 1], m[:, 1]), (v[:, 0], m[:, 0], m[:, 1]), (v[:, 0], m[:, 1], v[:, 2])],
        )
    three = np.flatnonzero(pattern == 3)
    if len(three):
        v, m = t[three], mids[three]
        _emit(
            parts,
            origin,
            three,
            [
                (v[:, 0], m[:, 0], m[:, 2]),
                (m[:, 0], v[:, 1], m[:, 1]),
                (m[:, 2], m[:, 1], v[:, 2]),
                (m[:, 0], m[:, 1], m[:, 2]),
            ],
        )
    return np.concatenate([verts, new_verts]), np.concatenate(parts), np.concatenate(origin), np.stack([lo, hi], 1)


def _midpoints(t: np.ndarray, rows: np.ndarray, marked_keys: np.ndarray, n: int) -> np.ndarray:
    """(T, 3) int64 the midpoint (``n`` + its row in ``marked_keys``) of each triangle's edge k (corner k -> k + 1),
    -1 where that edge is not split. Only a triangle with two corners of the split ones (``rows``) can have a split
    edge: only those are read."""
    corner = np.zeros(n, dtype=bool)
    corner[t[rows].ravel()] = True
    c0, c1, c2 = (corner[t[:, k]] for k in range(3))  # column by column: a 3-long axis reduces slowly
    near = np.flatnonzero((c0 & c1) | (c0 & c2) | (c1 & c2))
    a, b = t[near].ravel(), t[near][:, [1, 2, 0]].ravel()
    keys = np.minimum(a, b) * n + np.maximum(a, b)
    at = np.searchsorted(marked_keys, keys)
    at_ok = np.minimum(at, max(len(marked_keys) - 1, 0))
    marked = (at < len(marked_keys)) & (marked_keys[at_ok] == keys) if len(marked_keys) else np.zeros(len(keys), bool)
    mids = np.full((len(t), 3), -1, dtype=np.int64)
    mids[near] = np.where(marked, n + at_ok, -1).reshape(-1, 3)
    return mids


def _edges_to_split(verts, t: np.ndarray, long_edge: float) -> np.ndarray:
    """The sorted keys (low * V + high) of the edges to split of the triangles ``t`` to split: each one's longest,
    and a sliver's other long edges (:func:`split_triangles`)."""
    n = len(verts)
    a, b = t.ravel(), t[:, [1, 2, 0]].ravel()
    keys = (np.minimum(a, b) * n + np.maximum(a, b)).reshape(-1, 3)
    e = verts[t[:, [1, 2, 0]]].astype(np.float64) - verts[t].astype(np.float64)
    lengths = np.sqrt((e**2).sum(axis=2))
    longest = np.argmax(lengths, axis=1)
    across = (lengths > long_edge) & (lengths > 2.0 * lengths.min(axis=1, keepdims=True))
    return np.unique(np.r_[keys[np.arange(len(t)), longest], keys[across]])


def _turned(rows: np.ndarray, k: np.ndarray) -> np.ndarray:
    cols = (np.arange(3)[None, :] + k[:, None]) % 3
    return np.take_along_axis(rows, cols, axis=1)


def _emit(parts: list, origin: list, rows: np.ndarray, corners: list) -> None:
    for c in corners:
        parts.append(np.stack(c, axis=1))
        origin.append(rows)


def merge_kept(verts: np.ndarray, tris: np.ndarray, keep: np.ndarray, ends: np.ndarray):
    """Undo the splits inside kept regions: a midpoint whose triangles are all kept is collapsed into one end of the
    edge it splits (the triangles with that end go, the others take it in the midpoint's place: the midpoint lies on
    the edge, so the region they cover stays, in the same plane), where no triangle turns over. Midpoints along a
    kept region's border stay.

    Args:
        verts: (V, 3) float32; tris: (T, 3) int64 triangles after :func:`split_triangles`; keep: (T,) bool; ends:
            (V, 2) int64 the edge each vertex splits (-1 for the source's vertices).
    Returns:
        ``(tris, rows)``: the triangles left and (T',) int64 the row of ``tris`` each stands in (its parent, its
        verdict).
    """
    tris = np.array(tris, dtype=np.int64)
    keep = np.asarray(keep, dtype=bool)
    # only the triangles at a midpoint all of whose triangles are kept are read: a collapse takes such a midpoint and
    # changes only triangles at it (its valence counts them), into one of its edge's ends, a midpoint again (one of
    # those: it holds the two triangles the collapse drops) or a source vertex; the rest, unchanged, are set aside
    near = np.zeros(len(ends), dtype=bool)
    near[tris[keep].ravel()] = True
    blocked = np.zeros(len(ends), dtype=bool)  # a midpoint with a triangle not kept never collapses (that one stays)
    blocked[tris[~keep].ravel()] = True
    near &= (ends[:, 0] >= 0) & ~blocked
    rows = np.flatnonzero(any_corner(near, tris))  # (all kept: a triangle at such a midpoint is)
    tris, aside = tris[rows], set_aside(tris, rows)
    v64 = verts.astype(np.float64)
    ranks = position_ranks(verts)
    for _ in range(256):
        merged = False
        for side in (0, 1):
            flat = tris.ravel()
            candidate = near & (np.bincount(flat, minlength=len(ends)) >= 4)  # (no other vertex has triangles left)
            at = np.flatnonzero(candidate[flat])
            if not len(at):
                continue
            face, mid = at // 3, flat[at]
            end = ends[mid, side]
            at_face = tris[face]
            drop = (at_face[:, 0] == end) | (at_face[:, 1] == end) | (at_face[:, 2] == end)
            two_drops = np.bincount(mid[drop], minlength=len(ends)) == 2
            live = np.flatnonzero(two_drops[mid])  # (only a midpoint with two faces to drop can collapse)
            moved = np.where(at_face[live] == mid[live, None], end[live, None], at_face[live])
            turns = ~drop[live] & turned_over(v64, at_face[live], moved)
            bad = np.zeros(len(ends), dtype=bool)
            bad[mid[live[turns]]] = True
            ok = ~bad[mid] & two_drops[mid]
            win = claims_won(face, mid, ok, len(tris), ranks)
            if not win.any():
                continue
            merged = True
            stay = win[live] & ~drop[live]
            tris[face[live[stay]]] = moved[stay]
            alive = np.ones(len(tris), dtype=bool)
            alive[face[win & drop]] = False
            tris, rows = tris[alive], rows[alive]
        if not merged:
            break
    return put_back(tris, rows, aside)


def _normal_columns(points: np.ndarray, tris: np.ndarray) -> list:
    """The three coordinates of ``tris``' unnormalised normals on ``points`` (float64), as ``np.cross`` of their edges
    from the first corner gives them (the same products and differences)."""
    cols = [points[:, j] for j in range(3)]
    (a0, a1, a2), (b0, b1, b2) = ([c[tris[:, k]] - c[tris[:, 0]] for c in cols] for k in (1, 2))
    return [a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0]


def turned_over(points: np.ndarray, before: np.ndarray, after: np.ndarray) -> np.ndarray:
    """(T,) bool: the faces ``before`` whose normal and ``after``'s (a corner moved) point less than a millionth of
    its squared length the same way (turned over, or flat): as ``np.cross``, ``np.linalg.norm`` and ``np.einsum`` of
    (T, 3) rows find it, coordinate by coordinate (0.37x their time on 8,000 faces: 3-long axes reduce slowly)."""
    (x0, y0, z0), (x1, y1, z1) = _normal_columns(points, before), _normal_columns(points, after)
    area = np.sqrt((x0 * x0 + y0 * y0) + z0 * z0)
    return (x0 * x1 + y0 * y1) + z0 * z1 <= 1e-6 * area * area


def position_hash(points: np.ndarray) -> np.ndarray:
    """(V,) int32 a hash of each vertex's position (its float bits): orders that do not depend on numbering."""
    bits = np.ascontiguousarray(points, dtype=np.float32).view(np.uint32).astype(np.uint64)
    mixed = (bits[:, 0] * np.uint64(73856093)) ^ (bits[:, 1] * np.uint64(19349663)) ^ (bits[:, 2] * np.uint64(83492791))
    return (mixed % np.uint64(1 << 31)).astype(np.int32)


def position_ranks(points: np.ndarray) -> np.ndarray:
    """(V,) int64 distinct ranks of the vertices, by :func:`position_hash` (ties by index)."""
    return (position_hash(points).astype(np.int64) << 32) | np.arange(len(points), dtype=np.int64)


def claims_won(face: np.ndarray, vert: np.ndarray, use: np.ndarray, n_faces: int, ranks: np.ndarray) -> np.ndarray:
    """Per row (a vertex ``vert`` that would change face ``face``; ``use``: it may): whether its vertex holds every face
    it would change, each face going to the lowest-ranked of its vertices (``ranks``). Ranks from a hash of positions
    let about a third of a run's vertices win each round, where ranks by index (a run's midpoints numbered in a row)
    let only its first."""
    rank = ranks[vert]
    claim = np.full(n_faces, np.iinfo(np.int64).max, dtype=np.int64)
    np.minimum.at(claim, face[use], rank[use])
    lost = np.zeros(len(ranks), dtype=bool)
    lost[vert[use & (claim[face] != rank)]] = True
    return use & ~lost[vert]


def set_aside(tris: np.ndarray, read: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The rows of ``tris`` not in ``read`` (sorted row numbers) and their triangles, for :func:`put_back`."""
    unread = np.ones(len(tris), dtype=bool)
    unread[read] = False
    rest = np.flatnonzero(unread)
    return rest, tris[rest]


def put_back(tris: np.ndarray, rows: np.ndarray, aside) -> tuple[np.ndarray, np.ndarray]:
    """``(tris, rows)``: the triangles read (standing in ``rows``) and those set aside, in the order they came."""
    rest, rest_tris = aside
    rows, tris = np.concatenate([rows, rest]), np.concatenate([tris, rest_tris])
    at = np.full(int(rows.max(initial=-1)) + 1, -1, dtype=np.int64)
    at[rows] = np.arange(len(rows))
    placed = at[at >= 0]
    # each row once (collapses only take triangles away): row order is where each row is, no sort needed
    order = placed if len(placed) == len(rows) else np.argsort(rows, kind="stable")
    return tris[order], rows[order]


def edge_of_new(on: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """(M, 2) int64 the source edge (low, high source vertex) each new midpoint of a segment ``lo``-``hi`` lies on, -1
    inside a source triangle (``on``: the older vertices' own; (v, v) for a source vertex)."""
    vals = np.sort(np.concatenate([on[lo], on[hi]], axis=1), axis=1)
    distinct = 1 + (vals[:, 1:] != vals[:, :-1]).sum(axis=1)
    edge = (vals[:, 0] >= 0) & (distinct == 2)
    return np.where(edge[:, None], vals[:, [0, 3]], -1)


def _edge_of_vertices(ends: np.ndarray, n_source: int) -> np.ndarray:
    """(V, 2) int64 the source edge (low, high source vertex) each vertex lies on: (v, v) for a source vertex, -1
    for one inside a source triangle. Midpoints follow their edges' ends (:func:`edge_of_new`), resolved in as many
    passes as splits nested."""
    on = np.full((len(ends), 2), -2, dtype=np.int64)
    on[:n_source] = np.arange(n_source)[:, None]
    mids = np.arange(n_source, len(ends))
    for _ in range(len(ends)):
        todo = mids[on[mids, 0] == -2]
        if not len(todo):
            break
        ready = (on[ends[todo, 0], 0] != -2) & (on[ends[todo, 1], 0] != -2)
        todo = todo[ready]
        on[todo] = edge_of_new(on, ends[todo, 0], ends[todo, 1])
    return on


def restore_whole(verts, tris, parent, keep, ends, source_tris):
    """Give a source triangle whose pieces are all kept back as itself: its three corners (bit for bit, as the
    source lists them), or, where neighbours that stay split need midpoints on its edges, the polygon of its corners
    and those midpoints fanned from its centre (a new vertex on its plane).

    Args:
        verts: (V, 3) float32; tris: (T, 3) int64 pieces; parent: (T,) int64 their source triangles; keep: (T,)
            bool; ends: (V, 2) int64 (see :func:`merge_kept`); source_tris: (S, 3) int64 the source's triangles.
    Returns:
        ``(verts, tris, parent, keep)`` with the restored triangles in place of their pieces (at the end).
    """
    n_source = int(source_tris.max(initial=-1)) + 1
    pieces = np.bincount(parent, minlength=len(source_tris))
    kept_pieces = np.bincount(parent[keep], minlength=len(source_tris))
    whole = (pieces > 1) & (kept_pieces == pieces)
    if not whole.any():
        return verts, tris, parent, keep
    split_faces = ~whole[parent]
    needed = np.zeros(len(verts), dtype=bool)
    needed[tris[split_faces].ravel()] = True
    on = _edge_of_vertices(ends, n_source)
    p, v = _rings(verts, tris[~split_faces], parent[~split_faces], needed, on, source_tris)
    counts = np.bincount(p, minlength=len(source_tris))
    plain = whole & (counts == 3)
    fan = whole & (counts > 3)
    new_verts, fans, fan_parent = _fans(verts, source_tris, fan, p, v)
    out_tris = [tris[split_faces], source_tris[plain], fans]
    out_parent = [parent[split_faces], np.flatnonzero(plain), fan_parent]
    restored = len(out_parent[1]) + len(fan_parent)
    return (
        new_verts,
        np.concatenate(out_tris).astype(np.int64),
        np.concatenate(out_parent).astype(np.int64),
        np.r_[keep[split_faces], np.ones(restored, dtype=bool)],
    )


def _rings(verts, tris, parent, needed, on, source_tris) -> tuple[np.ndarray, np.ndarray]:
    """``(p, v)``: every (source triangle, vertex) of the pieces ``tris`` of whole source triangles (``parent``) that
    is one of its corners or lies on one of its edges and is ``needed`` there (by a neighbour that stays split), each
    triangle's in order round it from its first corner (``on``: each vertex's source edge)."""
    rows = np.repeat(np.arange(len(tris)), 3)
    p, v = parent[rows], tris.ravel()
    pv = np.unique(p * len(verts) + v)  # (p, v) pairs in the order of p, then v
    p, v = pv // len(verts), pv % len(verts)
    corners = source_tris[p]
    corner_at = (corners == v[:, None]).argmax(axis=1)
    is_corner = (corners == v[:, None]).any(axis=1)
    edge_ends = np.stack([corners, np.roll(corners, -1, axis=1)], axis=2)  # edge k: corner k -> k + 1
    lo, hi = np.minimum(edge_ends[..., 0], edge_ends[..., 1]), np.maximum(edge_ends[..., 0], edge_ends[..., 1])
    on_edge = (lo == on[v, 0][:, None]) & (hi == on[v, 1][:, None])
    ring = is_corner | (on_edge.any(axis=1) & needed[v])
    p, v, corner_at, on_edge, corners = p[ring], v[ring], corner_at[ring], on_edge[ring], corners[ring]
    is_corner = is_corner[ring]
    k = np.where(is_corner, corner_at, on_edge.argmax(axis=1))
    start = verts[corners[np.arange(len(k)), k]].astype(np.float64)
    end = verts[corners[np.arange(len(k)), (k + 1) % 3]].astype(np.float64)
    t = np.where(is_corner, 0.0, np.linalg.norm(verts[v] - start, axis=1) / np.linalg.norm(end - start, axis=1))
    order = np.lexsort((t, k, p))
    return p[order], v[order]


def _fans(verts, source_tris, fan, p, v) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(verts, tris, parent)``: the ``fan`` source triangles as fans from a new centre vertex each (appended to
    ``verts``) over their rings ``p``, ``v`` (:func:`_rings`)."""
    if not fan.any():
        return verts, np.zeros((0, 3), np.int64), np.zeros(0, np.int64)
    at_fan = fan[p]
    fp, fv = p[at_fan], v[at_fan]
    centre_of = np.full(len(source_tris), -1, dtype=np.int64)
    fan_rows = np.flatnonzero(fan)
    centre_of[fan_rows] = len(verts) + np.arange(len(fan_rows))
    centres = verts[source_tris[fan_rows]].astype(np.float64).mean(axis=1).astype(np.float32)
    first = np.r_[True, fp[1:] != fp[:-1]]
    group_start = np.maximum.accumulate(np.where(first, np.arange(len(fp)), 0))
    last = np.r_[fp[1:] != fp[:-1], True]
    nxt = np.where(last, group_start, np.arange(len(fp)) + 1)
    return np.concatenate([verts, centres]), np.stack([centre_of[fp], fv, fv[nxt]], axis=1), fp


def straighten_borders(verts, tris, keep, parent, n_source: int, tolerance: float, longest: float = np.inf):
    """Collapse the kept region's border vertices that lie on a straight run of it inside one source triangle into
    the border vertex before them: a border that follows a line of pieces cut across a sliver keeps that line's two
    ends rather than every piece's corner on it (the strips along it get as many vertices fewer). Kept triangles only;
    a source vertex stays, and so does a vertex whose collapse would turn a triangle over or join two edges.

    Args:
        verts: (V, 3) float32; tris: (T, 3) int64 pieces; keep: (T,) bool; parent: (T,) int64 their source
            triangles; n_source: the source's vertex count (vertices below it stay); tolerance: how far off the
            line through its border neighbours a vertex may lie; longest: the longest border edge a collapse makes.
    Returns:
        ``(tris, rows)``: the triangles left and (T',) int64 the row of ``tris`` each stands in.
    """
    tris = np.array(tris, dtype=np.int64)
    keep = np.asarray(keep, dtype=bool)
    # only kept triangles at a vertex of a piece with a midpoint are read (the edges at a midpoint, and the edges a
    # collapse could join to): the others are set aside, unchanged
    near = np.zeros(len(verts), dtype=bool)
    near[tris[keep & (tris >= n_source).any(axis=1)].ravel()] = True
    read = np.flatnonzero(keep & any_corner(near, tris))
    if not len(read):
        return tris, np.arange(len(tris), dtype=np.int64)
    aside = set_aside(tris, read)
    # on the vertices the triangles read use (in the order of their indices: the source's first), so that a round's
    # per-vertex arrays are as long as those, not as the leaf's every piece's (bunny with spot 7.7 -> 5.7 ms)
    used, local = compacted(tris[read], len(verts))
    tris, rows, keep, parent = local, read, keep[read], parent[read]
    v64 = verts[used].astype(np.float64)
    ranks = (position_hash(verts[used]).astype(np.int64) << 32) | used  # (:func:`position_ranks` of every vertex)
    n_source = int(np.searchsorted(used, n_source))
    for _ in range(64):
        moves = _border_collapses(v64, tris, parent, n_source, (tolerance, longest), ranks)
        if moves is None:
            break
        face, target, drop = moves
        tris[face] = target
        alive = np.ones(len(tris), dtype=bool)
        alive[face[drop]] = False
        tris, rows, parent = tris[alive], rows[alive], parent[alive]
    return put_back(used[tris], rows, aside)


def _border_collapses(v64, tris, parent, n_source: int, bounds: tuple, ranks: np.ndarray):
    """One round of :func:`straighten_borders` over the kept triangles: ``(faces, their new corners, dropped)``, or
    None when no vertex can go."""
    n = len(v64)
    if not len(tris):
        return None
    a, b = tris.ravel(), tris[:, [1, 2, 0]].ravel()
    # each edge once, undirected, with its way as the lowest bit, in one sort: a border edge is one whose key's run
    # holds one way only (its twin, the other way, is no triangle's); the runs' keys are the undirected edges
    keys = np.sort(2 * (np.minimum(a, b) * n + np.maximum(a, b)) + (a > b))
    undirected = keys >> 1
    start = np.flatnonzero(np.r_[True, undirected[1:] != undirected[:-1]])
    last = np.r_[start[1:], len(keys)] - 1
    both = (keys[start] & 1) != (keys[last] & 1)
    border = ~np.repeat(both, last - start + 1)
    low, high, way = undirected[border] // n, undirected[border] % n, keys[border] & 1
    tail, head = np.where(way == 1, high, low), np.where(way == 1, low, high)  # (way 1: the edge runs high -> low)
    out_count, in_count = np.bincount(tail, minlength=n), np.bincount(head, minlength=n)
    prev = np.full(n, -1, dtype=np.int64)
    nxt = np.full(n, -1, dtype=np.int64)
    prev[head], nxt[tail] = tail, head
    flat, owner = tris.ravel(), np.repeat(parent, 3)
    some = np.full(n, -1, dtype=np.int64)  # one source triangle of each vertex's pieces; any other marks it
    some[flat] = owner
    one_parent = some >= 0
    one_parent[flat[owner != some[flat]]] = False
    one_run = (out_count == 1) & (in_count == 1) & one_parent & (np.arange(n) >= n_source)
    v = np.flatnonzero(one_run)
    u, w = prev[v], nxt[v]
    d0, d1 = v64[v] - v64[u], v64[w] - v64[v]
    cross = np.linalg.norm(np.cross(d0, d1), axis=1)
    tolerance, longest = bounds
    run = np.linalg.norm(d0 + d1, axis=1)
    straight = (cross <= tolerance * run) & (np.einsum("ij,ij->i", d0, d1) > 0) & (run <= longest)
    go = np.zeros(n, dtype=bool)
    go[v[straight]] = True
    into = np.full(n, -1, dtype=np.int64)
    into[v[straight]] = u[straight]
    at_v = np.flatnonzero(go[tris.ravel()])
    if not len(at_v):
        return None
    face, vert = at_v // 3, tris.ravel()[at_v]
    target = np.where(tris[face] == vert[:, None], into[vert][:, None], tris[face])
    at_face, into_v = tris[face], into[vert]
    drop = (at_face[:, 0] == into_v) | (at_face[:, 1] == into_v) | (at_face[:, 2] == into_v)
    bad = ~drop & turned_over(v64, tris[face], target)
    # the link condition: a moved face's other corners must not be joined to the target already (but through the
    # dropped face)
    edge_keys = undirected[start]
    dropped = np.full((n, 3), -1, dtype=np.int64)  # the corners of the face each vertex drops
    dropped[vert[drop]] = tris[face[drop]]
    dropped = dropped[vert]
    for k in range(3):
        other = target[:, k]
        key = np.minimum(other, into[vert]) * n + np.maximum(other, into[vert])
        found = edge_keys[np.minimum(np.searchsorted(edge_keys, key), len(edge_keys) - 1)] == key
        in_dropped = (dropped == other[:, None]).any(axis=1)  # joined to the target through that face
        bad |= ~drop & found & (other != into[vert]) & ~in_dropped
    ok = np.bincount(vert[drop], minlength=n) == 1  # one face dropped: the border edge's own
    ok[vert[bad]] = False
    win = claims_won(face, vert, ok[vert], len(tris), ranks)
    if not win.any():
        return None
    return face[win], target[win], drop[win]
