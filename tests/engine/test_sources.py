"""Where a field's surface came from: ``closest_sources`` and ``source_barycentrics`` on built fields and booleans."""

import numpy as np
import pytest

import engine
from tests.support import box_mesh, uv_sphere


def _surface_points(verts, tris, n, seed=0):
    """Random points on a mesh: (N, 3), with the triangle each lies on and its barycentric coordinates."""
    rng = np.random.default_rng(seed)
    tri = rng.integers(0, len(tris), n)
    bary = rng.dirichlet([1.0, 1.0, 1.0], n)
    return np.einsum("nk,nkd->nd", bary, verts[tris[tri]]).astype(np.float32), tri, bary


def test_closest_sources_of_points_on_the_mesh_are_their_own_triangles():
    verts, tris = uv_sphere(1.0, rings=24, segments=48)
    # degenerate triangles first: the build drops them, the ids still count them
    degenerate = np.array([[0, 0, 1], [2, 2, 2]], dtype=np.int32)
    field = engine.build_field(verts, np.r_[degenerate, tris], voxel_size=0.05, field_id=4)
    points, tri, bary = _surface_points(verts, tris, 2000)
    ids, got_tri, got_bary = field.closest_sources(points)
    assert np.all(ids == 4)
    np.testing.assert_array_equal(got_tri, tri + len(degenerate))
    np.testing.assert_allclose(got_bary, bary, atol=2e-4)  # float32 closest points on unit-size triangles
    assert np.all(got_bary >= -1e-6) and np.allclose(got_bary.sum(axis=1), 1.0, atol=1e-5)


def test_closest_sources_of_a_boolean_follow_the_operand_that_decides():
    a_mesh = box_mesh(half=(1.0, 1.0, 1.0), subdivisions=4)
    b_mesh = uv_sphere(0.8, center=(1.0, 1.0, 1.0), rings=24, segments=48)
    a = engine.build_field(*a_mesh, voxel_size=0.04, field_id=0)
    b = engine.build_field(*b_mesh, voxel_size=0.04, field_id=1)
    result = engine.difference(a, b)
    verts, tris = result.to_mesh()
    centres = verts[tris].mean(axis=1)
    ids, tri, bary = result.closest_sources(centres)
    to_box = np.abs(np.abs(centres).max(axis=1) - 1.0)
    to_ball = np.abs(np.linalg.norm(centres - 1.0, axis=1) - 0.8)
    h = 0.04
    on_box, on_ball = (to_box < 0.25 * h) & (to_ball > 2 * h), (to_ball < 0.25 * h) & (to_box > 2 * h)
    assert on_box.sum() > 1000 and on_ball.sum() > 100
    assert np.all(ids[on_box] == 0) and np.all(ids[on_ball] == 1)  # away from the seam
    # each face's source point is the closest point of its operand's mesh: within the surface's error of the centre
    for field_id, (mv, mt) in enumerate((a_mesh, b_mesh)):
        rows = np.flatnonzero(ids == field_id)
        nearest = np.einsum("nk,nkd->nd", bary[rows], mv[mt[tri[rows]]])
        assert np.percentile(np.linalg.norm(nearest - centres[rows], axis=1), 95) < 0.3 * h  # measured 0.13 h


def test_source_barycentrics_project_points_onto_the_given_triangles():
    verts, tris = uv_sphere(1.0, rings=12, segments=24)
    field = engine.build_field(verts, tris, voxel_size=0.1, field_id=2)
    rng = np.random.default_rng(1)
    tri = rng.integers(0, len(tris), 500)
    weights = rng.normal(0.33, 0.5, (500, 3))
    weights /= weights.sum(axis=1, keepdims=True)  # outside the triangle too: extended linearly
    corners = verts[tris[tri]].astype(np.float64)
    normal = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    points = np.einsum("nk,nkd->nd", weights, corners) + 0.03 * normal  # off the plane: projected
    got = field.source_barycentrics(np.full(500, 2), tri, points)
    np.testing.assert_allclose(got, weights, atol=1e-4)
    np.testing.assert_array_equal(field.source_barycentrics([9], [0], [[0.0, 0.0, 0.0]]), [[0.0, 0.0, 0.0]])
    with pytest.raises(ValueError, match="one field id and one triangle id per point"):
        field.source_barycentrics([2, 2], [0], [[0.0, 0.0, 0.0]])
    with pytest.raises(ValueError, match=r"'points' of shape \(N, 3\)"):
        field.closest_sources(np.zeros(3))


def test_relabelled_fields_keep_their_source_under_the_new_id():
    verts, tris = uv_sphere(1.0, rings=12, segments=24)
    field = engine.build_field(verts, tris, voxel_size=0.1)
    relabelled = field.relabel(5)
    assert list(relabelled.sources) == [5] and relabelled.sources[5] is field.sources[0]
    ids, tri, _ = relabelled.closest_sources(verts[:10])
    assert np.all(ids == 5) and np.all(tri >= 0)


@pytest.mark.parametrize("width", [2, 4])
def test_corner_values_are_their_source_triangles_corners_weighted(width):
    rng = np.random.default_rng(7)
    values = rng.normal(size=(50, width)).astype(np.float32)
    corners = rng.integers(0, len(values), size=(30, 3))
    stacked = rng.integers(0, len(corners), size=40_000)  # enough faces to split the launch across cores
    weights = rng.random((len(stacked), 3, 3)).astype(np.float32)
    out = engine.interpolate_corners(values, corners, stacked, weights)
    expected = np.einsum("fck,fkw->fcw", weights, values[corners[stacked]]).reshape(-1, width)
    assert out.shape == (3 * len(stacked), width) and out.dtype == np.float32
    np.testing.assert_allclose(out, expected, rtol=1e-5, atol=1e-5)
    # a face's corner at one of its triangle's corners reads that corner's value exactly
    one_hot = np.broadcast_to(np.eye(3, dtype=np.float32), weights.shape)
    np.testing.assert_array_equal(
        engine.interpolate_corners(values, corners, stacked, one_hot)[:3], values[corners[stacked[0]]]
    )


def test_closest_points_read_one_by_one_are_the_bvh_s():
    # a few points of a mesh whose BVH is not at hand are read against every triangle: the same closest points as
    # the BVH's query gives (within float rounding), where no BVH was built
    from engine.sources import SourceMesh, closest_points

    verts, tris = uv_sphere(1.0)
    rng = np.random.default_rng(5)
    points = (rng.normal(size=(12, 3)) * 0.9).astype(np.float32)
    brute = SourceMesh(verts, tris, np.arange(len(tris)))
    by_brute = closest_points(brute, points, "cpu")
    assert brute.kept_bvh("cpu") is None  # (no BVH built for them)
    with_bvh = SourceMesh(verts, tris, np.arange(len(tris)))
    with_bvh.bvh("cpu")
    by_bvh = closest_points(with_bvh, points, "cpu")
    # measured: 5e-8 apart
    assert np.abs(by_brute - by_bvh).max() < 1.5e-7
    # and they lie on the sphere's facets: within its chords' sag of the unit sphere (measured 0.0010)
    assert np.abs(np.linalg.norm(by_brute, axis=1) - 1.0).max() < 0.003
