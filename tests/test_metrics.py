"""Tests of the measurement oracles in ``tests/metrics.py`` against analytic volumes and distances (no bpy)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tests.metrics import (
    distance_within,
    exact_boolean,
    exact_sdf,
    hausdorff,
    merge_vertices,
    mesh_area,
    mesh_volume,
    sample_surface,
    self_intersecting_faces,
    self_intersections,
    unsigned_distance,
    winding_inside,
    winding_numbers,
)
from tests.support import box_mesh, is_watertight, torus_mesh, uv_sphere


def open_box():
    """A 2×2×2 box around the origin with its +x face removed (open: 40 of 48 triangles)."""
    verts, tris = box_mesh(subdivisions=2)
    centres = verts[tris].mean(axis=1)
    return verts, tris[centres[:, 0] < 0.999]


def lens_volume(r: float, d: float) -> float:
    """Volume of the intersection of two spheres of radius ``r`` whose centres are ``d`` apart."""
    return math.pi * (4.0 * r + d) * (2.0 * r - d) ** 2 / 12.0


# ---- volumes ----


def test_box_volume_and_area_are_exact():
    verts, tris = box_mesh(half=(1.0, 2.0, 3.0), center=(5.0, -1.0, 2.0), subdivisions=3)
    assert mesh_volume(verts, tris) == pytest.approx(48.0, rel=1e-6)
    assert mesh_area(verts, tris) == pytest.approx(2.0 * (8.0 + 12.0 + 24.0), rel=1e-6)


def test_inverted_box_has_negative_volume():
    verts, tris = box_mesh()
    assert mesh_volume(verts, tris[:, ::-1]) == pytest.approx(-8.0, rel=1e-6)


def test_sphere_and_torus_volumes_match_formulas():
    sphere = mesh_volume(*uv_sphere(radius=2.0, rings=96, segments=192))
    torus = mesh_volume(*torus_mesh(major=1.0, minor=0.35, rings=192, segments=96))
    # Inscribed polyhedra: slightly smaller than the smooth shapes.
    assert 0.999 < sphere / (4.0 / 3.0 * math.pi * 8.0) < 1.0
    assert 0.998 < torus / (2.0 * math.pi**2 * 1.0 * 0.35**2) < 1.0


# ---- exact booleans ----


@pytest.mark.parametrize(
    ("op", "expected"),
    [
        ("UNION", 2.0 * 4.0 / 3.0 * math.pi - lens_volume(1.0, 0.8)),
        ("INTERSECT", lens_volume(1.0, 0.8)),
        ("DIFFERENCE", 4.0 / 3.0 * math.pi - lens_volume(1.0, 0.8)),
    ],
)
def test_exact_boolean_of_two_spheres_matches_lens_formula(op, expected):
    a = uv_sphere(radius=1.0, center=(0.0, 0.0, 0.0))
    b = uv_sphere(radius=1.0, center=(0.8, 0.0, 0.0))
    verts, tris = exact_boolean(op, *a, *b)
    assert verts.dtype == np.float32 and tris.dtype == np.int32
    assert is_watertight(tris)
    assert mesh_volume(verts, tris) == pytest.approx(expected, rel=5e-3)


def test_exact_boolean_difference_of_boxes_is_exact():
    a = box_mesh(half=(1.0, 1.0, 1.0))
    b = box_mesh(half=(0.5, 0.5, 2.0), center=(1.0, 0.0, 0.0))  # cuts a 0.5 x 1 x 2 slot out of a
    verts, tris = exact_boolean("DIFFERENCE", *a, *b)
    assert mesh_volume(verts, tris) == pytest.approx(8.0 - 1.0, rel=1e-6)


def test_exact_boolean_of_disjoint_meshes():
    a = box_mesh(center=(0.0, 0.0, 0.0))
    b = box_mesh(center=(5.0, 0.0, 0.0))
    assert mesh_volume(*exact_boolean("UNION", *a, *b)) == pytest.approx(16.0, rel=1e-6)
    verts, tris = exact_boolean("INTERSECT", *a, *b)
    assert len(tris) == 0 and mesh_volume(verts, tris) == 0.0


def test_exact_boolean_merges_a_triangle_soup():
    verts, tris = box_mesh()
    soup_verts, soup_tris = verts[tris].reshape(-1, 3), np.arange(3 * len(tris), dtype=np.int32).reshape(-1, 3)
    merged_verts, merged_tris = merge_vertices(soup_verts, soup_tris)
    assert len(merged_verts) == len(verts) and is_watertight(merged_tris)
    result = exact_boolean("UNION", soup_verts, soup_tris, *box_mesh(center=(1.0, 1.0, 1.0)))
    assert mesh_volume(*result) == pytest.approx(16.0 - 1.0, rel=1e-6)


def test_exact_boolean_rejects_an_open_mesh():
    with pytest.raises(ValueError, match="manifold3d rejected operand b .*NotManifold"):
        exact_boolean("UNION", *box_mesh(), *open_box())


def test_exact_boolean_rejects_an_unknown_operation():
    with pytest.raises(ValueError, match="Expected 'op' in"):
        exact_boolean("SUBTRACT", *box_mesh(), *box_mesh())


# ---- surface samples and distances ----


def test_sample_surface_is_area_weighted_and_seeded():
    verts, tris = box_mesh(half=(1.0, 2.0, 3.0), subdivisions=3)
    points = sample_surface(verts, tris, 100_000, seed=3)
    assert points.shape == (100_000, 3) and points.dtype == np.float32
    on_x_faces = np.isclose(np.abs(points[:, 0]), 1.0, atol=1e-6).mean()
    assert on_x_faces == pytest.approx(48.0 / 88.0, abs=0.01)  # x faces hold 2·(4·6) of the 88 units of area
    np.testing.assert_array_equal(points, sample_surface(verts, tris, 100_000, seed=3))
    assert not np.array_equal(points, sample_surface(verts, tris, 100_000, seed=4))


def test_sample_surface_points_lie_on_the_sphere():
    radii = np.linalg.norm(sample_surface(*uv_sphere(radius=1.5), 10_000, seed=0), axis=1)
    assert radii.max() <= 1.5 + 1e-5
    assert radii.min() > 1.5 * math.cos(math.pi / 48.0)  # no deeper than the flattest facet


def test_hausdorff_of_a_mesh_to_itself_is_zero():
    verts, tris = uv_sphere()
    result = hausdorff(verts, tris, verts, tris, n=50_000)
    assert result["max"] < 1e-5 and result["mean"] < 1e-6


def test_hausdorff_of_concentric_spheres_is_the_radius_gap():
    result = hausdorff(*uv_sphere(radius=1.0), *uv_sphere(radius=1.1), n=50_000)
    for key in ("p95", "max", "mean"):
        assert result[key] == pytest.approx(0.1, abs=1e-3)


def test_hausdorff_uses_exact_point_to_triangle_distances():
    # Two boxes 0.05 apart: a nearest-sample estimate from 2,000 samples would overshoot by the sample spacing.
    result = hausdorff(*box_mesh(), *box_mesh(center=(0.05, 0.0, 0.0)), n=2_000)
    assert result["max"] == pytest.approx(0.05, abs=1e-5)
    assert result["a_to_b"]["max"] == pytest.approx(0.05, abs=1e-5)
    assert result["b_to_a"]["max"] == pytest.approx(0.05, abs=1e-5)


def test_distance_within_measures_points_on_slivers_in_float64():
    # a sliver 1e-3 wide and 2 long, tilted: points on it lie on it, points off it are as far as their offset
    verts = np.array([[0.0, 0.0, 0.0], [2.0, 0.3, 0.7], [2.0, 0.301, 0.7]])
    verts = np.concatenate([verts, verts + [0.0, 0.0, 1.0]])
    tris = np.array([[0, 1, 2], [3, 4, 5]])
    on = sample_surface(verts, tris[:1], 2_000, seed=3).astype(np.float64)
    n = np.cross(verts[1] - verts[0], verts[2] - verts[0])
    n /= np.linalg.norm(n)
    assert distance_within(verts, tris, on, 0.1).max() < 1e-6
    np.testing.assert_allclose(distance_within(verts, tris, on[:50] + 0.01 * n, 0.1), 0.01, atol=1e-6)
    beyond = [[5.0, 0.0, 0.0], [-1.0, 0.0, 0.0], [1.0, 0.15, -0.3]]
    np.testing.assert_allclose(distance_within(verts, tris, beyond, 0.1), 0.1)  # nothing within reach
    np.testing.assert_allclose(distance_within(verts, tris, [[-0.05, 0.0, 0.0]], 0.1), 0.05, atol=1e-6)  # a corner


def test_exact_sdf_of_a_box_matches_the_analytic_distance():
    points = [[0, 0, 0], [0.5, 0, 0], [0, 0, -0.9], [2, 0, 0], [2, 2, 0], [2, 2, 2], [0, 0, 1.25]]
    expected = [-1.0, -0.5, -0.1, 1.0, math.sqrt(2.0), math.sqrt(3.0), 0.25]
    d = exact_sdf(*box_mesh(subdivisions=2), points)
    assert d.dtype == np.float32
    np.testing.assert_allclose(d, expected, atol=1e-5)
    np.testing.assert_allclose(unsigned_distance(*box_mesh(), points), np.abs(expected), atol=1e-5)


def test_winding_inside_an_open_box():
    verts, tris = open_box()
    assert not is_watertight(tris)
    inside = winding_inside(verts, tris, [[0, 0, 0], [-0.5, 0.5, 0.5], [50, 0, 0], [0, 0, 3], [1.5, 0, 0]])
    np.testing.assert_array_equal(inside, [True, True, False, False, False])
    # The sign follows the winding number; the distance is to the nearest remaining triangle (the hole's rim).
    d = exact_sdf(verts, tris, [[0, 0, 0], [1.5, 0, 0]])
    np.testing.assert_allclose(d, [-1.0, math.sqrt(1.25)], atol=1e-5)


# ---- argument checks ----


def test_exact_winding_numbers_of_closed_open_and_flipped_meshes():
    verts, tris = box_mesh(subdivisions=2)
    points = np.array([[0.0, 0.0, 0.0], [0.5, -0.3, 0.9], [3.0, 0.0, 0.0], [0.0, 0.0, 1.5]])
    np.testing.assert_allclose(winding_numbers(verts, tris, points), [1, 1, 0, 0], atol=1e-12)
    np.testing.assert_allclose(winding_numbers(verts, tris[:, ::-1], points), [-1, -1, 0, 0], atol=1e-12)
    # open box (+x face removed): seen from its centre the opening subtends a sixth of the sphere
    open_verts, open_tris = open_box()
    w = winding_numbers(open_verts, open_tris, [[0.0, 0.0, 0.0], [1.0 + 1e-9, 0.0, 0.0]])
    assert w[0] == pytest.approx(5.0 / 6.0, abs=1e-12)
    assert w[1] == pytest.approx(0.5, abs=1e-6)  # the centre of the opening's plane, seen from just outside it


def test_self_intersecting_faces_are_those_another_face_crosses():
    # two boxes overlapping as one soup: each crosses the other along a loop; a box alone crosses nothing
    a, b = box_mesh(), box_mesh(center=(1.0, 0.5, 0.25))
    verts = np.concatenate([a[0], b[0]])
    tris = np.concatenate([a[1], b[1] + len(a[0])])
    crossed = self_intersecting_faces(verts, tris)
    assert crossed.any() and crossed[: len(a[1])].any() and crossed[len(a[1]) :].any()
    # only the faces the other box passes through: its +x, +y, +z sides and theirs opposite
    centres = verts[tris].mean(axis=1)
    assert not crossed[: len(a[1])][centres[: len(a[1]), 0] < -0.99].any()
    assert self_intersections(verts, tris) * 2 >= crossed.sum()
    assert not self_intersecting_faces(*a).any() and self_intersections(*a) == 0


def test_points_of_the_wrong_shape_are_rejected():
    with pytest.raises(ValueError, match=r"Expected 'points' of shape \(N, 3\), but got \(3,\)"):
        exact_sdf(*box_mesh(), [0.0, 0.0, 0.0])


def test_out_of_range_triangles_are_rejected():
    verts, tris = box_mesh()
    with pytest.raises(ValueError, match="Triangle indices of 'verts' must lie in"):
        mesh_volume(verts[:4], tris)


@pytest.mark.parametrize(
    ("call", "error", "match"),
    [
        (lambda: mesh_volume(np.zeros((4, 2)), [[0, 1, 2]]), ValueError, r"'verts' of shape \(V, 3\)"),
        (lambda: mesh_volume(np.zeros((4, 3)), [0, 1, 2]), ValueError, r"triangles of 'verts' of shape \(T, 3\)"),
        (lambda: mesh_volume(np.zeros((4, 3)), [[0.0, 1.0, 2.0]]), TypeError, "integer triangle indices"),
        (lambda: sample_surface(*box_mesh(), -1), ValueError, "non-negative 'n'"),
        (lambda: exact_sdf(np.zeros((0, 3)), np.zeros((0, 3), int), [[0, 0, 0]]), ValueError, "at least one triangle"),
    ],
)
def test_malformed_arguments_are_rejected(call, error, match):
    with pytest.raises(error, match=match):
        call()


def test_empty_surface_cannot_be_sampled():
    with pytest.raises(ValueError, match="zero surface area"):
        sample_surface(np.zeros((3, 3)), [[0, 1, 2]], 10)
