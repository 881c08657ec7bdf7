"""Fields refined on demand (engine/ondemand.py): a field built with refine="none" has every level above the finest
as the full build has them and no finest octet; what is asked of it (samples, surfaces, booleans, offsets) equals
what the full field gives, and a boolean builds only the octets its result's surface may need."""

import numpy as np
import pytest

import engine
from engine import ondemand
from engine.expression import OP_DIFFERENCE
from engine.octree import morton_decode_np
from tests.metrics import unsigned_distance, winding_inside
from tests.support import box_mesh, is_watertight, load_mesh, normalised, overlapping_boxes, rotation, uv_sphere

H = 1.0 / 128


@pytest.fixture(scope="module")
def spot():
    return normalised(load_mesh("spot.obj"))


@pytest.fixture(scope="module")
def cutter():
    return normalised(uv_sphere(1.0, rings=24, segments=48), center=(0.2, 0.1, 0.15), diagonal=0.5)


@pytest.fixture(scope="module")
def spot_fields(spot):
    return engine.build_field(*spot, voxel_size=H), engine.build_field(*spot, voxel_size=H, refine="none")


def _levels(field, k):
    s = field.level_slice(k)
    return field.codes.numpy()[s], field.values.numpy()[s], field.closest_points.numpy()[s]


def test_a_field_built_on_demand_has_the_full_builds_coarse_levels_and_no_finest_octet(spot_fields):
    full, part = spot_fields
    assert part.level_counts[0] == 0 and full.level_counts[0] > 0
    assert part.level_counts[1:] == full.level_counts[1:]
    assert part.refiner is not None and part.refiner.share == 0.0
    for k in range(1, full.levels):
        codes_f, values_f, points_f = _levels(full, k)
        codes_p, values_p, points_p = _levels(part, k)
        assert np.array_equal(codes_f, codes_p)
        assert np.array_equal(np.sign(values_f), np.sign(values_p))
        assert np.abs(values_f - values_p).max() < 1e-5 * H  # float rounding (measured 2.9e-8 at /256)
        assert np.abs(points_f - points_p).max() < 1e-3 * H  # half-float offsets


def test_refining_everything_gives_the_full_build(spot, spot_fields):
    full, _ = spot_fields
    part = engine.build_field(*spot, voxel_size=H, refine="none")
    whole = ondemand.refined(part)
    assert whole.refiner is part.refiner and whole.refiner.share == 1.0
    assert whole.level_counts == full.level_counts
    assert np.array_equal(whole.codes.numpy(), full.codes.numpy())
    assert np.abs(whole.values.numpy() - full.values.numpy()).max() < 1e-5 * H
    assert np.array_equal(whole.tri.numpy(), full.tri.numpy())
    assert ondemand.refined(whole) is whole  # nothing more to add


def test_a_field_refined_in_steps_is_the_field_refined_at_once_to_the_bit():
    # two overlapping boxes: along their coinciding faces and edges many finest nodes lie as near two triangles, and
    # which one a node takes must not depend on which octets were built before it (a boolean's judge may refine an
    # operand whole in its thread before or after the boolean refines it along its seams)
    ball = normalised(uv_sphere(1.0, rings=32, segments=64), center=(0.3, 0.3, 0.3), diagonal=0.5)
    once = ondemand.refined(engine.build_field(*overlapping_boxes(), voxel_size=H, refine="none"))
    a, b = engine.build_fields([overlapping_boxes(), ball], voxel_size=H, refine="none")
    seams = ondemand.for_boolean(a, b, OP_DIFFERENCE, 0.0, seams=True)[0]
    assert 0.05 < seams.refiner.share < 0.95
    steps = ondemand.refined(seams)
    assert steps.refiner.share == once.refiner.share == 1.0
    for key in ("codes", "values", "tri", "closest_points", "source"):
        assert np.array_equal(getattr(steps, key).numpy(), getattr(once, key).numpy()), key


def test_a_field_refined_about_points_in_steps_is_the_field_refined_at_once_to_the_bit(spot):
    # spot's nodes as near two triangles but for rounding took either, by the octets built before them (950 of them
    # over these steps; the distances of a few differed in the last bit). At /200 its triangles are large enough for
    # an octet to take the triangles of the octet before it (OCTET_REUSE_MIN_AREA); at /128 they are not.
    rng, h = np.random.default_rng(5), 1.0 / 200
    once = ondemand.refined(engine.build_field(*spot, voxel_size=h, refine="none"))
    field = engine.build_field(*spot, voxel_size=h, refine="none")
    for _ in range(3):
        field = ondemand.refined(field, rng.uniform(-0.5, 0.5, (20, 3)), 0.1)
    assert 0.2 < field.refiner.share < 0.9  # measured 0.63
    steps = ondemand.refined(field)
    for key in ("codes", "values", "tri", "closest_points", "source"):
        assert np.array_equal(getattr(steps, key).numpy(), getattr(once, key).numpy()), key


def test_samples_of_a_field_built_on_demand_equal_the_full_fields_and_build_only_near_them(spot):
    full = engine.build_field(*spot, voxel_size=H)
    part = engine.build_field(*spot, voxel_size=H, refine="none")
    rng = np.random.default_rng(3)
    verts = spot[0][rng.choice(len(spot[0]), 200, replace=False)]
    points = verts + rng.normal(scale=2 * H, size=verts.shape)  # near the surface, where the finest level counts
    values, grads = part.sample(points, return_gradient=True)
    want, want_grads = full.sample(points, return_gradient=True)
    assert np.abs(values - want).max() < 1e-5 * H
    assert np.abs(grads - want_grads).max() < 1e-4
    assert 0.0 < part.refiner.share < 0.5  # only the octets about the points were built (0.31)
    assert part.level_counts[0] == 0  # the field asked keeps its own arrays; the refiner keeps what was built
    ids = part.source_ids(points)
    assert np.array_equal(ids, full.source_ids(points))


def test_a_query_reaching_only_built_octets_sorts_none_and_reads_the_full_fields_values(spot, monkeypatch):
    full = engine.build_field(*spot, voxel_size=H)
    part = engine.build_field(*spot, voxel_size=H, refine="none")
    refiner = part.refiner
    centres = ondemand.band_centres(part)
    x = spot[0][:, 0]
    low, mid, high = np.quantile(x, [0.1, 0.5, 0.9])
    refiner.refined_where(centres[:, 0] < mid)  # all but the band's octets beyond the middle
    lo, hi = refiner.unbuilt_box()
    unbuilt = morton_decode_np(refiner.band[~refiner.built])
    assert np.array_equal(lo, unbuilt.min(axis=0)) and np.array_equal(hi, unbuilt.max(axis=0))
    asked = []
    near = ondemand.octets_near
    monkeypatch.setattr(
        ondemand, "octets_near", lambda f, points, reach: asked.append(len(points)) or near(f, points, reach)
    )
    rng = np.random.default_rng(5)
    verts = spot[0][x < low]
    points = verts[rng.choice(len(verts), 100, replace=False)] + rng.normal(scale=H, size=(100, 3))
    before = refiner.latest
    values = part.sample(points)
    assert refiner.latest is before and sum(asked) == 0  # nothing near the unbuilt octets: nothing sorted, none built
    assert np.abs(values - full.sample(points)).max() < 1e-5 * H
    other = spot[0][x > high][:50]
    assert np.abs(part.sample(other) - full.sample(other)).max() < 1e-5 * H
    assert refiner.latest is not before and sum(asked) > 0


def test_octets_near_points_are_every_octet_within_the_reach():
    field = engine.build_field(*box_mesh((0.5, 0.5, 0.5)), voxel_size=0.1, refine="none")
    rng = np.random.default_rng(2)
    points = field.origin + rng.uniform(-0.3, 1.3, size=(500, 3)) * (field.fine_dims * field.voxel_size)
    octet, dims = 2.0 * field.voxel_size, field.fine_dims // 2
    for reach in (0.0, 0.07, 0.25):
        got = {tuple(c) for c in morton_decode_np(ondemand.octets_near(field, points, reach))}
        lo = np.clip(np.floor((points - field.origin - reach) / octet).astype(int), 0, dims - 1)
        hi = np.clip(np.floor((points - field.origin + reach) / octet).astype(int), 0, dims - 1)
        want = {
            (x, y, z)
            for a, b in zip(lo, hi, strict=True)
            for x in range(a[0], b[0] + 1)
            for y in range(a[1], b[1] + 1)
            for z in range(a[2], b[2] + 1)
        }
        assert want <= got  # every octet reached; beyond them, only octets of a point's first one and the span
        span = int((hi - lo).max()) + 1
        assert all(any(((np.array(c) >= a) & (np.array(c) < a + span)).all() for a in lo) for c in got - want)


def _finest(field):
    n0 = field.level_counts[0]
    return field.codes.numpy()[:n0], field.values.numpy()[:n0]


def test_a_boolean_of_fields_built_on_demand_is_made_along_its_seams_and_whole_when_asked(spot, cutter):
    full = engine.difference(*engine.build_fields([spot, cutter], voxel_size=H))
    a, b = engine.build_fields([spot, cutter], voxel_size=H, refine="none")
    part = engine.difference(a, b, seams=True)
    # along the seams: a part of the result's finest octets, the same nodes and values there
    codes, values = _finest(part)
    want_codes, want_values = _finest(full)
    assert 0 < len(codes) < 0.18 * len(want_codes)  # measured 0.061 (0.24 read off the other's nodes alone)
    at = np.searchsorted(want_codes, codes)
    assert np.array_equal(want_codes[at], codes) and np.abs(want_values[at] - values).max() < 1e-5 * H
    assert a.refiner.share < 0.27 and b.refiner.share < 0.7  # measured 0.09 and 0.26
    # asked for anything else, the whole result: the full boolean's nodes
    whole = ondemand.refined(part)
    assert whole.refiner is None
    assert np.array_equal(whole.codes.numpy(), full.codes.numpy())
    assert np.abs(whole.values.numpy() - full.values.numpy()).max() < 1e-5 * H
    # the ball's surface outside the cow is never the result's: its octets there are not built
    assert 0.2 < b.refiner.share < 0.7 and a.refiner.share > 0.9  # measured 0.42 and 1.0
    verts, tris = part.to_mesh()
    want_verts, want_tris = full.to_mesh()
    assert len(tris) == len(want_tris) and np.abs(verts - want_verts).max() < 1e-3 * H


def test_a_placed_field_built_on_demand_refines_its_source_for_every_copy(spot, cutter):
    turn = np.eye(4)
    turn[:3, :3] = rotation(2, 30.0)
    turn[:3, 3] = (0.05, -0.02, 0.0)
    full = engine.union(*engine.build_fields([spot, cutter], voxel_size=H))
    a, b = engine.build_fields([spot, cutter], voxel_size=H, refine="none")
    placed = engine.union(a, b.transformed(turn))  # whole at once: the full boolean's nodes
    assert placed.refiner is None
    want = engine.union(full.expression.a, full.expression.b.transformed(turn))
    assert np.array_equal(placed.codes.numpy(), want.codes.numpy())
    assert np.abs(placed.values.numpy() - want.values.numpy()).max() < 1e-5 * H
    assert b.refiner.share > 0.0  # the placed copy's octets were built on its source's refiner
    again = engine.union(a, b.transformed(turn))  # nothing left to build
    assert np.array_equal(again.values.numpy(), placed.values.numpy())


def _band_centres(refiner):
    octet = 2.0 * refiner.levels.plan["voxel_size"]
    return refiner.levels.plan["origin"] + (morton_decode_np(refiner.band) + 0.5) * octet


def test_a_moved_operand_refines_only_its_new_seam(spot):
    top = spot[0][np.argmax(spot[0][:, 2])]  # a ball about the cow's back: a seam all round
    ball = normalised(uv_sphere(1.0, rings=24, segments=48), center=tuple(top), diagonal=0.4)
    a, b = engine.build_fields([spot, ball], voxel_size=H, refine="none")
    engine.difference(a, b, seams=True)
    before = a.refiner.built.copy(), b.refiner.built.copy()
    # only octets along the seam: within the seams' reach and what the result's nodes read beyond it of the other's
    # surface (measured 11.3 voxels at most; bounds read off the other's nodes alone built 1.4 times as many, up to
    # 23 voxels off)
    reach = 1.25 * (ondemand.SEAM_REACH_VOXELS + ondemand.SEAM_READ_VOXELS) * H
    near_ball = unsigned_distance(*ball, _band_centres(a.refiner)[before[0]])
    assert near_ball.max() < reach and 0 < before[0].sum() < 0.3 * len(before[0])  # measured 0.14
    shift = np.float32([6 * H, 0.0, 0.0])
    move = np.eye(4)
    move[:3, 3] = shift
    moved = engine.difference(a, b.transformed(move), seams=True)
    pairs = list(zip((a.refiner, b.refiner), before, strict=True))
    assert all((r.built >= was).all() for r, was in pairs)  # nothing built before is built again
    added = [r.built & ~was for r, was in pairs]
    # the cow's new octets lie along the ball's new surface, away from its old one; the ball's (in its own frame)
    # along the cow's surface moved back
    new_a = _band_centres(a.refiner)[added[0]]
    assert len(new_a) and unsigned_distance(ball[0] + shift, ball[1], new_a).max() < reach
    away = 0.9 * (ondemand.SEAM_REACH_VOXELS + ondemand.SEAM_READ_VOXELS) * H
    assert unsigned_distance(*ball, new_a).min() > away  # measured 11.3 voxels
    new_b = _band_centres(b.refiner)[added[1]]
    assert len(new_b) and unsigned_distance(spot[0] - shift, spot[1], new_b).max() < reach
    assert added[0].sum() < 0.25 * before[0].sum()  # measured 117 octets against 1,416
    # and the result is the full boolean's along its seams
    full = engine.difference(*engine.build_fields([spot, ball], voxel_size=H))
    full = engine.difference(full.expression.a, full.expression.b.transformed(move))
    codes, values = _finest(moved)
    want_codes, want_values = _finest(full)
    at = np.searchsorted(want_codes, codes)
    assert np.array_equal(want_codes[at], codes) and np.abs(want_values[at] - values).max() < 1e-5 * H


def test_offsets_and_kept_faces_of_fields_built_on_demand_equal_the_full_ones(spot, cutter):
    full = engine.build_fields([spot, cutter], voxel_size=H)
    part = engine.build_fields([spot, cutter], voxel_size=H, refine="none")
    grown, want = engine.offset(part[0], 2 * H), engine.offset(full[0], 2 * H)
    assert grown.level_counts == want.level_counts
    assert np.abs(grown.values.numpy() - want.values.numpy()).max() < 1e-4 * H
    seams = engine.union(*part, seams=True)
    kept = seams.kept_surface()
    want_kept = engine.union(*full).kept_surface()
    assert len(kept["tris"]) == len(want_kept["tris"]) and kept["kept"].sum() == want_kept["kept"].sum()
    assert np.abs(np.sort(kept["verts"], axis=0) - np.sort(want_kept["verts"], axis=0)).max() < 1e-3 * H
    verts, tris = seams.to_mesh(keep_faces=True)
    assert len(tris) == len(kept["tris"])
    assert seams.refiner.whole is None  # joined along the seams: the whole result was never made


def test_a_cutter_that_misses_keeps_every_face_and_seams_too_narrow_are_joined_whole(spot, cutter, monkeypatch):
    far = normalised(uv_sphere(1.0, rings=24, segments=48), center=(0.6, 0.0, 0.0), diagonal=0.3)
    a, b = engine.build_fields([spot, far], voxel_size=H, refine="none")
    missed = engine.difference(a, b, seams=True)
    assert missed.level_counts[0] == 0  # no seam: no finest octet
    kept = missed.kept_surface()
    assert kept["kept"].all() and len(kept["tris"]) == len(spot[1]) and is_watertight(kept["tris"])
    empty = engine.intersection(a, b, seams=True).kept_surface()
    assert len(empty["tris"]) == 0
    # seams so narrow that the voxel surface ends before the kept faces begin: joined on the whole result
    monkeypatch.setattr(ondemand, "SEAM_REACH_VOXELS", 1.0)
    full = engine.build_fields([spot, cutter], voxel_size=H)
    part = engine.build_fields([spot, cutter], voxel_size=H, refine="none")
    narrow = engine.difference(*part, seams=True)
    joined = narrow.kept_surface()
    want = engine.difference(*full).kept_surface()
    assert narrow.refiner.whole is not None and not joined["stats"]["join_failed"]
    assert len(joined["tris"]) == len(want["tris"]) and joined["kept"].sum() == want["kept"].sum()


def _side_at(field, points, normals, offset):
    """The judge's reading of a face's side off a field (keep's): +1 growing across it, -1 falling, 0 both sides
    clearly on one side (an internal face)."""
    front = field.sample(points + offset * normals, method="linear")
    back = field.sample(points - offset * normals, method="linear")
    clear = 0.25 * offset
    internal = (np.maximum(front, back) < -clear) | (np.minimum(front, back) > clear)
    return np.where(internal, 0, np.where(front >= back, 1, -1)).astype(np.int8)


def test_own_sides_of_a_field_built_on_demand_are_the_full_fields():
    verts, tris = normalised(load_mesh("rocker-arm.obj"))
    h, offset = 1.0 / 256, 0.5 / 256  # the judge's offset: half a voxel
    full = engine.build_field(verts, tris, voxel_size=h)
    part = engine.build_field(verts, tris, voxel_size=h, refine="none")
    verts, tris = verts.astype(np.float32), np.asarray(tris)
    normals = np.cross(verts[tris[:, 1]] - verts[tris[:, 0]], verts[tris[:, 2]] - verts[tris[:, 0]])
    centres, normals = verts[tris].mean(axis=1), normals / np.linalg.norm(normals, axis=1, keepdims=True)
    want = _side_at(full, centres, normals, offset)
    sides = ondemand.own_sides(part, centres, normals, offset, _side_at)
    assert np.array_equal(sides, want)  # (a narrow groove reads internal off the mesh, not off the field)
    assert part.refiner.share < 0.2  # off the field only where the mesh's reading is not clear


def test_an_operand_that_passes_through_itself_is_built_whole_for_its_kept_faces():
    box_v, box_t = normalised(box_mesh(), diagonal=1.0)
    other = normalised(box_mesh(), center=(0.25, 0.2, 0.15), diagonal=1.0)
    overlap = (np.concatenate([box_v, other[0]]), np.concatenate([box_t, other[1] + len(box_v)]))
    ball = normalised(uv_sphere(1.0, rings=32, segments=64), center=(0.3, 0.3, 0.3), diagonal=0.5)
    a, b = engine.build_fields([overlap, ball], voxel_size=H, refine="none")
    assert a.refiner is not None  # closed and oriented, though it crosses itself
    result = engine.difference(a, b, seams=True)
    kept = result.kept_surface()
    want = engine.difference(*engine.build_fields([overlap, ball], voxel_size=H)).kept_surface()
    assert is_watertight(kept["tris"]) and a.refiner.share == 1.0  # read at every sample: built whole
    corners = kept["verts"][kept["tris"][kept["kept"] & (kept["field_id"] == 0)]].mean(axis=1)
    assert not (winding_inside(box_v, box_t, corners) & winding_inside(*other, corners)).any()
    # the same judge; the voxel surface's extent (along the seams alone) moves a few faces at its end (measured 8 kept
    # faces more of 3,811)
    assert abs(len(kept["tris"]) / len(want["tris"]) - 1) < 0.01 and abs(kept["kept"].sum() - want["kept"].sum()) < 16
    # marked with where it gives its faces up: the next boolean builds it whole at once, its octets kept along the
    # seams and about there (the ball's along the seams, as before), joined without the whole result
    assert ondemand.along_seams_only(a, b) and ondemand.along_seams_only(b, a)
    again = engine.difference(a, b, seams=True)
    assert len(again.kept_surface()["tris"]) == len(kept["tris"]) and again.refiner.whole is None


@pytest.mark.parametrize("hole", [False, True])  # spot, and spot with a hole in its back (about its cap too)
def test_meshes_built_whole_closed_or_open_are_made_along_their_seams(spot, cutter, hole):
    verts, tris = spot
    centres = verts[tris].mean(axis=1)
    top = np.linalg.norm(centres - centres[np.argmax(centres[:, 2])], axis=1) < (0.05 if hole else 0.0)
    a, b = engine.build_fields([(verts, tris[~top]), cutter], voxel_size=H)  # built whole
    assert ("hole_caps" in a.stats) == hole and ondemand.along_seams_only(a, b) and ondemand.along_seams_only(b, a)
    full, part = engine.difference(a, b), engine.difference(a, b, seams=True)
    assert 0 < part.level_counts[0] < (0.6 if hole else 0.18) * full.level_counts[0]  # measured 0.22 and 0.061
    kept, want = part.kept_surface(), full.kept_surface()
    assert part.refiner.whole is None  # joined along the seams: the whole result was never made
    assert is_watertight(kept["tris"]) and kept["kept"].sum() == want["kept"].sum()
    assert len(kept["tris"]) == len(want["tris"])
    assert np.abs(np.sort(kept["verts"], axis=0) - np.sort(want["verts"], axis=0)).max() < 1e-3 * H


@pytest.mark.parametrize("depth", [3, 1])  # the slab a third of the octets (counted from those kept), or most of them
def test_pinholes_and_notches_an_octet_wide_are_closed_and_nothing_else(depth):
    from engine.octree import filled_notches, morton_encode_np

    grid = np.stack(np.meshgrid(np.arange(6), np.arange(6), np.arange(depth), indexing="ij"), axis=-1).reshape(-1, 3)
    codes = np.sort(morton_encode_np(grid))
    coords = morton_decode_np(codes)
    z = depth // 2
    keep = coords[:, 2] == z  # a slab one octet thick
    pinhole, notch, corner = (coords == (2, 3, z)).all(axis=1), (coords == (0, 2, z)).all(axis=1), (coords == (0, 0, z))
    keep &= ~pinhole & ~notch & ~corner.all(axis=1)  # its hole (4 kept neighbours), edge notch (3), corner (2)
    out = filled_notches(codes, keep)
    assert out[pinhole].all() and out[notch].all() and not out[corner.all(axis=1)].any()
    assert np.array_equal(out & ~(pinhole | notch), keep)  # nothing else: the slab's sides have 1 neighbour each


def test_a_copy_placed_five_voxels_off_is_joined_along_its_seams():
    """The rocker arm united with its copy placed 5.12 voxels along x, built whole: its octets within 6 voxels of the
    copy left one out among kept ones, and the surface made along the seams had a hole a voxel across that no kept
    face bordered; the join ran out of rounds and the whole result was made and joined (1.8 s against 0.9)."""
    from tests.support import cad_pairs

    arm = cad_pairs()["rocker-arm - cube"][1]
    h = float(np.linalg.norm(arm[0].max(0) - arm[0].min(0))) / 256
    a, b = engine.build_fields([arm, arm], voxel_size=h)
    shift = np.eye(4)
    shift[0, 3] = 5.12 * h
    result = engine.union(a, b.transformed(shift), seams=True)
    kept = result.kept_surface()
    assert result.refiner.whole is None  # joined along the seams
    assert is_watertight(kept["tris"]) and kept["kept"].sum() > 0.4 * 2 * len(arm[1])  # measured 16,560 of 40,176


def test_a_mesh_built_whole_that_passes_through_itself_is_made_along_its_seams_and_its_crossings():
    # two overlapping boxes as one mesh: its faces are given up about where it crosses itself, away from the seams
    overlap = overlapping_boxes()
    ball = normalised(uv_sphere(1.0, rings=32, segments=64), center=(0.3, 0.3, 0.3), diagonal=0.5)
    c, d = engine.build_fields([overlap, ball], voxel_size=H)
    first = engine.difference(c, d, seams=True)
    kept = first.kept_surface()
    full = engine.difference(c, d)
    want = full.kept_surface()
    assert first.refiner.whole is None and is_watertight(kept["tris"])  # made again about its crossings, not whole
    assert len(kept["tris"]) == len(want["tris"]) and kept["kept"].sum() == want["kept"].sum()
    assert np.abs(np.sort(kept["verts"], axis=0) - np.sort(want["verts"], axis=0)).max() < 1e-3 * H
    # marked with where it gives its faces up: the next booleans build its octets and those beside it there and
    # along the seams, not all of them (measured 0.31 of the whole result's finest octets)
    assert ondemand.along_seams_only(c, d) and ondemand.along_seams_only(d, c)
    again = engine.difference(c, d, seams=True)
    assert again.level_counts[0] < 0.6 * full.level_counts[0]
    surface = again.kept_surface()
    assert again.refiner.whole is None and len(surface["tris"]) == len(want["tris"])


def _enclosed(verts, tris) -> float:
    v = np.asarray(verts, dtype=np.float64)
    return float(np.einsum("ij,ij->i", v[tris[:, 0]], np.cross(v[tris[:, 1]], v[tris[:, 2]])).sum() / 6.0)


@pytest.mark.parametrize("refine", ["none", "all"])
def test_defects_other_than_holes_far_from_the_seams_keep_their_surface(refine):
    # a closed unit box listing each face twice (every face repeated: none kept), and two boxes sharing an edge (an
    # edge of four faces): their faces near the defects are given up, so the voxel surface must be made there too,
    # though no seam is near; both vanished from the union with a ball beside them (the join gave every face up, and
    # the ball alone was a closed surface)
    box_v, box_t = box_mesh((0.5, 0.5, 0.5))
    doubled = (box_v, np.concatenate([box_t, box_t]))
    other = box_mesh((0.5, 0.5, 0.5), center=(1.0, 1.0, 0.0))
    sharing = (np.concatenate([box_v, other[0]]), np.concatenate([box_t, other[1] + len(box_v)]))
    ball = uv_sphere(0.5, rings=16, segments=32)
    ball = (ball[0] + np.array([2.5, 0.5, 0.5], np.float32), ball[1])
    for mesh, volume in ((doubled, 1.0), (sharing, 2.0)):
        fields = engine.build_fields([mesh, ball], voxel_size=1.0 / 32, refine=refine)
        kept = engine.union(*fields, seams=True).kept_surface()
        assert is_watertight(kept["tris"]) and not kept["stats"]["kept_fallback"]
        enclosed = _enclosed(kept["verts"], kept["tris"]) - _enclosed(*ball)
        assert abs(enclosed - volume) < 0.01 * volume, enclosed  # (the boxes' faces are the lattice's planes)
        from_box = kept["kept"] & (kept["field_id"] == 0)
        assert from_box.any() != (mesh is doubled)  # (repeated faces are never kept)


def test_a_join_that_gives_up_faces_no_voxel_surface_lies_under_is_made_whole(monkeypatch):
    # should a defect go unnoticed (two boxes sharing an edge taken for a clean mesh: no octet about it), the join
    # along the seams alone gives every face of the boxes up, round by round; that is caught, and the whole result
    # joined instead
    import engine.earlyjudge

    monkeypatch.setattr(engine.earlyjudge, "gives_own_faces_up", lambda leaf, voxel: False)
    box_v, box_t = box_mesh((0.5, 0.5, 0.5))
    other = box_mesh((0.5, 0.5, 0.5), center=(1.0, 1.0, 0.0))
    sharing = (np.concatenate([box_v, other[0]]), np.concatenate([box_t, other[1] + len(box_v)]))
    ball = uv_sphere(0.5, rings=16, segments=32)
    ball = (ball[0] + np.array([2.5, 0.5, 0.5], np.float32), ball[1])
    result = engine.union(*engine.build_fields([sharing, ball], voxel_size=1.0 / 32, refine="none"), seams=True)
    kept = result.kept_surface()
    assert result.refiner.whole is not None  # made whole
    assert is_watertight(kept["tris"]) and (kept["kept"] & (kept["field_id"] == 0)).any()
    assert abs(_enclosed(kept["verts"], kept["tris"]) - _enclosed(*ball) - 2.0) < 0.02


def test_an_open_mesh_built_on_demand_builds_about_its_holes_first_and_refines_to_the_full_build():
    bunny = normalised(load_mesh("stanford-bunny.obj"))  # open: its build refines across its holes
    full = engine.build_field(*bunny, voxel_size=H)
    part = engine.build_field(*bunny, voxel_size=H, refine="none")
    assert 0.0 < part.refiner.share < 0.6  # the octets about its holes' caps (measured 0.28 at /256)
    assert part.stats["sign_refinements"] == full.stats["sign_refinements"]
    whole = ondemand.refined(part)
    assert np.array_equal(whole.codes.numpy(), full.codes.numpy())
    assert np.abs(whole.values.numpy() - full.values.numpy()).max() < 1e-5 * H
    assert "hole_caps" in whole.stats  # where its sign may jump: a boolean reads no bound there
    box = engine.build_field(*box_mesh(), voxel_size=0.1, levels=2, refine="none")
    assert box.refiner is None  # no level between the finest and the dense top: built whole


def test_auto_builds_on_demand_where_the_band_is_large_for_the_triangles(spot):
    coarse = engine.build_field(*spot, voxel_size=H, refine="auto")  # 13 finest nodes a triangle: built whole
    fine = engine.build_field(*spot, voxel_size=H / 2, refine="auto")  # 54 a triangle: on demand
    assert coarse.refiner is None and coarse.level_counts[0] < 24 * len(spot[1])
    assert fine.refiner is not None and fine.level_counts[0] == 0


def test_auto_builds_a_mesh_that_passes_through_itself_whole():
    # two boxes through each other: a boolean that keeps faces would refine it whole (its own field read everywhere)
    boxes = normalised(overlapping_boxes())
    assert engine.build_field(*boxes, voxel_size=H, refine="none").refiner is not None  # (its band is large)
    whole = engine.build_field(*boxes, voxel_size=H, refine="auto")
    assert whole.refiner is None and whole.level_counts[0] > 0
    assert engine.build_field(*normalised(box_mesh()), voxel_size=H, refine="auto").refiner is not None


def test_build_fields_takes_one_refine_per_mesh(spot):
    box = normalised(box_mesh())
    whole, part = engine.build_fields([spot, box], voxel_size=H, refine=["all", "none"])
    assert whole.refiner is None and whole.level_counts[0] > 0
    assert part.refiner is not None and part.level_counts[0] == 0
    with pytest.raises(ValueError, match="1 refine values for 2 meshes"):
        engine.build_fields([spot, box], voxel_size=H, refine=["all"])
    with pytest.raises(ValueError, match="'refine' to be 'all', 'none' or 'auto'"):
        engine.build_fields([spot, box], voxel_size=H, refine=["all", "some"])


def test_an_unknown_refine_is_refused_before_any_work(spot):
    with pytest.raises(ValueError, match="'refine' to be 'all', 'none' or 'auto'"):
        engine.build_field(*spot, voxel_size=H, refine="seams")
    with pytest.raises(ValueError, match="'refine' to be 'all', 'none' or 'auto'"):
        engine.build_fields([spot], voxel_size=H, refine=None)
