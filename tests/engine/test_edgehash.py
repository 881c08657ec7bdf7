"""Counting keys through a hash table and directed edges by their first vertex (engine/edgehash.py) against numpy's
sorting, the twin lookups built on it
(a surface's border edges, doubled faces) on meshes with open, doubled and flipped edges, and the weld's grouping of
vertices by position (engine/meshcheck.py) against numpy's unique rows."""

import numpy as np
import pytest

from engine import edgehash
from engine.edgehash import EdgeCounts, KeyCounts, directed_edges
from engine.meshcheck import compacted, position_groups
from engine.zipper import border_halves
from tests.support import box_mesh, uv_sphere


def test_counts_match_numpy_on_random_keys_with_repeats():
    rng = np.random.default_rng(3)
    keys = rng.integers(0, 5_000, size=20_000).astype(np.int64) * 1_000_003  # many repeats, spread high bits
    queries = np.r_[keys[:500], rng.integers(0, 10_000, size=500).astype(np.int64) * 1_000_003]
    values, counts = np.unique(keys, return_counts=True)
    at = np.minimum(np.searchsorted(values, queries), len(values) - 1)
    expected = np.where(values[at] == queries, counts[at], 0)
    assert np.array_equal(KeyCounts(keys).of(queries), expected)
    assert np.array_equal(KeyCounts(np.zeros(0, np.int64)).of(queries), np.zeros(len(queries)))


@pytest.mark.parametrize("degree", [6, 5_000])  # listed by vertex; a fan's apex past MAX_DEGREE: hashed
def test_edge_counts_match_numpy_with_repeats_reverses_and_a_fan(degree):
    rng = np.random.default_rng(degree)
    n = 4_000
    a = rng.integers(0, n, size=6 * n)
    b = (a + rng.integers(1, 9, size=len(a))) % n  # near vertices, some edges repeated, some with their reverse
    a, b = np.r_[a, b[:500], np.zeros(degree, np.int64)], np.r_[b, a[:500], rng.integers(1, n, degree)]
    qa, qb = np.r_[a, b, rng.integers(0, n, 300)], np.r_[b, a, rng.integers(0, n, 300)]
    keys, queries = a * n + b, qa * n + qb
    values, counts = np.unique(keys, return_counts=True)
    at = np.minimum(np.searchsorted(values, queries), len(values) - 1)
    expected = np.where(values[at] == queries, counts[at], 0)
    table = EdgeCounts(a, b, n)
    assert (table.hashed is not None) == (degree > edgehash.MAX_DEGREE)
    assert np.array_equal(table.of(qa, qb), expected)
    assert np.array_equal(table.repeats(), expected[: len(a)]) and np.array_equal(
        table.reverses(), expected[len(a) :][: len(a)]
    )
    few = EdgeCounts(a[:10], b[:10], n)  # fewer edges than vertices: hashed
    assert few.hashed is not None
    assert np.array_equal(
        few.reverses(), [np.sum((a[:10] == y) & (b[:10] == x)) for x, y in zip(a[:10], b[:10], strict=True)]
    )
    assert len(EdgeCounts(a[:0], b[:0], 0).reverses()) == 0


def test_border_of_a_sphere_with_a_cap_removed_is_the_cap_rim():
    verts, tris = uv_sphere(1.0, rings=12, segments=24)
    assert len(border_halves(tris, len(verts))) == 0  # closed
    top = (verts[tris][:, :, 2] > 0.9).all(axis=1)
    border = border_halves(tris[~top], len(verts))
    rim = np.unique(border)
    assert len(border) == len(rim) and np.allclose(verts[rim][:, 2], verts[rim][0, 2])  # one ring of edges


def test_doubled_and_flipped_edges_are_counted():
    verts, tris = box_mesh()
    tris = np.asarray(tris, dtype=np.int64)
    _, _, keys, reverses = directed_edges(np.r_[tris, tris[:1]], len(verts))
    table = KeyCounts(keys)
    assert (table.of(keys[:3]) == 2).all() and (table.of(keys[3:36]) == 1).all()
    assert (table.of(reverses) >= 1).all()
    flipped = np.r_[tris[:1, ::-1], tris[1:]]
    _, _, keys, reverses = directed_edges(flipped, len(verts))
    assert (KeyCounts(keys).of(reverses) == 0).sum() == 6  # the flipped face's 3 edges and their 3 neighbours'


def test_compacted_is_unique_with_inverse():
    tris = np.array([[7, 3, 9], [3, 9, 12], [12, 7, 3]])
    used, local = compacted(tris, 20)
    expected_used, inverse = np.unique(tris, return_inverse=True)
    assert np.array_equal(used, expected_used) and np.array_equal(local, inverse.reshape(-1, 3))


def test_position_groups_match_numpy_unique_rows():
    rng = np.random.default_rng(5)
    points = rng.integers(-3, 3, size=(3000, 3)).astype(np.float32) * np.float32(0.5)  # many repeats, signed zeros
    points[::7] *= -1.0
    first, inverse = position_groups(points)
    _, np_first, np_inverse = np.unique(points, axis=0, return_index=True, return_inverse=True)
    assert np.array_equal(np.sort(first), np.sort(np_first))  # the same groups, each by its least index
    assert np.array_equal(first[inverse], np_first[np_inverse.reshape(-1)])
