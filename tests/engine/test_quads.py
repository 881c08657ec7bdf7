"""Quads (``to_mesh(quads=True)``, engine/quads.py): the dual surface's quads kept whole where planar and convex, the
polygons closed and 2-manifold, the same surface as the triangles.

Voxel = 1/256 of the operands' bounding-box diagonal (each normalised to 1).
"""

import numpy as np
import pytest
import warp as wp

import engine
from engine import dual, extract
from engine.assembly import voxel_surface_only
from engine.octree import morton_encode_np
from engine.quads import QUAD_ANGLE, merge_pairs, polygon_edges, quad_halves_first, triangulate
from tests.support import cad_pairs, normalised, uv_sphere

H = 1.0 / 256.0
OPS = {"UNION": engine.union, "INTERSECT": engine.intersection, "DIFFERENCE": engine.difference}
PAIRS = cad_pairs()
CASES = ["rocker-arm - cube", "cube - bore", "sphere"]


def _field(name):
    if name == "sphere":
        return engine.build_field(*normalised(uv_sphere(1.0, rings=96, segments=192)), voxel_size=H)
    op, a, b = PAIRS[name]
    return OPS[op](*engine.build_fields([a, b], voxel_size=H))


@pytest.fixture(scope="module", params=CASES)
def case(request):
    field = _field(request.param)
    verts, tris = field.to_mesh()
    pverts, faces, sizes, creases = field.to_mesh(quads=True, return_creases=True)
    return {"name": request.param, "tris": (verts, tris), "polygons": (pverts, faces, sizes), "creases": creases}


def closed_2_manifold(n_verts, faces, sizes) -> bool:
    """Every directed edge once and its reverse once (closed, consistently oriented), and around every vertex as many
    edges as faces (its faces form one fan: no two sheets touching at a vertex)."""
    edges = polygon_edges(faces, sizes)
    n = np.int64(n_verts)
    forward, backward = edges[:, 0] * n + edges[:, 1], edges[:, 1] * n + edges[:, 0]
    if len(np.unique(forward)) != len(forward) or not np.isin(forward, backward).all():
        return False
    undirected = np.unique(np.minimum(forward, backward))
    ends = np.concatenate([undirected // n, undirected % n])
    return np.array_equal(np.bincount(ends, minlength=n_verts), np.bincount(faces, minlength=n_verts))


def test_most_faces_are_quads_away_from_creases(case):
    verts, faces, sizes = case["polygons"]
    on_crease = np.zeros(len(verts), dtype=bool)
    on_crease[case["creases"].ravel()] = True
    start = np.cumsum(sizes) - sizes
    touches = np.add.reduceat(on_crease[faces].astype(np.int64), start) > 0
    # measured: rocker-arm - cube 0.965 (0.937 of all faces), cube - bore 0.998 (0.988), sphere 1.000 (1.000)
    assert np.mean(sizes[~touches] == 4) >= 0.9, case["name"]
    assert np.mean(sizes == 4) >= 0.9, case["name"]
    assert set(np.unique(sizes)) <= {3, 4}


def test_polygons_are_the_triangles_surface_closed_and_2_manifold(case):
    verts, tris = case["tris"]
    pverts, faces, sizes = case["polygons"]
    assert faces.dtype == np.int32 and sizes.dtype == np.int32 and sizes.sum() == len(faces)
    assert np.array_equal(verts, pverts)
    # the polygons' fans are the triangles, every one (as corner sets: a quad starts at an end of its diagonal)
    again = triangulate(faces, sizes)
    assert len(again) == len(tris)
    assert np.array_equal(np.unique(np.sort(again, axis=1), axis=0), np.unique(np.sort(tris, axis=1), axis=0))
    assert closed_2_manifold(len(pverts), faces, sizes)
    # each quad is planar and convex: its two triangles within QUAD_ANGLE along both diagonals
    quads = faces[: 4 * np.count_nonzero(sizes == 4)].reshape(-1, 4)
    p = pverts[quads].astype(np.float64)
    for a, b, c, d in ((0, 1, 2, 3), (1, 2, 3, 0)):
        n1 = np.cross(p[:, b] - p[:, a], p[:, c] - p[:, a])
        n2 = np.cross(p[:, c] - p[:, a], p[:, d] - p[:, a])
        cos = np.einsum("ij,ij->i", n1, n2) / (np.linalg.norm(n1, axis=1) * np.linalg.norm(n2, axis=1))
        assert cos.min() >= np.cos(np.radians(QUAD_ANGLE)) - 1e-6


def test_a_mirrored_field_gives_the_same_polygons_turned_over():
    field = _field("cube - bore")
    mirrored = field.transformed(np.diag([1.0, -1.0, 1.0, 1.0]))
    verts, tris = mirrored.to_mesh()
    pverts, faces, sizes = mirrored.to_mesh(quads=True)
    assert np.allclose(verts, pverts)
    again = triangulate(faces, sizes)
    assert np.array_equal(np.unique(np.sort(again, axis=1), axis=0), np.unique(np.sort(tris, axis=1), axis=0))
    # turned over with the triangles: the first fan triangle of each face is one of them, corner order and all
    turned = {tuple(np.roll(t, k)) for t in tris[:2000].tolist() for k in range(3)}
    assert sum(tuple(t) in turned for t in again.tolist()) >= 1000
    assert closed_2_manifold(len(pverts), faces, sizes)


@pytest.mark.parametrize("seed", [1, 2])
def test_random_fields_with_tunnels_giveclosed_2_manifold_polygons(seed):
    from tests.engine.test_extract import lattice

    rng = np.random.default_rng(seed)
    coords = lattice((-3, 5, -7), (9, 17, 5))
    values = rng.standard_normal(len(coords)).astype(np.float32)
    border = (coords == coords.min(axis=0)).any(axis=1) | (coords == coords.max(axis=0)).any(axis=1)
    values[border] = 1.0
    cubes = extract.lattice_cubes(coords, values.astype(np.float64), origin=np.zeros(3), spacing=1.0, iso=0.0)
    order = cubes["order"] if cubes["order"] is not None else np.arange(len(coords))
    lo = coords.min(axis=0)
    surface = dual.contour_dual(
        cubes["cube_corners"],
        cubes["shifted"],
        wp.array(morton_encode_np(coords[order] - lo), dtype=wp.int64),
        wp.zeros(len(coords), dtype=wp.vec3h),
        origin=lo.astype(np.float64),
        spacing=1.0,
    )
    assert surface["tunnels"] > 0
    faces, sizes = merge_pairs(surface["tris"], surface["whole"])
    assert closed_2_manifold(len(surface["verts"]), faces, sizes)
    assert len(triangulate(faces, sizes)) == len(surface["tris"])
    # random values: twisted quads everywhere, yet some stay whole (measured 0.27 and 0.25 of the faces)
    assert 0.05 < np.mean(sizes == 4) < 0.9


def test_triangulate_and_merge_pairs_by_hand():
    tris = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 7], [5, 6, 7], [8, 9, 10]], dtype=np.int32)
    faces, sizes = merge_pairs(tris, np.array([1, 2], dtype=np.uint8))
    assert sizes.tolist() == [4, 4, 3]
    assert faces.tolist() == [0, 1, 2, 3, 5, 6, 7, 4, 8, 9, 10]
    assert triangulate(faces, sizes).tolist() == [[0, 1, 2], [0, 2, 3], [5, 6, 7], [5, 7, 4], [8, 9, 10]]
    faces, sizes = merge_pairs(tris, np.array([0, 2], dtype=np.uint8))
    assert sizes.tolist() == [4, 3, 3, 3]
    assert faces.tolist() == [5, 6, 7, 4, 0, 1, 2, 0, 2, 3, 8, 9, 10]


def test_a_voxel_surface_in_quad_order_is_given_as_it_is_and_as_a_reordered_one_comes_back(case):
    """A kept surface that is the voxel surface (nothing kept) has its quads' halves first already: given as it is,
    with as many quads as the same rows shuffled within each quad are put back to."""
    verts, faces, sizes = case["polygons"]
    surface = voxel_surface_only(verts, triangulate(faces, sizes), "nothing kept", failed=False)
    quads = int(np.count_nonzero(sizes == 4))
    surface["voxel_face"] = np.where(surface["voxel_face"] < 2 * quads, surface["voxel_face"], -1)
    given = quad_halves_first(surface)
    assert given["quads"] == quads > 0 and given["tris"] is surface["tris"]
    swapped = np.arange(len(surface["tris"]))
    swapped[: 2 * quads] = swapped[: 2 * quads].reshape(-1, 2)[:, ::-1].ravel()  # each quad's halves the other way
    shuffled = {**surface, **{k: surface[k][swapped] for k in ("tris", "kept", "field_id", "triangle_id")}}
    shuffled.update(corner_bary=surface["corner_bary"][swapped], voxel_face=surface["voxel_face"][swapped])
    back = quad_halves_first(shuffled)
    assert back["quads"] == quads
    np.testing.assert_array_equal(back["tris"], given["tris"])
    np.testing.assert_array_equal(back["voxel_face"], given["voxel_face"])


@pytest.mark.parametrize("bad", [-0.1, 1.5, float("nan")])
def test_adaptivity_out_of_range_is_refused(bad):
    field = _field("sphere")
    with pytest.raises(ValueError, match="Expected an 'adaptivity' from 0 to 1"):
        field.to_mesh(adaptivity=bad)
