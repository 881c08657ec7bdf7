"""The kept faces' judge started beside a boolean made along its seams: the same verdicts as a judge after it, taken
only where they hold, and none where an operand passes through itself."""

from __future__ import annotations

import threading

import numpy as np
import pytest

import engine
from engine import boolean, earlyjudge, hybrid
from engine.keep import kept_triangles
from engine.ondemand import as_built, built_leaves, refined
from tests.support import box_mesh, load_mesh, normalised, overlapping_boxes, uv_sphere

H = 1.0 / 128


@pytest.fixture(scope="module")
def pair():
    spot = normalised(load_mesh("spot.obj"))
    cutter = normalised(uv_sphere(1.0, rings=24, segments=48), center=(0.2, 0.1, 0.15), diagonal=0.5)
    return spot, cutter


def _view(result):
    view = as_built(result)
    view.expression = built_leaves(view.expression)
    return view


def _same_judged(found, want) -> bool:
    keys = ("field_id", "verts", "tris", "parent", "kept", "flip")
    return len(found) == len(want) and all(
        all(np.array_equal(f[k], w[k]) for k in keys) for f, w in zip(found, want, strict=True)
    )


def test_the_early_judge_gives_what_a_judge_after_the_boolean_gives(pair):
    a, b = engine.build_fields(list(pair), voxel_size=H, refine="auto")
    result = engine.difference(a, b, seams=True)
    assert isinstance(result.early_judge, earlyjudge.EarlyJudge) and result.early_judge.crossing() == []
    view = _view(result)
    avoid = np.zeros((0, 3))
    found = earlyjudge.early_verdicts(view, avoid)
    want = kept_triangles(view, avoid=avoid)
    assert found is not None and _same_judged(found, want)
    assert sum(int(leaf["kept"].sum()) for leaf in found) > 1000
    assert earlyjudge.early_verdicts(view, avoid) is None  # taken once: let go


def test_verdicts_for_other_points_or_operands_are_not_taken(pair, monkeypatch):
    a, b = engine.build_fields(list(pair), voxel_size=H, refine="auto")
    result = engine.difference(a, b, seams=True)
    assert result.early_judge.take(_view(result), np.array([[0.0, 0.0, 0.1]])) is None  # clear of other points
    moved = np.eye(4)
    moved[0, 3] = 3 * H
    other = engine.difference(a, b.transformed(moved), seams=True)
    assert engine.difference(a, b, seams=True).early_judge.take(_view(other), np.zeros((0, 3))) is None
    # without its early judge, the kept surface judges itself, to the same surface
    with_early = other.kept_surface()
    calls = []
    monkeypatch.setattr(hybrid, "kept_triangles", lambda *args, **kw: calls.append(1) or kept_triangles(*args, **kw))
    alone = engine.difference(a, b.transformed(moved), seams=True)
    alone.early_judge = None
    alone = alone.kept_surface()
    assert calls == [1] and all(np.array_equal(with_early[k], alone[k]) for k in ("verts", "tris", "kept"))


def _through_itself(monkeypatch, ahead: bool) -> tuple:
    """A box made of two overlapping boxes minus a ball, its kept surface, how often the boolean was made again and
    how often the kept surface judged the triangles itself; ``ahead`` False: the crossings not looked for before the
    boolean (it is made again about them afterwards)."""
    if not ahead:
        monkeypatch.setattr(earlyjudge, "_made_about_crossings", lambda crossing, voxel, device: [])
    again, judged = [], []
    made = boolean.BooleanRefiner.along_seams
    monkeypatch.setattr(boolean.BooleanRefiner, "along_seams", lambda self: again.append(1) or made(self))
    monkeypatch.setattr(hybrid, "kept_triangles", lambda *args, **kw: judged.append(1) or kept_triangles(*args, **kw))
    ball = normalised(uv_sphere(1.0, rings=32, segments=64), center=(0.3, 0.3, 0.3), diagonal=0.5)
    a, b = engine.build_fields([overlapping_boxes(), ball], voxel_size=H, refine="none")
    result = engine.difference(a, b, seams=True)
    assert [leaf.sources for leaf in result.early_judge.crossing()] == [a.sources]
    return result, result.kept_surface(), len(again), len(judged)


def test_an_operand_that_passes_through_itself_is_made_about_its_crossings_at_once(monkeypatch):
    result, surface, again, judged = _through_itself(monkeypatch, ahead=True)
    # made once, its verdicts the early judge's (the kept surface judged nothing itself)
    assert again == 0 and judged == 0 and result.early_judge.about(result.early_judge.crossing())
    # the same surface as the boolean made again about the crossings once it is found to cross itself, and judged
    _, late, again, judged = _through_itself(monkeypatch, ahead=False)
    assert again == 1 and judged == 1
    assert all(np.array_equal(surface[k], late[k]) for k in ("verts", "tris", "kept", "triangle_id"))
    assert surface["kept"].sum() > 100


def test_the_kept_surface_is_the_same_whichever_thread_refines_a_crossing_operand_first():
    # the judge's thread builds an operand that passes through itself whole while the boolean refines it along its
    # seams: refined whole first here, as the thread may be when the boolean's refinement starts late
    ball = normalised(uv_sphere(1.0, rings=32, segments=64), center=(0.3, 0.3, 0.3), diagonal=0.5)

    def kept(whole_first: bool) -> dict:
        a, b = engine.build_fields([overlapping_boxes(), ball], voxel_size=H, refine="none")
        if whole_first:
            refined(a)
        return engine.difference(a, b, seams=True).kept_surface()

    first, beside = kept(True), kept(False)
    assert all(np.array_equal(first[k], beside[k]) for k in ("verts", "tris", "kept", "triangle_id"))
    assert first["kept"].sum() > 100


def test_a_boolean_refused_for_its_domain_stops_its_judge(monkeypatch):
    # two small boxes side by side blended 1e4 wide: each field is small, their boolean's domain more than the octree
    # can address (boxes 1e4 apart are refused before the judge starts: float32 cannot resolve their voxels there)
    started = []
    start = boolean.start_judge
    monkeypatch.setattr(boolean, "start_judge", lambda *args: started.append(start(*args)) or started[-1])
    near = normalised(box_mesh(), diagonal=0.1)
    beside = normalised(box_mesh(), center=(0.05, 0.0, 0.0), diagonal=0.1)
    a, b = engine.build_fields([near, beside], voxel_size=H / 8, refine="auto")
    with pytest.raises(engine.AasdfError, match="octree can address"):
        engine.union(a, b, blend=1e4, seams=True)
    waiting = threading.Thread(target=started[0].crossing)  # ends once the judge's thread has stopped
    waiting.start()
    waiting.join(timeout=30)
    assert not waiting.is_alive() and started[0].crossing() is None
