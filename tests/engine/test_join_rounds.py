"""The join's rounds read again only what a round changed (engine/hybrid.py): the border after faces are dropped, the
voxel vertices over the kept faces after some are given up. Against reading everything again each round, on joins
of many rounds (the beetle with a ball: two joins), the surfaces are the same."""

import numpy as np

import engine
from engine import hybrid
from engine.meshcheck import all_corners, any_corner
from engine.zipper import border_halves, vertices_over
from tests.support import is_watertight, load_mesh, normalised, uv_sphere


def _beetle_with_a_ball() -> dict:
    mesh = normalised(load_mesh("beetle.obj"))
    ball = normalised(uv_sphere(1.0, rings=48, segments=96), center=(0.2, 0.2, 0.2), diagonal=0.6)
    v = np.concatenate([mesh[0], ball[0]])
    h = float(np.linalg.norm(v.max(0) - v.min(0))) / 256.0
    fa, fb = engine.build_fields([mesh, ball], voxel_size=h, field_ids=[0, 1])
    return engine.union(fa, fb).kept_surface()


def test_rounds_that_read_only_what_changed_join_as_rounds_that_read_everything(monkeypatch):
    fast = _beetle_with_a_ball()
    assert fast["stats"]["rejoined"] > 0  # several joins of several rounds each

    def border_after(tris, alive, n_verts, before, halves):
        return border_halves(tris[alive], n_verts)

    def still_over(points, kept, before, over, voxel, device):
        tris, alive, border, ways = kept
        return vertices_over(points, tris[alive], border, np.flatnonzero(over), voxel, device, ways)

    monkeypatch.setattr(hybrid, "_border_after", border_after)
    monkeypatch.setattr(hybrid, "_still_over", still_over)
    slow = _beetle_with_a_ball()
    for key in ("verts", "tris", "kept", "field_id", "triangle_id", "vertex_id"):
        np.testing.assert_array_equal(fast[key], slow[key])


def test_corner_marks_column_by_column_are_numpys():
    rng = np.random.default_rng(0)
    marked = rng.random(500) < 0.3
    for width in (2, 3, 4):
        rows = rng.integers(0, 500, (2000, width))
        np.testing.assert_array_equal(any_corner(marked, rows), marked[rows].any(axis=1))
        np.testing.assert_array_equal(all_corners(marked, rows), marked[rows].all(axis=1))


def test_a_kept_finger_a_strip_stretches_to_is_given_up_a_ring_a_round():
    """Where a strip stretches to a finger of kept faces one vertex at a time (the cow minus a ball at /128: the join
    gave the faces up at one vertex a round, and after twelve rounds fell back to the voxel surface), a loop failing
    again gives up a ring of kept faces about each such vertex: the join is made."""
    cow = load_mesh("cow.obj")
    ball = uv_sphere(2.5063107, center=(-0.13546729, 2.68412329, -0.81628078), rings=24, segments=48)
    v = np.concatenate([cow[0], ball[0]])
    h = float(np.linalg.norm(v.max(0) - v.min(0))) / 128.0
    fa, fb = engine.build_fields([cow, ball], voxel_size=h, refine="auto")
    s = engine.difference(fa, fb, seams=True).kept_surface()
    assert s["stats"]["kept_fallback"] == "" and s["stats"]["kept_faces"] > 4000, s["stats"]  # measured 5,510
    assert is_watertight(s["tris"])
