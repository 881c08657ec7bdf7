"""Blends of any width: finest nodes only where a blend shapes the surface (the zone where both operands come within
its radius), the surface exactly what a uniformly grown band gives, the added volume of a chamfer its exact one."""

import math

import numpy as np
import pytest
import warp as wp

import engine
import engine.boolean as boolean
from engine import octree
from engine.prune import operand_octets
from tests.support import box_mesh, is_watertight, signed_volume

H = 1 / 256
SHIFT = np.array([0.4, 0.3, 0.2])


def _box_sdf_slice(xs, ys, z, centre, half: float):
    """(X, Y) float32 exact distances to the box of ``centre`` and half-size ``half`` on the lattice of ``xs`` by ``ys``
    at height ``z``: q = |p - centre| - half, |max(q, 0)| + min(max of q, 0), taken axis by axis."""
    qx, qy, qz = (
        np.abs(np.asarray(v, np.float32) - np.float32(c)) - np.float32(half)
        for v, c in zip((xs, ys, z), centre, strict=True)
    )
    out = np.maximum(qx, 0.0)[:, None] ** 2 + np.maximum(qy, 0.0)[None, :] ** 2 + np.maximum(qz, 0.0) ** 2
    return np.sqrt(out) + np.minimum(np.maximum(np.maximum(qx[:, None], qy[None, :]), qz), 0.0)


def _blend(a, b, k: float, mode: str):
    if mode == "chamfer":
        return np.minimum(np.minimum(a, b), (a + b - k) / math.sqrt(2.0))
    t = np.clip(0.5 + 0.5 * (b - a) / k, 0.0, 1.0)
    return b + (a - b) * t - k * t * (1.0 - t)


def _exact_added_volumes(cases, s: float = 1 / 240) -> dict:
    """Per (blend, mode), the volume a blend adds to the two boxes' union, from their exact distances: summed slice by
    slice, the occupancy clamp(1/2 - phi / s) of each cell (exact for planes through a cell; the blend's curvature
    error is second order) of the blended union less the hard one's. Summed over the cells where a blend can change the
    occupancy alone: where the hard union's is not 1 (min(a, b) > -s/2), where a blend can bring it above 0 (min(a, b)
    below k/2 + s: the round blend stays within k/4 below the hard union, the chamfer's (a + b - k)/sqrt(2) is at least
    (2 min(a, b) - k)/sqrt(2)) and where it departs from min(a, b) at all (|a - b| < k + s); elsewhere both occupancies
    are the same."""
    reach = max(k for k, _ in cases)
    lo, hi = np.array([-0.4, -0.4, -0.4]) - reach, np.array([0.8, 0.7, 0.6]) + reach
    xs = [np.arange(a + s / 2, b, s, dtype=np.float32) for a, b in zip(lo, hi, strict=True)]
    added = dict.fromkeys(cases, 0.0)
    for z in xs[2]:
        a, b = (_box_sdf_slice(xs[0], xs[1], z, centre, 0.4) for centre in (np.zeros(3), SHIFT))
        m = np.minimum(a, b)
        zone = (m > -s / 2) & (m < reach / 2 + s) & (np.abs(a - b) < reach + s)
        a, b, m = a[zone], b[zone], m[zone]
        hard = np.clip(0.5 - m / s, 0.0, 1.0).sum()
        for k, mode in cases:
            added[k, mode] += np.clip(0.5 - _blend(a, b, k, mode) / s, 0.0, 1.0).sum() - hard
    return {case: v * s**3 for case, v in added.items()}


@pytest.fixture(scope="module")
def boxes():
    """Two boxes of 0.8 crossing each other, at voxel 1/256, and their hard union."""
    fa = engine.build_field(*box_mesh(half=(0.4, 0.4, 0.4)), voxel_size=H)
    fb = engine.build_field(*box_mesh(half=(0.4, 0.4, 0.4), center=tuple(SHIFT)), voxel_size=H)
    return fa, fb, engine.union(fa, fb)


def test_wide_blends_cost_at_most_a_half_more_nodes_than_the_hard_union_and_add_their_exact_volume(boxes):
    # a blend of a quarter of the boxes' size (51 voxels) was refused before ("needs about 16 GiB"): every operand
    # octet grown by the blend's reach; now nodes 1.07-1.28x the hard union's (2.03 M)
    fa, fb, hard = boxes
    cases = [(0.1, "round"), (0.1, "chamfer"), (0.2, "round"), (0.2, "chamfer")]
    exact = _exact_added_volumes(cases)
    for k, mode in cases:
        blended = engine.union(fa, fb, blend=k, blend_mode=mode)
        assert 1.0 < sum(blended.level_counts) / sum(hard.level_counts) < 1.45, (k, mode)
        verts, tris = blended.to_mesh()
        assert is_watertight(tris)
        # measured within 0.3 % (chamfer 0.0166, 0.0726; round 0.0053, 0.0225); the issue asks 15 % of a chamfer's
        assert signed_volume(verts, tris) - 0.904 == pytest.approx(exact[k, mode], rel=0.01), (k, mode)


def _grown_octets(fa, fb):
    """The earlier candidates: every operand octet grown by the blend's reach, octet by octet."""

    def candidates(a_arg, b_arg, origin, h, top_dims, levels, op, blend, mode, band):
        oct_dims = np.asarray(top_dims) * 2 ** (levels - 2)
        end_bit = 3 * octree.code_bits(oct_dims)
        octets = octree.merge_unique(
            *(operand_octets(f, origin, h, oct_dims, True, "cpu") for f in (fa, fb)), end_bit=end_bit
        )
        for _ in range(math.ceil((0.5 if mode == 1 else 0.25) * blend / (2.0 * h))):
            octets = octree.dilate_octets(octets, oct_dims, end_bit=end_bit)
        return octets

    return candidates


@pytest.mark.parametrize("mode", ["round", "chamfer"])
def test_the_blend_zone_gives_the_surface_a_grown_band_gives(monkeypatch, mode):
    h = 1 / 96
    fa = engine.build_field(*box_mesh(half=(0.4, 0.4, 0.4)), voxel_size=h)
    fb = engine.build_field(*box_mesh(half=(0.4, 0.4, 0.4), center=tuple(SHIFT)), voxel_size=h)
    zone = engine.union(fa, fb, blend=0.15, blend_mode=mode)
    monkeypatch.setattr(boolean, "blend_octets", _grown_octets(fa, fb))
    grown = engine.union(fa, fb, blend=0.15, blend_mode=mode)
    assert zone.level_counts[0] < 0.9 * grown.level_counts[0]  # measured 0.78x (round), 0.80x (chamfer)
    (v1, t1), (v2, t2) = zone.to_mesh(), grown.to_mesh()
    assert len(t1) == len(t2)
    # the same vertices, whatever order the nodes came in
    assert np.abs(np.sort(v1, axis=0) - np.sort(v2, axis=0)).max() < 1e-5


def test_a_chamfer_wider_than_the_boxes_gap_fills_beyond_them_and_stays_closed():
    # a chamfer's plane reaches half its size outside both operands: the result's domain grows by that much (an
    # earlier domain cut the surface 0.033 below the lower box: 684 open edges)
    h = 1 / 128
    fa = engine.build_field(*box_mesh(half=(0.4, 0.4, 0.4)), voxel_size=h)
    fb = engine.build_field(*box_mesh(half=(0.4, 0.4, 0.4), center=tuple(SHIFT)), voxel_size=h)
    verts, tris = engine.union(fa, fb, blend=0.3, blend_mode="chamfer").to_mesh()
    assert is_watertight(tris)
    assert verts[:, 2].min() < -0.42  # below the lower box's face (z = -0.4): measured -0.433


@pytest.fixture(scope="module")
def two_balls_and_a_box():
    from tests.support import uv_sphere

    a = uv_sphere(0.5, center=(0.0, 0.0, 0.0))
    b = uv_sphere(0.4, center=(0.6, 0.0, 0.0))
    c = box_mesh(half=(0.3, 0.3, 0.3), center=(0.3, 0.5, 0.0))
    h = 2.0 / 256
    return engine.build_fields([a, b, c], voxel_size=h), h


def test_a_boolean_read_inside_far_from_its_surface_keeps_its_distances(two_balls_and_a_box):
    # a union's node keeps its operand's closest point, which may lie inside the other ball (its surface buried
    # there): a coarse leaf read off those points alone was up to 19 voxels off min(a, b) inside; read trilinearly
    # where that breaks the field's 1-Lipschitz bound, 2.6 at most (measured)
    (fa, fb, _), h = two_balls_and_a_box
    union = engine.union(fa, fb)
    points = np.random.default_rng(1).uniform((-0.6, -0.6, -0.6), (1.1, 0.6, 0.6), (20000, 3)).astype(np.float32)
    exact = np.minimum(np.linalg.norm(points, axis=1) - 0.5, np.linalg.norm(points - (0.6, 0.0, 0.0), axis=1) - 0.4)
    error = np.abs(union.sample(points) - exact) / h
    assert error[exact < 0].max() <= 8.0, error[exact < 0].max()


@pytest.mark.parametrize("mode", ["round", "chamfer"])
def test_a_blend_over_a_boolean_result_stays_closed(two_balls_and_a_box, mode):
    # a blended difference or intersection whose first operand is a boolean read that boolean's inside, where a
    # coarse leaf's value was many voxels off: holes at 4 voxels and wider (measured: every case closed now)
    (fa, fb, fc), h = two_balls_and_a_box
    union = engine.union(fa, fb)
    for blend in (4, 16):
        for result in (
            engine.difference(union, fc, blend=blend * h, blend_mode=mode),
            engine.intersection(union, fc, blend=blend * h, blend_mode=mode),
        ):
            verts, tris = result.to_mesh()
            assert len(tris) and is_watertight(tris), (mode, blend)


def _balls_chamfer(points: np.ndarray, k: float) -> np.ndarray:
    """The chamfered union of the fixture's two balls' exact distances."""
    a = np.linalg.norm(points, axis=1) - 0.5
    b = np.linalg.norm(points - (0.6, 0.0, 0.0), axis=1) - 0.4
    return np.minimum(np.minimum(a, b), (a + b - k) / math.sqrt(2.0))


def test_a_chamfered_boolean_read_off_its_coarse_leaves_keeps_to_its_nodes(two_balls_and_a_box):
    # a node's closest point is one ball's, not the chamfer's: read by those points, the chamfered union was up to 5.2
    # voxels off 2-12 voxels from its surface (its nodes within 0.2); read trilinearly and within its leaf's Lipschitz
    # bracket (sqrt(2) for a chamfer), 2.1 at most (measured)
    (fa, fb, _), h = two_balls_and_a_box
    union = engine.union(fa, fb, blend=8 * h, blend_mode="chamfer")
    assert union.stats["lipschitz"] == pytest.approx(math.sqrt(2.0))
    rng = np.random.default_rng(0)
    points = (np.array([0.375, 0.286, -0.303]) + rng.uniform(-12 * h, 12 * h, (20000, 3))).astype(np.float32)
    error = np.abs(union.sample(points) - _balls_chamfer(points.astype(np.float64), 8 * h)) / h
    assert error.max() <= 3.0, error.max()


@pytest.mark.parametrize("blend", [8, 32])
def test_a_chamfer_over_a_chamfered_boolean_stays_closed(two_balls_and_a_box, blend):
    # the inner chamfer read off its coarse leaves strays from the brackets the outer one prunes with: 8, 96 and 3,844
    # open edges at 8, 32 and 64 voxels, a chamfer over that 204, 2,436 and 12,367; the octets its values show lacking
    # about its surface are added (engine/closure.py): every case closed, 3-12 % more nodes (measured)
    (fa, fb, fc), h = two_balls_and_a_box
    inner = engine.union(fa, fb, blend=blend * h, blend_mode="chamfer")
    outer = engine.union(inner, fc, blend=blend * h, blend_mode="chamfer")
    assert outer.stats["lipschitz"] == pytest.approx(1.0 + math.sqrt(0.5))  # (sqrt(2) + 1) / sqrt(2)
    moved = np.eye(4)
    moved[:3, 3] = (0.05, -0.3, 0.1)
    for result in (outer, engine.union(outer, fa.transformed(moved), blend=blend * h, blend_mode="chamfer")):
        verts, tris = result.to_mesh()
        assert len(tris) and is_watertight(tris), blend


def test_the_closure_asks_for_the_octets_about_each_crossed_edge():
    from engine.closure import surface_gaps

    # one octet at (1, 1, 1) of a 3^3 grid, its node at its -x -y -z corner inside: the edges from it are crossed, and
    # the cubes about them reach the octets towards that corner and, from the other ends, one axis the other way
    octets = wp.array(octree.morton_encode_np(np.array([[1, 1, 1]])), dtype=wp.int64)
    values = np.ones(8, dtype=np.float32)
    values[0] = -1.0
    gaps = surface_gaps(octets, wp.array(values), (3, 3, 3))
    steps = [(x, y, z) for x in (-1, 0, 1) for y in (-1, 0, 1) for z in (-1, 0, 1) if (x, y, z) != (0, 0, 0)]
    wanted = [s for s in steps if sum(v == 1 for v in s) <= 1]
    assert sorted(gaps.tolist()) == sorted(octree.morton_encode_np(np.array(wanted) + 1).tolist())
    # no crossing: nothing asked
    assert not len(surface_gaps(octets, wp.ones(8, dtype=wp.float32), (3, 3, 3)))
    # a neighbour across a face of the other sign: the nodes on that face are ends too
    two = wp.array(octree.morton_encode_np(np.array([[1, 1, 1], [2, 1, 1]])), dtype=wp.int64)
    gaps = surface_gaps(two, wp.array(np.r_[np.ones(8), -np.ones(8)].astype(np.float32)), (4, 3, 3))
    faces = [(x, y, z) for x in (1, 2) for y in (0, 1, 2) for z in (0, 1, 2) if (y, z) != (1, 1)]
    assert sorted(gaps.tolist()) == sorted(octree.morton_encode_np(np.array(faces)).tolist())
