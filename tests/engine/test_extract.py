"""Tests for ``engine.extract``: sparse marching cubes over a band of lattice samples of analytic SDFs (no bpy)."""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree
from skimage.measure import marching_cubes

from engine.errors import AasdfError
from engine.extract import extract_surface
from tests.support import edge_use_counts, is_watertight, signed_volume

# Both devices always listed: where there is no GPU the CUDA cases are reported as skipped, not left out.
DEVICES = [
    "cpu",
    pytest.param("cuda:0", marks=pytest.mark.skipif(not wp.is_cuda_available(), reason="no CUDA device")),
]
BAND = 2.5  # half width of the sample band, in cells


# ---- analytic shapes ----


def sdf_sphere(p, radius, center=(0.0, 0.0, 0.0)):
    return np.linalg.norm(p - np.asarray(center), axis=-1) - radius


def sdf_box(p, half, center=(0.0, 0.0, 0.0)):
    q = np.abs(p - np.asarray(center)) - np.asarray(half)
    return np.linalg.norm(np.maximum(q, 0.0), axis=-1) + np.minimum(q.max(axis=-1), 0.0)


def sdf_torus(p, major, minor):
    ring = np.hypot(p[..., 0], p[..., 1]) - major
    return np.hypot(ring, p[..., 2]) - minor


def lattice(lo, hi):
    """All integer points of the box [lo, hi) as (N, 3) int32."""
    axes = [np.arange(a, b) for a, b in zip(lo, hi, strict=True)]
    return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3).astype(np.int32)


def band_samples(sdf, lo, hi, *, origin, spacing, width=BAND):
    """Samples of ``sdf`` at the lattice points of [lo, hi) with ``|sdf| < width * spacing``.

    Returns:
        coords (N, 3) int32, values (N,) float32 (computed in float64).
    """
    coords = lattice(lo, hi)
    values = sdf(np.asarray(origin) + (coords + 0.5) * spacing)
    keep = np.abs(values) < width * spacing
    return coords[keep], values[keep].astype(np.float32)


# ---- mesh checks ----


def assert_clean_closed_mesh(verts, tris):
    """Dtypes, index range, no unused/duplicate vertices, no degenerate triangles, watertight + consistently wound."""
    assert verts.dtype == np.float32 and verts.ndim == 2 and verts.shape[1] == 3
    assert tris.dtype == np.int32 and tris.ndim == 2 and tris.shape[1] == 3
    assert len(tris) > 0
    assert tris.min() >= 0 and tris.max() < len(verts)
    assert np.array_equal(np.unique(tris), np.arange(len(verts))), "unused vertices"
    assert len(np.unique(verts, axis=0)) == len(verts), "duplicate vertex positions"
    repeated = (tris[:, 0] == tris[:, 1]) | (tris[:, 1] == tris[:, 2]) | (tris[:, 2] == tris[:, 0])
    assert not repeated.any(), f"{repeated.sum()} triangles repeat an index"
    v = verts.astype(np.float64)[tris]
    areas = 0.5 * np.linalg.norm(np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]), axis=1)
    assert areas.min() > 0.0, f"{np.count_nonzero(areas == 0.0)} zero-area triangles"
    assert is_watertight(tris)


def euler_characteristic(verts, tris) -> int:
    return len(verts) - len(edge_use_counts(tris)) + len(tris)


def face_normals_and_centroids(verts, tris):
    v = verts.astype(np.float64)[tris]
    return np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]), v.mean(axis=1)


def components(verts, tris):
    """Label each triangle with the connected component (shared vertices) it belongs to."""
    t = tris.astype(np.int64)
    rows = np.concatenate([t[:, 0], t[:, 1], t[:, 2]])
    cols = np.concatenate([t[:, 1], t[:, 2], t[:, 0]])
    graph = coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(len(verts), len(verts)))
    count, labels = connected_components(graph, directed=False)
    return count, labels[tris[:, 0]]


# ---- surfaces ----

H = 0.025  # spacing of the main sphere tests: R = 40 cells
R = 40 * H
CENTER = (0.0123, -0.0311, 0.0071)  # off the lattice, so no symmetry hides errors


def sphere_band(spacing=H, radius=R, center=CENTER, width=BAND, origin=(0.0, 0.0, 0.0)):
    m = int(np.ceil((radius + np.abs(center).max()) / spacing + width + 2))
    sdf = lambda p: sdf_sphere(p, radius, center)  # noqa: E731
    return band_samples(sdf, (-m,) * 3, (m,) * 3, origin=origin, spacing=spacing, width=width)


@pytest.mark.parametrize("device", DEVICES)
def test_sphere_is_closed_outward_and_accurate(device):
    coords, values = sphere_band()
    verts, tris = extract_surface(coords, values, origin=(0.0, 0.0, 0.0), spacing=H, device=device)
    assert_clean_closed_mesh(verts, tris)
    assert euler_characteristic(verts, tris) == 2
    exact = 4.0 / 3.0 * np.pi * R**3
    assert abs(signed_volume(verts, tris) / exact - 1.0) < 0.005
    radial = np.linalg.norm(verts.astype(np.float64) - CENTER, axis=1) - R
    assert np.abs(radial).max() < 0.05 * H
    normals, centroids = face_normals_and_centroids(verts, tris)
    outward = np.einsum("ij,ij->i", normals, centroids - CENTER)
    assert outward.min() > 0.0, f"{np.count_nonzero(outward <= 0)} faces point inwards"


def test_sphere_vertices_match_dense_scikit_image():
    # Sparse == dense: each surface edge of the full grid lies in a complete cube of the band, so the vertex sets agree.
    # extract_surface pushes samples within 1e-3 * spacing of the level out to that distance; do the same for the
    # dense reference so that the vertices sliding along near-tangent edges match too.
    m, nudge = 45, 1e-3 * H
    coords = lattice((-m,) * 3, (m,) * 3)
    values = sdf_sphere((coords + 0.5) * H, R, CENTER)
    keep = np.abs(values) < BAND * H
    verts, tris = extract_surface(coords[keep], values[keep], origin=(0.0, 0.0, 0.0), spacing=H)
    dense = np.where(np.abs(values) < nudge, np.where(values < 0.0, -nudge, nudge), values).reshape((2 * m,) * 3)
    ref_verts, ref_tris, _, _ = marching_cubes(dense.astype(np.float32), level=0.0)
    ref_verts = (ref_verts - m + 0.5) * H
    assert len(verts) == len(ref_verts)
    distance, nearest = cKDTree(ref_verts).query(verts)
    assert len(np.unique(nearest)) == len(verts)  # a one-to-one match
    assert distance.max() < 1e-4 * H
    assert abs(signed_volume(verts, tris) / signed_volume(ref_verts, ref_tris) - 1.0) < 1e-5


def test_box_is_closed_with_box_volume():
    h, half, center = 0.05, np.array([1.0, 0.7, 0.5]), np.array([0.013, -0.021, 0.034])
    coords, values = band_samples(
        lambda p: sdf_box(p, half, center), (-26,) * 3, (26,) * 3, origin=(0, 0, 0), spacing=h
    )
    verts, tris = extract_surface(coords, values, origin=(0.0, 0.0, 0.0), spacing=h)
    assert_clean_closed_mesh(verts, tris)
    assert euler_characteristic(verts, tris) == 2
    assert abs(signed_volume(verts, tris) / np.prod(2 * half) - 1.0) < 0.005
    assert np.abs(sdf_box(verts.astype(np.float64), half, center)).max() < 0.3 * h


def test_torus_is_closed_with_genus_one():
    h, major, minor = 0.05, 1.2, 0.4
    coords, values = band_samples(
        lambda p: sdf_torus(p, major, minor), (-36, -36, -14), (36, 36, 14), origin=(0.01, 0.02, 0.03), spacing=h
    )
    verts, tris = extract_surface(coords, values, origin=(0.01, 0.02, 0.03), spacing=h)
    assert_clean_closed_mesh(verts, tris)
    assert euler_characteristic(verts, tris) == 0
    exact = 2.0 * np.pi**2 * major * minor**2
    assert abs(signed_volume(verts, tris) / exact - 1.0) < 0.005
    assert np.abs(sdf_torus(verts.astype(np.float64), major, minor)).max() < 0.05 * h


def test_iso_extracts_an_offset_surface():
    offset = 1.5 * H
    coords, values = sphere_band(width=4.0)
    verts, tris = extract_surface(coords, values, origin=(0.0, 0.0, 0.0), spacing=H, iso=offset)
    assert_clean_closed_mesh(verts, tris)
    radial = np.linalg.norm(verts.astype(np.float64) - CENTER, axis=1) - (R + offset)
    assert np.abs(radial).max() < 0.05 * H
    assert abs(signed_volume(verts, tris) / (4.0 / 3.0 * np.pi * (R + offset) ** 3) - 1.0) < 0.005


@pytest.mark.parametrize(
    "sdf",
    [
        pytest.param(lambda p: sdf_sphere(p, 25.0), id="sphere-r25"),  # 625 = i^2 + j^2 + k^2 has many solutions
        pytest.param(lambda p: sdf_box(p, (10.0, 8.0, 6.0)), id="box"),  # faces pass through samples
    ],
)
def test_samples_exactly_on_the_surface_stay_watertight(sdf):
    # origin = -0.5 puts sample (i, j, k) at the integer point (i, j, k): the SDF is exactly 0 on many samples.
    coords, values = band_samples(sdf, (-30,) * 3, (30,) * 3, origin=(-0.5, -0.5, -0.5), spacing=1.0)
    assert np.count_nonzero(values == 0.0) >= 50
    verts, tris = extract_surface(coords, values, origin=(-0.5, -0.5, -0.5), spacing=1.0)
    assert_clean_closed_mesh(verts, tris)
    assert euler_characteristic(verts, tris) == 2
    assert np.abs(sdf(verts.astype(np.float64))).max() < 0.05


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_random_field_is_watertight(seed):
    # Ambiguous faces and cube interiors everywhere: neighbouring cubes must still agree on the surface between them.
    rng = np.random.default_rng(seed)
    coords = lattice((-3, 5, -7), (9, 17, 5))
    values = rng.standard_normal(len(coords)).astype(np.float32)
    border = (coords == coords.min(axis=0)).any(axis=1) | (coords == coords.max(axis=0)).any(axis=1)
    values[border] = 1.0
    verts, tris = extract_surface(coords, values, origin=(0.0, 0.0, 0.0), spacing=0.1)
    assert_clean_closed_mesh(verts, tris)
    assert signed_volume(verts, tris) > 0.0


def test_two_disjoint_spheres_are_two_closed_components():
    h, r, centers = 0.05, 0.6, (np.array([-1.0, 0.02, 0.01]), np.array([1.1, -0.03, 0.0]))
    sdf = lambda p: np.minimum(sdf_sphere(p, r, centers[0]), sdf_sphere(p, r, centers[1]))  # noqa: E731
    coords, values = band_samples(sdf, (-40, -20, -20), (40, 20, 20), origin=(0, 0, 0), spacing=h)
    verts, tris = extract_surface(coords, values, origin=(0.0, 0.0, 0.0), spacing=h)
    assert_clean_closed_mesh(verts, tris)
    count, labels = components(verts, tris)
    assert count == 2
    for label in range(2):
        part = tris[labels == label]
        assert is_watertight(part)
        assert abs(signed_volume(verts, part) / (4.0 / 3.0 * np.pi * r**3) - 1.0) < 0.01


def test_negative_coordinates_match_a_translated_band():
    h = 0.05
    coords, values = sphere_band(spacing=h, radius=0.8, center=(-3.13, -2.21, -4.72))
    assert coords.max() < 0
    verts, tris = extract_surface(coords, values, origin=(0.0, 0.0, 0.0), spacing=h)
    assert_clean_closed_mesh(verts, tris)
    assert abs(signed_volume(verts, tris) / (4.0 / 3.0 * np.pi * 0.8**3) - 1.0) < 0.005
    shift = np.array([200, 150, 300], dtype=np.int32)
    moved_verts, moved_tris = extract_surface(coords + shift, values, origin=-shift * h, spacing=h)
    np.testing.assert_array_equal(moved_tris, tris)
    assert np.abs(moved_verts - verts).max() < 1e-5


def test_lattice_far_from_the_origin_stays_clean():
    # At 1e5 cells from the origin float32 resolves 1/128 cell: vertices must still be distinct and triangles non-flat.
    offset = np.array([100_000, -90_000, 95_000], dtype=np.int32)
    coords, values = sphere_band(spacing=1.0, radius=12.0, center=(0.31, -0.22, 0.13))
    verts, tris = extract_surface(coords + offset, values, origin=(0.0, 0.0, 0.0), spacing=1.0)
    assert np.abs(verts).max() > 90_000
    assert_clean_closed_mesh(verts, tris)
    centred = verts.astype(np.float64) - (offset + np.array([0.31, -0.22, 0.13]))
    assert abs(signed_volume(centred, tris) / (4.0 / 3.0 * np.pi * 12.0**3) - 1.0) < 0.01
    assert np.abs(np.linalg.norm(centred, axis=1) - 12.0).max() < 0.05


def test_lattice_too_far_from_the_origin_is_refused():
    coords, values = sphere_band(spacing=1.0, radius=5.0)
    with pytest.raises(AasdfError, match=r"too far from the world origin for its voxel size"):
        extract_surface(coords + 2**30, values, origin=(0.0, 0.0, 0.0), spacing=1.0)
    # The same lattice is fine once the origin brings it back near zero.
    verts, tris = extract_surface(coords + 2**30, values, origin=(-(2.0**30),) * 3, spacing=1.0)
    assert is_watertight(tris)


def oriented_triangles(verts, tris, reference):
    """``tris`` as sorted rows of indices into ``reference`` (matched by position), each rotated to start at its
    smallest index so orientation is kept."""
    distance, index = cKDTree(reference).query(verts)
    assert distance.max() < 1e-5 and len(np.unique(index)) == len(verts)
    mapped = index[tris]
    first = np.argmin(mapped, axis=1)
    rows = np.arange(len(mapped))
    mapped = np.stack([mapped[rows, (first + k) % 3] for k in range(3)], axis=1)
    return mapped[np.lexsort(mapped.T[::-1])]


@pytest.mark.parametrize("case", ["sphere", "random"])
def test_shared_corner_path_matches_warps_public_marching_cubes(monkeypatch, case):
    # Samples are the shared corners themselves; Warp's public entry point finds them again by sorting cube corners.
    import engine.extract as extract

    assert extract.HAS_SHARED_CORNER_CORE  # the pinned Warp has the core this path calls
    if case == "sphere":
        coords, values = sphere_band(spacing=0.05)
    else:
        coords = lattice((-3, 5, -7), (9, 17, 5))
        values = np.random.default_rng(3).standard_normal(len(coords)).astype(np.float32)
    verts, tris = extract_surface(coords, values, origin=(0.1, -0.2, 0.3), spacing=0.05)
    monkeypatch.setattr(extract, "HAS_SHARED_CORNER_CORE", False)
    public_verts, public_tris = extract_surface(coords, values, origin=(0.1, -0.2, 0.3), spacing=0.05)
    assert len(tris) > 100 and len(verts) == len(public_verts) and len(tris) == len(public_tris)
    np.testing.assert_array_equal(
        oriented_triangles(verts, tris, public_verts), oriented_triangles(public_verts, public_tris, public_verts)
    )


def test_marching_cubes_split_over_the_cores_gives_warps_mesh_in_warps_order(monkeypatch):
    # Every pass of the polygonisation is launched in parts (enough cubes here to split): same arrays, same order.
    import engine.marching as marching

    coords, values = sphere_band(spacing=R / 60)
    verts, tris = extract_surface(coords, values, origin=(0.1, -0.2, 0.3), spacing=R / 60)
    assert len(tris) > 40_000
    monkeypatch.setattr(
        marching,
        "_split_marching_cubes",
        lambda cubes, points, values, device: marching._shared_corner_marching_cubes(
            cubes, points, values, 0.0, device
        ),
    )
    warp_verts, warp_tris = extract_surface(coords, values, origin=(0.1, -0.2, 0.3), spacing=R / 60)
    np.testing.assert_array_equal(verts, warp_verts)
    np.testing.assert_array_equal(tris, warp_tris)


def test_sample_order_does_not_change_the_mesh():
    coords, values = sphere_band(spacing=0.05)
    verts, tris = extract_surface(coords, values, origin=(0.0, 0.0, 0.0), spacing=0.05)
    order = np.random.default_rng(7).permutation(len(coords))
    shuffled_verts, shuffled_tris = extract_surface(coords[order], values[order], origin=(0.0, 0.0, 0.0), spacing=0.05)
    np.testing.assert_array_equal(shuffled_verts, verts)
    np.testing.assert_array_equal(shuffled_tris, tris)


def test_cube_with_a_missing_corner_is_skipped():
    h = 0.05
    coords, values = sphere_band(spacing=h)
    full_verts, full_tris = extract_surface(coords, values, origin=(0.0, 0.0, 0.0), spacing=h)
    gone = int(np.argmin(np.abs(values)))  # a sample right next to the surface
    keep = np.arange(len(coords)) != gone
    verts, tris = extract_surface(coords[keep], values[keep], origin=(0.0, 0.0, 0.0), spacing=h)
    assert 0 < len(full_tris) - len(tris) <= 8 * 5  # at most the 8 cubes around the sample, <= 5 triangles each
    assert not is_watertight(tris)
    t = tris.astype(np.int64)
    edges = np.sort(np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]]), axis=1)
    unique, counts = np.unique(edges, axis=0, return_counts=True)
    rim = np.unique(unique[counts == 1])
    assert len(rim) >= 3
    gone_position = (coords[gone] + 0.5) * h
    assert np.abs(verts[rim] - gone_position).max() <= h * (1.0 + 1e-5)


# ---- empty results ----


def test_empty_input_gives_empty_arrays():
    verts, tris = extract_surface(np.zeros((0, 3), np.int32), np.zeros(0, np.float32), origin=(0, 0, 0), spacing=1.0)
    assert verts.shape == (0, 3) and verts.dtype == np.float32
    assert tris.shape == (0, 3) and tris.dtype == np.int32


@pytest.mark.parametrize("side", [1.0, -1.0])
def test_band_that_does_not_cross_the_level_gives_empty_arrays(side):
    coords, values = sphere_band(spacing=0.05)
    values = side * (np.abs(values) + 0.01)
    verts, tris = extract_surface(coords, values, origin=(0.0, 0.0, 0.0), spacing=0.05)
    assert len(coords) > 1000
    assert verts.shape == (0, 3) and verts.dtype == np.float32
    assert tris.shape == (0, 3) and tris.dtype == np.int32


def test_isolated_samples_give_empty_arrays():
    coords = np.array([[0, 0, 0], [5, 5, 5], [-5, 0, 3]], dtype=np.int32)
    verts, tris = extract_surface(coords, [-1.0, 1.0, -1.0], origin=(0, 0, 0), spacing=1.0)
    assert verts.shape == (0, 3) and tris.shape == (0, 3)


# ---- validation ----


@pytest.mark.parametrize(
    ("coords", "values", "kwargs", "error", "match"),
    [
        ([1, 2, 3], [0.0], {}, ValueError, r"Expected 'coords' of shape \(N, 3\), but got \(3,\)\."),
        (np.zeros((2, 2), np.int32), [0.0, 1.0], {}, ValueError, r"of shape \(N, 3\), but got \(2, 2\)\."),
        (
            [[0, 0, 0], [0, 0, 1]],
            [0.0],
            {},
            ValueError,
            r"Expected 'values' of shape \(2,\) to match 'coords', but got \(1,\)\.",
        ),
        ([[0, 0, 0], [0, 0, 1]], [[0.0, 1.0]], {}, ValueError, r"Expected 'values' of shape \(2,\)"),
        (
            [[0, 0, 0], [0, 0, 1]],
            [0.0, np.nan],
            {},
            ValueError,
            r"Expected finite 'values', but got 1 non-finite entries\.",
        ),
        ([[0, 0, 0], [0, 0, 1]], [np.inf, -np.inf], {}, ValueError, r"but got 2 non-finite entries\."),
        (
            [[0, 0, 0], [0, 0, 1]],
            [0.0, 1.0],
            {"spacing": 0.0},
            ValueError,
            r"Expected a positive 'spacing', but got 0\.0\.",
        ),
        (
            [[0, 0, 0], [0, 0, 1]],
            [0.0, 1.0],
            {"spacing": -0.5},
            ValueError,
            r"Expected a positive 'spacing', but got -0\.5\.",
        ),
        ([[0, 0, 0], [0, 0, 1]], [0.0, 1.0], {"spacing": np.nan}, ValueError, r"Expected a positive 'spacing'"),
        (
            [[0, 0, 0], [0, 0, 1]],
            [0.0, 1.0],
            {"origin": (0.0, 0.0)},
            ValueError,
            r"Expected 'origin' of shape \(3,\), but got \(2,\)\.",
        ),
        ([[0, 0, 0], [0, 0, 1]], [0.0, 1.0], {"iso": np.nan}, ValueError, r"Expected a finite 'iso', but got nan\."),
        ([[0, 0, 0], [0, 0, 0]], [0.0, 1.0], {}, ValueError, r"Expected unique 'coords', but got 1 repeated samples\."),
        ([[0.0, 0.0, 0.0]], [0.0], {}, TypeError, r"Expected integer 'coords', but got dtype float64\."),
        ([[0, 0, 2**31]], [0.0], {}, ValueError, r"Expected 'coords' within the int32 range"),
        ([[0, 0, 0], [2**21, 0, 0]], [0.0, 1.0], {}, ValueError, r"Expected 'coords' spanning fewer than 2\*\*20"),
    ],
)
def test_invalid_arguments_raise(coords, values, kwargs, error, match):
    kwargs = {"origin": (0.0, 0.0, 0.0), "spacing": 1.0} | kwargs
    with pytest.raises(error, match=match):
        extract_surface(np.asarray(coords), values, **kwargs)


@pytest.mark.parametrize(("iso_voxels", "levels"), [(0.0, 4), (0.45, 4), (-0.4, 4), (0.0, 3), (0.0, 2), (0.0, 1)])
def test_octree_level_extraction_matches_the_generic_one(iso_voxels, levels):
    # to_mesh(sharp=False) takes each cube's corners from its octet's +x/+y/+z neighbours, found through the child
    # links from the dense top level (itself the octets' level with 2 levels, the finest with 1), without sorting: the
    # mesh must be the one extract_surface finds from the same samples.
    import engine
    from tests.support import uv_sphere

    a = uv_sphere(1.0, rings=24, segments=48)
    b = (a[0] + np.float32([0.9, 0.2, -0.1]), a[1])
    h = 0.04
    field = engine.union(*(engine.build_field(*m, voxel_size=h, levels=levels) for m in (a, b)))
    n0 = field.level_counts[0]
    iso = iso_voxels * h
    verts, tris = field.to_mesh(iso=iso, sharp=False)
    generic_verts, generic_tris = extract_surface(
        field.coords.numpy()[:n0], field.values.numpy()[:n0], origin=field.origin, spacing=h, iso=iso
    )
    assert len(tris) > 1000 and len(verts) == len(generic_verts) and len(tris) == len(generic_tris)
    np.testing.assert_array_equal(
        oriented_triangles(verts, tris, generic_verts),
        oriented_triangles(generic_verts, generic_tris, generic_verts),
    )


@pytest.mark.parametrize("iso_voxels", [0.4, 1.0, -1.0, 2.0])
def test_a_level_past_the_finest_band_is_its_offsets_surface_closed(iso_voxels):
    # the finest band holds every cube a level crosses only about half a voxel out (measured: 24-34 k open edges at
    # one voxel on the CAD pairs): past ISO_REACH, to_mesh(iso) is the zero surface of the field's offset by iso
    import engine
    from engine.field import ISO_REACH
    from tests.support import cad_pairs

    op, a, b = cad_pairs()["cube - bore"]
    h = 1.0 / 96.0
    field = engine.difference(*engine.build_fields([a, b], voxel_size=h))
    verts, tris = field.to_mesh(iso=iso_voxels * h)
    assert is_watertight(tris) and len(tris) > 1000
    if abs(iso_voxels) > ISO_REACH:
        offset_verts, offset_tris = engine.offset(field, iso_voxels * h).to_mesh()
        assert np.array_equal(verts, offset_verts) and np.array_equal(tris, offset_tris)
    # its vertices lie at the level (the field sampled there; a sharp corner of the offset planes lies farther out
    # than the rounded level, so the 95th percentile): measured 0.107, 0.099, 0.065 and 0.21 voxel (two voxels out,
    # past the finest band, the field's own samples are the coarse levels' interpolation)
    level = np.abs(field.sample(verts) - iso_voxels * h)
    bound = {0.4: 0.3, 1.0: 0.3, -1.0: 0.2, 2.0: 0.6}[iso_voxels]
    assert np.percentile(level, 95) < bound * h, np.percentile(level, 95) / h


def test_a_level_that_leaks_out_of_the_finest_band_is_its_offsets_surface():
    # the open beetle with a ball: its level 0.3 voxel out already leaves the finest band near the capped holes
    # (measured at /128: open at 0.2-0.4 voxel), so to_mesh gives its offset's zero surface, closed
    import engine
    from engine.meshing import field_mesh
    from tests.support import load_mesh, normalised, uv_sphere

    h = 1.0 / 128.0
    beetle = engine.build_field(*normalised(load_mesh("beetle.obj")), voxel_size=h)
    ball = engine.build_field(*normalised(uv_sphere(0.25, center=(0.2, 0.1, 0.0))), voxel_size=h)
    field = engine.union(beetle, ball)
    iso = 0.3 * h
    direct = field_mesh(field, iso, sharp=True, creases=False, quads=False, adaptivity=0.0)
    assert not direct["closed"] and not is_watertight(direct["tris"])
    verts, tris = field.to_mesh(iso=iso)
    assert is_watertight(tris)
    offset_verts, offset_tris = engine.offset(field, iso).to_mesh()
    assert np.array_equal(verts, offset_verts) and np.array_equal(tris, offset_tris)
