"""The strip between a kept border loop and the voxel surface's loop beside it (engine/zipper.py)."""

import numpy as np
import warp as wp

from engine.zipper import zip_loops


def _circles(spike: bool):
    """A kept loop (radius 10.4, 48 vertices, counter-clockwise) and the voxel loop beside it (radius 10, 70 vertices,
    listed clockwise: walked against its faces), as one point array and one ``next`` permutation. With ``spike``, the
    kept loop leaves the circle at its first vertex for a point 3 out and ahead, and comes back beside where it left
    (a border detour around a sliver the judge dropped)."""
    tp = 2 * np.pi * np.arange(48) / 48
    if spike:
        tp = np.r_[0.0, 0.3, 0.02, tp[2:]]
    kept = np.c_[10.4 * np.cos(tp), 10.4 * np.sin(tp), np.zeros(len(tp))]
    if spike:
        kept[1] *= 13.4 / 10.4
    tq = -2 * np.pi * np.arange(70) / 70
    voxel = np.c_[10.0 * np.cos(tq), 10.0 * np.sin(tq), np.zeros(70)]
    n = len(kept)
    nxt = np.r_[np.arange(1, n), 0, n + np.r_[69, np.arange(69)]].astype(np.int64)
    return np.concatenate([kept, voxel]).astype(np.float32), nxt, n


def _zipped(spike: bool):
    points, nxt, n = _circles(spike)
    ones = lambda v: np.array([v])  # noqa: E731
    return zip_loops(points, nxt, nxt, ones(0), ones(n), ones(n), ones(70), wp.get_device("cpu"), 2.0), n


def test_a_strip_zips_two_loops_side_by_side():
    (tris, gaps), n = _zipped(spike=False)
    assert len(tris) == n + 70  # one triangle a step, every vertex of both loops used
    assert np.array_equal(np.unique(tris), np.arange(n + 70))
    assert gaps.max() < 0.5  # the loops are 0.4 apart


def test_a_spike_of_the_kept_loop_does_not_drag_the_voxel_loop_ahead():
    # the voxel vertex nearest the spike lies five ahead, the kept loop's next vertex beside the start: the walk took
    # the voxel loop round the whole circle to come back to it (gaps up to 20.4)
    (tris, gaps), n = _zipped(spike=True)
    assert len(tris) == n + 70
    assert gaps.max() < 1.0, gaps.max()  # measured 0.45
