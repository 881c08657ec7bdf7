"""Samples on triangles about a given spacing apart: the corners, and rows of points parallel to the longest edge.

The judge (:mod:`.keep`, :mod:`.judging`) reads a triangle at these samples; its fused path walks them in its own
kernel (:func:`row_grid`, :func:`row_steps`, :func:`row_point`), its general path and the checks of a strip across a
hole (:mod:`.slits`) place them (:func:`triangle_samples`) and reduce readings over each triangle's
(:func:`per_triangle_min`).

Written by hand: the rows are a few lines of Warp; no library samples triangles at a spacing.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from .trimeasures import CHUNK_ROWS


@wp.func
def row_grid(a: wp.vec3, b: wp.vec3, c: wp.vec3, spacing: float) -> wp.vec2:
    """(the edge from a to b's length, how many rows parallel to it cover the triangle ``spacing`` apart)."""
    base = wp.length(b - a)
    height = wp.length(wp.cross(b - a, c - a)) / wp.max(base, 1.0e-30)
    return wp.vec2(base, float(wp.max(int(wp.ceil(height / spacing)), 1)))


@wp.func
def row_steps(s: float, base: float, spacing: float) -> int:
    """How many steps of at most ``spacing`` the row ``s`` of the way from edge a-b to corner c takes."""
    return wp.max(int(wp.ceil((1.0 - s) * base / spacing)), 1)


@wp.func
def row_point(a: wp.vec3, b: wp.vec3, c: wp.vec3, s: float, k: int, steps: int) -> wp.vec3:
    """Sample ``k`` of ``steps`` along the row ``s`` of the way from edge a-b to corner c."""
    start = a + s * (c - a)
    end = b + s * (c - b)
    return start + (float(k) / float(steps)) * (end - start)


@wp.kernel(enable_backward=False)
def _row_counts_kernel(
    verts: wp.array[wp.vec3],
    tris: wp.array2d[wp.int32],
    spacings: wp.array[wp.float32],
    counts: wp.array[wp.int32],
):
    """How many samples :func:`_row_samples_kernel` puts on each triangle besides its corners."""
    t = wp.tid()
    spacing = spacings[t]
    grid = row_grid(verts[tris[t, 0]], verts[tris[t, 1]], verts[tris[t, 2]], spacing)
    rows = int(grid[1])
    n = int(0)
    for r in range(rows):
        n += row_steps(float(r) / float(rows), grid[0], spacing) + 1
    counts[t] = n - 2  # rows 0..rows-1, less corners a and b (c, row ``rows``, is not among them)


@wp.kernel(enable_backward=False)
def _row_samples_kernel(
    verts: wp.array[wp.vec3],
    tris: wp.array2d[wp.int32],
    spacings: wp.array[wp.float32],
    first: wp.array[wp.int32],
    points: wp.array[wp.vec3],
):
    """Rows parallel to the edge from corner 0 to corner 1 (the longest), no farther apart than ``spacing``, each
    sampled no farther apart than ``spacing``; the corners left out."""
    t = wp.tid()
    spacing = spacings[t]
    a = verts[tris[t, 0]]
    b = verts[tris[t, 1]]
    c = verts[tris[t, 2]]
    grid = row_grid(a, b, c, spacing)
    rows = int(grid[1])
    out = first[t]
    for r in range(rows):
        s = float(r) / float(rows)
        steps = row_steps(s, grid[0], spacing)
        for k in range(steps + 1):
            if r > 0 or (k > 0 and k < steps):
                points[out] = row_point(a, b, c, s, k, steps)
                out += 1


def edge_turns(verts: np.ndarray, tris: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(T,) float64 each triangle's longest edge, (T,) int64 the corner it starts at (edge k: corner k to k + 1);
    :data:`.trimeasures.CHUNK_ROWS` triangles at a time (the passes' temporaries stay in the cache)."""
    if len(tris) <= CHUNK_ROWS:
        return _edge_turns(verts, tris)
    parts = [_edge_turns(verts, tris[k : k + CHUNK_ROWS]) for k in range(0, len(tris), CHUNK_ROWS)]
    return np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts])


def _edge_turns(verts: np.ndarray, tris: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    at = [[verts[tris[:, k], j].astype(np.float64) for j in range(3)] for k in range(3)]
    d = [[at[(k + 1) % 3][j] - at[k][j] for j in range(3)] for k in range(3)]
    s = [(x * x + y * y) + z * z for x, y, z in d]  # as numpy adds a 3-long axis, which it reduces slowly
    turn = np.where((s[0] >= s[1]) & (s[0] >= s[2]), 0, np.where(s[1] >= s[2], 1, 2))  # argmax's first largest
    return np.sqrt(np.choose(turn, s)), turn


def triangle_samples(verts: np.ndarray, tris: np.ndarray, spacing: np.ndarray, device):
    """Points on every triangle no farther than about its ``spacing`` from any of its points: the vertices, and on
    larger triangles rows of points (:func:`_row_samples_kernel`).

    Args:
        verts: (V, 3) float32; tris: (T, 3) int; spacing: (T,) float, each triangle's.
    Returns:
        ``(points, first)``: (V + G, 3) float32, the V vertices first, then each triangle's own samples, the (T + 1,)
        int64 offsets of the triangles' own among the G after the vertices.
    """
    cols = (np.arange(3)[None, :] + edge_turns(verts, tris)[1][:, None]) % 3  # the longest edge from corner 0 to 1
    turned = np.ascontiguousarray(np.take_along_axis(tris, cols, axis=1), dtype=np.int32)
    v_wp = wp.array(np.ascontiguousarray(verts, dtype=np.float32), dtype=wp.vec3, device=device)
    t_wp = wp.array(turned, dtype=wp.int32, device=device)
    s_wp = wp.array(np.ascontiguousarray(spacing, dtype=np.float32), dtype=wp.float32, device=device)
    counts = wp.empty(len(tris), dtype=wp.int32, device=device)
    if len(tris):
        wp.launch(_row_counts_kernel, len(tris), inputs=[v_wp, t_wp, s_wp, counts], device=device)
    first = np.zeros(len(tris) + 1, dtype=np.int64)
    np.cumsum(counts.numpy(), out=first[1:])
    out = wp.empty(int(first[-1]), dtype=wp.vec3, device=device)
    if first[-1]:
        first_wp = wp.array(first[:-1].astype(np.int32), dtype=wp.int32, device=device)
        wp.launch(_row_samples_kernel, len(tris), inputs=[v_wp, t_wp, s_wp, first_wp, out], device=device)
    points = np.concatenate([np.asarray(verts, dtype=np.float32), out.numpy().reshape(-1, 3)])
    return points, first


def per_triangle_min(values: np.ndarray, tris: np.ndarray, n_verts: int, first: np.ndarray) -> np.ndarray:
    """(T,) the least of ``values`` (one per sample of :func:`triangle_samples`) over each triangle's samples; (T, K)
    for (N, K) values, per column."""
    least = values[:n_verts][tris].min(axis=1)
    own = np.flatnonzero(first[1:] > first[:-1])
    if len(own):
        lows = np.minimum.reduceat(values[n_verts:], first[own], axis=0)
        least[own] = np.minimum(least[own], lows)
    return least


# From this many sign columns on, a triangle's samples are compared by one hash of all the columns (each sample's signs
# weighted by odd 64-bit numbers and summed with wrap-around: equal signs give equal sums, different ones the same sum
# with odds of about 2^-62) instead of column by column (a plate's judge with 100 bores reduced 200 columns a round).
HASHED_FROM = 8
_WEIGHTS = np.random.default_rng(20261206).integers(-(2**62), 2**62, 4096, dtype=np.int64) | 1


def same_all_over(columns: list, tris: np.ndarray, n_verts: int, first: np.ndarray) -> np.ndarray:
    """(T,) bool whether each triangle's samples (:func:`triangle_samples`) hold one value in every one of
    ``columns`` ((N,) int8 each)."""
    if len(columns) < HASHED_FROM or len(columns) > len(_WEIGHTS):
        stacked = np.stack(columns + [-s for s in columns], axis=1)
        low, minus_high = np.split(per_triangle_min(stacked, tris, n_verts, first), 2, axis=1)
        return (low == -minus_high).all(axis=1)
    hashed = np.zeros(len(columns[0]), dtype=np.int64)
    for column, weight in zip(columns, _WEIGHTS, strict=False):
        hashed += column.astype(np.int64) * weight  # (wraps around)
    low, not_high = per_triangle_min(np.stack([hashed, ~hashed], axis=1), tris, n_verts, first).T
    return low == ~not_high
