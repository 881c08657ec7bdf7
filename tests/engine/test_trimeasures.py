"""A mesh's triangles measured coordinate by coordinate (engine/trimeasures.py) and welded by sortable float bits
(engine/meshcheck.py): the same values, to the bit, as the (T, 3, 3) gathers with ``np.cross``, ``np.linalg.norm``
and ``mean`` they replace, and the same welded order as a sort of the float values, on a scan and on random
triangles with negative coordinates, signed zeros and repeated positions."""

import numpy as np
import pytest

from engine.meshcheck import weld_positions
from engine.slivers import strip_parents
from engine.trimeasures import triangle_measures, unit_normals
from tests.support import load_mesh, normalised


def _random_mesh(seed: int):
    rng = np.random.default_rng(seed)
    verts = rng.normal(size=(400, 3)).astype(np.float32)
    verts[:40] = verts[40:80]  # repeated positions
    verts[80:90, 0] = -0.0
    verts[90:100, 0] = 0.0
    verts[100:140] *= np.float32(1e-3)  # small triangles, slivers among them
    tris = rng.integers(0, len(verts), size=(900, 3))
    return verts, tris


@pytest.mark.parametrize("mesh", ["bunny", "random 0", "random 1"])
def test_measures_are_the_gathered_ones_to_the_bit(mesh):
    verts, tris = normalised(load_mesh("stanford-bunny.obj")) if mesh == "bunny" else _random_mesh(int(mesh[-1]))
    got = triangle_measures(verts, tris)
    corners = verts[tris]
    wide = corners.astype(np.float64)
    edges = wide[:, [1, 2, 0]] - wide
    normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]).astype(np.float64)
    normals = (normals / np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-30)).astype(np.float32)
    assert np.array_equal(got.centres, corners.mean(axis=1))
    assert np.array_equal(got.normals, normals) and np.array_equal(unit_normals(verts, tris), normals)
    assert np.array_equal(got.lengths, np.linalg.norm(edges, axis=2))
    area = np.linalg.norm(np.cross(wide[:, 1] - wide[:, 0], wide[:, 2] - wide[:, 0]), axis=1)
    assert np.array_equal(got.doubled_areas, area)
    # the slivers found from them are those found from the measures strip_parents takes itself
    for split in (1e-3, 1e-2, 0.1):
        given, own = strip_parents(verts, tris, split, got), strip_parents(verts, tris, split)
        assert np.array_equal(given[0], own[0]) and np.array_equal(given[1], own[1])


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_welded_positions_are_sorted_as_their_float_values(seed):
    verts, tris = _random_mesh(seed)
    welded, indices = weld_positions(verts, tris)
    as_values = np.unique(verts + np.float32(0.0), axis=0)  # -0 and 0 one position
    assert np.array_equal(welded, as_values)
    assert np.array_equal(welded[indices], verts[tris] + np.float32(0.0))
    # a float64 mesh takes the sort of its values
    welded64, indices64 = weld_positions(verts.astype(np.float64), tris)
    assert np.array_equal(welded64, as_values.astype(np.float64)) and np.array_equal(indices64, indices)


def test_measures_taken_in_pieces_are_those_taken_at_once(monkeypatch):
    from engine import samples, trimeasures

    verts, tris = load_mesh("stanford-bunny.obj")
    for module in (trimeasures, samples):
        monkeypatch.setattr(module, "CHUNK_ROWS", len(tris))
    whole = trimeasures.triangle_measures(verts, tris), samples.edge_turns(verts, tris)
    for module in (trimeasures, samples):
        monkeypatch.setattr(module, "CHUNK_ROWS", 1000)  # 70 pieces, the last one short
    measures, turns = trimeasures.triangle_measures(verts, tris), samples.edge_turns(verts, tris)
    for name in ("centres", "normals", "lengths", "doubled_areas"):
        assert np.array_equal(getattr(measures, name), getattr(whole[0], name)), name
    assert all(np.array_equal(a, b) for a, b in zip(turns, whole[1], strict=True))
