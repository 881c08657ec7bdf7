"""Where a field's surface came from: ``closest_sources`` and ``source_barycentrics`` on built fields and booleans."""

import numpy as np
import pytest

import engine
from tests.support import box_mesh, cylinder_mesh, rotation, uv_sphere


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


def test_a_field_keeps_its_builds_bvh_and_a_bvh_is_built_once_for_two_threads():
    # a field's source holds the BVH its build made (what reads the mesh later does not build it again), an open mesh's
    # too (its distances are not read off the mesh); two threads asking a fresh source for its BVH get the same one
    from concurrent.futures import ThreadPoolExecutor

    from engine.sources import SourceMesh

    verts, tris = uv_sphere(1.0)
    open_tris = tris[tris[:, 0] > 40]  # a hole at the pole
    field = engine.build_field(verts, open_tris, voxel_size=0.05)
    source = next(iter(field.sources.values()))
    assert not field.stats["mesh_distance"] and source.kept_bvh(field.device) is not None
    for _ in range(4):  # (without the lock, two were built in 5 of 10 tries)
        fresh = SourceMesh(verts, tris, np.arange(len(tris)))
        with ThreadPoolExecutor(2) as pool:
            first, second = pool.map(lambda _, fresh=fresh: fresh.bvh("cpu"), range(2))
        assert first is second


@pytest.mark.parametrize("turn", [0.0, 17.0])
def test_remeshed_faces_along_a_crease_take_a_triangle_of_the_side_they_lie_on(turn):
    """A remeshed box, square to the lattice and turned (/128): every face lying flat on a side takes a triangle of
    that side. The nodes about an edge lie as near both sides, and 1,760 and 505 faces (2.7 and 0.6 %) took the other
    side's triangle, along every edge, when the node's triangle was taken as it was (a material per side: a jagged
    stripe of the wrong one)."""
    turned = rotation(2, turn) @ rotation(0, 0.7 * turn)
    verts, tris = box_mesh()
    verts = (verts @ turned.T).astype(np.float32)
    field = engine.build_field(verts, tris, voxel_size=2.0 * np.sqrt(3.0) / 128)
    v, t = field.to_mesh()
    _, got, _ = field.face_sources(v, t)
    normals = np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]]) @ turned  # in the box's frame
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    flat = np.abs(normals).max(axis=1) > 0.999  # on one side's plane
    side = np.argmax(np.abs(normals), axis=1)
    source = np.cross(verts[tris[:, 1]] - verts[tris[:, 0]], verts[tris[:, 2]] - verts[tris[:, 0]]) @ turned
    assert flat.mean() > 0.95 and np.all(got >= 0)
    assert np.array_equal(np.argmax(np.abs(source), axis=1)[got[flat]], side[flat])  # measured: all


def test_remeshed_faces_on_an_operands_plane_take_that_operands_triangles():
    """A cube minus a turned bore, remeshed (/128): the faces on the cube's planes take the cube's triangles and those
    on the bore's wall the bore's (156 and 11 did not: the nodes along the rim lie as near both operands)."""
    box = box_mesh()
    turned = rotation(0, 20.0) @ rotation(1, 10.0)
    bore = cylinder_mesh(0.5, 3.0, 64)
    bore = ((bore[0] @ turned.T + (0.1, 0.05, 0.0)).astype(np.float32), bore[1])
    fa, fb = engine.build_fields([box, bore], voxel_size=2.0 * np.sqrt(3.0) / 128)
    result = engine.difference(fa, fb)
    v, t = result.to_mesh()
    ids, _, _ = result.face_sources(v, t)
    normals = np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]])
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    centres = v[t].mean(axis=1)
    on_box = (np.abs(np.abs(centres).max(axis=1) - 1.0) < 1e-3) & (np.abs(normals).max(axis=1) > 0.999)
    off_axis = centres - (0.1, 0.05, 0.0)
    axis = turned[:, 2]
    radius = np.linalg.norm(off_axis - np.outer(off_axis @ axis, axis), axis=1)
    on_bore = (np.abs(radius - 0.5) < 1e-3) & (np.abs(normals @ axis) < 0.05)
    assert on_box.sum() > 50_000 and on_bore.sum() > 20_000
    assert np.all(ids[on_box] == 0) and np.all(ids[on_bore] == 1)  # measured: all


def test_a_placed_copy_refits_the_bvh_of_one_that_is_gone_and_measures_as_a_built_one():
    # a drag places its operand anew on every move: the new copy takes the BVH of the copy before it (gone), its
    # points moved and boxes refitted, and reads the same distances as a BVH built for it; a copy still alive keeps its
    # own, and the next copy builds one
    import gc

    from engine.sources import SourceMesh, mesh_distances

    verts, tris = uv_sphere(1.0, rings=24, segments=48)
    field = engine.build_field(verts, tris, voxel_size=0.05)
    rng = np.random.default_rng(3)
    points = rng.uniform(-2.0, 2.0, (4000, 3)).astype(np.float32)

    def placed(shift, turn):
        m = np.eye(4)
        m[:3, :3] = rotation(2, turn)
        m[:3, 3] = shift
        return next(iter(field.transformed(m).world_sources().values()))

    first = placed((0.1, 0.0, 0.0), 0.0)
    mesh = first.bvh("cpu")
    kept = placed((0.0, 0.2, 0.0), 10.0)  # alive beside the first: a BVH of its own
    assert kept.bvh("cpu") is not mesh
    del first
    gc.collect()
    second = placed((0.3, -0.2, 0.1), 35.0)
    assert second.bvh("cpu") is mesh  # the first's, refitted
    built = SourceMesh(second.verts, second.tris, second.triangle_ids).bvh("cpu")
    refitted = mesh_distances(mesh, points, 3.0, "cpu")
    # the same closest points, found by another walk of the tree: equal to float rounding (measured 2.4e-7, 3 of 4000)
    np.testing.assert_allclose(refitted, mesh_distances(built, points, 3.0, "cpu"), rtol=0, atol=1e-6)
    assert np.abs(refitted - mesh_distances(kept.bvh("cpu"), points, 3.0, "cpu")).max() > 0.1  # (moved: not the same)
