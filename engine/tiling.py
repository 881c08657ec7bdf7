"""Triangulations of planar polygons, and of polygons with points inside them: the tiles :mod:`.uncross` lays where
new faces passed through others.

- :func:`tiled_polygons`: the triangulation of each polygon whose worst triangle is best (a dynamic program over its
  chords, O(n^3) for n corners), with no chord among those forbidden; none where the polygon is not simple or the
  forbidden chords leave no triangulation. Ear clipping, greedy, gets stuck where forbidden chords block the ears it
  would take.
- :func:`with_points`: points inside each tiled polygon inserted one after another (the tile holding each split in
  three, then Lawson's flips of the edges opposite it where the Delaunay criterion asks and the quadrilateral is
  convex: the polygon's edges never flip); a point on a tile's edge or outside the polygon is left out.

Written by hand: one Warp thread a polygon (they are small, and many); no library in a user's Blender triangulates in
Warp, and a constrained Delaunay library would still need the forbidden chords and the per-polygon batches.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from .parallel import launch_split

# A point is inside a tile where its doubled signed area with each edge is above this (square voxels): a point on an
# edge is left out.
INSIDE = 1.0e-6


@wp.func
def _turn(a: wp.vec2d, b: wp.vec2d, c: wp.vec2d) -> wp.float64:
    """Twice the signed area of (a, b, c): positive counter-clockwise."""
    return (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])


@wp.func
def _chord_clear(plane: wp.array[wp.vec2d], start: int, n: int, i: int, j: int) -> bool:
    """Whether chord i-j of the polygon ``plane[start : start + n]`` (counter-clockwise) lies inside it: it leaves
    both ends into the polygon's inside and neither crosses an edge nor passes through a corner."""
    a = plane[start + i]
    b = plane[start + j]
    zero = wp.float64(0.0)
    for end in range(2):
        at = wp.where(end == 0, i, j)
        to = wp.where(end == 0, b, a)
        p = plane[start + at]
        before = plane[start + (at + n - 1) % n]
        after = plane[start + (at + 1) % n]
        left_out = _turn(p, after, to) > zero
        left_in = _turn(before, p, to) > zero
        if _turn(before, p, after) > zero:
            if not (left_out and left_in):
                return False
        elif not (left_out or left_in):
            return False
    span = wp.length_sq(b - a)
    for e in range(n):
        f = (e + 1) % n
        c = plane[start + e]
        d = plane[start + f]
        if e != i and e != j:
            along = _turn(a, b, c)
            if wp.abs(along) <= wp.float64(1.0e-12) * span and wp.dot(c - a, c - b) < zero:
                return False  # a corner on the chord
        if e == i or e == j or f == i or f == j:
            continue
        if _turn(a, b, c) * _turn(a, b, d) < zero and _turn(c, d, a) * _turn(c, d, b) < zero:
            return False
    return True


@wp.func
def _shape(a: wp.vec2d, b: wp.vec2d, c: wp.vec2d) -> wp.float64:
    """A triangle's shape: its doubled signed area over the sum of its squared edges (negative: turned over)."""
    edges = wp.length_sq(b - a) + wp.length_sq(c - b) + wp.length_sq(a - c)
    return _turn(a, b, c) / wp.max(edges, wp.float64(1.0e-300))


@wp.func
def _mark_chords(
    plane: wp.array[wp.vec2d],
    start: int,
    n: int,
    sq: int,
    forbidden: wp.array[wp.uint8],
    usable: wp.array[wp.uint8],
    best: wp.array[wp.float64],
):
    """A polygon's square of corner pairs i < j: ``usable`` 1 for its edges and the chords inside it not forbidden;
    ``best`` +inf for its edges (no triangle), -1 (none yet) elsewhere."""
    for i in range(n):
        for j in range(i + 1, n):
            ok = j == i + 1 or (i == 0 and j == n - 1)
            if not ok and forbidden[sq + i * n + j] == wp.uint8(0):
                ok = _chord_clear(plane, start, n, i, j)
            usable[sq + i * n + j] = wp.where(ok, wp.uint8(1), wp.uint8(0))
            best[sq + i * n + j] = wp.where(j == i + 1, wp.float64(1.0e300), wp.float64(-1.0))


@wp.func
def _best_splits(
    plane: wp.array[wp.vec2d],
    start: int,
    n: int,
    sq: int,
    usable: wp.array[wp.uint8],
    best: wp.array[wp.float64],
    split: wp.array[wp.int32],
):
    """The dynamic program, shorter spans first: for each usable span i-j, the corner k whose triangle (i, k, j) and
    the spans i-k and k-j triangulated best leave the best worst shape (``best``; ``split`` its k)."""
    none = wp.float64(-1.0)
    for length in range(2, n):
        for i in range(n - length):
            j = i + length
            if usable[sq + i * n + j] == wp.uint8(0):
                continue
            top = none
            arg = int(-1)
            for k in range(i + 1, j):
                if usable[sq + i * n + k] == wp.uint8(0) or usable[sq + k * n + j] == wp.uint8(0):
                    continue
                left = best[sq + i * n + k]
                right = best[sq + k * n + j]
                shape = _shape(plane[start + i], plane[start + k], plane[start + j])
                if left <= none or right <= none or shape <= wp.float64(0.0):
                    continue
                worst = wp.min(shape, wp.min(left, right))
                if worst > top:
                    top = worst
                    arg = k
            best[sq + i * n + j] = top
            split[sq + i * n + j] = arg


@wp.func
def _write_tiles(
    n: int,
    sq: int,
    split: wp.array[wp.int32],
    stack: wp.array[wp.int32],
    top: int,
    row: int,
    tiles: wp.array2d[wp.int32],
):
    """The triangles the splits of span 0-(n - 1) make, read depth first (at most n spans wait on ``stack`` from
    ``top``), written to ``tiles`` from ``row``."""
    stack[top] = 0
    stack[top + 1] = n - 1
    depth = int(1)
    at = row
    while depth > 0:
        depth -= 1
        i = stack[top + 2 * depth]
        j = stack[top + 2 * depth + 1]
        if j - i < 2:
            continue
        k = split[sq + i * n + j]
        tiles[at, 0] = i
        tiles[at, 1] = k
        tiles[at, 2] = j
        at += 1
        stack[top + 2 * depth] = i
        stack[top + 2 * depth + 1] = k
        stack[top + 2 * depth + 2] = k
        stack[top + 2 * depth + 3] = j
        depth += 2


@wp.kernel(enable_backward=False)
def _tile_loops_kernel(
    plane: wp.array[wp.vec2d],
    starts: wp.array[wp.int32],
    sizes: wp.array[wp.int32],
    square_starts: wp.array[wp.int32],
    forbidden: wp.array[wp.uint8],
    offset: int,
    usable: wp.array[wp.uint8],
    best: wp.array[wp.float64],
    split: wp.array[wp.int32],
    stack: wp.array[wp.int32],
    tiles: wp.array2d[wp.int32],
    tiled: wp.array[wp.uint8],
):
    """Per loop: the triangulation of its polygon (``plane``, counter-clockwise) whose worst shape is best, with no
    chord ``forbidden`` (per pair of corners, row-major in the loop's square), its n - 2 triangles of corner indices
    written to ``tiles`` from row ``starts[loop] - 2 * loop``; ``tiled`` 0 where there is none."""
    loop = wp.tid() + offset
    start = starts[loop]
    n = sizes[loop]
    sq = square_starts[loop]
    _mark_chords(plane, start, n, sq, forbidden, usable, best)
    _best_splits(plane, start, n, sq, usable, best, split)
    ok = best[sq + n - 1] > wp.float64(-1.0)
    tiled[loop] = wp.where(ok, wp.uint8(1), wp.uint8(0))
    if ok:
        _write_tiles(n, sq, split, stack, 2 * start, start - 2 * loop, tiles)


def tiled_polygons(plane, starts, sizes, forbidden, device) -> tuple[np.ndarray, np.ndarray]:
    """Triangulations of polygons: ``plane`` (N, 2) float64 their corners one polygon after another, counter-clockwise
    (``starts``, ``sizes``), ``forbidden`` (sum of sizes squared,) uint8 per pair of a polygon's corners, row-major: 1
    where no tile may join them. Returns each polygon's tiles ((N - 2 P, 3) int64 corner indices within their polygon,
    polygon after polygon, n - 2 each) and (P,) bool whether it has them (:func:`_tile_loops_kernel`)."""
    square = sizes * sizes
    arrays = {
        "plane": wp.array(plane, dtype=wp.vec2d, device=device),
        "starts": wp.array(starts.astype(np.int32), dtype=wp.int32, device=device),
        "sizes": wp.array(sizes.astype(np.int32), dtype=wp.int32, device=device),
        "square_starts": wp.array((np.cumsum(square) - square).astype(np.int32), dtype=wp.int32, device=device),
        "forbidden": wp.array(forbidden, dtype=wp.uint8, device=device),
    }
    cells = int(square.sum())
    usable = wp.zeros(cells, dtype=wp.uint8, device=device)
    best = wp.zeros(cells, dtype=wp.float64, device=device)
    split = wp.zeros(cells, dtype=wp.int32, device=device)
    stack = wp.zeros(2 * len(plane), dtype=wp.int32, device=device)
    tiles = wp.zeros((len(plane) - 2 * len(sizes), 3), dtype=wp.int32, device=device)
    tiled = wp.zeros(len(sizes), dtype=wp.uint8, device=device)
    outputs = [usable, best, split, stack, tiles, tiled]
    launch_split(_tile_loops_kernel, len(sizes), lambda lo, _n: [*arrays.values(), lo, *outputs], device, min_dim=2)
    return tiles.numpy().astype(np.int64), tiled.numpy() > 0


@wp.func
def _corner(plane: wp.array[wp.vec2d], start: int, n: int, inner: wp.array[wp.vec2d], inner_start: int, k: int):
    """Point ``k`` of a polygon and its inner points: its corners first, then the points inside."""
    if k < n:
        return plane[start + k]
    return inner[inner_start + k - n]


@wp.func
def _in_circle(a: wp.vec2d, b: wp.vec2d, c: wp.vec2d, d: wp.vec2d) -> wp.float64:
    """Positive where ``d`` lies inside the circle through the counter-clockwise triangle (a, b, c)."""
    ax = a[0] - d[0]
    ay = a[1] - d[1]
    bx = b[0] - d[0]
    by = b[1] - d[1]
    cx = c[0] - d[0]
    cy = c[1] - d[1]
    return (
        (ax * ax + ay * ay) * (bx * cy - cx * by)
        - (bx * bx + by * by) * (ax * cy - cx * ay)
        + (cx * cx + cy * cy) * (ax * by - bx * ay)
    )


@wp.func
def _tile_with(tiles: wp.array2d[wp.int32], first: int, count: int, u: int, v: int) -> int:
    """The tile among rows ``first`` .. ``first + count - 1`` with the directed edge u -> v (-1 if none)."""
    for t in range(first, first + count):
        for e in range(3):
            if tiles[t, e] == u and tiles[t, (e + 1) % 3] == v:
                return t
    return -1


@wp.func
def _third(tiles: wp.array2d[wp.int32], t: int, u: int, v: int) -> int:
    """Tile ``t``'s corner that is neither u nor v."""
    for e in range(3):
        if tiles[t, e] != u and tiles[t, e] != v:
            return tiles[t, e]
    return -1


@wp.func
def _holding(
    plane: wp.array[wp.vec2d],
    start: int,
    n: int,
    inner: wp.array[wp.vec2d],
    inner_start: int,
    tiles: wp.array2d[wp.int32],
    first: int,
    count: int,
    x: wp.vec2d,
) -> int:
    """The tile among rows ``first`` .. ``first + count - 1`` that holds ``x`` strictly inside (-1 if none)."""
    eps = wp.float64(INSIDE)
    for t in range(first, first + count):
        a = _corner(plane, start, n, inner, inner_start, tiles[t, 0])
        b = _corner(plane, start, n, inner, inner_start, tiles[t, 1])
        c = _corner(plane, start, n, inner, inner_start, tiles[t, 2])
        if _turn(a, b, x) > eps and _turn(b, c, x) > eps and _turn(c, a, x) > eps:
            return t
    return -1


@wp.func
def _legalised(
    plane: wp.array[wp.vec2d],
    start: int,
    n: int,
    inner: wp.array[wp.vec2d],
    inner_start: int,
    tiles: wp.array2d[wp.int32],
    first: int,
    count: int,
    q: int,
    stack: wp.array[wp.int32],
    base: int,
    room: int,
    depth_: int,
):
    """Lawson's flips about the point ``q`` just inserted: each edge u-v on ``stack`` (its tile u, v, q) flipped to
    q-w where the tile across it (v, u, w) has w inside the circle of (u, v, q) and the quadrilateral is convex; the
    new edges u-w and w-v pushed in turn. A polygon edge has no tile across."""
    depth = depth_
    x = _corner(plane, start, n, inner, inner_start, q)
    while depth > 0:
        depth -= 1
        u = stack[base + 2 * depth]
        v = stack[base + 2 * depth + 1]
        across = _tile_with(tiles, first, count, v, u)
        if across < 0:
            continue
        w = _third(tiles, across, v, u)
        pu = _corner(plane, start, n, inner, inner_start, u)
        pv = _corner(plane, start, n, inner, inner_start, v)
        pw = _corner(plane, start, n, inner, inner_start, w)
        zero = wp.float64(0.0)
        if _in_circle(pu, pv, x, pw) <= zero or _turn(x, pu, pw) <= zero or _turn(x, pw, pv) <= zero:
            continue
        here = _tile_with(tiles, first, count, u, v)
        tiles[here, 0] = u
        tiles[here, 1] = w
        tiles[here, 2] = q
        tiles[across, 0] = w
        tiles[across, 1] = v
        tiles[across, 2] = q
        if 2 * depth + 4 <= room:
            stack[base + 2 * depth] = u
            stack[base + 2 * depth + 1] = w
            stack[base + 2 * depth + 2] = w
            stack[base + 2 * depth + 3] = v
            depth += 2


@wp.kernel(enable_backward=False)
def _insert_points_kernel(
    plane: wp.array[wp.vec2d],
    starts: wp.array[wp.int32],
    sizes: wp.array[wp.int32],
    inner: wp.array[wp.vec2d],
    inner_starts: wp.array[wp.int32],
    inner_sizes: wp.array[wp.int32],
    tile_starts: wp.array[wp.int32],
    offset: int,
    tiles: wp.array2d[wp.int32],
    counts: wp.array[wp.int32],
    stack: wp.array[wp.int32],
    inserted: wp.array[wp.uint8],
):
    """Per polygon: its inner points inserted into its tiles (rows ``tile_starts[p]`` on, ``counts[p]`` of them; room
    for two more a point), each in the tile holding it, split in three, then the edges opposite it flipped where the
    Delaunay criterion asks (:func:`_legalised`); ``inserted`` 1 for each point taken. ``stack``: room for 4 entries
    a tile row."""
    p = wp.tid() + offset
    start = starts[p]
    n = sizes[p]
    first = tile_starts[p]
    count = counts[p]
    base = 4 * first
    room = 4 * (n - 2 + 2 * inner_sizes[p])
    for k in range(inner_sizes[p]):
        x = inner[inner_starts[p] + k]
        hold = _holding(plane, start, n, inner, inner_starts[p], tiles, first, count, x)
        if hold < 0:
            continue
        inserted[inner_starts[p] + k] = wp.uint8(1)
        q = n + k
        a = tiles[hold, 0]
        b = tiles[hold, 1]
        c = tiles[hold, 2]
        tiles[hold, 2] = q
        tiles[first + count, 0] = b
        tiles[first + count, 1] = c
        tiles[first + count, 2] = q
        tiles[first + count + 1, 0] = c
        tiles[first + count + 1, 1] = a
        tiles[first + count + 1, 2] = q
        count += 2
        for e in range(3):  # the held tile's edges, opposite the point
            stack[base + 2 * e] = wp.where(e == 0, a, wp.where(e == 1, b, c))
            stack[base + 2 * e + 1] = wp.where(e == 0, b, wp.where(e == 1, c, a))
        _legalised(plane, start, n, inner, inner_starts[p], tiles, first, count, q, stack, base, room, 3)
    counts[p] = count


def with_points(plane, starts, sizes, tiles, tiled, inner, inner_starts, inner_sizes, device) -> tuple:
    """Polygons' tiles (:func:`tiled_polygons`' ``tiles`` and ``tiled``) with points inside them inserted (``inner``
    (M, 2) float64, ``inner_starts`` and ``inner_sizes`` per polygon; :func:`_insert_points_kernel`). Returns the
    tiles ((K, 3) int64 indices among each polygon's corners and then its inner points, polygon after polygon),
    (P,) int64 how many each polygon has (0 where it had none) and (M,) bool which points were inserted."""
    room = np.where(tiled, sizes - 2 + 2 * inner_sizes, 0)
    first = np.cumsum(room) - room
    out = np.zeros((int(room.sum()), 3), dtype=np.int32)
    rows = np.repeat(tiled, sizes - 2)
    take = np.repeat(first[tiled], (sizes - 2)[tiled]) + _ranks(sizes[tiled] - 2)
    out[take] = tiles[rows]
    counts = np.where(tiled, sizes - 2, 0)
    arrays = [
        wp.array(plane, dtype=wp.vec2d, device=device),
        wp.array(starts.astype(np.int32), dtype=wp.int32, device=device),
        wp.array(sizes.astype(np.int32), dtype=wp.int32, device=device),
        wp.array(np.asarray(inner, dtype=np.float64).reshape(-1, 2), dtype=wp.vec2d, device=device),
        wp.array(inner_starts.astype(np.int32), dtype=wp.int32, device=device),
        wp.array(np.where(tiled, inner_sizes, 0).astype(np.int32), dtype=wp.int32, device=device),
        wp.array(first.astype(np.int32), dtype=wp.int32, device=device),
    ]
    out_wp = wp.array(out, dtype=wp.int32, device=device)
    counts_wp = wp.array(counts.astype(np.int32), dtype=wp.int32, device=device)
    stack = wp.zeros(4 * len(out) + 8, dtype=wp.int32, device=device)
    inserted = wp.zeros(len(inner), dtype=wp.uint8, device=device)
    outputs = [out_wp, counts_wp, stack, inserted]
    launch_split(_insert_points_kernel, len(sizes), lambda lo, _n: [*arrays, lo, *outputs], device, min_dim=2)
    counts = counts_wp.numpy().astype(np.int64)
    keep = _ranks(room) < np.repeat(counts, room)
    return out_wp.numpy()[keep].astype(np.int64), counts, inserted.numpy() > 0


def _ranks(sizes: np.ndarray) -> np.ndarray:
    """0 .. size - 1 for each size, one after another."""
    return np.arange(int(sizes.sum())) - np.repeat(np.cumsum(sizes) - sizes, sizes)
