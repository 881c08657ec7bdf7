"""Field operations: offsets and shells against analytic shapes, thickness for surfaces that enclose nothing, chamfer
blends against the analytic bevel, bad input."""

import manifold3d
import numpy as np
import pytest

import engine
from engine import fieldops
from engine.octree import morton_decode_np
from engine.quads import triangulate
from tests.engine.test_field import _check_structure
from tests.metrics import exact_boolean, hausdorff, mesh_volume, to_manifold, unsigned_distance, winding_inside
from tests.support import box_mesh, is_watertight, load_mesh, normalised, uv_sphere

H = 0.04
HALF = np.array([0.6, 0.5, 0.4])


def _box_sdf(p, half):
    q = np.abs(p) - half
    return np.linalg.norm(np.maximum(q, 0.0), axis=1) + np.minimum(q.max(axis=1), 0.0)


def _sheet(n=4, size=1.0):
    """A square of triangles in the plane z = 0, spanning [-size, size]^2: a surface that encloses nothing."""
    g = np.linspace(-size, size, n + 1)
    x, y = np.meshgrid(g, g, indexing="ij")
    verts = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], axis=1).astype(np.float32)
    ids = np.arange(x.size).reshape(n + 1, n + 1)
    a, b, c, d = ids[:-1, :-1], ids[1:, :-1], ids[1:, 1:], ids[:-1, 1:]
    tris = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)])
    return verts, tris.astype(np.int32)


@pytest.fixture(scope="module")
def ball():
    return engine.build_field(*uv_sphere(1.0, rings=64, segments=128), voxel_size=H)


@pytest.fixture(scope="module")
def cube():
    return engine.build_field(*box_mesh(half=tuple(HALF), subdivisions=4), voxel_size=H)


# ---- offset ----


@pytest.mark.parametrize(("distance", "max_voxels"), [(0.5, 0.1), (-0.5, 0.065)])  # measured 0.034, 0.021 voxel
def test_a_sphere_offset_by_half_its_radius_is_exact(ball, distance, max_voxels):
    grown = engine.offset(ball, distance)
    verts, tris = grown.to_mesh()
    assert is_watertight(tris)
    assert np.abs(np.linalg.norm(verts, axis=1) - (1.0 + distance)).max() <= max_voxels * H
    # far beyond the old band, and a signed distance everywhere (measured p95 0.41 %, max 0.14 voxel)
    pts = np.random.default_rng(0).uniform(*grown.bounds, (20_000, 3)).astype(np.float32)
    exact = np.linalg.norm(pts, axis=1) - (1.0 + distance)
    got = grown.sample(pts)
    far = np.abs(exact) > 4 * H
    assert np.percentile(np.abs(got - exact)[far] / np.abs(exact[far]), 95) <= 0.012
    assert np.abs(got - exact).max() <= 0.4 * H
    assert grown.stats["exact_distance"]
    _check_structure(grown)


def test_an_outward_offset_grows_the_domain(ball):
    grown = engine.offset(ball, 0.5)
    lo, hi = grown.bounds
    assert np.all(lo < -1.5) and np.all(hi > 1.5)
    assert np.all(ball.bounds[1] < 1.5)  # the sphere's own domain ends before the new surface


def test_a_large_offset_adds_levels_to_keep_the_top_level_small():
    small = engine.build_field(*uv_sphere(1.0, rings=32, segments=64), voxel_size=0.1)
    grown = engine.offset(small, 3.0)
    assert grown.levels == small.levels + 1
    verts, _ = grown.to_mesh()
    assert np.abs(np.linalg.norm(verts, axis=1) - 4.0).max() <= 0.1 * 0.1  # measured 0.043 voxel


def test_a_cube_offset_outward_has_exactly_rounded_edges(cube):
    d = 0.2
    verts, tris = engine.offset(cube, d).to_mesh()
    assert is_watertight(tris)
    # the rounded box: exact radius d around every edge and corner (measured 0.025 voxel)
    assert np.abs(_box_sdf(verts.astype(np.float64), HALF) - d).max() <= 0.075 * H
    a, b, c = 2 * HALF
    volume = a * b * c + 2 * d * (a * b + b * c + c * a) + np.pi * d * d * (a + b + c) + 4 / 3 * np.pi * d**3
    assert mesh_volume(verts, tris) == pytest.approx(volume, rel=0.0045)  # measured -0.15 %


def test_a_cube_offset_inward_keeps_sharp_edges(cube):
    verts, _ = engine.offset(cube, -0.1).to_mesh()
    assert np.abs(_box_sdf(verts.astype(np.float64), HALF - 0.1)).max() <= 0.01 * H  # measured 0.002 voxel


def test_a_boolean_is_redistanced_before_its_offset():
    a = engine.build_field(*uv_sphere(1.0, rings=48, segments=96), voxel_size=H)
    b = engine.build_field(*uv_sphere(1.0, center=(1.2, 0.0, 0.0), rings=48, segments=96), voxel_size=H)
    union = engine.union(a, b)
    assert not union.stats.get("surface_points", False)  # a union's closest points may lie inside the other sphere
    verts, tris = engine.offset(union, 0.3).to_mesh()
    assert is_watertight(tris)
    both = np.minimum(np.linalg.norm(verts, axis=1), np.linalg.norm(verts - np.float32([1.2, 0, 0]), axis=1))
    err = np.abs(both - 1.3)
    assert np.percentile(err, 99) <= 0.11 * H  # measured 0.038 voxel
    # the largest error is at the seam x = 0.6, where the union's marching-cubes surface bridges the crease
    assert err.max() <= 0.75 * H  # measured 0.47 voxel


def test_a_chamfered_boolean_is_redistanced_on_the_side_its_leaves_read():
    # a rocker arm chamfered with itself: some of the boolean's coarse nodes that have children hold a value of the
    # wrong sign a few voxels off its surface (what their level read of the chamfer); redistanced, such a node that
    # became a leaf kept that sign, and the offset's surface ran into it and left a hole
    mesh = normalised(load_mesh("rocker-arm.obj"))
    h = 1.0 / 128
    (arm,) = engine.build_fields([mesh], voxel_size=h)
    chamfered = engine.intersection(arm, arm, blend=16 * h, blend_mode="chamfer")
    verts, tris = chamfered.to_mesh()
    field = engine.redistance(chamfered)
    for k in range(1, field.levels - 1):
        rows = slice(int(field.level_offsets[k]), int(field.level_offsets[k + 1]))
        centres = field.origin + (morton_decode_np(field.codes.numpy()[rows]) + 0.5) * h * 2**k
        truth = np.where(winding_inside(verts, tris, centres), -1.0, 1.0) * unsigned_distance(verts, tris, centres)
        wrong = (np.sign(field.values.numpy()[rows]) != np.sign(truth)) & (np.abs(truth) > h)
        assert not wrong.any(), (k, int(wrong.sum()))  # 49 nodes more than a voxel off, before
    assert is_watertight(engine.offset(chamfered, 1.9 * h).to_mesh()[1])  # 43 open edges before


def test_an_offset_of_a_blended_shell_is_closed():
    # a turned box grown by 3.3 voxels, less the box blended by 4 and grown again by 4.6: in the shell's concave
    # blend, walks through its closest points ended a voxel or two far, a band cell the new surface passes was culled
    # and a node read outside what it lies inside (3 open edges); the distances are now held near its triangles'
    corners = np.float32(
        [
            [-0.141327, 0.750933, 0.434358],
            [-0.335364, 0.566085, 0.202186],
            [0.277618, 0.582361, 0.218439],
            [0.083581, 0.397513, -0.013733],
            [-0.142834, 1.021514, 0.22019],
            [-0.33687, 0.836666, -0.011982],
            [0.276111, 0.852942, 0.00427],
            [0.082075, 0.668094, -0.227902],
        ]
    )
    tris = np.int32([[3, 2, 0], [1, 3, 0], [4, 6, 7], [4, 7, 5], [5, 1, 0], [4, 5, 0], [2, 3, 7], [2, 7, 6]])
    tris = np.concatenate([tris, np.int32([[6, 4, 0], [2, 6, 0], [1, 5, 7], [1, 7, 3]])])
    h = 0.0112
    box = engine.build_field(corners, tris, voxel_size=h)
    shell = engine.difference(engine.offset(box, 3.3 * h), box, blend=4.0 * h)
    assert is_watertight(engine.offset(shell, 4.6 * h).to_mesh()[1])


def test_a_far_offset_of_a_concave_shape_outside_its_domain_is_exact():
    # 93 % of the new surface lies outside the union's domain, where the nearest of the union's closest points is
    # looked for from the domain's border: its foot may lie as far aside as the point lies out
    h = 0.1
    a = engine.build_field(*uv_sphere(1.0, rings=32, segments=64), voxel_size=h)
    b = engine.build_field(*uv_sphere(0.8, center=(1.4, 0.3, 0.0), rings=32, segments=64), voxel_size=h)
    verts, _ = engine.offset(engine.union(a, b), 2.0).to_mesh()
    both = np.minimum(
        np.linalg.norm(verts, axis=1) - 1.0, np.linalg.norm(verts - np.float32([1.4, 0.3, 0]), axis=1) - 0.8
    )
    err = np.abs(both - 2.0)
    assert np.percentile(err, 99) <= 0.15 * h  # measured 0.052 voxel
    assert err.max() <= 0.45 * h  # measured 0.16 voxel (3.5 voxels on spot before the border's wider search)


def test_shrinking_a_thin_shape_away_leaves_an_empty_field():
    thin = engine.build_field(*box_mesh(half=(0.5, 0.5, 0.1)), voxel_size=H)
    gone = engine.offset(thin, -0.15)
    assert gone.is_empty
    verts, tris = gone.to_mesh()
    assert verts.shape == (0, 3) and tris.shape == (0, 3)


def test_an_offset_past_the_addressable_domain_is_refused_before_any_work(ball, monkeypatch):
    def no_work(*args, **kwargs):
        raise AssertionError("work started")

    monkeypatch.setattr(fieldops, "levelset_field", no_work)
    monkeypatch.setattr(fieldops, "redistance", no_work)
    with pytest.raises(engine.AasdfError, match="the octree can address; use a smaller distance"):
        engine.offset(ball, 1.0e6)
    with pytest.raises(engine.AasdfError, match="octree can address"):
        engine.shell(ball, 1.0e6, side="outside")


@pytest.mark.parametrize(("distance", "error", "match"), [
    (float("nan"), ValueError, "Expected a finite 'distance', but got nan"),
    (float("inf"), ValueError, "Expected a finite 'distance', but got inf"),
    ("far", TypeError, "Expected a number for 'distance'"),
])  # fmt: skip
def test_bad_distances_are_refused(ball, distance, error, match):
    with pytest.raises(error, match=match):
        engine.offset(ball, distance)


def test_offset_wants_a_field():
    with pytest.raises(TypeError, match="Expected 'field' to be an AdaptiveField"):
        engine.offset("ball", 0.1)


# ---- shell ----


@pytest.mark.parametrize(("side", "inner", "outer", "rel"), [
    ("inside", 0.8, 1.0, 0.0055),  # measured -0.18 %
    ("outside", 1.0, 1.2, 0.0078),  # measured -0.26 %
    ("center", 0.9, 1.1, 0.006),  # measured -0.19 %
])  # fmt: skip
def test_a_hollowed_sphere_has_the_volume_of_its_wall(ball, side, inner, outer, rel):
    hollow = engine.shell(ball, 0.2, side=side)
    verts, tris = hollow.to_mesh()
    assert is_watertight(tris)
    assert mesh_volume(verts, tris) == pytest.approx(4 / 3 * np.pi * (outer**3 - inner**3), rel=rel)  # issue: 1 %
    r = np.linalg.norm(verts, axis=1)
    assert np.abs(np.minimum(np.abs(r - inner), np.abs(r - outer))).max() <= 0.25 * H


def test_walls_thinner_than_two_voxels_are_refused(ball):
    with pytest.raises(engine.AasdfError, match=r"thinner than two voxels \(0.08\).*at least 0.08, or a smaller"):
        engine.shell(ball, 0.06)


@pytest.mark.parametrize(("kwargs", "match"), [
    ({"thickness": float("nan")}, "Expected a finite 'thickness', but got nan"),
    ({"thickness": -0.2}, "Expected a positive 'thickness'"),
    ({"thickness": 0.2, "side": "both"}, "Expected 'side' to be one of"),
])  # fmt: skip
def test_bad_shells_are_refused(ball, kwargs, match):
    with pytest.raises(ValueError, match=match):
        engine.shell(ball, **kwargs)


# ---- thickness ----


@pytest.fixture(scope="module")
def thick_sheet():
    return engine.build_field(*_sheet(), voxel_size=H, thickness=0.2)


def test_a_sheet_with_thickness_is_a_solid_slab(thick_sheet):
    verts, tris = thick_sheet.to_mesh()
    assert is_watertight(tris)
    t = 0.2  # a 2 x 2 slab with half-cylinder edges and quarter-sphere corners
    volume = 4 * t + 8 * np.pi * (t / 2) ** 2 / 2 + 4 / 3 * np.pi * (t / 2) ** 3
    assert mesh_volume(verts, tris) == pytest.approx(volume, rel=0.015)  # measured -0.48 %
    pts = np.random.default_rng(0).uniform([-0.9, -0.9, -0.5], [0.9, 0.9, 0.5], (5000, 3)).astype(np.float32)
    err = np.abs(thick_sheet.sample(pts) - (np.abs(pts[:, 2]) - t / 2))
    assert np.percentile(err[np.abs(pts[:, 2]) > 1.5 * H], 99) <= 0.1 * H  # measured 0.036 voxel
    # the linear MLS fit spans the kink of |z| on the slab's medial plane z = 0
    assert err.max() <= 0.75 * H  # measured 0.51 voxel


def test_a_plane_with_thickness_cuts_a_slot(thick_sheet):
    box = box_mesh(half=(0.5, 0.5, 0.5), subdivisions=2)
    slot = engine.difference(engine.build_field(*box, voxel_size=H, field_id=1), thick_sheet)
    verts, tris = slot.to_mesh()
    assert is_watertight(tris)
    faces = (np.abs(verts[:, 0]) < 0.4) & (np.abs(verts[:, 1]) < 0.4) & (np.abs(verts[:, 2]) < 0.3)
    assert np.abs(np.abs(verts[faces, 2]) - 0.1).max() <= 0.003 * H  # measured 0.001 voxel
    exact = exact_boolean("DIFFERENCE", *box, *box_mesh(half=(1.5, 1.5, 0.1)))
    assert hausdorff(verts, tris, *exact, n=20_000)["p95"] <= H  # measured 0.46 voxel (sharp edges)
    assert slot.sample(np.float32([[0.0, 0.0, 0.0], [0.0, 0.0, 0.3]])).tolist()[0] > 0.0


def test_a_closed_mesh_with_thickness_becomes_a_shell_centred_on_it():
    hollow = engine.build_field(*uv_sphere(1.0, rings=64, segments=128), voxel_size=H, thickness=0.2)
    verts, tris = hollow.to_mesh()
    assert mesh_volume(verts, tris) == pytest.approx(4 / 3 * np.pi * (1.1**3 - 0.9**3), rel=0.0027)  # -0.09 %


def test_build_fields_takes_a_thickness_per_mesh(thick_sheet):
    box = box_mesh(half=(0.5, 0.5, 0.5))
    solid, sheet = engine.build_fields([box, _sheet()], voxel_size=H, thickness=[None, 0.2])
    assert mesh_volume(*solid.to_mesh()) == pytest.approx(1.0, rel=0.02)  # measured -0.75 % (sharp edges)
    np.testing.assert_allclose(sheet.values.numpy(), thick_sheet.values.numpy(), atol=1e-6)
    with pytest.raises(ValueError, match=r"Expected one thickness per mesh \(2\), but got 3"):
        engine.build_fields([box, _sheet()], voxel_size=H, thickness=[0.2, 0.2, 0.2])


def test_check_meshes_plans_the_thickness():
    plain = engine.check_meshes([_sheet()], voxel_size=H)
    assert engine.check_meshes([_sheet()], voxel_size=H, thickness=0.2) > plain  # both sides of the sheet
    with pytest.raises(engine.AasdfError, match="A thickness of 0.05 is thinner than two voxels"):
        engine.check_meshes([_sheet()], voxel_size=H, thickness=0.05)
    with pytest.raises(engine.AasdfError, match="Mesh 0: A thickness of 1e.07 needs a domain of .* octree can"):
        engine.check_meshes([_sheet()], voxel_size=H, thickness=1.0e7)


@pytest.mark.parametrize(("thickness", "error", "match"), [
    (float("inf"), ValueError, "Expected a finite 'thickness', but got inf"),
    (0.0, ValueError, "Expected a positive 'thickness'"),
    (0.05, engine.AasdfError, "thinner than two voxels"),
])  # fmt: skip
def test_bad_thicknesses_are_refused(thickness, error, match):
    with pytest.raises(error, match=match):
        engine.build_field(*_sheet(), voxel_size=H, thickness=thickness)


# ---- chamfer blends ----

K = 0.2  # the bevel meets each face this far from the seam


def _boxes(op):
    """Two boxes whose seam runs along z, the bevel's plane as a signed offset (x, y) -> offset and the seam's
    quadrant in the seam's own coordinates (u, v: each face's distance from the seam, positive on the bevel's side)."""
    a = box_mesh(half=(0.5, 1.0, 1.0), center=(-0.5, 0.0, 0.0), subdivisions=2)
    b = box_mesh(half=(1.0, 0.5, 1.0), center=(0.0, -0.5, 0.0), subdivisions=2)
    if op == "UNION":  # a concave seam in the quadrant x, y > 0: the bevel x + y = K
        return a, b, lambda x, y: x + y - K, lambda x, y: (x, y)
    if op == "INTERSECT":  # a convex seam in the quadrant x, y < 0: the bevel x + y = -K
        return a, b, lambda x, y: x + y + K, lambda x, y: (-x, -y)
    # a cube less the half space x > 0: a convex seam where x = 0 meets y = 1, the bevel x + (y - 1) = -K
    c = box_mesh(half=(1.0, 1.0, 1.0), subdivisions=2)
    cut = box_mesh(half=(1.0, 2.0, 2.0), center=(1.0, 0.0, 0.0), subdivisions=2)
    return c, cut, lambda x, y: x + y - 1.0 + K, lambda x, y: (-x, 1.0 - y)


@pytest.mark.parametrize("op", ["UNION", "INTERSECT", "DIFFERENCE"])
def test_a_chamfer_is_the_flat_bevel_between_perpendicular_faces(op):
    a, b, plane, seam = _boxes(op)
    fa, fb = engine.build_fields([a, b], voxel_size=H)
    fn = {"UNION": engine.union, "INTERSECT": engine.intersection, "DIFFERENCE": engine.difference}[op]
    verts, tris = fn(fa, fb, blend=K, blend_mode="chamfer").to_mesh()
    assert is_watertight(tris)
    u, v = seam(verts[:, 0], verts[:, 1])
    # vertices strictly between the bevel's two edges (each K from the seam), away from the boxes' ends
    on_bevel = (u > 0.1 * K) & (v > 0.1 * K) & (u < 0.9 * K) & (v < 0.9 * K) & (np.abs(verts[:, 2]) < 0.5)
    assert on_bevel.sum() > 100  # measured 144-175
    err = np.abs(plane(verts[on_bevel, 0], verts[on_bevel, 1]))
    assert err.max() <= 0.004 * H  # measured 0.0014 voxel
    # the round blend of the same size does not lie on it: on the seam's diagonal it is K / (2 sqrt 2) inside
    round_verts, _ = fn(fa, fb, blend=K).to_mesh()
    u, v = seam(round_verts[:, 0], round_verts[:, 1])
    diagonal = (np.abs(u - v) < 0.5 * H) & (u > 0) & (np.abs(round_verts[:, 2]) < 0.5)
    assert np.abs(plane(round_verts[diagonal, 0], round_verts[diagonal, 1])).min() > 2 * H  # measured 2.45 voxels


def _bevelled_half_cube(k):
    """The cube [-1, 1]^3 less x > 0, each of its four edges on x = 0 cut by the plane k from both faces (exact)."""
    solid = manifold3d.Manifold.cube([2.0, 2.0, 2.0], True).trim_by_plane([-1.0, 0.0, 0.0], 0.0)
    for axis, side in ((1, 1.0), (1, -1.0), (2, 1.0), (2, -1.0)):
        normal = np.zeros(3)
        normal[0], normal[axis] = -1.0, -side
        solid = solid.trim_by_plane((normal / np.sqrt(2.0)).tolist(), -(1.0 - k) / np.sqrt(2.0))  # x + |y| <= 1 - k
    mesh = solid.to_mesh()
    return np.asarray(mesh.vert_properties, dtype=np.float32)[:, :3], np.asarray(mesh.tri_verts, dtype=np.int32)


def test_a_small_chamfer_is_its_exact_bevel():
    # a blend of 2.5 voxels on the cube less a half space: four flat bevels of legs k, where two meet a corner cut
    k = 2.5 * H
    c, cut, _, _ = _boxes("DIFFERENCE")
    fc, fcut = engine.build_fields([c, cut], voxel_size=H)
    verts, tris = engine.difference(fc, fcut, blend=k, blend_mode="chamfer").to_mesh()
    exact = _bevelled_half_cube(k)
    assert is_watertight(tris)
    assert mesh_volume(*exact) == pytest.approx(4.0 - 4.0 * k * k + 4.0 * k**3 / 3.0, rel=1e-7)
    removed = 4.0 - mesh_volume(verts, tris)
    distance = hausdorff(verts, tris, *exact, n=50_000)["p95"]
    assert removed == pytest.approx(4.0 - mesh_volume(*exact), rel=0.06)  # measured +1.9 %
    assert distance <= 0.06 * H  # measured 0.021 voxel
    # and not the hard difference: that one keeps the edges
    hard = engine.difference(fc, fcut).to_mesh()
    assert 4.0 - mesh_volume(*hard) < 0.2 * removed


def test_an_unknown_blend_mode_is_refused():
    fa = engine.build_field(*uv_sphere(0.5), voxel_size=0.05)
    with pytest.raises(ValueError, match="Expected 'blend_mode' to be one of \\['chamfer', 'round'\\]"):
        engine.union(fa, fa, blend=0.1, blend_mode="bevel")


def test_an_offset_of_a_placed_field_is_grown_where_the_field_is_placed(cube):
    # a cube turned 30 degrees about z, doubled and moved: its offset is the grown box in the new place
    turn = np.radians(30.0)
    matrix = np.eye(4)
    matrix[:3, :3] = 2.0 * np.array([[np.cos(turn), -np.sin(turn), 0], [np.sin(turn), np.cos(turn), 0], [0, 0, 1]])
    matrix[:3, 3] = (3.0, -1.0, 0.5)
    placed = cube.transformed(matrix)
    verts, tris = engine.offset(placed, -0.2).to_mesh()
    assert is_watertight(tris)
    local = (verts.astype(np.float64) - matrix[:3, 3]) @ (matrix[:3, :3] / 2.0)  # back into the cube's frame, x 2
    err = np.abs(_box_sdf(local, 2.0 * HALF - 0.2)).max() / (2.0 * H)
    assert err <= 0.006, err  # measured 0.002 voxel, as unplaced


def test_an_offset_asked_for_polygons_is_dual_contoured_and_merges_where_flat(cube):
    """Quads and an adaptivity are the dual surface's: an offset gives them as a boolean does (its closest points lie
    on the re-distanced surface, so no crease beyond it)."""
    d = 0.2
    grown = engine.offset(cube, d)
    counts = {}
    for adaptivity in (0.0, 0.5):
        verts, faces, sizes = grown.to_mesh(quads=True, adaptivity=adaptivity)
        tris = triangulate(faces, sizes)
        assert is_watertight(tris)
        to_manifold(verts, tris)  # 2-manifold
        error = np.abs(_box_sdf(verts.astype(np.float64), HALF) - d) / H
        counts[adaptivity] = len(sizes)
        if adaptivity == 0.0:
            assert np.mean(sizes == 4) > 0.95  # measured 1.0
            assert error.max() <= 0.2, error.max()  # measured 0.068 voxel
        else:
            assert error.max() <= 0.8, error.max()  # measured 0.27 voxel
    assert counts[0.5] < counts[0.0] / 6.5, counts  # measured 7,272 -> 372 polygons
    np.testing.assert_array_equal(grown.to_mesh()[0], grown.to_mesh(sharp=False)[0])  # triangles: marching cubes


@pytest.mark.parametrize(("blend_voxels", "mode"), [(0, "round"), (8, "chamfer"), (8, "round")])
def test_a_box_intersected_with_a_sheet_is_empty_and_so_are_its_offsets(blend_voxels, mode):
    """A box intersected with a sheet turned about (a surface that encloses nothing). The sheet's distance is
    unsigned, kinked on it: read through a fit or a tangent plane across it, it read below 0 on its far side (14-59
    nodes down to -0.9 voxel, ``is_empty`` False, 0.9 % of the box read inside by ``sample``), and an offset grown by 5
    voxels made 8,980 triangles with holes. A field with no node inside is now read as its absolute value."""
    h = 2.0 * np.sqrt(3.0) / 64
    turn = np.eye(4)
    c, s = np.cos([0.714, 1.958, 0.264]), np.sin([0.714, 1.958, 0.264])
    rx = np.array([[1, 0, 0], [0, c[0], -s[0]], [0, s[0], c[0]]])
    ry = np.array([[c[1], 0, s[1]], [0, 1, 0], [-s[1], 0, c[1]]])
    rz = np.array([[c[2], -s[2], 0], [s[2], c[2], 0], [0, 0, 1]])
    turn[:3, :3], turn[:3, 3] = rz @ ry @ rx, [0.133, 0.115, -0.104]
    sheet = _sheet(n=24)
    sheet = (sheet[0] + np.float32([0.0, 0.0, 0.05]), sheet[1])
    fa, fb = engine.build_fields([box_mesh(half=(0.5, 0.5, 0.5)), sheet], voxel_size=h)
    field = engine.intersection(fa, fb.transformed(turn), blend=blend_voxels * h, blend_mode=mode)
    assert field.is_empty and not len(field.to_mesh()[1])
    points = np.random.default_rng(1).uniform(-0.5, 0.5, (20000, 3)).astype(np.float32)
    assert (field.sample(points) >= 0.0).all()
    for out in (engine.offset(field, 5 * h), engine.offset(field, -2 * h), engine.shell(field, 3 * h)):
        assert out.is_empty and not len(out.to_mesh()[1])
