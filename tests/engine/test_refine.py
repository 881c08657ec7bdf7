"""The collapses of split pieces (engine/refine.py): which of the candidates collapse in a round, which faces a
collapse turns over, and the rows set aside and put back around them."""

import numpy as np

from engine.refine import claims_won, position_ranks, put_back, set_aside, turned_over


def _strip(n: int):
    """A strip of triangles along a straight border run: vertices 0..n on y = 0 (numbered in a row, as a run of
    midpoints is), n+1..2n+1 on y = 1."""
    x = np.arange(n + 1, dtype=np.float32)
    verts = np.concatenate([np.stack([x, 0 * x, 0 * x], 1), np.stack([x, 0 * x + 1, 0 * x], 1)])
    low, high = np.arange(n), np.arange(n) + n + 1
    tris = np.concatenate([np.stack([low, low + 1, high], 1), np.stack([low + 1, high + 1, high], 1)])
    return verts, tris


def test_claims_ranked_by_position_let_many_of_a_run_go_at_once_and_no_two_share_a_face():
    n = 200
    verts, tris = _strip(n)
    run = np.arange(1, n)  # the run's inner vertices, each wanting to change every face it is in
    at = np.flatnonzero(np.isin(tris, run))
    face, vert = at // 3, tris.ravel()[at]
    use = np.ones(len(face), dtype=bool)
    won = claims_won(face, vert, use, len(tris), position_ranks(verts))
    winners = np.unique(vert[won])
    # measured: 39 of the 199 (about one in five); ranked by index only the run's first goes
    assert len(winners) > n // 8, len(winners)
    by_index = claims_won(face, vert, use, len(tris), np.arange(len(verts), dtype=np.int64))
    assert len(np.unique(vert[by_index])) == 1
    # a winner holds every face it changes: no face has two winners
    faces_of_winners = face[won]
    assert len(np.unique(faces_of_winners)) == len(faces_of_winners)
    # and every face a winning vertex changes is its
    assert won[np.isin(vert, winners)].all()


def test_turned_over_is_the_cross_product_test_bit_for_bit():
    rng = np.random.default_rng(3)
    points = rng.random((500, 3))
    before = rng.integers(0, 500, (4000, 3))
    after = before.copy()
    after[:, 0] = rng.integers(0, 500, 4000)  # a corner moved
    after[:10] = before[:10, [0, 2, 1]]  # turned over for sure
    old = np.cross(points[before[:, 1]] - points[before[:, 0]], points[before[:, 2]] - points[before[:, 0]])
    new = np.cross(points[after[:, 1]] - points[after[:, 0]], points[after[:, 2]] - points[after[:, 0]])
    area = np.linalg.norm(old, axis=1)
    expected = np.einsum("ij,ij->i", old, new) <= 1e-6 * area * area
    got = turned_over(points, before, after)
    assert np.array_equal(got, expected)
    assert got[:10].all() and 0 < got.sum() < len(got)


def test_rows_set_aside_come_back_in_row_order_with_or_without_repeats():
    tris = np.arange(30).reshape(10, 3)
    read = np.array([1, 4, 5, 8])
    aside = set_aside(tris, read)
    assert np.array_equal(aside[0], [0, 2, 3, 6, 7, 9])
    # the rows read, one taken away (a collapse), back among the others in row order
    kept = np.array([0, 2, 3])
    back, rows = put_back(tris[read][kept], read[kept], aside)
    assert np.array_equal(rows, [0, 1, 2, 3, 5, 6, 7, 8, 9])
    assert np.array_equal(back, tris[rows])
    # a row standing in twice keeps its order (a stable sort)
    twice = np.array([[100, 101, 102], [103, 104, 105]])
    back, rows = put_back(twice, np.array([4, 4]), aside)
    assert np.array_equal(rows, [0, 2, 3, 4, 4, 6, 7, 9])
    assert np.array_equal(back[3:5], twice)
