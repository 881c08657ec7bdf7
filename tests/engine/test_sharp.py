"""Sharp surfaces (``to_mesh(sharp=True)``, engine/dual.py): creases and corners of CAD-like booleans against
manifold3d's exact booleans, the mesh invariants users rely on, smooth shapes and blends no worse than marching cubes.

Voxel = 1/256 of the operands' bounding-box diagonal (each normalised to 1); distances are stated in voxels.
"""

import numpy as np
import pytest
import warp as wp
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

import engine
from engine import dual, extract, reached
from engine.octree import morton_encode_np
from tests.metrics import (
    crease_points,
    exact_boolean,
    exact_sdf,
    hausdorff,
    mesh_volume,
    self_intersections,
    to_manifold,
    unsigned_distance,
)
from tests.support import (
    box_mesh,
    cad_pairs,
    edge_use_counts,
    is_watertight,
    load_mesh,
    normalised,
    rotation,
    torus_mesh,
    uv_sphere,
)

H = 1.0 / 256.0
OPS = {"UNION": engine.union, "INTERSECT": engine.intersection, "DIFFERENCE": engine.difference}
PAIRS = cad_pairs()


def _one_fan_per_vertex(verts, tris) -> bool:
    """On a closed mesh: each vertex has as many edges as triangles, so its triangles form one fan (no two sheets
    touching at a vertex)."""
    t = tris.astype(np.int64)
    e = np.sort(np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]]), axis=1)
    codes = np.unique(e[:, 0] * len(verts) + e[:, 1])
    ends = np.concatenate([codes // len(verts), codes % len(verts)])
    return np.array_equal(np.bincount(ends, minlength=len(verts)), np.bincount(t.ravel(), minlength=len(verts)))


@pytest.fixture(scope="module", params=list(PAIRS))
def cad(request):
    """One CAD pair at /256: its boolean field, the exact boolean, and both surfaces."""
    op, a, b = PAIRS[request.param]
    fa, fb = engine.build_fields([a, b], voxel_size=H)
    field = OPS[op](fa, fb)
    verts, tris, creases = field.to_mesh(return_creases=True)
    mc_verts, mc_tris = field.to_mesh(sharp=False)
    return {
        "name": request.param,
        "field": field,
        "exact": exact_boolean(op, *a, *b),
        "sharp": (verts, tris),
        "creases": creases,
        "mc": (mc_verts, mc_tris),
    }


def test_cad_pairs_meet_the_crease_targets(cad):
    # measured max / p95 (voxels): fandisk - cylinder 0.37 / 0.008 (marching cubes 0.61 / 0.038), rocker-arm - cube
    # 0.31 / 0.035 (0.60 / 0.052), cube | tilted cube 0.40 / 0.000 (0.76 / 0.001), cube - bore 0.44 / 0.007
    # (0.65 / 0.010), hex prism & sphere 0.17 / 0.020 (0.34 / 0.025); the bounds are the targets of issue 21
    dist = hausdorff(*cad["sharp"], *cad["exact"], n=200_000)
    assert dist["max"] <= 0.5 * H, (cad["name"], dist["max"] / H)
    assert dist["p95"] <= 0.05 * H, (cad["name"], dist["p95"] / H)
    mc = hausdorff(*cad["mc"], *cad["exact"], n=200_000)
    assert dist["max"] < mc["max"], (cad["name"], dist["max"] / H, mc["max"] / H)


def test_sharp_surface_is_a_closed_outward_2_manifold(cad):
    verts, tris = cad["sharp"]
    assert verts.dtype == np.float32 and tris.dtype == np.int32
    assert is_watertight(tris)
    assert np.array_equal(np.unique(tris), np.arange(len(verts))), "unused vertices"
    to_manifold(verts, tris, cad["name"])  # manifold3d accepts it (raises otherwise)
    # outward, and the volume of the exact boolean (measured within 0.029 %, rocker-arm - cube)
    assert abs(mesh_volume(verts, tris) / mesh_volume(*cad["exact"]) - 1.0) < 0.0009
    # no vertex where three or more sheets meet: every vertex's triangles form one fan (edges == triangles around it)
    assert _one_fan_per_vertex(verts, tris)
    # the dual of the marching cubes: a quad per marching-cubes vertex, so 2 * V_mc triangles (T_mc + 2 * Euler
    # characteristic: 4 more on a sphere-like part, as many on a torus-like one), and 2 more per tunnel vertex
    # (test_random_fields_give_closed_2_manifolds; none here)
    assert len(tris) == 2 * len(cad["mc"][0])
    assert len(tris) <= len(cad["mc"][1]) + 4


def test_surface_edges_are_each_surfaces_own_and_refuse_an_unclosed_surface(cad):
    for verts, tris in (cad["sharp"], cad["mc"]):
        edge_verts, corner_edge = engine.surface_edges(tris, len(verts))
        t = tris.astype(np.int64)
        heads, tails = t.ravel(), np.roll(t, -1, axis=1).ravel()  # each corner to the next corner of its triangle
        keys = np.minimum(heads, tails) * len(verts) + np.maximum(heads, tails)
        pairs = edge_verts.astype(np.int64)
        assert np.all(pairs[:, 0] < pairs[:, 1])
        # every undirected edge once, and each corner's edge joins it to the next corner
        assert np.array_equal(np.sort(pairs[:, 0] * len(verts) + pairs[:, 1]), np.unique(keys))
        assert np.array_equal(pairs[corner_edge, 0] * len(verts) + pairs[corner_edge, 1], keys)
    verts, tris = cad["sharp"]
    flipped = tris.copy()
    flipped[7] = flipped[7, ::-1]
    doubled = np.concatenate([tris, tris[:1]])  # an edge with three faces
    degenerate = tris.copy()
    degenerate[3, 1] = degenerate[3, 0]
    for bad in (tris[1:], flipped, doubled, degenerate, tris[:0]):
        assert engine.surface_edges(bad, len(verts)) is None


def test_sharp_surface_does_not_cross_itself_at_creases(cad):
    # pairs of triangles whose edges pass through each other: none (before the fold-free splits and the damped planes
    # of nodes on the surface: 341, 379, 924, 571 and 372)
    assert self_intersections(*cad["mc"]) == 0
    assert self_intersections(*cad["sharp"]) == 0


def test_parts_thinner_than_a_voxel_give_sharp_surfaces_that_hardly_cross_themselves():
    # slabs 0.4-0.8 voxel thick, each at 4 random turns: a vertex that sees both sides of such a part lies at its
    # patch's mass point (engine/dual.py); measured 38 crossing pairs in all (25,398 with every vertex where its planes
    # put it, the neighbouring vertices on either side of the slab), every surface closed
    h, total = 1.0 / 128.0, 0
    for thickness in (0.4, 0.6, 0.8):
        for seed in range(4):
            turn = Rotation.random(random_state=seed).as_matrix()
            verts, tris = box_mesh(half=(0.5, 0.5, 0.5 * thickness * h))
            v, t = engine.build_field(verts @ turn.T, tris, voxel_size=h).to_mesh(sharp=True)
            assert is_watertight(t), (thickness, seed)
            total += self_intersections(v, t)
    assert total <= 110, total


def test_a_scan_with_thin_parts_gives_a_sharp_surface_that_does_not_cross_itself():
    # the open beetle (legs and feelers thinner than a voxel) united with a ball at /256: measured 0 crossing pairs
    # (55 with every vertex where its planes put it)
    beetle = normalised(load_mesh("beetle.obj"))
    ball = normalised(uv_sphere(1.0, rings=48, segments=96), center=(0.2, 0.2, 0.2), diagonal=0.6)
    v = np.concatenate([beetle[0], ball[0]])
    h = float(np.linalg.norm(v.max(0) - v.min(0))) / 256.0
    verts, tris = engine.union(*engine.build_fields([beetle, ball], voxel_size=h)).to_mesh(sharp=True)
    assert is_watertight(tris)
    assert self_intersections(verts, tris) <= 3, self_intersections(verts, tris)


def test_crease_edges_lie_on_the_exact_creases(cad):
    verts, tris = cad["sharp"]
    creases = cad["creases"]
    assert creases.dtype == np.int32 and creases.ndim == 2 and creases.shape[1] == 2 and len(creases) > 100
    # each crease is an edge of the mesh
    t = tris.astype(np.int64)
    mesh_edges = np.sort(np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]]), axis=1)
    codes = mesh_edges[:, 0] * len(verts) + mesh_edges[:, 1]
    crease_codes = creases[:, 0].astype(np.int64) * len(verts) + creases[:, 1]
    assert np.isin(crease_codes, codes).all()
    # crease edge midpoints lie on the exact creases (edges folding by more than 20 degrees; the rocker-arm's own
    # facets fold by 10-30): measured p90 0.04-0.36 voxel
    mid = verts[creases].astype(np.float64).mean(axis=1)
    d = cKDTree(crease_points(*cad["exact"], angle=20.0, step=0.1 * H)).query(mid)[0] / H
    assert np.percentile(d, 90) < 1.0, (cad["name"], np.percentile(d, 90))
    # and they cover the exact creases folding by more than 30 degrees: measured 0.80 (rocker-arm) to 1.00 of their
    # points within a voxel of a crease edge's midpoint
    covered = cKDTree(mid).query(crease_points(*cad["exact"], angle=30.0, step=0.1 * H))[0] < H
    assert covered.mean() > 0.6, (cad["name"], covered.mean())


def test_vertices_stay_in_their_cubes():
    # every vertex lies in its own cube (with CELL_MARGIN), except crease vertices whose crease line misses it: those
    # may reach EMPTY_REACH voxels into a face neighbour that no active cube occupies
    op, a, b = PAIRS["rocker-arm - cube"]
    field = OPS[op](*engine.build_fields([a, b], voxel_size=H))
    n0 = field.level_counts[0]
    codes, values, proj = field.codes[:n0], field.values[:n0], field.proj[:n0]
    tree = field.tree
    cubes = extract.octree_level_cubes(codes, values, tree, origin=field.origin, spacing=H)
    surface = dual.contour_dual(cubes["cube_corners"], cubes["shifted"], codes, proj, origin=field.origin, spacing=H)
    lattice = field.coords.numpy()[cubes["cube_corners"].numpy()[:, 0]]
    local = (surface["verts"].astype(np.float64) - field.origin) / H - 0.5 - lattice[surface["cells"]]
    inside = np.all((local >= 0.0) & (local <= 1.0), axis=1)
    assert inside.mean() > 0.999  # measured: all but 25 of 81,094
    outside = ~inside
    assert np.all(surface["ranks"][outside] == 2)
    assert np.all((local[outside] >= -dual.EMPTY_REACH - 1e-4) & (local[outside] <= 1.0 + dual.EMPTY_REACH + 1e-4))
    # the cube such a vertex lies in is not an active one
    spot = np.floor((surface["verts"][outside] - field.origin) / H - 0.5).astype(np.int64)
    key = lambda c: (c[:, 0] * 2**21 + c[:, 1]) * 2**21 + c[:, 2]  # noqa: E731
    assert not np.isin(key(spot), key(lattice.astype(np.int64))).any()


def test_a_crease_vertex_past_its_cube_off_every_operand_goes_back_into_it():
    # the rocker arm - cube at /256 of its diagonal: a crease vertex's planes meet 0.98 voxel past its cube, 0.63
    # voxel from both operands' triangles (the tip of faces that end first): engine/reached.py puts it back into its
    # cube; the true wedge tips of the other pairs lie within 0.07 voxel of a surface and stay (a second such vertex,
    # 0.83 voxel past, was the corner of a plane that misses its cube: the crease of those through it is solved
    # since). Measured against manifold3d: max 0.54 -> 0.50 -> 0.34-0.41 voxel remeshed (0.68 -> 0.38 with kept faces)
    op, a, b = PAIRS["rocker-arm - cube"]
    v = np.concatenate([a[0], b[0]])
    h = float(np.linalg.norm(v.max(0) - v.min(0))) / 256.0
    field = OPS[op](*engine.build_fields([a, b], voxel_size=h))
    verts, tris = field.to_mesh()
    frame = field.in_frame()
    n0 = frame.level_counts[0]
    codes, values, proj = frame.codes[:n0], frame.values[:n0], frame.proj[:n0]
    cubes = extract.octree_level_cubes(codes, values, frame.tree, origin=frame.origin, spacing=h)
    raw = dual.contour_dual(cubes["cube_corners"], cubes["shifted"], codes, proj, origin=frame.origin, spacing=h)
    lattice = frame.coords.numpy()[cubes["cube_corners"].numpy()[:, 0]]
    local = (raw["verts"].astype(np.float64) - frame.origin) / h - 0.5 - lattice[raw["cells"]]
    past = np.maximum(-local, local - 1.0).max(axis=1)
    near = np.minimum(unsigned_distance(*a, raw["verts"]), unsigned_distance(*b, raw["verts"])) / h
    off = (past > reached.PAST_VOXELS) & (near > reached.OFF_VOXELS)
    assert off.sum() == 1, off.sum()  # what the contouring alone gives
    assert len(verts) == len(raw["verts"]) and np.array_equal(verts[~off], raw["verts"][~off])
    # the surface written has them in their cubes, and every other vertex where the contouring put it
    moved = (verts[off].astype(np.float64) - frame.origin) / h - 0.5 - lattice[raw["cells"][off]]
    assert np.all((moved >= 0.0) & (moved <= 1.0))
    d = hausdorff(verts, tris, *exact_boolean(op, *a, *b), n=100_000)
    assert d["max"] <= 0.6 * h, d["max"] / h


# ---- smooth shapes and blends ----


SMOOTH = {
    "sphere": lambda: normalised(uv_sphere(1.0, rings=96, segments=192)),
    "torus": lambda: normalised(torus_mesh(1.0, 0.35, rings=192, segments=96)),
    "bunny": lambda: normalised(load_mesh("stanford-bunny.obj")),
}


@pytest.mark.parametrize("name", list(SMOOTH))
def test_smooth_surfaces_are_no_worse_than_marching_cubes(name):
    # measured p95 / max (voxels), marching cubes -> sharp: sphere 0.008 / 0.017 -> 0.006 / 0.014, torus
    # 0.014 / 0.025 -> 0.011 / 0.020, bunny 0.060 / 8.7 -> 0.045 / 8.9
    # (its holes: the field caps them), 0.59 -> 0.49 from the mesh
    mesh = SMOOTH[name]()
    field = engine.build_field(*mesh, voxel_size=H)
    verts, tris, creases = field.to_mesh(return_creases=True)
    sharp = hausdorff(verts, tris, *mesh, n=100_000)
    mc = hausdorff(*field.to_mesh(sharp=False), *mesh, n=100_000)
    assert sharp["p95"] <= mc["p95"], (sharp["p95"] / H, mc["p95"] / H)
    # the bunny's caps lie up to 9 voxels from its triangles either way: its largest error is measured from the mesh
    key = "b_to_a" if name == "bunny" else None
    worst, worst_mc = (sharp[key]["max"], mc[key]["max"]) if key else (sharp["max"], mc["max"])
    assert worst <= worst_mc + 0.01 * H, (worst / H, worst_mc / H)
    if name != "bunny":  # the bunny's capped holes have real rims
        assert len(creases) == 0


@pytest.fixture(scope="module")
def two_spheres():
    a = normalised(uv_sphere(1.0, rings=96, segments=192), diagonal=0.6)
    b = normalised(uv_sphere(1.0, rings=96, segments=192), center=(0.2, 0.05, 0.0), diagonal=0.6)
    return a, b, engine.build_fields([a, b], voxel_size=H)


@pytest.mark.parametrize(("op", "blend"), [("UNION", 0.02), ("UNION", 0.03), ("DIFFERENCE", 0.02)])
def test_blends_get_no_crease_and_stay_on_the_smooth_surface(two_spheres, op, blend):
    # the blend zone's values are smooth minima, not distances to the closest points the nodes hold: the planes come
    # from the interpolant there. Measured |smooth minimum of the exact distances| at the vertices: union 0.02
    # 0.032, union 0.03 0.033, difference 0.02 0.043 voxel (marching cubes 0.019, 0.047, 0.034)
    a, b, (fa, fb) = two_spheres
    field = OPS[op](fa, fb, blend=blend)
    verts, tris, creases = field.to_mesh(return_creases=True)
    assert len(creases) == 0
    assert is_watertight(tris)
    da = exact_sdf(*a, verts).astype(np.float64)
    db = exact_sdf(*b, verts).astype(np.float64)
    if op == "DIFFERENCE":  # max(a, -b) = -smooth_min(-a, b)
        da, db = -da, db
    k = np.clip(0.5 + 0.5 * (db - da) / blend, 0.0, 1.0)
    phi = db + (da - db) * k - blend * k * (1.0 - k)
    assert np.abs(phi).max() <= 0.1 * H, np.abs(phi).max() / H


# ---- API ----


def test_sharp_false_is_the_marching_cubes():
    mesh = box_mesh(half=(0.3, 0.2, 0.25))
    field = engine.build_field(*mesh, voxel_size=0.02)
    n0 = field.level_counts[0]
    tree = field.tree
    verts, tris = extract.extract_octree_level(
        field.codes[:n0], field.values[:n0], tree, origin=field.origin, spacing=field.voxel_size
    )
    mc_verts, mc_tris, creases = field.to_mesh(sharp=False, return_creases=True)
    assert np.array_equal(mc_verts, verts) and np.array_equal(mc_tris, tris)
    assert creases.shape == (0, 2) and creases.dtype == np.int32
    with pytest.raises(ValueError, match="Expected a finite 'iso'"):
        field.to_mesh(iso=float("nan"))


def test_a_box_keeps_its_edges_and_corners():
    # an axis-aligned box off the lattice: marching cubes bevels its 12 edges, the sharp surface keeps them
    half, center = np.array([0.31, 0.22, 0.17]), np.array([0.013, -0.021, 0.034])
    mesh = box_mesh(half=half, center=center)
    field = engine.build_field(*mesh, voxel_size=0.02)
    verts, tris, creases = field.to_mesh(return_creases=True)
    corners = center + half * np.array([[i, j, k] for i in (-1, 1) for j in (-1, 1) for k in (-1, 1)])
    assert cKDTree(verts).query(corners)[0].max() < 1.4e-5  # measured 4.6e-6 (0.0002 voxel)
    mc_verts, _ = field.to_mesh(sharp=False)
    assert cKDTree(mc_verts).query(corners)[0].max() > 0.3 * 0.02  # bevelled (measured 0.5 voxel)
    assert abs(mesh_volume(verts, tris) / np.prod(2 * half) - 1.0) < 8e-7  # measured 2.6e-7
    assert len(creases) > 0 and edge_use_counts(tris).max() == 2


def test_levels_1_gives_the_surface_of_levels_4():
    # the dense top level as the finest (its nodes in x-fastest order, sorted before the cubes are found)
    mesh = box_mesh(half=(0.3, 0.2, 0.25), center=(0.01, 0.02, -0.03))
    mesh = (mesh[0] @ rotation(2, 20.0).T.astype(np.float32), mesh[1])
    one = engine.build_field(*mesh, voxel_size=0.03, levels=1).to_mesh()
    four = engine.build_field(*mesh, voxel_size=0.03, levels=4).to_mesh()
    assert len(one[1]) == len(four[1]) > 500
    d = unsigned_distance(*four, one[0]).max()
    assert d < 1e-5, d


@pytest.mark.parametrize("seed", range(6))
def test_random_fields_give_closed_2_manifolds(seed):
    # ambiguous faces everywhere: where two cubes each cross their shared face with one patch in two segments (a
    # tunnel of the marching cubes surface) the dual needs a vertex more on one of the two dual edges between them
    from tests.engine.test_extract import lattice

    rng = np.random.default_rng(seed)
    coords = lattice((-3, 5, -7), (9, 17, 5))
    values = rng.standard_normal(len(coords)).astype(np.float32)
    border = (coords == coords.min(axis=0)).any(axis=1) | (coords == coords.max(axis=0)).any(axis=1)
    values[border] = 1.0
    cubes = extract.lattice_cubes(coords, values.astype(np.float64), origin=np.zeros(3), spacing=1.0, iso=0.0)
    order = cubes["order"] if cubes["order"] is not None else np.arange(len(coords))
    lo = coords.min(axis=0)  # Morton codes of the lattice from its lowest point
    surface = dual.contour_dual(
        cubes["cube_corners"],
        cubes["shifted"],
        wp.array(morton_encode_np(coords[order] - lo), dtype=wp.int64),
        wp.zeros(len(coords), dtype=wp.vec3h),  # closest points on the nodes: no Hermite data, interpolant planes
        origin=lo.astype(np.float64),
        spacing=1.0,
    )
    verts, tris = surface["verts"], surface["tris"]
    mc_verts, _ = extract.extract_surface(coords, values, origin=np.zeros(3), spacing=1.0)
    assert is_watertight(tris)
    to_manifold(verts, tris)
    assert _one_fan_per_vertex(verts, tris)
    # a quad per marching-cubes vertex, and two triangles more per vertex given to a tunnel (measured 1-2 of them)
    assert surface["tunnels"] > 0
    assert len(tris) == 2 * len(mc_verts) + 2 * surface["tunnels"]
