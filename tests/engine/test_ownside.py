"""Gaps in a mesh narrower than its field sees (engine/ownside.py): the walls facing each other across one are the
result's surface and are kept; faces inside another shell are not, however near they face each other.

Voxel = 1/256 of the operands' bounding-box diagonal.
"""

import numpy as np
import pytest

import engine
from engine.ownside import side_at
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


@pytest.mark.parametrize(("voxels", "inside_out"), [(0.3, False), (0.7, False), (0.5, True)])
def test_the_walls_of_a_gap_narrower_than_a_voxel_are_kept(voxels, inside_out):
    # measured: both walls kept whole (0.16 of the two blocks' area), inside out too (turned outward); taken for
    # internal faces before, they were dropped and the voxel surface closed the gap over
    h = _voxel(_two_blocks(0.0), BALL)
    gap = voxels * h
    mesh = _two_blocks(gap)
    if inside_out:
        mesh = (mesh[0], mesh[1][:, ::-1].copy())
    fa, fb = engine.build_fields([mesh, BALL], voxel_size=h, field_ids=[0, 1])
    s = engine.union(fa, fb).kept_surface()
    kept = s["tris"][s["kept"] & (s["field_id"] == 0)]
    walls = mesh_area(mesh[0], mesh[1][_walls(*mesh, gap)])
    assert abs(mesh_area(s["verts"], kept) - mesh_area(*mesh)) < 1e-3 * walls  # every face, the walls too
    assert engine.surface_edges(s["tris"], len(s["verts"])) is not None
    manifold = to_manifold(s["verts"], s["tris"])
    assert manifold.status().name == "NoError" and manifold.volume() > 0.0  # closed, facing outward


@pytest.mark.parametrize("inside_out", [False, True])
def test_only_a_gap_outside_every_shell_counts(inside_out):
    # the walls read inside on both sides (the field closes a gap of 0.5 voxel); a ray from each meets the other wall
    # ahead: a gap, the side towards it (behind, inside out). With a third block about the gap, its middle is inside
    # that block and the walls are internal faces (side 0)
    h = _voxel(_two_blocks(0.0), BALL)
    gap = 0.5 * h
    turn = -1 if inside_out else 1
    for around, expected in ((False, turn), (True, 0)):
        verts, tris = _two_blocks(gap, around)
        if inside_out:
            tris = tris[:, ::-1].copy()
        field = engine.build_fields([(verts, tris)], voxel_size=h)[0]
        walls = np.flatnonzero(_walls(verts, tris, gap))
        centres = verts[tris[walls]].mean(axis=1)
        normals = turn * np.where(centres[:, :1] < 0.0, 1.0, -1.0) * np.array([[1.0, 0.0, 0.0]])
        bvh = SourceMesh(verts, tris.astype(np.int32), np.arange(len(tris))).bvh("cpu")
        assert (side_at(field, centres, normals, 0.5 * h) == 0).all()  # without the mesh: internal faces
        sides = side_at(field, centres, normals, 0.5 * h, rays=bvh, tiny=1e-3 * h, turn=turn)
        assert (sides == expected).all(), (around, sides)
