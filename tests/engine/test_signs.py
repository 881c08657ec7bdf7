"""Inside and outside: |w| >= 1/2 whatever the orientation, decided exactly near 1/2, and surfaces that enclose nothing.

Oracles: the exact winding number (``tests.metrics.winding_numbers``, every triangle's solid angle in float64),
exact distances, analytic volumes, and the engine's own field of the outward-facing mesh.
"""

import numpy as np
import pytest
import warp as wp

import engine
from engine.meshcheck import encloses_nothing, hole_boundary, weld_positions
from engine.winding import WindingArg, exact_winding, winding_arg, winding_expansion, winding_number
from tests.metrics import mesh_volume, unsigned_distance, winding_numbers
from tests.support import box_mesh, is_watertight, load_mesh, uv_sphere


def _voxel(verts, res):
    return float(np.linalg.norm(verts.max(axis=0) - verts.min(axis=0)) / res)


def _open_box(flip=False):
    """A 2 x 2 x 2 box around the origin without its top face (+z)."""
    verts, tris = box_mesh(subdivisions=4)
    normals = np.cross(verts[tris[:, 1]] - verts[tris[:, 0]], verts[tris[:, 2]] - verts[tris[:, 0]])
    tris = tris[~((normals[:, 2] > 0) & (verts[tris].mean(axis=1)[:, 2] > 0.99))]
    return verts, tris[:, ::-1].copy() if flip else tris


# ---- orientation does not matter ----


@pytest.mark.parametrize("name", ["cube", "stanford-bunny.obj"])
def test_an_inside_out_mesh_gives_the_same_field_as_the_outward_one(name):
    verts, tris = box_mesh(subdivisions=3) if name == "cube" else load_mesh(name)
    h = 0.04 if name == "cube" else _voxel(verts, 128)
    outward = engine.build_field(verts, tris, voxel_size=h)
    inward = engine.build_field(verts, np.ascontiguousarray(tris[:, ::-1]), voxel_size=h)
    assert inward.encloses_volume and outward.encloses_volume
    assert inward.level_counts == outward.level_counts
    np.testing.assert_array_equal(inward.codes.numpy(), outward.codes.numpy())
    a, b = outward.values.numpy(), inward.values.numpy()
    # the same distances within float rounding of the coordinates (measured: 1.3e-7 at most on the unit cube, 2.9e-8
    # on the bunny, whose triangles' corners come in the other order) and the same signs but on the surface itself
    np.testing.assert_allclose(b, a, rtol=0.0, atol=4e-7 * float(np.abs(verts).max()))
    clear = np.abs(a) > 1e-3 * h
    np.testing.assert_array_equal(b[clear] < 0.0, a[clear] < 0.0)
    verts_in, tris_in = inward.to_mesh()
    assert mesh_volume(verts_in, tris_in) == pytest.approx(mesh_volume(*outward.to_mesh()), rel=1e-6)


def _nested(inner_inward: bool, flip_all: bool):
    outer, t_outer = uv_sphere(1.0, rings=40, segments=80)
    inner, t_inner = uv_sphere(0.5, rings=30, segments=60)
    if inner_inward:
        t_inner = t_inner[:, ::-1]
    verts = np.vstack([outer, inner])
    tris = np.vstack([t_outer, t_inner + len(outer)])
    return verts, np.ascontiguousarray(tris[:, ::-1] if flip_all else tris)


PROBES = np.array([[0.0, 0.0, 0.0], [0.2, 0.1, 0.0], [0.75, 0.0, 0.0], [0.0, -0.7, 0.3], [1.3, 0.0, 0.0]], np.float32)


@pytest.mark.parametrize("flip_all", [False, True])
def test_a_shell_facing_inward_inside_another_is_a_cavity(flip_all):
    # the cavity's winding number is 1 - 1 = 0 (or -1 + 1 flipped): outside, and the surface holds both shells
    verts, tris = _nested(inner_inward=True, flip_all=flip_all)
    field = engine.build_field(verts, tris, voxel_size=0.04)
    values = field.sample(PROBES)
    assert np.all(values[:2] > 0.0) and np.all(values[2:4] < 0.0) and values[4] > 0.0, values
    expected = [0.5, 0.5 - np.hypot(0.2, 0.1), -0.25, np.hypot(0.7, 0.3) - 1.0, 0.3]
    np.testing.assert_allclose(values, expected, atol=0.03)  # measured 0.016 (the far field's 5 % at 1.3)
    out_verts, out_tris = field.to_mesh()
    assert is_watertight(out_tris)
    shell = 4.0 / 3.0 * np.pi * (1.0 - 0.125)
    # measured 0.3 % below the spheres' (the polygons' own volume is 0.5 % below it)
    assert abs(mesh_volume(out_verts, out_tris)) == pytest.approx(shell, rel=0.009)
    # two shells facing the same way nest a solid inside a solid (w = 2): no cavity
    solid = engine.build_field(*_nested(inner_inward=False, flip_all=flip_all), voxel_size=0.04)
    assert np.all(solid.sample(PROBES)[:4] < 0.0)


# ---- winding numbers near 1/2, exactly ----


@wp.kernel(enable_backward=False)
def _exact_kernel(f: WindingArg, points: wp.array[wp.vec3], out: wp.array[wp.float32]):
    i = wp.tid()
    out[i] = exact_winding(f, points[i], winding_number(f.mesh, points[i], 1.0))


@wp.kernel(enable_backward=False)
def _expansion_kernel(
    f: WindingArg,
    points: wp.array[wp.vec3],
    reach: float,
    w: wp.array[wp.float32],
    grad: wp.array[wp.vec3],
    hess: wp.array[wp.mat33],
    d3: wp.array[wp.float32],
):
    i = wp.tid()
    value, gradient, hessian, _near, bound = winding_expansion(f, points[i], 0.5 * reach, reach)
    w[i] = value
    grad[i] = gradient
    hess[i] = hessian
    d3[i] = bound


def _winding(verts, tris):
    mesh = wp.Mesh(
        points=wp.array(verts, dtype=wp.vec3),
        indices=wp.array(tris.reshape(-1).astype(np.int32), dtype=wp.int32),
        support_winding_number=True,
    )
    return mesh, winding_arg(mesh, hole_boundary(*weld_positions(verts, tris)), wp.get_device())


@pytest.mark.parametrize("name", ["beetle.obj", "suzanne.obj"])
def test_open_meshes_winding_numbers_are_exact_through_their_boundary_cones(name):
    verts, tris = load_mesh(name)
    _mesh, arg = _winding(verts, tris)
    assert arg.mode == engine.winding.WINDING_EXACT
    rng = np.random.default_rng(1)
    lo, hi = verts.min(axis=0), verts.max(axis=0)
    points = rng.uniform(lo, hi, size=(3000, 3)).astype(np.float32)
    out = wp.zeros(len(points), dtype=wp.float32)
    wp.launch(_exact_kernel, dim=len(points), inputs=[arg, wp.array(points, dtype=wp.vec3), out])
    err = np.abs(out.numpy() - winding_numbers(verts, tris, points))
    # measured 6.7e-5 at most on the beetle (float32 sums over 345 edges; p99 2.8e-6): within WINDING_ROUNDING
    assert err.max() <= engine.winding.WINDING_ROUNDING, err.max()


def test_taylor_bounds_of_the_expansion_hold_against_the_exact_winding_number():
    # what the top-down pass relies on: w(x + d) within |D^3 w| |d|^3 / 6 of the expansion at x, along segments that
    # cross no triangle; points near the beetle's large holes, where w is near 1/2
    verts, tris = load_mesh("beetle.obj")
    mesh, arg = _winding(verts, tris)
    h = _voxel(verts, 256)
    rng = np.random.default_rng(2)
    centres = rng.uniform(verts.min(axis=0), verts.max(axis=0), size=(400, 3)).astype(np.float32)
    reach = 2.0 * h
    w, grad, hess = wp.zeros(400, dtype=float), wp.zeros(400, dtype=wp.vec3), wp.zeros(400, dtype=wp.mat33)
    d3 = wp.zeros(400, dtype=float)
    wp.launch(_expansion_kernel, dim=400, inputs=[arg, wp.array(centres, dtype=wp.vec3), reach, w, grad, hess, d3])
    w, grad, hess, d3 = w.numpy(), grad.numpy(), hess.numpy(), d3.numpy()
    offsets = rng.normal(size=(400, 3))
    offsets *= reach * rng.uniform(0.2, 1.0, (400, 1)) / np.linalg.norm(offsets, axis=1, keepdims=True)
    ends = centres + offsets
    clear = unsigned_distance(verts, tris, centres) > reach  # balls without triangles: no jump on the segments
    assert clear.sum() > 200
    exact = winding_numbers(verts, tris, ends[clear])
    taylor = w + np.einsum("ni,ni->n", grad, offsets) + 0.5 * np.einsum("ni,nij,nj->n", offsets, hess, offsets)
    remainder = np.abs(exact - taylor[clear])
    bound = d3[clear] * np.linalg.norm(offsets[clear], axis=1) ** 3 / 6.0 + 1e-4
    assert np.all(remainder <= bound), (remainder / bound).max()
    # the bound is not vacuous: measured 1.2 % of it used at the median, 11 % at most
    assert np.median(remainder / bound) < 0.04


# ---- holes close, flat surfaces enclose nothing ----


def test_the_winding_number_in_a_planar_hole_is_a_half_on_its_cones_edges_too():
    # in the plane of the open box's missing face the cones' triangles lie flat, and on the edges between two of them
    # their solid angles' signs are either side's: the cones read 0 for 1/2 there, and w came out 1 (inside)
    verts, tris = _open_box()
    _mesh, arg = _winding(verts, tris)
    corners = np.array([[1, 1], [1, -1], [-1, -1], [-1, 1], [0.5, 1], [1, -0.5]], np.float32)
    along = np.linspace(0.1, 0.9, 9, dtype=np.float32)[:, None, None] * corners[None]
    points = np.concatenate([along.reshape(-1, 2), np.ones((along.size // 2, 1), np.float32)], axis=1)
    out = wp.zeros(len(points), dtype=wp.float32)
    wp.launch(_exact_kernel, dim=len(points), inputs=[arg, wp.array(points, dtype=wp.vec3), out])
    assert np.abs(out.numpy() - 0.5).max() < 5e-3  # (the accurate fast winding number there: measured 1.8e-3)


@pytest.mark.parametrize(("flip", "voxel"), [(False, 0.04), (True, 0.04), (False, 0.05)])
def test_a_cube_with_one_face_missing_still_closes_across_the_hole(flip, voxel):
    # at voxels of 0.05 the top level's nodes lie in the hole's plane, some on its cones' edges (open before)
    verts, tris = _open_box(flip)
    field = engine.build_field(verts, tris, voxel_size=voxel)
    assert field.encloses_volume
    out_verts, out_tris = field.to_mesh()
    assert is_watertight(out_tris)
    # the opening is closed where the box's top was: volume 8 (measured 0.16 % below), the top at z = 1 (measured
    # 2.4e-6 below: the values on either side of it are equal and opposite)
    assert abs(mesh_volume(out_verts, out_tris)) == pytest.approx(8.0, rel=0.005)
    top = out_verts[np.abs(out_verts[:, 0]) < 0.5]
    assert top[:, 2].max() == pytest.approx(1.0, abs=1e-5)


PLANE = (np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], np.float32), np.array([[0, 1, 2], [0, 2, 3]]))


@pytest.mark.parametrize("shape", ["plane", "triangle", "annulus", "alligator.obj"])
def test_flat_surfaces_enclose_nothing(shape):
    if shape == "plane":
        verts, tris = PLANE
    elif shape == "triangle":
        verts, tris = PLANE[0][:3], PLANE[1][:1]
    elif shape == "annulus":  # a square sheet with a square hole: the boundary winds once around the sheet's points
        ring = np.array([[-2, -2], [2, -2], [2, 2], [-2, 2], [-1, -1], [1, -1], [1, 1], [-1, 1]], np.float32)
        verts = np.column_stack([ring, np.full(8, 0.3, np.float32)])
        tris = np.array([[0, 1, 5], [0, 5, 4], [1, 2, 6], [1, 6, 5], [2, 3, 7], [2, 7, 6], [3, 0, 4], [3, 4, 7]])
    else:
        verts, tris = load_mesh(shape)
    h = _voxel(verts, 64)
    field = engine.build_field(verts, tris, voxel_size=h)
    assert field.stats["flat"] and not field.encloses_volume
    assert sum(field.stats["sign_queries"].values()) == 0  # no winding number needed
    assert np.all(field.values.numpy() >= 0.0)
    out_verts, out_tris = field.to_mesh()
    assert out_verts.shape == (0, 3) and out_tris.shape == (0, 3)
    # an unsigned distance, its kink on the sheet kept: points within two voxels of it, off the faces' centres
    rng = np.random.default_rng(0)
    normal = np.linalg.svd(verts - verts.mean(axis=0))[2][2]
    points = verts[tris[rng.integers(0, len(tris), 500)]].mean(axis=1) + np.outer(rng.normal(0.0, h, 500), normal)
    exact = unsigned_distance(verts, tris, points.astype(np.float32))
    err = np.abs(field.sample(points) - exact) / h
    # measured p99: 4.2e-4 voxel on the annulus (its nearest closest point is exact on a flat face, kept in half floats:
    # within 2^-11 of its distance), 0.28 on the alligator (its legs are a few voxels wide at / 64)
    assert np.percentile(err, 99) <= (0.5 if shape == "alligator.obj" else 1.2e-3), np.percentile(err, 99)


def test_a_flat_mesh_encloses_nothing_however_often_it_covers_its_plane():
    verts, tris = PLANE
    assert encloses_nothing(verts, hole_boundary(verts, tris))
    doubled = (np.vstack([verts, verts]), np.vstack([tris, tris + 4]))  # covered twice: |w| near 1 beside it
    welded_verts, welded_tris = weld_positions(*doubled)
    assert encloses_nothing(welded_verts, hole_boundary(welded_verts, welded_tris))
    nested = (np.vstack([verts, 0.5 * verts]), np.vstack([tris, tris + 4]))  # the inner square covered twice
    assert encloses_nothing(nested[0], hole_boundary(*nested))
    crossing = (np.vstack([verts, verts + np.float32([1.0, 0.5, 0.0])]), nested[1])  # an arrayed plane over itself
    assert encloses_nothing(crossing[0], hole_boundary(*crossing))
    bent = verts.copy()
    bent[2, 2] = 0.1
    assert not encloses_nothing(bent, hole_boundary(bent, tris))
    # the winding number made a lens of the part covered twice, its surface touching the sheet (not a 2-manifold):
    # now an unsigned distance, nothing inside
    for mesh in (doubled, crossing):
        field = engine.build_field(*mesh, voxel_size=0.05)
        assert field.stats["flat"] and not field.encloses_volume
        assert len(field.to_mesh()[1]) == 0


def test_boolean_results_say_whether_they_enclose_a_volume():
    a = engine.build_field(*uv_sphere(1.0), voxel_size=0.05)
    b = engine.build_field(*uv_sphere(0.5, center=(3.0, 0.0, 0.0)), voxel_size=0.05)
    assert (a | b).encloses_volume
    apart = a & b
    assert not apart.encloses_volume
    verts, tris = apart.to_mesh()
    assert len(verts) == 0 and len(tris) == 0


def test_a_boundary_too_long_to_sum_leaves_the_signs_to_the_accurate_fast_winding_number(monkeypatch):
    # beyond MAX_BOUNDARY_EDGES the cones are not summed: the accurate fast winding number decides (measured: the
    # surface's volume 0.01 % from the exact build's, every sign of 848 points beyond 2 voxels right)
    verts, tris = load_mesh("stanford-bunny.obj")
    h = _voxel(verts, 128)
    exact = engine.build_field(verts, tris, voxel_size=h)
    monkeypatch.setattr(engine.winding, "MAX_BOUNDARY_EDGES", 100)  # the bunny has 223
    approximate = engine.build_field(verts, tris, voxel_size=h)
    assert approximate.encloses_volume
    volume, reference = mesh_volume(*approximate.to_mesh()), mesh_volume(*exact.to_mesh())
    assert volume == pytest.approx(reference, rel=3e-4)
    rng = np.random.default_rng(3)
    points = rng.uniform(verts.min(axis=0), verts.max(axis=0), (1000, 3)).astype(np.float32)
    far = unsigned_distance(verts, tris, points) > 2.0 * h
    inside = np.abs(winding_numbers(verts, tris, points[far])) >= 0.5
    assert np.mean((approximate.sample(points[far]) < 0.0) == inside) >= 0.995


def test_a_plates_ring_refined_about_a_bore_takes_its_signs_from_its_parents():
    """A plate refined along a bore's wall only: its layer of nodes just off the faces, in a ring away from the rim,
    has no signed neighbour to spread from. Each takes its parent's sign across a segment that meets no triangle
    (before: 20,032 winding numbers on the bench's plate minus four bores); the values are the full build's."""
    from engine.ondemand import refined
    from tests.support import plate_and_bores

    plate, bores = plate_and_bores()
    h = _voxel(np.concatenate([plate[0], bores[0]]), 256)
    whole = engine.build_fields([plate], voxel_size=h, refine="all")[0]
    coarse = engine.build_fields([plate], voxel_size=h, refine="none")[0]
    turn = np.linspace(0.0, 2.0 * np.pi, 64)
    ring = np.c_[0.5 + 0.2 * np.cos(turn), 0.5 + 0.2 * np.sin(turn)]  # a bore's wall through the plate
    points = np.concatenate([np.c_[ring, np.full(64, z)] for z in (-0.1, 0.0, 0.1)]).astype(np.float32)
    ring_field = refined(coarse, points, reach=6 * h)
    assert ring_field.stats["sign_queries"][0] == 0
    n0 = ring_field.level_counts[0]
    codes, values = ring_field.codes.numpy()[:n0], ring_field.values.numpy()[:n0]
    whole_codes = whole.codes.numpy()[: whole.level_counts[0]]
    at = np.minimum(np.searchsorted(whole_codes, codes), len(whole_codes) - 1)
    assert len(codes) > 1000 and (whole_codes[at] == codes).all()
    np.testing.assert_array_equal(values, whole.values.numpy()[at])
