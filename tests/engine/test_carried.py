"""Where a join gave a leaf's own faces up, carried to the next boolean over it (engine/carried.py, engine/rejoin.py),
and verdicts reused where the same points are kept clear of (engine/verdicts.py).

The beetle (open, thin legs) united with a ball at /256: its first join gives faces up about voxel loops it cannot
pair, and a second judge keeps clear of those points (tests/engine/test_rejoin.py).
"""

import hashlib

import numpy as np
import pytest

import engine
from engine import carried, hybrid, verdicts
from tests.metrics import to_manifold
from tests.support import box_mesh, load_mesh, normalised, uv_sphere


@pytest.fixture()
def fresh():
    verdicts.forget()
    carried.forget()
    yield
    verdicts.forget()
    carried.forget()


@pytest.fixture()
def joins(monkeypatch):
    """How many joins each kept surface made (calls of ``hybrid.hybrid_surface``)."""
    count = [0]
    join = hybrid.hybrid_surface

    def counted(*args, **kwargs):
        count[0] += 1
        return join(*args, **kwargs)

    monkeypatch.setattr(hybrid, "hybrid_surface", counted)
    return count


def _beetle_and_ball():
    mesh = normalised(load_mesh("beetle.obj"))
    ball = normalised(uv_sphere(1.0, rings=48, segments=96), center=(0.2, 0.2, 0.2), diagonal=0.6)
    v = np.concatenate([mesh[0], ball[0]])
    h = float(np.linalg.norm(v.max(0) - v.min(0))) / 256.0
    return engine.build_fields([mesh, ball], voxel_size=h, field_ids=[0, 1], refine="auto"), h


def _moved(field, h, step):
    m = np.eye(4)
    m[:3, 3] = (0.5 * h * step, 0.3 * h * step, 0.0)
    return field.transformed(m) if step else field


def _fingerprint(surface) -> str:
    digest = hashlib.sha1()
    for key in ("verts", "tris", "kept", "field_id", "triangle_id", "corner_bary"):
        digest.update(np.ascontiguousarray(surface[key]).tobytes())
    return digest.hexdigest()


def test_a_cutter_moved_beside_a_mesh_whose_join_gave_faces_up_needs_no_rejoin_and_keeps_as_much(fresh, joins):
    (fa, fb), h = _beetle_and_ball()
    first = engine.union(fa, fb, seams=True).kept_surface(sharp=True)
    # joined, joined again clear of the faces given up, and once more clear of where faces were left crossing
    assert joins[0] == 3 and first["stats"]["rejoined"] > 0 and first["stats"]["crossing_left"] == 0
    held = carried.carried(engine.union(fa, fb))
    # measured: 56 of the 73 points the last judge kept clear of (those farther than 7 voxels from the ball)
    assert 0.7 * first["stats"]["rejoined"] <= len(held) <= first["stats"]["rejoined"]
    for step in (1, 2):
        joins[0] = 0
        moved = engine.union(fa, _moved(fb, h, step), seams=True).kept_surface(sharp=True)
        # judged clear of the beetle's points from the first: no rejoin (measured 1 and 2 joins: the second move left
        # a place crossing, judged again)
        assert joins[0] <= 2, joins[0]
        assert moved["stats"]["kept_fallback"] == ""
        assert engine.surface_edges(moved["tris"], len(moved["verts"])) is not None  # closed, oriented
        assert to_manifold(moved["verts"], moved["tris"]).status().name == "NoError"
        carried.forget()  # the same boolean as a first one: three joins, no more faces kept
        joins[0] = 0
        alone = engine.union(fa, _moved(fb, h, step), seams=True).kept_surface(sharp=True)
        assert joins[0] == 3
        # measured: 12,593 and 12,667 kept faces carried, as many as found again
        assert moved["kept"].sum() >= alone["kept"].sum() - 10, (moved["kept"].sum(), alone["kept"].sum())


def test_verdicts_reused_beside_carried_points_give_what_a_fresh_judge_gives(fresh, monkeypatch):
    (fa, fb), h = _beetle_and_ball()
    found, log = verdicts.reused, []

    def spy(source, expression, index, *args):
        out = found(source, expression, index, *args)
        log.append(0 if out is None else int((out[0] != verdicts.UNKNOWN).sum()))
        return out

    monkeypatch.setattr(verdicts, "reused", spy)
    runs = []
    for forget in (False, True):
        verdicts.forget()
        carried.forget()
        prints, log[:] = [], []
        for step in range(3):
            if forget:
                verdicts.forget()  # the points carried, every triangle judged afresh
            prints.append(_fingerprint(engine.union(fa, _moved(fb, h, step), seams=True).kept_surface(sharp=True)))
        runs.append((prints, sum(log)))
    assert runs[0][0] == runs[1][0]
    # measured: 1,483 verdicts reused over the two moves, none where the records were forgotten
    assert runs[0][1] > 500 and runs[1][1] == 0, (runs[0][1], runs[1][1])


def test_points_are_carried_with_their_leaf_and_only_far_from_the_others(fresh):
    cube = box_mesh(half=(0.3, 0.3, 0.3))
    ball = normalised(uv_sphere(1.0, rings=16, segments=32), center=(0.3, 0.0, 0.0), diagonal=0.3)
    h = 0.01
    fa, fb = engine.build_fields([cube, ball], voxel_size=h, field_ids=[0, 1])
    union = engine.union(fa, fb)
    on_cube_far = [-0.3, 0.1, 0.05]  # on the cube's face x = -0.3, 60 voxels from the ball
    on_cube_near = [0.3, 0.12, 0.0]  # on its face x = 0.3, 3 voxels from the ball
    on_ball_far = ball[0][np.argmax(ball[0][:, 0])]  # the ball's vertex farthest out of the cube: 8.7 voxels
    off_both = [0.0, 0.0, 0.0]  # on no leaf
    carried.remember(union, np.array([on_cube_far, on_cube_near, on_ball_far, off_both], np.float32))
    np.testing.assert_allclose(carried.carried(union), [on_cube_far, on_ball_far], atol=1e-6)
    m = np.eye(4)
    m[:3, 3] = (0.02, 0.01, 0.0)
    # the ball moved: the cube's point stays where the cube is, the ball's goes with it
    moved = carried.carried(engine.union(fa, fb.transformed(m)))
    np.testing.assert_allclose(moved, [on_cube_far, on_ball_far + m[:3, 3]], atol=1e-6)
    # the cube moved: its point with it
    moved = carried.carried(engine.difference(fa.transformed(m), fb))
    np.testing.assert_allclose(moved, [np.add(on_cube_far, m[:3, 3]), on_ball_far], atol=1e-6)
    # at another voxel size nothing is carried; a boolean that kept clear of nothing forgets what each leaf had
    assert not len(carried.carried(engine.union(*engine.build_fields([cube, ball], voxel_size=2 * h))))
    carried.remember(union, np.zeros((0, 3)))
    assert not len(carried.carried(union))


def test_a_join_that_falls_back_beside_carried_points_is_made_as_a_first_boolean_would(fresh, monkeypatch):
    (fa, fb), h = _beetle_and_ball()
    engine.union(fa, fb, seams=True).kept_surface(sharp=True)
    assert len(carried.carried(engine.union(fa, fb)))
    join, calls = hybrid.hybrid_surface, []

    def first_fails(field, verts, tris, judged, partial=False):
        calls.append(judged)
        if len(calls) == 1:  # the join of the triangles judged clear of the points carried
            return hybrid.voxel_surface_only(verts, tris, "loops left unpaired")
        return join(field, verts, tris, judged, partial)

    monkeypatch.setattr(hybrid, "hybrid_surface", first_fails)
    surface = engine.union(fa, _moved(fb, h, 1), seams=True).kept_surface(sharp=True)
    assert surface["stats"]["kept_fallback"] == "" and surface["kept"].sum() > 9_000  # measured 9,670
    # judged afresh, then joined as a first boolean: twice, and once more clear of where faces were left crossing
    assert len(calls) == 4 and calls[1] is not calls[0] and surface["stats"]["crossing_left"] == 0
