"""A closed mesh's faces' sides from a few winding numbers carried between neighbours: the sides two winding numbers a
face give, to the face."""

from __future__ import annotations

import numpy as np
import pytest

import engine
from engine import meshsides, ondemand
from engine.trimeasures import triangle_measures
from tests.support import box_mesh, load_mesh, normalised, overlapping_boxes, torus_mesh, uv_sphere

H = 1.0 / 128


def _inside_out(mesh):
    verts, tris = mesh
    return verts, tris[:, ::-1].copy()


def _points(mesh, offset: float):
    """The field built on demand's winding number, the faces, the points ``offset`` ahead of and behind each, and the
    field (which keeps the winding number's mesh)."""
    field = engine.build_field(*normalised(mesh), voxel_size=H, refine="none")
    source = next(iter(field.sources.values()))
    measures = triangle_measures(source.verts, source.tris.astype(np.int64))
    ends = [measures.centres + sign * offset * measures.normals for sign in (1.0, -1.0)]
    return source.refiner.levels.winding, source.tris, ends, field


CLOSED = {
    "spot": lambda: load_mesh("spot.obj"),
    "ball inside out": lambda: _inside_out(uv_sphere(1.0, rings=24, segments=48)),
    "two boxes through each other": overlapping_boxes,
    "torus": lambda: torus_mesh(rings=48, segments=24),
    "box, split faces": lambda: box_mesh(subdivisions=6),
}


@pytest.mark.parametrize("name", list(CLOSED))
@pytest.mark.parametrize("offset_voxels", [0.5, 3.0])
def test_the_sides_are_those_two_winding_numbers_a_face_give(name, offset_voxels, monkeypatch):
    winding, tris, ends, _field = _points(CLOSED[name](), offset_voxels * H)
    want = ondemand.winding_sides(winding, ends, "cpu")
    evaluated = []
    windings = meshsides._windings
    monkeypatch.setattr(meshsides, "_windings", lambda w, x, d: evaluated.append(len(x)) or windings(w, x, d))
    got = meshsides.closed_sides(winding, tris, *ends, "cpu")
    assert got is not None and np.array_equal(got, want)
    assert sum(evaluated) <= max(8, len(tris) // 50)  # (two a face before)
    if name == "two boxes through each other":  # faces inside the other box: inside on both sides
        assert (got == 0).sum() > 0 and (got == 1).sum() > 0
    else:
        assert (got == (-1 if name == "ball inside out" else 1)).mean() > 0.9


def test_an_open_mesh_is_left_to_the_winding_numbers():
    verts, tris = uv_sphere(1.0, rings=24, segments=48)
    winding, tris, ends, _field = _points((verts, tris[: len(tris) - 48]), 0.5 * H)  # a cap taken off
    assert meshsides.closed_sides(winding, tris, *ends, "cpu") is None
