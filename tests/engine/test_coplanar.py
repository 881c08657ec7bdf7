"""Faces of two operands in one plane (engine/coplanar.py): read with their planes, kept once where the result's
surface is theirs, instead of given up as lying on another surface and remeshed.

Voxel = 1/256 of the operands' bounding-box diagonal."""

import numpy as np
import pytest
import warp as wp

import engine
from engine.coplanar import coplanar_readings, flush_triangles, triangles_near, unflushed
from tests.metrics import distance_within, exact_boolean, hausdorff, mesh_area, mesh_volume, sample_surface, to_manifold
from tests.support import box_mesh, is_watertight, uv_sphere

OPS = {"UNION": engine.union, "INTERSECT": engine.intersection, "DIFFERENCE": engine.difference}
BOX = box_mesh(half=(1.0, 0.5, 0.5))


def _kept(op: str, a, b, matrix=None, *, placed=None) -> tuple[dict, float]:
    """The kept surface of ``a`` op ``b`` (``b`` placed by ``matrix``) at 1/256 of the diagonal of ``a`` and ``b``
    (or of ``a`` and ``placed``: ``b`` where it is placed)."""
    v = np.concatenate([a[0], (b if placed is None else placed)[0]])
    h = float(np.linalg.norm(v.max(0) - v.min(0))) / 256
    fa, fb = engine.build_fields([a, b], voxel_size=h, field_ids=[0, 1])
    if matrix is not None:
        fb = fb.transformed(matrix)
    return OPS[op](fa, fb).kept_surface(), h


def test_two_identical_boxes_united_keep_one_boxs_twelve_triangles():
    s, _ = _kept("UNION", BOX, BOX)
    # 8,158 triangles, none kept, while every face lay on the other box's surface
    assert len(s["tris"]) == 12 and s["kept"].all()
    assert (s["field_id"] == 0).all()  # the first operand's: none kept twice
    np.testing.assert_array_equal(np.sort(s["verts"], axis=0), np.sort(BOX[0].astype(np.float32), axis=0))


def test_a_moved_copy_lying_on_the_box_is_read_in_its_planes():
    """A copy built elsewhere and moved onto the box: its corners land there within float rounding."""
    moved = (BOX[0] + np.float32([0.3, -0.2, 0.1]), BOX[1])
    matrix = np.eye(4)
    matrix[:3, 3] = [-0.3, 0.2, -0.1]
    s, _ = _kept("UNION", BOX, moved, matrix)
    assert len(s["tris"]) == 12 and s["kept"].all() and (s["field_id"] == 0).all()


# measured kept share of the result's area (before faces were read in their planes): side by side 0.984 (0.698),
# intersected 0.949 (0.223), a step flush on three sides 0.974 (0.652), a block touching the top from outside,
# subtracted 0.990 (0.933); bounds three times the shortfall
PAIRS = {
    "side by side ∪": ("UNION", BOX, box_mesh(half=(1.0, 0.5, 0.5), center=(1.0, 0.0, 0.0)), 0.95),
    "side by side ∩": ("INTERSECT", BOX, box_mesh(half=(1.0, 0.5, 0.5), center=(0.5, 0.0, 0.0)), 0.85),
    "flush step ∪": ("UNION", BOX, box_mesh(half=(0.5, 0.5, 0.75), center=(0.5, 0.0, 0.25)), 0.92),
    "touching −": ("DIFFERENCE", BOX, box_mesh(half=(0.5, 0.3, 0.25), center=(0.2, 0.0, 0.75)), 0.97),
}


@pytest.mark.parametrize("name", list(PAIRS))
def test_coplanar_pairs_keep_their_faces_once_closed_and_exact(name):
    op, a, b, least = PAIRS[name]
    s, h = _kept(op, a, b)
    exact = exact_boolean(op, *a, *b)
    assert s["stats"]["kept_fallback"] == ""
    assert is_watertight(s["tris"]) and engine.surface_edges(s["tris"], len(s["verts"])) is not None
    to_manifold(s["verts"], s["tris"], "kept surface")
    d = hausdorff(s["verts"], s["tris"], *exact, n=100_000)
    assert d["max"] <= 0.5 * h and d["p95"] <= 0.02 * h, d  # measured max 0.014-0.21 voxel
    assert abs(mesh_volume(s["verts"], s["tris"]) / mesh_volume(*exact) - 1.0) < 1e-3
    kept = s["tris"][s["kept"]]
    assert mesh_area(s["verts"], kept) >= least * mesh_area(*exact)
    if name == "side by side ∪":  # new faces where the first box's faces end and the second's go on (x = 1), and
        # none along the second's end wall inside the first (x = 0) but a few where it meets the boxes' edges:
        # measured 42 (616 while every wall counted, inside the result or not)
        centres = s["verts"][s["tris"][~s["kept"]]].mean(axis=1)
        assert (np.abs(centres[:, 0] - 1.0) > 0.05).sum() <= 120
    # no place kept twice: the second operand's kept faces do not lie on the first's
    first, second = (s["tris"][s["kept"] & (s["field_id"] == k)] for k in (0, 1))
    if len(second):
        points = sample_surface(s["verts"], second, 20_000, seed=1)
        assert (distance_within(s["verts"], first, points, h) > 1e-4 * h).mean() > 0.999


@pytest.mark.parametrize("name", list(PAIRS))
def test_a_mirrored_operand_keeps_its_coinciding_faces_as_an_unmirrored_one(name):
    """The second box built about the origin and placed by a reflection (its triangles, turned with it, face in):
    the same shape, so the same faces are kept. Its faces' ways were read turned: a box minus its mirrored copy came
    out whole, the two intersected were remeshed."""
    op, a, b, least = PAIRS[name]
    centre = b[0].mean(axis=0)
    matrix = np.diag([-1.0, 1.0, 1.0, 1.0])
    matrix[:3, 3] = centre
    s, h = _kept(op, a, ((b[0] - centre).astype(np.float32), b[1]), matrix, placed=b)
    exact = exact_boolean(op, *a, *b)
    assert is_watertight(s["tris"]) and abs(mesh_volume(s["verts"], s["tris"]) / mesh_volume(*exact) - 1.0) < 1e-3
    assert mesh_area(s["verts"], s["tris"][s["kept"]]) >= least * mesh_area(*exact)
    mirror = np.diag([-1.0, 1.0, 1.0, 1.0])
    assert not len(_kept("DIFFERENCE", BOX, BOX, mirror)[0]["tris"])  # (the whole box before)
    same = _kept("INTERSECT", BOX, BOX, mirror)[0]
    assert len(same["tris"]) == 12 and same["kept"].all()  # (4,184 new triangles before)


def test_coplanar_readings_skip_the_faces_in_a_points_plane_and_tie_its_sign():
    verts, tris = box_mesh(half=(1.0, 1.0, 1.0))
    mesh = wp.Mesh(points=wp.array(verts, dtype=wp.vec3), indices=wp.array(tris.reshape(-1).astype(np.int32)))
    points = np.float32([[0.2, 0.3, 1.0], [0.2, 0.3, 1.0], [0.9, 0.0, 1.0], [0.2, 0.3, 1.5]])
    normals = np.float32([[0, 0, 1], [0, 0, -1], [0, 0, 1], [0, 0, 1]])
    alone = flush_triangles(mesh, None, 0.01, "cpu")
    distance, tie, live = coplanar_readings(mesh, None, alone, points, normals, 5.0, 0.01, "cpu")
    # on the top face, facing its way and the other way; off the plane, no tie and the top face counts
    np.testing.assert_array_equal(tie, [1, -1, 1, 0])
    np.testing.assert_array_equal(live, tie != 0)  # (none of the faces skipped)
    # the nearest face out of the plane: the side walls (0.7 and 0.1 away), not the top face under the point
    np.testing.assert_allclose(distance[:3], [0.7, 0.7, 0.1], atol=1e-6)
    np.testing.assert_allclose(distance[3], 0.5, atol=1e-6)
    # read from a copy of the box: every wall lies flush on the copy's, so none is another surface
    copy = wp.Mesh(points=wp.array(verts + np.float32(1e-7), dtype=wp.vec3), indices=mesh.indices)
    flush = flush_triangles(mesh, copy, 0.01, "cpu")
    assert flush.all()
    distance, tie, _ = coplanar_readings(mesh, copy, flush, points, normals, 5.0, 0.01, "cpu")
    np.testing.assert_array_equal(tie, [1, -1, 1, 0])
    np.testing.assert_allclose(distance, 5.0)
    assert unflushed(mesh, flush, "cpu") is None  # (no triangle left to search over the reach)
    # the walls at x = +-1 skipped: the nearest out of the plane is a wall at y = +-1; the top face still ties
    walls = (np.abs(verts[tris][:, :, 0] - np.abs(verts[tris][:, :, 0]).max()) < 1e-6).all(axis=1)
    walls |= (np.abs(verts[tris][:, :, 0] + np.abs(verts[tris][:, :, 0]).max()) < 1e-6).all(axis=1)
    skip = (alone | walls).astype(np.uint8)
    surface = unflushed(mesh, skip, "cpu")
    assert surface.indices.shape[0] == 3 * int((skip == 0).sum()) == 3 * 8
    for given in (False, surface):
        distance, tie, live = coplanar_readings(mesh, None, skip, points, normals, 5.0, 0.01, "cpu", surface=given)
        np.testing.assert_array_equal(tie, [1, -1, 1, 0])
        np.testing.assert_allclose(distance[:3], [0.7, 0.7, 1.0], atol=1e-6)


def test_flush_walls_are_looked_for_near_the_faces_in_a_plane_and_few_skipped_by_their_flags():
    """A mesh with a few faces in another's planes (a copy moved by a voxel) has its flush and internal walls looked
    for about those faces only, and skips the few it flags by their flags instead of building a BVH without them."""
    verts, tris = uv_sphere(1.0, rings=24, segments=48)
    mesh = wp.Mesh(points=wp.array(verts, dtype=wp.vec3), indices=wp.array(tris.reshape(-1).astype(np.int32)))
    corners = verts[tris[[5, 600]]]  # two faces near the poles' ends of a band
    near = triangles_near(mesh, corners, 0.1, "cpu")
    lo, hi = verts[tris].min(axis=1), verts[tris].max(axis=1)
    meets = np.zeros(len(tris), dtype=bool)
    for c in corners:  # (by brute force: boxes within the reach of each other)
        meets |= ((lo <= c.max(axis=0) + 0.1) & (hi >= c.min(axis=0) - 0.1)).all(axis=1)
    np.testing.assert_array_equal(near, meets)
    assert 40 < near.sum() < len(tris) // 8  # measured: 123 of 2,208
    # flush on a copy: only the triangles looked at, each as when all are
    copy = wp.Mesh(points=wp.array(verts + np.float32(1e-7), dtype=wp.vec3), indices=mesh.indices)
    every = flush_triangles(mesh, copy, 0.01, "cpu")
    assert every.all()
    np.testing.assert_array_equal(flush_triangles(mesh, copy, 0.01, "cpu", near), near.astype(np.uint8))
    # three skipped of 2,208: the mesh itself, its readings skipping them; the same as over a BVH built without them
    skip = np.zeros(len(tris), dtype=np.uint8)
    skip[[5, 6, 7]] = 1
    assert unflushed(mesh, skip, "cpu") is mesh
    built = wp.Mesh(points=mesh.points, indices=wp.array(tris[skip == 0].reshape(-1).astype(np.int32)))
    points = (corners.mean(axis=1) * 1.02).astype(np.float32)
    points = np.concatenate([points, verts[tris[[5, 6, 7]]].mean(axis=1) * np.float32(1.05)])
    normals = np.float32([[0, 0, 1]] * len(points))
    ours = coplanar_readings(mesh, None, skip, points, normals, 0.5, 0.01, "cpu", surface=mesh)
    theirs = coplanar_readings(mesh, None, skip, points, normals, 0.5, 0.01, "cpu", surface=built)
    for a, b in zip(ours, theirs, strict=True):
        np.testing.assert_array_equal(a, b)
    alone = coplanar_readings(mesh, None, np.zeros_like(skip), points, normals, 0.5, 0.01, "cpu", surface=mesh)
    assert (ours[0][2:] > alone[0][2:]).all()  # (the skipped faces were the nearest to the last three points)


def test_a_blend_over_coinciding_faces_keeps_none_of_them():
    """A round or chamfered union of two coinciding boxes lies off both boxes' faces (a blend of two equal values
    moves the surface out): their faces are not the result's, and none is kept (12 were, under a chamfer, while ties
    were evaluated as hard booleans)."""
    v = BOX[0]
    h = float(np.linalg.norm(v.max(0) - v.min(0))) / 256
    fa, fb = engine.build_fields([BOX, BOX], voxel_size=h, field_ids=[0, 1])
    for mode in ("round", "chamfer"):
        field = engine.union(fa, fb, blend=8 * h, blend_mode=mode)
        s = field.kept_surface()
        assert not s["kept"].any()
        assert is_watertight(s["tris"])
        d = hausdorff(s["verts"], s["tris"], *field.to_mesh(), n=50_000)
        assert d["max"] <= 1.0 * h, d  # measured 0.14 and 0.69 voxel: both the blend's voxel surface


def test_many_leaves_in_each_others_planes_flag_their_faces_without_listing_every_sign_pattern(monkeypatch):
    # which coplanar faces may be kept once was found over every sign pattern of the other leaves, 3^(n - 2) rows:
    # 16 cubes in a row, face to face, took over 4 GB (20 were killed for memory). Past MAX_TABLE_LEAVES other leaves
    # every such face is judged in its planes; here the cap is lowered to reach that with four cubes
    import engine.judging as judging
    import engine.keep as keep

    listed = []
    monkeypatch.setattr(keep, "MAX_TABLE_LEAVES", 1)
    monkeypatch.setattr(keep, "sign_patterns", lambda n: listed.append(n) or judging.sign_patterns(n))
    cubes = [box_mesh((0.5, 0.5, 0.5), center=(float(i), 0.0, 0.0)) for i in range(4)]
    a, b, c, d = engine.build_fields(cubes, voxel_size=1.0 / 8)
    kept = engine.union(engine.union(a, b), engine.union(c, d)).kept_surface()
    assert all(n <= 1 for n in listed)  # (without the cap: 2 other leaves listed)
    assert is_watertight(kept["tris"]) and mesh_volume(kept["verts"], kept["tris"]) == pytest.approx(4.0, rel=0.01)
    assert kept["kept"].any()


def test_a_row_of_cubes_reads_each_cube_only_near_it_and_keeps_what_reading_every_cube_keeps(monkeypatch):
    # each cube's faces lie in its neighbours' planes, so they are judged sample by sample; every other cube was read
    # at every sample (six cubes: 15 s, eight: 52 s). A closed clean mesh's leaf is now read only near its bounding box
    import engine.keep as keep
    import engine.otherleaves as otherleaves

    cubes = [box_mesh((0.5, 0.5, 0.5), center=(float(i), 0.1 * (i % 3), 0.0)) for i in range(5)]
    fields = engine.build_fields(cubes, voxel_size=1.0 / 8)
    read = []

    def leaf_margin(other, bvh, jumps, points, *args):
        read.append(len(points))
        return otherleaves.leaf_margin(other, bvh, jumps, points, *args)

    def united():
        read.clear()
        tree = engine.union(engine.union(*fields[:2]), engine.union(fields[2], engine.union(*fields[3:])))
        return tree.kept_surface(), sum(read)

    monkeypatch.setattr(keep, "leaf_margin", leaf_margin)
    near, near_reads = united()
    monkeypatch.setattr(keep, "leaf_boxes", lambda leaves: [None] * len(leaves))  # every leaf read everywhere
    every, every_reads = united()
    assert near_reads < 0.5 * every_reads, (near_reads, every_reads)  # measured 6,517 of 28,249
    for key in ("verts", "tris", "kept", "triangle_id"):
        assert np.array_equal(near[key], every[key])
    assert is_watertight(near["tris"]) and mesh_volume(near["verts"], near["tris"]) == pytest.approx(5.0, rel=0.01)
