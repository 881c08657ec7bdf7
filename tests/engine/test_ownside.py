"""Gaps in a mesh narrower than its field sees (engine/ownside.py): the walls facing each other across one are the
result's surface and are kept; faces inside another shell are not, however near they face each other.

Voxel = 1/256 of the operands' bounding-box diagonal.
"""

import numpy as np
import pytest

import engine
from engine.ownside import gaps_in_front
from engine.sources import SourceMesh
from tests.metrics import mesh_area, to_manifold
from tests.support import box_mesh, normalised, uv_sphere

HALF = 0.2


def _two_blocks(gap: float, around: bool = False):
    """Two blocks, one mesh, facing each other across ``gap`` along x (with ``around``, a third block enclosing the
    gap: the facing walls inside it)."""
    parts = [
        box_mesh(half=(HALF, HALF, HALF), center=(-HALF - gap / 2, 0.0, 0.0)),
        box_mesh(half=(HALF, HALF, HALF), center=(HALF + gap / 2, 0.0, 0.0)),
    ]
    if around:
        parts.append(box_mesh(half=(0.1, 0.1, 0.1)))
    verts = np.concatenate([p[0] for p in parts])
    offsets = np.cumsum([0] + [len(p[0]) for p in parts[:-1]])
    tris = np.concatenate([p[1] + o for p, o in zip(parts, offsets, strict=True)])
    return verts.astype(np.float32), tris.astype(np.int64)


def _voxel(mesh, ball) -> float:
    v = np.concatenate([mesh[0], ball[0]])
    return float(np.linalg.norm(v.max(0) - v.min(0))) / 256.0


BALL = normalised(uv_sphere(1.0, rings=12, segments=24), center=(0.0, 0.0, 0.6), diagonal=0.1)


def _walls(verts, tris, gap) -> np.ndarray:
    """(T,) the triangles of the two walls facing each other across the gap."""
    x = verts[tris][:, :, 0]
    return (np.abs(np.abs(x) - gap / 2) < 1e-6).all(axis=1)


@pytest.mark.parametrize("voxels", [0.3, 0.7])
def test_the_walls_of_a_gap_narrower_than_a_voxel_are_kept(voxels):
    # measured: both walls kept whole (0.16 of the two blocks' area); taken for internal faces before, they were
    # dropped and the voxel surface closed the gap over
    h = _voxel(_two_blocks(0.0), BALL)
    gap = voxels * h
    mesh = _two_blocks(gap)
    fa, fb = engine.build_fields([mesh, BALL], voxel_size=h, field_ids=[0, 1])
    s = engine.union(fa, fb).kept_surface()
    kept = s["tris"][s["kept"] & (s["field_id"] == 0)]
    walls = mesh_area(mesh[0], mesh[1][_walls(*mesh, gap)])
    assert abs(mesh_area(s["verts"], kept) - mesh_area(*mesh)) < 1e-3 * walls  # every face, the walls too
    assert engine.surface_edges(s["tris"], len(s["verts"])) is not None
    assert to_manifold(s["verts"], s["tris"]).status().name == "NoError"


def test_only_a_gap_outside_every_shell_counts():
    # a ray from each wall meets the other wall 0.5 voxel ahead; with a third block about the gap, its middle is
    # inside that block (the walls are internal faces there): no gap
    h = _voxel(_two_blocks(0.0), BALL)
    gap = 0.5 * h
    for around, expected in ((False, True), (True, False)):
        verts, tris = _two_blocks(gap, around)
        walls = np.flatnonzero(_walls(verts, tris, gap))
        centres = verts[tris[walls]].mean(axis=1)
        normals = np.where(centres[:, :1] < 0.0, 1.0, -1.0) * np.array([[1.0, 0.0, 0.0]])
        bvh = SourceMesh(verts, tris.astype(np.int32), np.arange(len(tris))).bvh("cpu")
        found = gaps_in_front(bvh, centres, normals, 2.0 * h, 1e-3 * h, "cpu")
        assert found.all() if expected else not found.any(), (around, found)
        assert not gaps_in_front(bvh, centres, -normals, 2.0 * h, 1e-3 * h, "cpu").any()  # behind: the block
