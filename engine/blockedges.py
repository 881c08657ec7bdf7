"""The edges the adaptivity's clustering joins vertices along (:mod:`.adaptive`'s steps 1 and 2), in Warp.

Each undirected edge of the faces (their corners (P, 4), a triangle's last corner repeated: the edge from each corner
to the next where the first is the smaller, once per edge of a closed, oriented surface) is looked at by one thread,
in three launches over the faces' corners:

1. the vertices next to a crease or corner vertex (or one themselves);
2. the vertices along a seam between two source regions held (made corners, never merging), except where two
   operands meet next to a crease: the crease keeps the seam;
3. for each edge between two vertices that may merge, the level from which it joins its ends: the highest bit its
   ends' cells differ in (the smallest block holding both), or the largest integer where it never joins them (two
   classes, two regions of an operand, or crease vertices not along their crease).

They replace about forty whole-array passes of numpy over the edges; only the edges kept are gathered in numpy.
"""

from __future__ import annotations

import numpy as np
import warp as wp

# A ``joins`` of an edge that never joins its ends (np.iinfo(np.int32).max).
NEVER = wp.constant(2147483647)


@wp.func
def _ends(corners: wp.array2d(dtype=wp.int32), f: int, j: int) -> wp.vec2i:
    """The edge from corner ``j`` of face ``f`` to the next one; (-1, -1) where the first is not the smaller."""
    a = corners[f, j]
    b = corners[f, (j + 1) % 4]
    if a >= b:
        return wp.vec2i(-1, -1)
    return wp.vec2i(a, b)


@wp.kernel(enable_backward=False)
def _mark_by_crease_kernel(
    corners: wp.array2d(dtype=wp.int32), cls: wp.array(dtype=wp.int8), by_crease: wp.array(dtype=wp.int8)
):
    f = wp.tid()
    for j in range(4):
        e = _ends(corners, f, j)
        if e[0] >= 0:
            if cls[e[0]] != wp.int8(1) or cls[e[1]] != wp.int8(1):
                by_crease[e[0]] = wp.int8(1)
                by_crease[e[1]] = wp.int8(1)


@wp.kernel(enable_backward=False)
def _hold_seams_kernel(
    corners: wp.array2d(dtype=wp.int32),
    label: wp.array(dtype=wp.int64),
    by_crease: wp.array(dtype=wp.int8),
    hold: wp.array(dtype=wp.int8),
):
    f = wp.tid()
    for j in range(4):
        e = _ends(corners, f, j)
        if e[0] >= 0:
            la = label[e[0]]
            lb = label[e[1]]
            if la != lb:
                operands = (la >> wp.int64(32)) != (lb >> wp.int64(32))
                near = by_crease[e[0]] != wp.int8(0) or by_crease[e[1]] != wp.int8(0)
                if not (operands and near):
                    hold[e[0]] = wp.int8(1)
                    hold[e[1]] = wp.int8(1)


@wp.func
def _bit_length(d: wp.int64) -> wp.int32:
    """The bits of ``d`` >= 0 up to its highest set one (0 for 0)."""
    x = d
    n = wp.int32(0)
    while x > wp.int64(0):
        x = x >> wp.int64(1)
        n = n + wp.int32(1)
    return n


@wp.func
def _edge_level(
    corners: wp.array2d(dtype=wp.int32),
    cls: wp.array(dtype=wp.int8),
    label: wp.array(dtype=wp.int64),
    neighbours: wp.array2d(dtype=wp.int32),
    cell: wp.array2d(dtype=wp.int64),
    f: int,
    j: int,
    u: wp.array2d(dtype=wp.int32),
    v: wp.array2d(dtype=wp.int32),
) -> wp.int32:
    """The level from which the edge at corner ``j`` of face ``f`` joins its ends (its ends written to ``u``,
    ``v``); -1 for no edge here."""
    e = _ends(corners, f, j)
    if e[0] < 0:
        return wp.int32(-1)
    a = e[0]
    b = e[1]
    ca = cls[a]
    cb = cls[b]
    if ca <= wp.int8(0) or cb <= wp.int8(0):
        return wp.int32(-1)
    u[f, j] = a
    v[f, j] = b
    la = label[a]
    lb = label[b]
    same = la == lb
    along = False  # both inside crease lines: is the edge one of theirs?
    if ca == wp.int8(2) and cb == wp.int8(2):
        along = neighbours[a, 0] == b or neighbours[a, 1] == b
    # smooth vertices of one region; crease vertices along a crease, within one region of an operand (between two
    # operands the crease is their seam, where each vertex's operand is either)
    joinable = False
    if ca == cb:
        joinable = (ca == wp.int8(1) and same) or (along and (same or (la >> wp.int64(32)) != (lb >> wp.int64(32))))
    if not joinable:
        return NEVER
    # the highest bit the ends' cells differ in on any axis (cells of two signs never share a block)
    d = (cell[a, 0] ^ cell[b, 0]) | (cell[a, 1] ^ cell[b, 1]) | (cell[a, 2] ^ cell[b, 2])
    if d < wp.int64(0):
        return wp.int32(63)
    return _bit_length(d)


@wp.kernel(enable_backward=False)
def _edge_levels_kernel(
    corners: wp.array2d(dtype=wp.int32),
    cls: wp.array(dtype=wp.int8),
    label: wp.array(dtype=wp.int64),
    neighbours: wp.array2d(dtype=wp.int32),
    cell: wp.array2d(dtype=wp.int64),
    u: wp.array2d(dtype=wp.int32),
    v: wp.array2d(dtype=wp.int32),
    joins: wp.array2d(dtype=wp.int32),
):
    f = wp.tid()
    for j in range(4):
        joins[f, j] = _edge_level(corners, cls, label, neighbours, cell, f, j, u, v)


def edge_levels(corners, cls, label, lines, cell, device=None):
    """The edges of the faces between vertices that may merge, and the level from which each joins its ends; the
    vertices along a seam between two source regions held first (``cls`` set to 0 there, in place).

    Args:
        corners: (P, 4) int faces (:func:`.adaptive._padded`).
        cls: (V,) int8 vertex classes: 1 smooth, 2 inside a crease line, 0 never merging.
        label: (V,) int64 source region of each vertex (its operand's field id times 2^32 plus a region).
        lines: (L, 2) int the crease edges.
        cell: (V, 3) int64 the lattice cell of each vertex.
        device: Warp device (default: the current one).
    Returns:
        ``u``, ``v`` (E,) int32 the ends of each edge (the first the smaller), ``joins`` (E,) int32 the level from
        which it joins them (NEVER: never).
    """
    device = wp.get_device(device)
    p = len(corners)
    wp_corners = wp.array(np.ascontiguousarray(corners, dtype=np.int32), dtype=wp.int32, device=device)
    wp_label = wp.array(np.ascontiguousarray(label, dtype=np.int64), dtype=wp.int64, device=device)
    wp_cls = wp.array(cls, dtype=wp.int8, device=device)
    if p and label.min() != label.max():  # a seam somewhere
        by_crease = wp.zeros(len(cls), dtype=wp.int8, device=device)
        wp.launch(_mark_by_crease_kernel, dim=p, inputs=[wp_corners, wp_cls, by_crease], device=device)
        hold = wp.zeros(len(cls), dtype=wp.int8, device=device)
        wp.launch(_hold_seams_kernel, dim=p, inputs=[wp_corners, wp_label, by_crease, hold], device=device)
        cls[hold.numpy().astype(bool)] = 0
        wp_cls = wp.array(cls, dtype=wp.int8, device=device)
    out = [wp.empty((p, 4), dtype=wp.int32, device=device) for _ in range(3)]
    neighbours = wp.array(_crease_neighbours(lines, len(cls)), dtype=wp.int32, device=device)
    wp_cell = wp.array(np.ascontiguousarray(cell, dtype=np.int64), dtype=wp.int64, device=device)
    inputs = [wp_corners, wp_cls, wp_label, neighbours, wp_cell]
    wp.launch(_edge_levels_kernel, dim=p, inputs=[*inputs, *out], device=device)
    u, v, joins = (x.numpy().ravel() for x in out)
    kept = np.flatnonzero(joins >= 0)
    return u[kept], v[kept], joins[kept]


def _crease_neighbours(lines, n: int) -> np.ndarray:
    """(n, 2) int32 the two ends of the crease edges ``lines`` (E, 2) at each vertex inside a crease line (-1 where
    none; at a vertex of other degrees any two)."""
    lines = np.asarray(lines).reshape(-1, 2)
    ends = np.concatenate([lines[:, 0], lines[:, 1]])
    order = np.argsort(ends, kind="stable")
    ends, other = ends[order], np.concatenate([lines[:, 1], lines[:, 0]])[order]
    first = np.ones(len(ends), dtype=bool)
    first[1:] = ends[1:] != ends[:-1]
    nb = np.full((n, 2), -1, dtype=np.int32)
    nb[ends[first], 0] = other[first]
    nb[ends[~first], 1] = other[~first]
    return nb
