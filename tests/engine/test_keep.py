"""Booleans that keep the operands' own faces (``AdaptiveField.kept_surface``, ``to_mesh(keep_faces=True)``:
engine/keep.py, engine/refine.py, engine/zipper.py, engine/hybrid.py) against manifold3d's exact booleans.

Voxel = 1/256 of the operands' bounding-box diagonal; distances are stated in voxels. "Should be kept": points of an
operand's surface that lie on the exact result's surface, farther than 3 voxels from every other operand's surface.
"""

import numpy as np
import pytest
from scipy.spatial import cKDTree

import engine
from engine import carried, ownpart
from tests.metrics import (
    distance_within,
    exact_boolean,
    exact_sdf,
    hausdorff,
    mesh_area,
    mesh_volume,
    sample_surface,
    self_intersections,
    to_manifold,
    unsigned_distance,
    winding_inside,
)
from tests.support import (
    box_mesh,
    cad_pairs,
    cylinder_mesh,
    is_watertight,
    load_mesh,
    normalised,
    plate_and_bores,
    rotation,
    uv_sphere,
)

OPS = {"UNION": engine.union, "INTERSECT": engine.intersection, "DIFFERENCE": engine.difference}


def _voxel(*meshes) -> float:
    v = np.concatenate([m[0] for m in meshes])
    return float(np.linalg.norm(v.max(0) - v.min(0))) / 256.0


def _seam_length(exact, a) -> float:
    """Length of the exact result's edges between a face on operand a and one that is not."""
    verts, tris = exact
    on_a = unsigned_distance(*a, verts[tris].mean(axis=1)) < 1e-5
    t = tris.astype(np.int64)
    e = np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
    face = np.tile(np.arange(len(t)), 3)
    key = np.minimum(e[:, 0], e[:, 1]) * len(verts) + np.maximum(e[:, 0], e[:, 1])
    order = np.argsort(key, kind="stable")
    key, face, e = key[order], face[order], e[order]
    pairs = np.flatnonzero(key[1:] == key[:-1])
    seam = on_a[face[pairs]] != on_a[face[pairs + 1]]
    ends = e[pairs[seam]]
    return float(np.linalg.norm(verts[ends[:, 0]] - verts[ends[:, 1]], axis=1).sum())


def _kept_share(surface, operands, exact, h: float, n: int = 60_000) -> float:
    """The share of the surface that should be kept (module docstring) lying on kept faces."""
    kv, kt = surface["verts"], surface["tris"][surface["kept"]]
    covered, total = 0, 0
    for i, (verts, tris) in enumerate(operands):
        pts = sample_surface(verts, tris, n, seed=i)
        on_result = unsigned_distance(*exact, pts) < 1e-5 * 256 * h
        far = np.ones(len(pts), dtype=bool)
        for j, other in enumerate(operands):
            if j != i:
                far &= unsigned_distance(*other, pts) > 3.0 * h
        want = pts[on_result & far]
        total += len(want)
        covered += int((distance_within(kv, kt, want, h) < 1e-5 * 256 * h).sum()) if len(kt) else 0
    return covered / max(total, 1)


def _check_closed(surface):
    verts, tris = surface["verts"], surface["tris"]
    assert is_watertight(tris)
    assert engine.surface_edges(tris, len(verts)) is not None  # closed, consistently oriented
    to_manifold(verts, tris, "kept surface")  # manifold3d takes it as a solid


CASES = {
    "plate - 4 bores": ("DIFFERENCE", *plate_and_bores()),
    **{k: cad_pairs()[k] for k in ("cube - bore", "rocker-arm - cube", "hex prism & sphere", "cube | tilted cube")},
}


@pytest.fixture(scope="module", params=list(CASES))
def case(request):
    op, a, b = CASES[request.param]
    h = _voxel(a, b)
    fa, fb = engine.build_fields([a, b], voxel_size=h)
    field = OPS[op](fa, fb)
    return {
        "name": request.param,
        "h": h,
        "operands": (a, b),
        "surface": field.kept_surface(),
        "remeshed": len(field.to_mesh()[1]),
        "exact": exact_boolean(op, *a, *b),
        "field": field,
    }


def test_kept_surface_is_closed_and_close_to_the_exact_boolean(case):
    s, h = case["surface"], case["h"]
    assert s["stats"]["kept_fallback"] == ""
    _check_closed(s)
    d = hausdorff(s["verts"], s["tris"], *case["exact"], n=100_000)
    # measured: max 0.06-0.41 voxel, the 0.5 (cube | tilted cube's 0.55 while a concave seam's vertex took a
    # plane that misses its cube, engine/dual.py; the rocker arm 0.41, 0.72 before its crease vertex off both operands
    # went back into its cube, engine/reached.py), p95 <= 0.016
    assert d["max"] <= 0.5 * h and d["p95"] <= 0.02 * h, d
    volume, exact = mesh_volume(s["verts"], s["tris"]), mesh_volume(*case["exact"])
    assert abs(volume - exact) < 1e-3 * abs(exact)  # measured <= 5e-5
    # no pair of faces passing through each other: 0, 0, 5, 33 and 10 before the new faces crossing others were tiled
    # again (engine/uncross.py), at the hex prism & sphere's sphere's slivers along the seam; cube | tilted cube had
    # 1,280 with kept border runs as long as its faces
    assert self_intersections(s["verts"], s["tris"]) == 0
    assert s["stats"]["crossing_left"] == 0


def test_kept_faces_cover_what_should_be_kept_and_new_faces_only_the_seams(case):
    s, h = case["surface"], case["h"]
    share = _kept_share(s, case["operands"], case["exact"], h)
    # measured: 1.000 on every pair (cube - bore's 128-sided bore has walls of slivers 1.5 voxels wide and 240 long,
    # on which a float32 closest point lands up to 0.12 voxel off: the distances in float64)
    assert share >= 0.99, share
    seam = _seam_length(case["exact"], case["operands"][0]) / h
    new = s["stats"]["new_faces"]
    # measured: 12-18 new triangles a voxel of seam
    assert new <= 24 * seam * 1.25, (new, seam)
    # the whole output against the remeshed one, measured: plate 0.059, cube - bore 0.033, cube | tilted cube 0.094
    # (new faces collapsed where flat); the rocker arm 0.20 and the hex prism & sphere 0.24, whose operands' own
    # triangles (20,088 and 36,480) are most of it
    low_poly = case["name"] in ("plate - 4 bores", "cube | tilted cube", "cube - bore")
    assert len(s["tris"]) <= (0.15 if low_poly else 0.3) * case["remeshed"]


def test_kept_faces_are_their_sources_own(case):
    """Corners of kept faces that are source vertices sit exactly where the source has them, and kept faces name
    their source triangle: its plane holds them."""
    s, field = case["surface"], case["field"]
    kept = s["kept"]
    assert kept.any()
    for field_id, source in field.sources.items():
        rows = np.flatnonzero(s["vertex_field"] == field_id)
        rows = rows[s["vertex_id"][rows] >= 0]
        np.testing.assert_array_equal(s["verts"][rows], source.verts[s["vertex_id"][rows]])
        faces = np.flatnonzero(kept & (s["field_id"] == field_id))
        src = source.verts[source.tris[np.searchsorted(source.triangle_ids, s["triangle_id"][faces])]]
        n = np.cross(src[:, 1] - src[:, 0], src[:, 2] - src[:, 0])
        n /= np.linalg.norm(n, axis=1, keepdims=True)
        corners = s["verts"][s["tris"][faces]]
        off = np.abs(np.einsum("fkj,fj->fk", corners - src[:, :1], n))
        assert off.max(initial=0.0) < 1e-5 * 256 * case["h"]


def test_kept_faces_face_their_sources_way_and_subtracted_ones_flipped():
    """Kept faces lie in their source triangle, facing its way; a subtracted operand's kept faces come back
    flipped (a bore's wall faces its axis)."""
    op, a, b = CASES["plate - 4 bores"]
    h = _voxel(a, b)
    fa, fb = engine.build_fields([a, b], voxel_size=h, field_ids=[0, 1])
    s = (fa - fb).kept_surface()
    corners = s["verts"][s["tris"]]
    normal = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    for field_id, (verts, tris), sign in ((0, a, 1.0), (1, b, -1.0)):
        faces = np.flatnonzero(s["kept"] & (s["field_id"] == field_id))
        assert len(faces)
        src = verts[tris[s["triangle_id"][faces]]]
        src_normal = np.cross(src[:, 1] - src[:, 0], src[:, 2] - src[:, 0])
        assert (sign * np.einsum("ij,ij->i", normal[faces], src_normal) > 0).all()
    bore = np.flatnonzero(s["kept"] & (s["field_id"] == 1))
    centre = corners[bore].mean(axis=1)
    axis = np.array([[-0.5, -0.5], [-0.5, 0.5], [0.5, -0.5], [0.5, 0.5]])
    nearest = axis[np.argmin(((centre[:, None, :2] - axis[None]) ** 2).sum(axis=2), axis=1)]
    assert (np.einsum("ij,ij->i", normal[bore, :2], nearest - centre[:, :2]) > 0).all()


def test_small_triangles_far_from_the_seam_come_back_bit_for_bit():
    spot = normalised(load_mesh("spot.obj"))
    ball = normalised(uv_sphere(1.0, rings=24, segments=48), center=(0.25, 0.1, 0.2), diagonal=0.5)
    h = _voxel(spot, ball)
    fa, fb = engine.build_fields([spot, ball], voxel_size=h, field_ids=[0, 1])
    s = (fa - fb).kept_surface()
    faces = np.flatnonzero(s["kept"] & (s["field_id"] == 0))
    corners = s["verts"][s["tris"][faces]]
    source = spot[0][spot[1][s["triangle_id"][faces]]]
    same = np.zeros(len(faces), dtype=bool)
    for k in range(3):  # the same corners in any of the three turns
        same |= (np.roll(corners, k, axis=1) == source).all(axis=(1, 2))
    assert same.mean() > 0.99, same.mean()  # the same corners in the same turn, bit for bit
    assert len(faces) > 0.8 * len(spot[1])


def test_open_scan_united_with_a_ball_keeps_its_faces_away_from_the_holes():
    bunny = normalised(load_mesh("stanford-bunny.obj"))
    ball = normalised(uv_sphere(1.0), center=(0.2, 0.2, 0.2), diagonal=0.6)
    h = _voxel(bunny, ball)
    fa, fb = engine.build_fields([bunny, ball], voxel_size=h)
    field = fa | fb
    s = field.kept_surface()
    _check_closed(s)
    remeshed = field.to_mesh()
    assert len(s["tris"]) < 0.5 * len(remeshed[1])  # measured 84 k against 191 k
    # the bunny's own faces outside the ball, 3 voxels from it and from the bunny's holes, are kept
    pts = sample_surface(*bunny, 40_000)
    outside = ~winding_inside(*ball, pts) & (unsigned_distance(*ball, pts) > 3 * h)
    far_from_holes = _distance_to_defects(*bunny, pts, 0.25 * h) > 3 * h
    want = pts[outside & far_from_holes]
    kept = unsigned_distance(s["verts"], s["tris"][s["kept"]], want) < 1e-6
    assert kept.mean() >= 0.99, kept.mean()
    # the holes are capped as the field caps them: the kept surface and the voxel surface agree there
    d = hausdorff(s["verts"], s["tris"], *remeshed, n=50_000)
    assert d["max"] < 1.0 * h, d


def _distance_to_defects(verts, tris, points, step: float) -> np.ndarray:
    """(N,) distance (within ``step``) from each point to the mesh's defects: its open and non-manifold edges and the
    edges its two faces list in one direction (vertices at one position merged first), sampled ``step`` apart."""
    unique, weld = np.unique(verts, axis=0, return_inverse=True)
    t = weld.reshape(-1)[np.asarray(tris, dtype=np.int64)]
    e = np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
    key = np.minimum(e[:, 0], e[:, 1]) * len(unique) + np.maximum(e[:, 0], e[:, 1])
    _, inverse, counts = np.unique(key, return_inverse=True, return_counts=True)
    inverse = inverse.reshape(-1)
    forward = np.bincount(inverse, weights=e[:, 0] < e[:, 1], minlength=len(counts))
    bad = e[((counts != 2) | (forward != 1))[inverse]]
    a, b = unique[bad[:, 0]].astype(np.float64), unique[bad[:, 1]].astype(np.float64)
    steps = np.maximum(np.ceil(np.linalg.norm(b - a, axis=1) / step), 1).astype(np.int64)
    edge = np.repeat(np.arange(len(bad)), steps + 1)
    k = np.arange(len(edge)) - np.repeat(np.cumsum(steps + 1) - (steps + 1), steps + 1)
    along = (k / steps[edge])[:, None]
    cloud = a[edge] + along * (b[edge] - a[edge])
    return cKDTree(cloud).query(points)[0]


def test_a_chain_keeps_faces_of_every_operand_and_moved_operands_keep_theirs_where_placed():
    a = normalised(box_mesh(), diagonal=1.0)
    b = normalised(box_mesh(), center=(0.35, 0.1, 0.05), diagonal=0.8, matrix=rotation(2, 20.0))
    c = normalised(uv_sphere(1.0, rings=32, segments=64), center=(-0.1, -0.3, 0.3), diagonal=0.5)
    h = _voxel(a, b, c)
    fa, fb, fc = engine.build_fields([a, b, c], voxel_size=h, field_ids=[0, 1, 2])
    turn = np.eye(4)
    turn[:3, :3] = rotation(1, 15.0)
    turn[:3, 3] = (0.02, -0.03, 0.01)
    fc_moved = fc.transformed(turn)
    field = (fa | fb) - fc_moved
    s = field.kept_surface()
    _check_closed(s)
    assert set(np.unique(s["field_id"][s["kept"]])) == {0, 1, 2}
    placed_c = (c[0] @ turn[:3, :3].T + turn[:3, 3]).astype(np.float32)
    exact_ab = exact_boolean("UNION", *a, *b)
    exact = exact_boolean("DIFFERENCE", *exact_ab, placed_c, c[1])
    d = hausdorff(s["verts"], s["tris"], *exact, n=50_000)
    remeshed = hausdorff(*field.to_mesh(), *exact, n=50_000)
    # measured: max 1.07 voxels, as the remeshed surface's (a wedge at a seam of the turned boxes), p95 < 0.001
    assert d["max"] <= remeshed["max"] + 0.1 * h and d["p95"] < 0.05 * h, (d, remeshed)
    rows = np.flatnonzero((s["vertex_field"] == 2) & (s["vertex_id"] >= 0))
    np.testing.assert_allclose(s["verts"][rows], placed_c[s["vertex_id"][rows]], atol=1e-6)


@pytest.mark.parametrize("seams", [False, True])
def test_a_placed_boolean_keeps_its_operands_faces_where_it_is_placed(seams):
    """A boolean's result placed (turned, scaled, moved) and used as an operand: its operands' faces are kept where it
    was placed (the outer boolean took the inner one's operands where they were built: kept faces 26 voxels off, the
    volume 1.4 % over)."""
    a, b = box_mesh(half=(0.5, 0.4, 0.3)), box_mesh(half=(0.3, 0.3, 0.3), center=(0.3, 0.3, 0.2))
    c = uv_sphere(0.55, center=(0.2, 0.1, 0.05), rings=24, segments=48)
    h = 0.016
    fa, fb, fc = engine.build_fields([a, b, c], voxel_size=h, field_ids=[0, 1, 2], refine="auto")
    move = np.eye(4)
    move[:3, :3], move[:3, 3] = 1.15 * rotation(2, 30.0), (0.15, -0.1, 0.08)
    inner = engine.union(fa, fb, seams=seams).transformed(move)
    s = engine.difference(fc, inner.transformed(move), seams=seams).kept_surface()
    _check_closed(s)
    twice = move @ move
    placed = (exact_boolean("UNION", *a, *b)[0] @ twice[:3, :3].T + twice[:3, 3]).astype(np.float32)
    exact = exact_boolean("DIFFERENCE", *c, placed, exact_boolean("UNION", *a, *b)[1])
    assert set(np.unique(s["field_id"][s["kept"]])) == {0, 1, 2}
    assert unsigned_distance(*exact, s["verts"]).max() <= 0.75 * h  # measured 0.45 voxel
    assert abs(mesh_volume(s["verts"], s["tris"]) / mesh_volume(*exact) - 1.0) < 0.004  # measured -0.20 %


def test_inside_out_and_internal_faces():
    """An inside-out box's kept faces face outward; the internal faces of two overlapping boxes given as one mesh
    are not kept (they are not on the surface); both results stay closed."""
    box_v, box_t = normalised(box_mesh(), diagonal=1.0)
    flipped = (box_v, box_t[:, ::-1].copy())
    ball = normalised(uv_sphere(1.0, rings=32, segments=64), center=(0.3, 0.3, 0.3), diagonal=0.5)
    h = _voxel(flipped, ball)
    fa, fb = engine.build_fields([flipped, ball], voxel_size=h)
    s = (fa | fb).kept_surface()
    _check_closed(s)
    assert s["kept"].sum() >= 8 and mesh_volume(s["verts"], s["tris"]) > 0
    exact = exact_boolean("UNION", box_v, box_t, *ball)
    assert abs(mesh_volume(s["verts"], s["tris"]) / mesh_volume(*exact) - 1) < 1e-3
    # two overlapping boxes as one self-intersecting mesh
    other = normalised(box_mesh(), center=(0.25, 0.2, 0.15), diagonal=1.0)
    overlap = (np.concatenate([box_v, other[0]]), np.concatenate([box_t, other[1] + len(box_v)]))
    fa, fb = engine.build_fields([overlap, ball], voxel_size=_voxel(overlap, ball))
    s = (fa - fb).kept_surface()
    _check_closed(s)
    # the ball's faces inside the boxes are kept (the cavity's wall); the boxes' own faces near their crossing are
    # judged but their border does not pair with the voxel surface's there yet: remeshed, conservatively
    assert (s["kept"] & (s["field_id"] == 1)).sum() > 1000
    corners = s["verts"][s["tris"][s["kept"] & (s["field_id"] == 0)]]
    inside_both = winding_inside(box_v, box_t, corners.mean(axis=1)) & winding_inside(*other, corners.mean(axis=1))
    assert not inside_both.any()  # no kept face inside the other box
    # nor any part of one: kept faces stay a band from where the mesh passes through itself (measured: none of
    # 10,440 samples; 2,094 of 12,500 up to 0.64 voxel inside when only sampled a voxel apart by the judge)
    samples = np.einsum("tsk,tkd->tsd", np.random.default_rng(0).dirichlet([1, 1, 1], (len(corners), 20)), corners)
    samples = samples.reshape(-1, 3).astype(np.float32)
    depth = np.maximum(exact_sdf(box_v, box_t, samples), exact_sdf(*other, samples))  # > 0 outside either box
    assert (depth > -1e-4 * _voxel(overlap, ball)).all(), depth.min()
    exact = exact_boolean("DIFFERENCE", *exact_boolean("UNION", box_v, box_t, *other), *ball)
    assert abs(mesh_volume(s["verts"], s["tris"]) / mesh_volume(*exact) - 1) < 1e-3


@pytest.mark.parametrize("inside_out", [False, True], ids=["outward", "inside out"])
def test_a_plate_thinner_than_a_voxel_keeps_its_faces(inside_out):
    """A plate a third of a voxel thick is invisible to its field (both sides of its faces read outside) and gone
    from the voxel surface; its faces are the surface all the same, facing the way the rest of the mesh does."""
    h = 1.6 / 128
    plate = box_mesh(half=(0.5, 0.5, 0.5 * 0.3 * h), center=(0.0, 0.0, -0.2), subdivisions=4)
    body = normalised(box_mesh(), center=(0.0, 0.0, -0.45), diagonal=0.4)  # the mesh's way is read off it
    mesh = (np.concatenate([plate[0], body[0]]), np.concatenate([plate[1], body[1] + len(plate[0])]))
    if inside_out:
        mesh = (mesh[0], mesh[1][:, ::-1].copy())
    ball = normalised(uv_sphere(1.0, rings=24, segments=48), center=(0.0, 0.0, 0.6), diagonal=0.5)
    fa, fb = engine.build_fields([mesh, ball], voxel_size=h, field_ids=[0, 1])
    s = engine.union(fa, fb).kept_surface()
    _check_closed(s)
    exact = exact_boolean("UNION", *exact_boolean("UNION", *plate, *body), *ball)
    d = hausdorff(s["verts"], s["tris"], *exact, n=20_000)
    # measured: max 0.016 voxel, the volume to 1e-15 (before: the plate gone, 74 voxels off, a quarter of the volume)
    assert d["max"] < 0.05 * h, d
    assert abs(mesh_volume(s["verts"], s["tris"]) / mesh_volume(*exact) - 1) < 1e-4


def test_fields_without_source_faces_are_remeshed_and_bad_requests_refused():
    a = normalised(box_mesh(), diagonal=1.0)
    (fa,) = engine.build_fields([a], voxel_size=1 / 128)
    s = fa.kept_surface()  # a built field is no boolean: its voxel surface
    assert not s["kept"].any() and len(s["tris"]) == len(fa.to_mesh()[1])
    ball = normalised(uv_sphere(1.0, rings=24, segments=48), center=(0.3, 0.3, 0.3), diagonal=0.5)
    (fb,) = engine.build_fields([ball], voxel_size=1 / 128, field_ids=[1])
    grown = engine.offset(fa, 2 / 128) - fb  # an offset has no source faces: only the ball's are kept
    s = grown.kept_surface()
    _check_closed(s)
    assert set(np.unique(s["field_id"][s["kept"]])) == {1}
    with pytest.raises(ValueError, match="'iso' 0 with 'keep_faces'"):
        grown.to_mesh(0.01, keep_faces=True)


def test_corner_weights_of_kept_faces_give_back_their_corners():
    """Each kept face's corners as weights of its source triangle's corners: the weights give the corners back, and a
    corner that is a source corner has weight exactly 1 there (UVs and colours read off it bit for bit)."""
    op, a, b = CASES["plate - 4 bores"]
    h = _voxel(a, b)
    fa, fb = engine.build_fields([a, b], voxel_size=h, field_ids=[0, 1])
    s = (fa - fb).kept_surface()
    for field_id, (verts, tris) in ((0, a), (1, b)):
        faces = np.flatnonzero(s["kept"] & (s["field_id"] == field_id))
        src = verts[tris[s["triangle_id"][faces]]].astype(np.float64)  # (F, 3, 3)
        back = np.einsum("fkc,fcj->fkj", s["corner_bary"][faces].astype(np.float64), src)
        np.testing.assert_allclose(back, s["verts"][s["tris"][faces]], atol=1e-5)
        corner = s["vertex_id"][s["tris"][faces]] >= 0
        weights = s["corner_bary"][faces][corner]
        assert ((weights == 0) | (weights == 1)).all() and (weights.sum(axis=1) == 1).all()
    assert not s["corner_bary"][~s["kept"]].any()


@pytest.mark.parametrize("centre", [(0.2, 0.2, 0.2), (0.2, 0.15, 0.1)])
def test_the_beetle_with_its_large_holes_united_with_a_ball_is_closed_and_keeps_faces(centre):
    # (at the second place, kept loops zipped to each other left a voxel loop with no kept loop near it to give faces
    # up at, round after round: the join fell back to the voxel surface alone)
    beetle = normalised(load_mesh("beetle.obj"))
    ball = normalised(uv_sphere(1.0), center=centre, diagonal=0.6)
    fa, fb = engine.build_fields([beetle, ball], voxel_size=_voxel(beetle, ball))
    field = fa | fb
    s = field.kept_surface()
    _check_closed(s)
    assert s["stats"]["kept_fallback"] == ""
    # measured: 11,600-12,000 faces kept, 81-84 k in all against 188 k remeshed
    assert s["kept"].sum() > 4000 and len(s["tris"]) < 0.6 * len(field.to_mesh()[1])


SHARED = ("alligator", "beetle", "cow", "fandisk", "homer", "rocker-arm", "spot", "stanford-bunny", "suzanne", "teapot")


@pytest.mark.parametrize("name", SHARED)
def test_every_shared_mesh_with_a_ball_gives_closed_kept_surfaces(name):
    """Union, difference and intersection of each shared mesh (open, inside-out or flat ones too) with a ball at
    /128: closed and consistently oriented whenever not empty; a closed clean mesh keeps faces of its own."""
    mesh = normalised(load_mesh(f"{name}.obj"))
    ball = normalised(uv_sphere(1.0, rings=32, segments=64), center=(0.15, 0.1, 0.2), diagonal=0.6)
    h = _voxel(mesh, ball) * 2.0
    fa, fb = engine.build_fields([mesh, ball], voxel_size=h, field_ids=[0, 1])
    for op in (engine.union, engine.difference, engine.intersection):
        s = op(fa, fb).kept_surface()
        if len(s["tris"]):
            assert engine.surface_edges(s["tris"], len(s["verts"])) is not None, op.__name__
            assert s["stats"]["kept_fallback"] in ("", "not a boolean of meshes"), s["stats"]
        if fa.stats.get("clean_mesh") and op is not engine.intersection:
            # measured: the cow 7,986 / 5,127, homer 13,844 / 10,057, the rocker arm 20,939 / 17,672 faces kept
            assert (s["kept"] & (s["field_id"] == 0)).sum() > 0.2 * len(mesh[1]), op.__name__


def test_a_drag_keeps_the_faces_a_fresh_field_would():
    """A drag's moves judge the unmoved operand's triangles with what its first move found of them (its defects,
    the sides of its own field): the last move keeps exactly the faces that a field built afresh keeps."""
    base = box_mesh(half=(1.0, 0.8, 0.6), subdivisions=3)
    cutter = uv_sphere(0.5, center=(0.9, 0.0, 0.3), rings=24, segments=48)
    h = 2.0 * _voxel(base, cutter)  # /128: the same judging as /256 at a quarter of its samples
    fa, fb = engine.build_fields([base, cutter], voxel_size=h, field_ids=[0, 1])
    (fresh,) = engine.build_fields([base], voxel_size=h, field_ids=[0])

    def moved(step):
        matrix = np.eye(4)
        matrix[:3, 3] = (-0.05 * step, 0.02 * step, 0.0)
        return fb.transformed(matrix)

    for step in range(3):
        (fa - moved(step)).kept_surface()
    dragged, afresh = (fa - moved(3)).kept_surface(), (fresh - moved(3)).kept_surface()
    assert dragged["kept"].sum() > 0.2 * len(dragged["tris"])  # the box's own faces: measured 1,652 of 3,870
    for name in ("verts", "tris", "kept", "field_id", "triangle_id", "corner_bary"):
        np.testing.assert_array_equal(dragged[name], afresh[name])


def test_a_placed_operand_is_judged_with_its_unplaced_sources_own_part(monkeypatch):
    """A placed operand's defects (here Suzanne's open edges and the curves where its eyes pass through its head),
    sides and slivers are found once on its unplaced source and placed: the kept surface is the one found afresh."""
    suzanne = normalised(load_mesh("suzanne.obj"))
    ball = normalised(uv_sphere(1.0, rings=32, segments=64), center=(0.15, 0.1, 0.2), diagonal=0.6)
    h = 2.0 * _voxel(suzanne, ball)
    fa, fb = engine.build_fields([suzanne, ball], voxel_size=h, field_ids=[0, 1])
    matrix = np.eye(4)
    matrix[:3, :3] = 1.1 * rotation(2, 17.0)
    matrix[:3, 3] = (0.01, -0.02, 0.0)
    placed = fa.transformed(matrix)
    reused = (fb | placed).kept_surface()
    assert ownpart._OWN.get(next(iter(fa.sources.values()))) is not None  # found on the unplaced source
    monkeypatch.setattr(ownpart, "_placed_own", lambda leaf, voxel, device: None)
    carried.forget()  # (the points the first join gave faces up at would be kept clear of from the first)
    afresh = (fb | placed).kept_surface()
    assert reused["kept"].sum() > 1000
    for name in ("verts", "tris", "kept", "field_id", "triangle_id", "corner_bary"):
        np.testing.assert_array_equal(reused[name], afresh[name])


# measured (own faces kept, against the input's triangles; pieces of split ones count apiece): homer 11,388 of
# 12,000 (none before: the join gave up whole pieces, round after round, and fell back to the voxel surface), the cow
# 5,048 of 5,804 (none), the teapot 2,679 of 6,320 (none: its triangles at open edges were never kept, now their parts
# a band away are), suzanne 1,013 of 968 (1), the beetle with its large holes 1,055 of 2,053 (18)
MESSY = {"homer": 9000, "cow": 4000, "teapot": 900, "suzanne": 340, "beetle": 350}


@pytest.mark.parametrize("name", list(MESSY))
def test_meshes_with_thin_parts_and_open_edges_keep_their_faces_with_a_ball(name):
    """Each united with a ball at /256: loops near thin parts fail for several rounds (each giving up a few kept faces
    rings deep, not whole pieces), and triangles at open or inconsistent edges keep their parts a band away."""
    mesh = normalised(load_mesh(f"{name}.obj"))
    ball = normalised(uv_sphere(1.0, rings=48, segments=96), center=(0.2, 0.2, 0.2), diagonal=0.6)
    fa, fb = engine.build_fields([mesh, ball], voxel_size=_voxel(mesh, ball), field_ids=[0, 1])
    s = engine.union(fa, fb).kept_surface()
    assert s["stats"]["kept_fallback"] == "", s["stats"]
    _check_closed(s)
    assert (s["kept"] & (s["field_id"] == 0)).sum() > MESSY[name]


def _new_faces_off_the_seam(surface, a, b, h: float) -> int:
    """New faces whose centre is farther than 4 voxels from one of the two operands (off the seam, where the
    surface is one operand's own)."""
    centres = surface["verts"][surface["tris"][~surface["kept"]]].mean(axis=1)
    return int((np.maximum(unsigned_distance(*a, centres), unsigned_distance(*b, centres)) > 4.0 * h).sum())


def _area(verts, tris) -> float:
    return float(
        0.5
        * np.linalg.norm(
            np.cross(verts[tris[:, 1]] - verts[tris[:, 0]], verts[tris[:, 2]] - verts[tris[:, 0]]), axis=1
        ).sum()
    )


def _kept_wall_share(surface, exact, bore, field_id: int, tolerance: float) -> float:
    """The area of the bore's kept faces over the area of the exact result's faces on the bore (their centres within
    ``tolerance`` of it: the distance query reads points on its slivers up to 0.12 voxel off)."""
    ev, et = exact
    on_bore = unsigned_distance(*bore, ev[et].mean(axis=1)) < tolerance
    kept = surface["kept"] & (surface["field_id"] == field_id)
    return _area(surface["verts"], surface["tris"][kept]) / _area(ev, et[on_bore])


@pytest.mark.parametrize("segments", [128, 256])
def test_a_bore_through_the_fandisk_keeps_its_sliver_wall(segments):
    """The cylinder's wall triangles are slivers (1.4 and 0.7 voxels wide, 220 long): the pieces near the seam are cut
    across (a strip between each sliver's long edges, engine/slivers.py: no pieces narrower than the sliver), the kept
    border straightened along their cuts, and the strips follow it, so the bore keeps its wall. With 256 sides a kept
    finger a fifth of a voxel wide runs along the seam where the fandisk's bottom grazes the cylinder: only it is given
    up."""
    op, a, b = cad_pairs()["fandisk - cylinder"]
    if segments != 128:
        r = 0.12  # as cad_pairs() makes it
        bore = normalised(cylinder_mesh(r, np.sqrt(1.0 - 8.0 * r * r), segments=segments))
        b = normalised(bore, center=(0.0, 0.05, -0.05), matrix=rotation(1, 90.0))
    h = _voxel(a, b)
    fa, fb = engine.build_fields([a, b], voxel_size=h, field_ids=[0, 1])
    s = OPS[op](fa, fb).kept_surface()
    _check_closed(s)
    assert s["stats"]["kept_fallback"] == ""
    exact = exact_boolean(op, *a, *b)
    # measured: 712 and 1,400 of the cylinder's faces kept (1,576 and 2,606 when slivers were bisected into needles),
    # 0.866 and 0.873 of its wall's area (none before: its wall came back as 13,000 voxel faces)
    assert 0 < (s["kept"] & (s["field_id"] == 1)).sum() < {128: 1100, 256: 2100}[segments]
    assert _kept_wall_share(s, exact, b, 1, 0.2 * h) > 0.8
    assert _new_faces_off_the_seam(s, a, b, h) <= 20  # measured 0 at /96 to /256
    d = hausdorff(s["verts"], s["tris"], *exact, n=50_000)
    assert d["max"] < 1.0 * h and d["p95"] < 0.05 * h, d  # measured max 0.37 voxel, p95 0.001


@pytest.mark.parametrize("resolution", [128, 160])
def test_a_bore_keeps_its_sliver_wall_at_coarser_voxels(resolution):
    """At /128 and /160 the bore's wall triangles are under a voxel wide: their kept border runs along cuts across
    them, and the strip pairs it with the voxel loop step by step."""
    op, a, b = cad_pairs()["cube - bore"]
    h = _voxel(a, b) * 256 / resolution
    fa, fb = engine.build_fields([a, b], voxel_size=h, field_ids=[0, 1])
    s = OPS[op](fa, fb).kept_surface()
    _check_closed(s)
    assert s["stats"]["kept_fallback"] == ""
    exact = exact_boolean(op, *a, *b)
    # measured: the bore's faces kept 1,024 (/128) and 3,160 (/160), 0.916 and 0.942 of its wall's area; 304 and 272
    # faces kept in all before, none of them the bore's
    assert (s["kept"] & (s["field_id"] == 1)).sum() > {128: 340, 160: 1050}[resolution]
    assert _kept_wall_share(s, exact, b, 1, 0.2 * _voxel(a, b)) > 0.85
    assert _new_faces_off_the_seam(s, a, b, h) <= 20  # measured 0
    d = hausdorff(s["verts"], s["tris"], *exact, n=50_000)
    assert d["max"] < 1.0 * h and d["p95"] < 0.05 * h, d  # measured max 0.36-0.37 voxel, p95 0.002


def test_a_closed_clean_leaf_is_read_at_the_samples_near_its_box_and_others_everywhere():
    from engine.otherleaves import NearRows, leaf_boxes, leaf_bvh, leaf_jumps

    cube = box_mesh((0.5, 0.5, 0.5), center=(1.0, 0.0, 0.0))
    hole = (cube[0], cube[1][2:])  # open: its field may jump, read everywhere
    far = box_mesh((0.5, 0.5, 0.5), center=(9.0, 0.0, 0.0))
    around = box_mesh((2.6, 2.6, 2.6), center=(0.5, 0.5, 0.5))  # its box holds every point
    fields = engine.build_fields([cube, hole, far, around], voxel_size=0.1)
    bvhs = [leaf_bvh(f, "cpu") for f in fields]
    near = NearRows(bvhs, [leaf_jumps(f, "cpu") for f in fields], leaf_boxes(fields))
    points = np.random.default_rng(4).uniform(-2.0, 3.0, size=(5000, 3)).astype(np.float32)
    indexed = near.index(points)
    rows = near.rows(0, indexed, 0.3)
    want = np.flatnonzero((np.abs(points - (1.0, 0.0, 0.0)) <= 0.5 + 0.3).all(axis=1))
    assert np.array_equal(rows, want) and 0 < len(rows) < len(points)
    assert np.array_equal(near.rows(1, indexed, 0.3), np.arange(len(points)))
    assert len(near.rows(2, indexed, 0.3)) == 0
    # the leaves whose box comes near the points' at all, and all their rows found together, the same rows
    assert np.array_equal(near.rows(3, indexed, 0.0), np.arange(len(points)))
    assert near.near(indexed, 0.3).tolist() == [True, True, False, True]
    together = near.rows_of([0, 1, 2, 3], indexed, 0.3)
    assert all(np.array_equal(together[j], near.rows(j, indexed, 0.3)) for j in range(4))
    # a box that holds all but a few points: every row but theirs
    inside = np.flatnonzero((np.abs(points - 0.5) <= 2.4).all(axis=1))
    assert np.array_equal(near.rows(3, indexed, -0.2), inside) and 0 < len(inside) < len(points)


def test_a_bore_half_a_voxel_under_a_face_is_judged_by_the_cylinders_mls_signs_and_joined(monkeypatch):
    """A block minus a cylinder of 64 long thin sides, tilted a degree, half a voxel under the block's top face (/256).
    Past its finest band the cylinder's linear values read the wrong sign about its thin wall: the judge kept pieces
    inside it, and the join left 186 pairs of faces passing through each other; the voxel surface was given instead.
    Their signs read again by MLS where they miss the mesh's distance (engine/otherleaves.py), the join holds: the
    block's faces kept but along the cut, as close to the exact difference as the voxel surface is (the 0.57-voxel
    skin over the bore opens in both). With the linear signs alone (the re-read turned off), the triangles judged
    again clear of the faces left crossing, round after round (engine/clearing.py), give a surface as good."""
    from engine import clearing, otherleaves
    from engine.selfcross import crossing_pairs

    voxel = 2.0 * np.sqrt(3.0) / 256
    turn = rotation(2, 232.98822416673) @ rotation(1, 90.0 + 0.99426621199651) @ rotation(2, 241.42478928970692)
    cylinder = cylinder_mesh(0.4, 3.0, 64)
    cylinder = ((cylinder[0] @ turn.T + (0.0, 0.0, 0.6 - 0.57079917786366 * voxel)).astype(np.float32), cylinder[1])
    block = box_mesh(half=(0.6, 0.6, 1.0))

    judged, rounds = clearing.kept_triangles, []
    monkeypatch.setattr(clearing, "kept_triangles", lambda *args, **kwargs: rounds.append(1) or judged(*args, **kwargs))
    exact = to_manifold(*block) - to_manifold(*cylinder)
    near = exact_boolean("DIFFERENCE", *block, *cylinder)

    def kept(p95: float):
        rounds.clear()
        fa, fb = engine.build_fields([block, cylinder], voxel_size=voxel, refine="auto")
        s = engine.difference(fa, fb, seams=True).kept_surface(sharp=True)
        assert s["stats"]["kept_fallback"] == ""
        _check_closed(s)
        assert not len(crossing_pairs(s["verts"], s["tris"].astype(np.int64), "cpu"))
        assert mesh_volume(s["verts"], s["tris"]) == pytest.approx(exact.volume(), rel=1e-3)  # measured -0.029 %
        d = hausdorff(s["verts"], s["tris"], *near, n=100_000)
        # measured: max 4.73 voxels where the skin opens (the remeshed surface's too)
        assert d["max"] < 5.0 * voxel and d["p95"] < p95 * voxel, d
        return mesh_area(s["verts"], s["tris"][s["kept"]]) / exact.surface_area()

    assert kept(0.005) > 0.8 and not rounds  # measured 0.926, joined once; p95 0.0017 voxel (remeshed 0.0091)
    monkeypatch.setattr(otherleaves, "SIGN_CHECK_VOXELS", np.inf)  # the linear signs alone
    assert kept(0.008) > 0.8 and rounds  # measured 0.916, after two rounds; p95 0.0028 voxel


def test_different_meshes_with_one_field_id_are_refused_with_what_to_do_and_copies_of_one_field_keep():
    plate, slot = box_mesh((1.0, 1.0, 0.2)), box_mesh((0.5, 0.1, 0.5), center=(0.3, 0.2, 0.0))
    fp, fs = engine.build_field(*plate, voxel_size=0.04), engine.build_field(*slot, voxel_size=0.04)  # both id 0
    with pytest.raises(ValueError, match="different meshes with the same field id 0.*engine.build_fields"):
        engine.difference(fp, fs, seams=True).kept_surface()
    kept = engine.difference(fp, fs.relabel(1), seams=True).kept_surface()
    assert is_watertight(kept["tris"]) and kept["kept"].sum() > 0
    moved = np.eye(4)
    moved[:3, 3] = (-0.6, -0.5, 0.0)
    copies = engine.difference(fp, engine.union(fs.relabel(1), fs.relabel(1).transformed(moved)), seams=True)
    twice = copies.kept_surface()  # one mesh placed twice under one id: its faces are the same triangles
    assert is_watertight(twice["tris"]) and twice["kept"].sum() > kept["kept"].sum()


def test_a_join_that_leaves_faces_passing_through_each_other_is_judged_again_clear_of_them(monkeypatch):
    """A box minus a cylinder of 40 long thin sides, turned and mirrored: the join broke down along the seam (a sliver
    given up whole left its neighbour's edge, as long as the bore, to a fan of strips) and left 1,023 pairs of faces
    passing through each other (16 % of its new faces). Judged again clear of where they cross, the join holds;
    where it would not, the voxel surface is given, saying why."""
    from engine import hybrid
    from engine.selfcross import crossing_pairs

    matrix = np.eye(4)
    matrix[:3, :3] = rotation(1, np.degrees(0.2)) @ rotation(0, np.degrees(0.4)) @ np.diag([-1.0, 1.0, 1.0])
    matrix[:3, 3] = (0.5074, 0.2958, 0.2026)
    cylinder = cylinder_mesh(0.4, 3.0, 40)
    cylinder = ((cylinder[0] @ matrix[:3, :3].T + matrix[:3, 3]).astype(np.float32), cylinder[1][:, ::-1].copy())
    box = box_mesh(subdivisions=4)

    def kept():
        fa, fb = engine.build_fields([box, cylinder], voxel_size=1.0 / 64, refine="auto")
        return engine.difference(fa, fb, seams=True).kept_surface(sharp=True)

    s = kept()
    assert not s["stats"]["kept_fallback"] and s["stats"]["rejoined"] > 0
    _check_closed(s)
    assert not len(crossing_pairs(s["verts"], s["tris"].astype(np.int64), "cpu"))
    exact = to_manifold(*box) - to_manifold(*cylinder)
    assert mesh_volume(s["verts"], s["tris"]) == pytest.approx(exact.volume(), rel=2e-4)  # measured -0.005 %
    assert mesh_area(s["verts"], s["tris"][s["kept"]]) > 0.9 * exact.surface_area()  # measured 0.969
    # judged again clear of nothing: the same join, and the voxel surface, saying why
    finished = hybrid.finished

    def nowhere(*args):  # the faces left crossing said to lie nowhere
        out = finished(*args)
        return {**out, "stats": {**out["stats"], "crossing_at": np.zeros((0, 3), np.float32)}}

    monkeypatch.setattr(hybrid, "finished", nowhere)
    s = kept()
    assert "passing through each other" in s["stats"]["kept_fallback"] and not s["kept"].any()
    _check_closed(s)
    assert not len(crossing_pairs(s["verts"], s["tris"].astype(np.int64), "cpu"))
    monkeypatch.setattr(hybrid, "CROSSED_SHARE", 1.0)  # what was given before (not judged again, not given up)
    monkeypatch.setattr(hybrid, "_clear_of_crossings", lambda field, join, surface, finish: surface)
    before = kept()
    assert before["stats"]["crossing_left"] > 0.05 * np.count_nonzero(~before["kept"])  # measured 16 %
