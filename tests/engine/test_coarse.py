"""High adaptivities contoured on the field's level 1 (engine/coarse.py): that surface near the exact boolean, and
taken only where it is closed and loses nothing the finest surface has.

Voxel = 1/256 of the operands' bounding-box diagonal (each normalised to 1); distances are stated in voxels.
"""

import numpy as np
import pytest

import engine
from engine.coarse import coarse_surface, level_one
from engine.contouring import sharp_surface
from engine.quads import triangulate
from tests.engine.test_quads import closed_2_manifold
from tests.metrics import exact_boolean, hausdorff
from tests.support import box_mesh, cad_pairs

H = 1.0 / 256.0


@pytest.fixture(scope="module")
def cube_bore():
    op, a, b = cad_pairs()["cube - bore"]
    return engine.difference(*engine.build_fields([a, b], voxel_size=H)), exact_boolean(op, *a, *b)


def test_level_one_is_the_level_above_the_finest(cube_bore):
    field, exact = cube_bore
    view = level_one(field)
    assert view.voxel_size == 2 * field.voxel_size and view.levels == field.levels - 1
    assert list(view.level_counts) == list(field.level_counts[1:])
    assert np.array_equal(view.values.numpy(), field.values.numpy()[field.level_counts[0] :])
    verts, tris = view.to_mesh()
    assert closed_2_manifold(len(verts), tris.ravel(), np.full(len(tris), 3))
    # measured: p95 0.019, max 0.67 voxel (fandisk - cylinder 0.029, 0.81), a quarter of the finest's triangles
    dist = hausdorff(verts, tris, *exact, n=100_000)
    assert dist["p95"] <= 0.06 * H and dist["max"] <= 2.0 * H, (dist["p95"] / H, dist["max"] / H)
    assert coarse_surface(field, 0.0) is not None


def _fin(offset: float):
    """A box with a fin 1.2 voxels thick standing 64 voxels out of its top (its exact union too)."""
    a = box_mesh(half=(0.3, 0.3, 0.3))
    b = box_mesh(half=(0.15, 0.6 * H, 0.2), center=(0.0, offset, 0.35))
    return engine.union(*engine.build_fields([a, b], voxel_size=H)), exact_boolean("UNION", *a, *b)


@pytest.mark.parametrize("offset", [0.0, 0.0145, 0.013])
def test_a_fin_thinner_than_the_coarse_cells_keeps_the_finest_surface(offset):
    field, exact = _fin(offset)
    coarse = coarse_surface(field, 0.0)
    # where the fin falls between level 1's nodes, the coarse surface misses it (1,216-2,432 octets) and the finest
    # level is contoured; where a row of them lies inside it (offset 0.013), level 1 holds it and is taken
    assert (coarse is None) == (offset != 0.013)
    verts, faces, sizes = field.to_mesh(quads=True, adaptivity=0.5)
    assert closed_2_manifold(len(verts), faces, sizes)
    # measured max 0.49-0.57 voxel falling back, 0.86 on level 1; the fin lost would be 64 voxels
    dist = hausdorff(verts, triangulate(faces, sizes), *exact, n=100_000)
    assert dist["max"] <= 2.6 * H, (offset, dist["max"] / H)


@pytest.fixture(scope="module")
def rocker():
    op, a, b = cad_pairs()["rocker-arm - cube"]
    return engine.difference(*engine.build_fields([a, b], voxel_size=H)), exact_boolean(op, *a, *b)


@pytest.fixture(scope="module")
def chamfered():
    """rocker-arm - cube chamfered 0.03 wide: a chamfer changes faster than the distance moved, so the boolean's band
    can leave a level-1 cube along its seam without a corner; the result's own finest surface."""
    _, a, b = cad_pairs()["rocker-arm - cube"]
    field = engine.difference(*engine.build_fields([a, b], voxel_size=H), blend=0.03, blend_mode="chamfer")
    return field, field.to_mesh()


def test_a_booleans_band_keeps_every_corner_of_its_crossed_level_one_cubes(rocker):
    # with a band of 2.5 voxels the rocker arm's level 1 was open along its seam (6 edges in one triangle each, at a
    # cube missing a corner 3.3 voxels off the surface) and was contoured twice
    field, _ = rocker
    own = sharp_surface(level_one(field), 0.0)
    assert own["closed"] and closed_2_manifold(len(own["verts"]), own["tris"].ravel(), np.full(len(own["tris"]), 3))


def test_a_coarse_band_left_open_near_a_seam_is_patched(chamfered):
    field, finest = chamfered
    own = sharp_surface(level_one(field), 0.0)
    # measured: 12 vertices on open edges, at level-1 cubes missing a corner along the chamfer
    assert not closed_2_manifold(len(own["verts"]), own["tris"].ravel(), np.full(len(own["tris"]), 3))
    surface = coarse_surface(field, 0.0)
    assert surface is not None and closed_2_manifold(len(surface["verts"]), surface["tris"].ravel(),
                                                      np.full(len(surface["tris"]), 3))  # fmt: skip
    # 2 of the nodes added are corners of active cubes; measured p95 0.105, max 1.30 voxel from the finest surface
    assert len(surface["cube_corners"]) and surface["cube_corners"].max() >= level_one(field).level_counts[0]
    dist = hausdorff(surface["verts"], surface["tris"], *finest, n=100_000)
    assert dist["p95"] <= 0.3 * H and dist["max"] <= 3.0 * H, (dist["p95"] / H, dist["max"] / H)


def test_a_coarse_band_left_open_falls_back_to_the_finest(chamfered, monkeypatch):
    from engine import coarse

    field, finest = chamfered
    monkeypatch.setattr(coarse, "PATCH_ROUNDS", 0)
    assert coarse_surface(field, 0.0) is None
    verts, faces, sizes = field.to_mesh(quads=True, adaptivity=0.5)
    assert closed_2_manifold(len(verts), faces, sizes)
    # measured: 11,372 polygons (82,669 at adaptivity 0) at p95 0.239, max 0.85 voxel (the finest level merged)
    dist = hausdorff(verts, triangulate(faces, sizes), *finest, n=100_000)
    assert len(sizes) < 0.2 * len(field.to_mesh(quads=True)[2]) and dist["p95"] <= 0.75 * H


@pytest.mark.parametrize("setting", ["blended", "turned", "mirrored"])
def test_level_one_serves_blended_and_placed_results(setting, cube_bore):
    # a blended boolean's level 1 holds blended values (no Hermite planes at the blend: the gradient there, as at the
    # finest), and a placed result is contoured in its own frame: closed, 2-manifold, near its own adaptivity-0
    # surface (measured p95 0.21 voxel, max 1.04-1.31 at 0.5 on the three)
    field, _ = cube_bore
    op, a, b = cad_pairs()["cube - bore"]
    if setting == "blended":
        field = engine.difference(*engine.build_fields([a, b], voxel_size=H), blend=0.03)
    elif setting == "turned":
        field = field.transformed(
            np.array([[0.0, -1.0, 0.0, 0.3], [1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.1], [0, 0, 0, 1]])
        )
    else:
        field = field.transformed(np.diag([-1.0, 1.0, 1.0, 1.0]))
    assert coarse_surface(field.in_frame(), 0.0) is not None
    verts, faces, sizes = field.to_mesh(quads=True, adaptivity=0.5)
    assert closed_2_manifold(len(verts), faces, sizes)
    dist = hausdorff(verts, triangulate(faces, sizes), *field.to_mesh(), n=50_000)
    assert dist["p95"] <= 0.6 * H and dist["max"] <= 3.5 * H, (setting, dist["p95"] / H, dist["max"] / H)
