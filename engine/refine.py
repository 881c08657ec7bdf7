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
import warp as wp

# ---- samples ----


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
    a = verts[tris[t, 0]]
    b = verts[tris[t, 1]]
    c = verts[tris[t, 2]]
    base = wp.length(b - a)
    height = wp.length(wp.cross(b - a, c - a)) / wp.max(base, 1.0e-30)
    rows = wp.max(int(wp.ceil(height / spacing)), 1)
    n = int(0)
    for r in range(rows):
        along = (1.0 - float(r) / float(rows)) * base
        n += wp.max(int(wp.ceil(along / spacing)), 1) + 1
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
    base = wp.length(b - a)
    height = wp.length(wp.cross(b - a, c - a)) / wp.max(base, 1.0e-30)
    rows = wp.max(int(wp.ceil(height / spacing)), 1)
    out = first[t]
    for r in range(rows):
        s = float(r) / float(rows)
        start = a + s * (c - a)
        end = b + s * (c - b)
        steps = wp.max(int(wp.ceil((1.0 - s) * base / spacing)), 1)
        for k in range(steps + 1):
            corner = r == 0 and (k == 0 or k == steps)
            if not corner:
                points[out] = start + (float(k) / float(steps)) * (end - start)
                out += 1


def longest_first(verts: np.ndarray, tris: np.ndarray) -> np.ndarray:
    """``tris`` with each triangle's corners turned (order kept) so that its longest edge runs from corner 0 to 1."""
    e = verts[tris[:, [1, 2, 0]]].astype(np.float64) - verts[tris].astype(np.float64)
    k = np.argmax((e**2).sum(axis=2), axis=1)
    cols = (np.arange(3)[None, :] + k[:, None]) % 3
    return np.take_along_axis(tris, cols, axis=1)


def triangle_samples(verts: np.ndarray, tris: np.ndarray, spacing: np.ndarray, device):
    """Points on every triangle no farther than about its ``spacing`` from any of its points: the vertices, and on
    larger triangles rows of points (:func:`_row_samples_kernel`).

    Args:
        verts: (V, 3) float32; tris: (T, 3) int; spacing: (T,) float, each triangle's.
    Returns:
        ``(points, first)``: (V + G, 3) float32, the V vertices first, then each triangle's own samples, the (T + 1,)
        int64 offsets of the triangles' own among the G after the vertices.
    """
    turned = np.ascontiguousarray(longest_first(verts, tris), dtype=np.int32)
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
    """(T,) the least of ``values`` (one per sample of :func:`triangle_samples`) over each triangle's samples."""
    least = values[:n_verts][tris].min(axis=1)
    own = np.flatnonzero(first[1:] > first[:-1])
    if len(own):
        lows = np.minimum.reduceat(values[n_verts:], first[own])
        least[own] = np.minimum(least[own], lows)
    return least


# ---- splitting ----
def split_triangles(verts: np.ndarray, tris: np.ndarray, split: np.ndarray):
    """Split the longest edge of each ``split`` triangle at its midpoint, in every triangle that has that edge
    (longest-edge bisection, Rivara's: pieces keep their shape where splitting every edge would keep a sliver's).

    Args:
        verts: (V, 3) float32; tris: (T, 3) int64; split: (T,) bool.
    Returns:
        ``(verts, tris, origin, ends)``: the vertices with the midpoints appended, the new triangles, (T',) int64 the
        triangle of ``tris`` each new one lies in, and (M, 2) int64 the edge each midpoint splits.
    """
    t = np.asarray(tris, dtype=np.int64)
    n = len(verts)
    a, b = t.ravel(), t[:, [1, 2, 0]].ravel()
    keys = np.minimum(a, b) * n + np.maximum(a, b)
    e = verts[t[:, [1, 2, 0]]].astype(np.float64) - verts[t].astype(np.float64)
    longest = np.argmax((e**2).sum(axis=2), axis=1)
    rows = np.flatnonzero(split)
    marked_keys = np.unique(keys.reshape(-1, 3)[rows, longest[rows]])
    at = np.searchsorted(marked_keys, keys)
    at_ok = np.minimum(at, max(len(marked_keys) - 1, 0))
    marked = (at < len(marked_keys)) & (marked_keys[at_ok] == keys) if len(marked_keys) else np.zeros(len(keys), bool)
    mids = np.where(marked, n + at_ok, -1).reshape(-1, 3)  # the midpoint of each triangle's edge k (corner k -> k+1)
    lo, hi = marked_keys // n, marked_keys % n
    new_verts = (0.5 * (verts[lo].astype(np.float64) + verts[hi].astype(np.float64))).astype(np.float32)
    pattern = (mids >= 0).sum(axis=1)
    parts, origin = [], []

    none = np.flatnonzero(pattern == 0)
    parts.append(t[none])
    origin.append(none)
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


def _turned(rows: np.ndarray, k: np.ndarray) -> np.ndarray:
    cols = (np.arange(3)[None, :] + k[:, None]) % 3
    return np.take_along_axis(rows, cols, axis=1)


def _emit(parts: list, origin: list, rows: np.ndarray, corners: list) -> None:
    for c in corners:
        parts.append(np.stack(c, axis=1))
        origin.append(rows)


def merge_kept(tris: np.ndarray, keep: np.ndarray, ends: np.ndarray):
    """Undo the splits inside kept regions: a midpoint whose four triangles are all kept is removed, its edge's two
    halves joined again on either side (the two triangles on one side become one: the midpoint lies on the edge, so
    the joined triangle covers the same plane and faces the same way). Midpoints along a kept region's border stay.

    Args:
        tris: (T, 3) int64 triangles after :func:`split_triangles`; keep: (T,) bool; ends: (V, 2) int64 the edge each
            vertex splits (-1 for the original vertices).
    Returns:
        ``(tris, rows)``: the triangles left (joined ones in place of one of their halves) and (T',) int64 the row of
        ``tris`` each stands in (its parent, its verdict).
    """
    tris = np.array(tris, dtype=np.int64)
    rows = np.arange(len(tris), dtype=np.int64)
    keep = np.asarray(keep, dtype=bool)
    for _ in range(256):
        flat = tris.ravel()
        valence = np.bincount(flat, minlength=len(ends))
        kept_valence = np.bincount(flat[np.repeat(keep, 3)], minlength=len(ends))
        candidate = (ends[:, 0] >= 0) & (valence == 4) & (kept_valence == 4)
        if not candidate.any():
            break
        at = np.flatnonzero(candidate[flat])
        order = np.argsort(flat[at], kind="stable")
        mid, face = flat[at][order].reshape(-1, 4), (at[order] // 3).reshape(-1, 4)
        corners = tris[face]  # (C, 4, 3)
        has_a = (corners == ends[mid, 0][:, :, None]).any(axis=2)
        has_b = (corners == ends[mid, 1][:, :, None]).any(axis=2)
        ok = ((has_a ^ has_b).all(axis=1)) & (has_a.sum(axis=1) == 2)
        claim = np.full(len(tris), np.iinfo(np.int64).max, dtype=np.int64)
        np.minimum.at(claim, face[ok].ravel(), np.repeat(mid[ok, 0], 4))
        win = ok & (claim[face] == mid[:, :1]).all(axis=1)
        if not win.any():
            break
        grow, drop = face[win][has_a[win]], face[win][has_b[win]]
        m = np.repeat(mid[win, 0], 2)
        b = np.repeat(ends[mid[win, 0], 1], 2)
        tris[grow] = np.where(tris[grow] == m[:, None], b[:, None], tris[grow])
        alive = np.ones(len(tris), dtype=bool)
        alive[drop] = False
        tris, rows, keep = tris[alive], rows[alive], keep[alive]
    return tris, rows
