"""The edges the adaptivity's clustering joins along (engine/blockedges.py, Warp): the seams held and each edge's
level, against the rules spelled out edge by edge in Python on random faces."""

import numpy as np
import pytest

from engine.blockedges import NEVER, edge_levels


def reference(corners, cls, label, lines, cell):
    """The rules one edge at a time: seams held (cls 0 in place), then (u, v, joins) in the faces' order."""
    edges = [(a, b) for row in corners.tolist() for a, b in zip(row, row[1:] + row[:1], strict=True) if a < b]
    by_crease = np.zeros(len(cls), dtype=bool)
    for a, b in edges:
        if cls[a] != 1 or cls[b] != 1:
            by_crease[a] = by_crease[b] = True
    hold = np.zeros(len(cls), dtype=bool)
    for a, b in edges:
        if label[a] != label[b]:
            operands = (label[a] >> 32) != (label[b] >> 32)
            if not (operands and (by_crease[a] or by_crease[b])):
                hold[a] = hold[b] = True
    cls[hold] = 0
    crease = {tuple(sorted(e)) for e in lines.tolist()}
    out = []
    for a, b in edges:
        if cls[a] <= 0 or cls[b] <= 0:
            continue
        same = label[a] == label[b]
        along = cls[a] == 2 and cls[b] == 2 and (a, b) in crease
        joinable = cls[a] == cls[b] and (
            (cls[a] == 1 and same) or (along and (same or (label[a] >> 32) != (label[b] >> 32)))
        )
        differ = int(np.bitwise_or.reduce(cell[a] ^ cell[b]))
        joins = NEVER if not joinable else (63 if differ < 0 else differ.bit_length())
        out.append((a, b, joins))
    return np.array(out, dtype=np.int64).reshape(-1, 3)


@pytest.mark.parametrize("seed", range(4))
def test_edge_levels_follow_the_rules_edge_by_edge(seed):
    rng = np.random.default_rng(seed)
    n, p = 300, 500
    corners = np.stack([rng.permutation(n)[:4] for _ in range(p)]).astype(np.int32)
    corners[: p // 3, 3] = corners[: p // 3, 2]  # triangles: the last corner repeated
    # two operands (the high 32 bits), two regions of the first: seams between operands and within one
    label = (rng.integers(0, 2, n).astype(np.int64) << 32) + rng.integers(0, 2, n) * (rng.random(n) < 0.2)
    row_ends = corners[:, [0, 1]]  # crease lines: some face edges, some not
    lines = np.concatenate([row_ends[rng.random(p) < 0.3], rng.integers(0, n, (40, 2))])
    lines = lines[lines[:, 0] != lines[:, 1]]
    # smooth, corners, and inside a crease line (of two crease edges, as adaptive's classes give them)
    cls = rng.choice(np.array([0, 1, 1, 1, 2, 2], dtype=np.int8), n)
    cls[(cls == 2) & (np.bincount(lines.ravel(), minlength=n) != 2)] = 1
    cell = rng.integers(-1, 40, (n, 3)).astype(np.int64)  # a few negative: never a block of the others'
    held_before, expected_cls = cls.copy(), cls.copy()
    expected = reference(corners, expected_cls, label, lines, cell)
    u, v, joins = edge_levels(corners, cls, label, lines, cell)
    assert np.array_equal(cls, expected_cls)
    assert np.array_equal(np.stack([u, v, joins], axis=1), expected)
    # the rules' branches met: vertices held at seams, edges that never join, levels of several blocks, of two signs
    assert (cls == 0).sum() > (held_before == 0).sum()
    assert (joins == NEVER).any() and (joins == 63).any() and len(np.unique(joins)) > 4
