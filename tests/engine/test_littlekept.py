"""Booleans whose operands' faces are the result's surface almost nowhere are remeshed, not joined
(engine/littlekept.py): a ball united with its own copy moved by a voxel, at 1/128 of a unit."""

import numpy as np
import pytest

import engine
from engine import hybrid, littlekept
from engine.meshcheck import triangle_areas
from tests.metrics import mesh_volume, to_manifold
from tests.support import is_watertight, uv_sphere

H = 1.0 / 128
BALL = uv_sphere(0.5, rings=24, segments=48)


def _with_copy(voxels: float, seams: bool):
    """The ball united with its copy moved ``voxels`` along a slanted direction, and the copy's placement."""
    direction = np.array([1.0, 0.7, -0.4]) / np.linalg.norm([1.0, 0.7, -0.4])
    move = np.eye(4)
    move[:3, 3] = direction * voxels * H
    a, b = engine.build_fields([BALL, BALL], voxel_size=H)
    return engine.union(a, b.transformed(move), seams=seams), move


def _kept_share(surface: dict) -> float:
    area = triangle_areas(surface["verts"].astype(np.float64), surface["tris"])
    return float(area[surface["kept"]].sum() / area.sum())


@pytest.mark.parametrize("seams", [False, True])
def test_a_copy_moved_by_a_voxel_is_remeshed_without_a_join_closed_and_exact(monkeypatch, seams):
    field, move = _with_copy(1.0, seams)
    joined = []
    real_join = hybrid.hybrid_surface
    monkeypatch.setattr(hybrid, "hybrid_surface", lambda *a, **k: joined.append(1) or real_join(*a, **k))
    s = field.kept_surface()
    assert not joined
    assert s["stats"]["kept_fallback"] == littlekept.LITTLE_KEPT and not s["stats"]["join_failed"]
    assert not s["kept"].any()
    assert is_watertight(s["tris"]) and to_manifold(s["verts"], s["tris"]) is not None
    moved = ((BALL[0] @ move[:3, :3].T + move[:3, 3]).astype(np.float32), BALL[1])
    exact = (to_manifold(*BALL) + to_manifold(*moved)).volume()
    assert abs(mesh_volume(s["verts"], s["tris"]) - exact) < 2e-4 * exact  # measured 7e-5


def test_along_the_seams_an_operand_apart_from_them_is_not_lost():
    """The copy and a small ball apart from both (2 % of the operands' area, all of it kept): the seams' surface,
    closed about the copy, has nothing where the small ball is; the whole result's is given."""
    small = uv_sphere(0.1, rings=12, segments=24)
    small = ((small[0] + np.array([1.2, 0.0, 0.0])).astype(np.float32), small[1])
    a, b, c = engine.build_fields([BALL, BALL, small], voxel_size=H)
    _, move = _with_copy(1.0, True)
    s = engine.union(engine.union(a, b.transformed(move), seams=True), c, seams=True).kept_surface()
    assert s["stats"]["kept_fallback"] == littlekept.LITTLE_KEPT and is_watertight(s["tris"])
    moved = ((BALL[0] + move[:3, 3]).astype(np.float32), BALL[1])
    exact = (to_manifold(*BALL) + to_manifold(*moved) + to_manifold(*small)).volume()
    # measured 9e-5; without the small ball's 0.76 % of the volume
    assert abs(mesh_volume(s["verts"], s["tris"]) - exact) < 3e-4 * exact


def test_a_seams_surface_with_a_hole_or_far_from_a_kept_face_is_not_the_whole_result():
    """The seams' surface stands for the whole result only where it is closed and lies about every face kept."""
    verts, tris = BALL
    judged = [{"verts": verts, "tris": tris.astype(np.int64), "kept": np.arange(len(tris)) < 10}]
    assert littlekept.whole_along_seams(judged, verts, tris, H, "cpu")
    assert not littlekept.whole_along_seams(judged, verts, tris[1:], H, "cpu")  # (a face missing: open)
    turned = tris.copy()
    turned[5] = turned[5, ::-1]
    assert not littlekept.whole_along_seams(judged, verts, turned, H, "cpu")  # (a face turned against its neighbours)
    far = [{**judged[0], "verts": verts + np.float32(0.3)}]  # the kept faces 0.52 away (66 voxels)
    assert not littlekept.whole_along_seams(far, verts, tris, H, "cpu")


def test_joined_anyway_the_copy_would_keep_under_the_share_in_islands(monkeypatch):
    field, _ = _with_copy(1.0, False)
    share = littlekept.MIN_KEPT_SHARE
    monkeypatch.setattr(littlekept, "MIN_KEPT_SHARE", 0.0)
    s = field.kept_surface()
    assert s["stats"]["kept_fallback"] == "" and _kept_share(s) < share  # measured 0.000 (nothing to join)


@pytest.mark.parametrize("voxels, least", [(2.0, 0.06), (5.0, 0.33)])  # measured 0.119 and 0.653
def test_a_copy_moved_farther_keeps_its_faces_joined(voxels, least):
    field, _ = _with_copy(voxels, True)
    s = field.kept_surface()
    assert s["stats"]["kept_fallback"] == "" and _kept_share(s) > least
    assert is_watertight(s["tris"]) and to_manifold(s["verts"], s["tris"]) is not None


def test_a_thin_lens_two_large_balls_share_keeps_its_faces_little_of_theirs_as_they_are():
    a, b = engine.build_fields([BALL, BALL], voxel_size=H)
    apart = np.eye(4)
    apart[0, 3] = 0.95  # a lens 0.05 (6.4 voxels) thick: 2.5 % of each ball's area
    s = engine.intersection(a, b.transformed(apart)).kept_surface()
    assert s["stats"]["kept_fallback"] == "" and _kept_share(s) > 0.3  # measured 0.70
    assert is_watertight(s["tris"]) and to_manifold(s["verts"], s["tris"]) is not None


def test_an_empty_boolean_says_its_result_is_empty():
    a, b = engine.build_fields([BALL, BALL], voxel_size=H)
    away = np.eye(4)
    away[0, 3] = 2.0
    s = engine.intersection(a, b.transformed(away)).kept_surface()
    assert len(s["tris"]) == 0 and s["stats"]["kept_fallback"] == "the result is empty"


def test_along_the_seams_every_face_has_its_source_read_where_it_was_made():
    """The seams' surface taken whole: every face's source read off the seams (not looked up again by the add-on,
    which cost 10 times the remeshed result's) as the whole boolean gives it."""
    field, _ = _with_copy(1.0, True)
    s = field.kept_surface()
    rows, ids, tri_ids, _ = s["new_sources"]
    assert np.array_equal(rows, np.arange(len(s["tris"])))
    whole_ids, whole_tris, _ = _with_copy(1.0, False)[0].face_sources(s["verts"], s["tris"])
    assert np.array_equal(ids, whole_ids) and (tri_ids == whole_tris).mean() > 0.999  # measured: all the same


def test_the_remeshed_surface_is_given_as_it_is_and_at_an_adaptivity_coarse_where_flat():
    # what Keep Original Faces off gives at adaptivity 0 (not made coarse, nothing tiled: its cost); at an adaptivity,
    # merged where flat as a join's new faces are
    from engine.quads import triangulate

    field, _ = _with_copy(1.0, False)
    s = field.kept_surface()
    verts, faces, sizes = field.to_mesh(quads=True)
    assert len(s["tris"]) == len(triangulate(faces, sizes))
    np.testing.assert_array_equal(np.unique(s["verts"], axis=0), np.unique(verts, axis=0))
    coarse = field.kept_surface(adaptivity=0.5)
    assert coarse["stats"]["kept_fallback"] == littlekept.LITTLE_KEPT and is_watertight(coarse["tris"])
    assert len(coarse["tris"]) < 0.1 * len(s["tris"])  # measured 4,566 of 155,112
