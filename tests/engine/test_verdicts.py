"""A leaf's first verdicts reused when only placements changed (engine/verdicts.py, engine/keep.py): the surface is
the one judging every triangle afresh gives, bit for bit, and the bound refuses what it cannot vouch for.

Voxel = 1/128 of the operands' bounding-box diagonal.
"""

import numpy as np
import pytest

import engine
from engine import verdicts
from engine.keep import kept_triangles
from tests.support import box_mesh, normalised, uv_sphere


@pytest.fixture()
def reuse_log(monkeypatch):
    """Per call of ``verdicts.reused``: (leaf index, triangles whose verdict was reused or None when nothing could
    be, triangles)."""
    log = []
    found = verdicts.reused

    def spy(source, expression, index, *args):
        out = found(source, expression, index, *args)
        log.append((index, None if out is None else int((out[0] != verdicts.UNKNOWN).sum()), len(args[2])))
        return out

    monkeypatch.setattr(verdicts, "reused", spy)
    verdicts.forget()
    yield log
    verdicts.forget()


def _ball_and_box(refine="all"):
    ball = normalised(uv_sphere(1.0, rings=32, segments=64))
    box = normalised(box_mesh(), center=(0.3, 0.25, 0.2), diagonal=0.6)
    v = np.concatenate([ball[0], box[0]])
    voxel = float(np.linalg.norm(v.max(0) - v.min(0))) / 128.0
    return engine.build_fields([ball, box], voxel_size=voxel, field_ids=[0, 1], refine=refine), voxel


def _moved(field, shift):
    matrix = np.eye(4)
    matrix[:3, 3] = shift
    return field.transformed(matrix)


@pytest.mark.parametrize("refine", ["all", "none"], ids=["built whole", "built on demand, along the seams"])
def test_a_moved_cutter_gives_what_a_fresh_judge_gives_and_reuses_the_far_verdicts(reuse_log, refine):
    (ball, box), voxel = _ball_and_box(refine)
    seams = refine == "none"  # (each move refines the fields further: the verdicts hold across)
    for step in range(4):
        cutter = _moved(box, (2.0 * voxel * step, 0.5 * voxel * step, 0.0))
        reusing = engine.difference(ball, cutter, seams=seams).kept_surface()
        reused = [None if count is None else count / total for index, count, total in reuse_log[-2:] if index == 0]
        kept_records = dict(verdicts._RECORDS)
        verdicts.forget()
        fresh = engine.difference(ball, cutter, seams=seams).kept_surface()
        verdicts._RECORDS.update(kept_records)
        assert np.array_equal(reusing["verts"], fresh["verts"]) and np.array_equal(reusing["tris"], fresh["tris"])
        assert np.array_equal(reusing["kept"], fresh["kept"])
        if step == 1:  # a first move records (a first boolean marks the fields judged, no more)
            assert reused[0] is None, reused
        if step >= 2:
            # the ball's triangles far from the box: 0.92 of them measured at each step
            assert reused[0] is not None and reused[0] >= 0.6, reused


def test_turning_the_ball_itself_reuses_too(reuse_log):
    (ball, box), voxel = _ball_and_box()
    engine.difference(ball, box).kept_surface()
    turn = np.eye(4)
    turn[:3, :3] = [[np.cos(0.005), -np.sin(0.005), 0], [np.sin(0.005), np.cos(0.005), 0], [0, 0, 1]]
    engine.difference(ball.transformed(turn), box).kept_surface()  # (the first turn records)
    turn = turn @ turn
    turned = engine.difference(ball.transformed(turn), box).kept_surface()
    reused = [None if count is None else count / total for index, count, total in reuse_log[-2:] if index == 0]
    assert reused[0] is not None and reused[0] >= 0.6, reused  # measured 0.96
    verdicts.forget()
    fresh = engine.difference(ball.transformed(turn), box).kept_surface()
    assert np.array_equal(turned["tris"], fresh["tris"]) and np.array_equal(turned["verts"], fresh["verts"])


def test_a_first_boolean_and_its_repeats_in_place_record_nothing_a_move_records(reuse_log, monkeypatch):
    (ball, box), voxel = _ball_and_box()
    recorded = []
    remember = verdicts.remember
    monkeypatch.setattr(verdicts, "remember", lambda *args: recorded.append(len(args[5])) or remember(*args))
    first = engine.difference(ball, box).kept_surface()
    again = engine.difference(ball, box).kept_surface()  # in place (as a second join's judge): a mark again
    assert recorded == [0, 0, 0, 0] and np.array_equal(first["tris"], again["tris"])
    engine.difference(ball, _moved(box, (voxel, 0.0, 0.0))).kept_surface()
    assert sorted(recorded[4:]) == sorted([len(ball.sources[0].tris), len(box.sources[1].tris)])  # moved: recorded


def test_another_expression_a_rebuilt_field_or_a_far_move_reuses_nothing(reuse_log):
    (ball, box), voxel = _ball_and_box()
    engine.difference(ball, box).kept_surface()
    engine.union(ball, box).kept_surface()  # another operation: another expression
    assert [count for _, count, _ in reuse_log[-2:]] == [None, None]
    engine.difference(ball, box).kept_surface()
    (ball2, box2), _ = _ball_and_box()  # the same meshes built again: other fields
    engine.difference(ball, box2).kept_surface()
    assert [count for _, count, _ in reuse_log[-2:]] == [None, None]
    engine.difference(ball, _moved(box2, (40.0 * voxel, 0.0, 0.0))).kept_surface()
    far = [count for _, count, _ in reuse_log[-2:]]
    assert all(count in (None, 0) for count in far), far  # a move far beyond the distances kept settles nothing


def test_a_moved_open_leaf_is_bounded_by_its_jump_spheres_and_a_moved_offset_gives_no_bound(reuse_log):
    (ball, _), voxel = _ball_and_box()
    verts, tris = normalised(uv_sphere(1.0, rings=24, segments=48), center=(0.3, 0.2, 0.2), diagonal=0.6)
    open_cap = tris[~(verts[tris][:, :, 2] > 0.25).all(axis=1)]  # the top cap gone: its sign may jump over the hole
    (cutter,) = engine.build_fields([(verts, open_cap)], voxel_size=voxel, field_ids=[1])
    engine.difference(ball, cutter).kept_surface()
    engine.difference(ball, _moved(cutter, (0.5 * voxel, 0.0, 0.0))).kept_surface()  # (the first move records)
    moved = _moved(cutter, (voxel, 0.0, 0.0))
    reusing = engine.difference(ball, moved).kept_surface()
    ball_entry = [count for index, count, _ in reuse_log[-2:] if index == 0]
    assert ball_entry[0] is not None and ball_entry[0] > 0.5 * len(ball.sources[0].tris), ball_entry
    kept_records = dict(verdicts._RECORDS)
    verdicts.forget()
    fresh = engine.difference(ball, moved).kept_surface()  # the surface a fresh judge gives
    verdicts._RECORDS.update(kept_records)
    assert np.array_equal(reusing["verts"], fresh["verts"]) and np.array_equal(reusing["tris"], fresh["tris"])
    assert np.array_equal(reusing["kept"], fresh["kept"])
    # an offset is read through its field alone: moved, it bounds nothing
    grown = engine.offset(cutter, voxel)
    engine.difference(ball, grown).kept_surface()
    engine.difference(ball, _moved(grown, (voxel, 0.0, 0.0))).kept_surface()
    assert reuse_log[-1][:2] == (0, None), reuse_log[-1]  # (the ball's the only mesh leaf judged)


def test_recorded_distances_bound_every_sample_read_from_a_centre_where_a_face_has_many_samples():
    # a face of many samples and a few voxels across (the ball's) has its centre read as far as a record needs (its
    # samples only as far as its verdict does): a bound below every sample's distance, within twice the face's spread
    # of it; a face far larger (the box's) has every sample read that far, as the sample-by-sample path reads them
    (ball, box), voxel = _ball_and_box()
    records = {}
    for fused in (True, False):
        verdicts.forget()
        kept_triangles(engine.difference(ball, box), fused=fused)  # (a first boolean marks)
        kept_triangles(engine.difference(ball, _moved(box, (voxel, 0.0, 0.0))), fused=fused)  # a move records
        records[fused] = [verdicts._RECORDS[field.sources[k]][k] for k, field in enumerate((ball, box))]
    verdicts.forget()
    for k, field in enumerate((ball, box)):
        centre, general = records[True][k], records[False][k]
        np.testing.assert_array_equal(centre.status, general.status)
        np.testing.assert_array_equal(centre.flip, general.flip)
        source = field.sources[k]
        corners = source.verts[source.tris].astype(np.float64)
        spread = np.linalg.norm(corners - corners.mean(axis=1, keepdims=True), axis=2).max(axis=1)
        read = np.isfinite(general.margin)
        if k == 1:  # the box's faces, 27 voxels from their centres
            np.testing.assert_array_equal(centre.margin, general.margin)
            continue
        assert (centre.margin[read] <= general.margin[read] + 1e-6).all()  # a bound of every sample's distance
        assert (centre.margin[read] >= general.margin[read] - 2.0 * spread[read] - 1e-6).all()
        assert (centre.margin[read] < general.margin[read] - 0.1 * voxel).sum() > 100  # measured
