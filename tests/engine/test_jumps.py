"""Where a messy mesh's field may jump (engine/jumps.py), and the judge that reads its sign a band away only there."""

import numpy as np

import engine
from engine import keep
from engine.jumps import JumpSpheres, jump_spheres
from engine.sources import SourceMesh
from tests.support import box_mesh, load_mesh, normalised, uv_sphere


def test_an_open_box_has_one_sphere_about_its_hole_and_a_closed_one_none():
    verts, tris = box_mesh(half=(1.0, 1.0, 1.0))
    top = verts[tris].mean(axis=1)[:, 2] > 0.99  # the two triangles of the top face
    spheres = jump_spheres(SourceMesh(verts, tris[~top], np.arange(int((~top).sum()))))
    assert spheres.shape == (1, 4)
    np.testing.assert_allclose(spheres[0, :3], [0.0, 0.0, 1.0], atol=1e-6)  # the hole's four corners' mean
    assert abs(spheres[0, 3] - 1.5 * np.sqrt(2.0)) < 1e-5  # their distance from it, widened by half
    assert len(jump_spheres(SourceMesh(verts, tris, np.arange(len(tris))))) == 0
    near = JumpSpheres(spheres, "cpu").near(np.array([[0.0, 0.0, 1.0], [0.0, 0.0, -3.0], [3.3, 0.0, 1.0]]), 0.5)
    assert near.tolist() == [True, False, False]  # 3.3 is 0.17 past the sphere's 2.62 and its reach of 0.5
    assert JumpSpheres(None, "cpu").near(np.zeros((2, 3)), 0.1).all()  # no mesh: anywhere


def test_the_judge_reading_jumps_only_near_the_defects_keeps_what_reading_them_everywhere_keeps(monkeypatch):
    # the beetle (296 open, 47 non-manifold edges in 26 pieces) with a ball, judged both ways: the same pieces, kept
    # and flipped alike, through the fused and the sample-by-sample paths
    beetle = normalised(load_mesh("beetle.obj"))
    ball = normalised(uv_sphere(1.0, rings=24, segments=48), center=(0.2, 0.2, 0.2), diagonal=0.6)
    v = np.concatenate([beetle[0], ball[0]])
    h = float(np.linalg.norm(v.max(0) - v.min(0))) / 256.0
    fa, fb = engine.build_fields([beetle, ball], voxel_size=h, field_ids=[0, 1])
    for fused in (True, False):
        engine.verdicts.forget()
        near = keep.kept_triangles(engine.union(fb, fa), fused=fused)
        with monkeypatch.context() as patch:
            patch.setattr(keep, "leaf_jumps", lambda leaf, device: None if leaf is fb else JumpSpheres(None, device))
            engine.verdicts.forget()
            everywhere = keep.kept_triangles(engine.union(fb, fa), fused=fused)
        for mine, theirs in zip(near, everywhere, strict=True):
            for key in ("verts", "tris", "parent", "kept", "flip"):
                np.testing.assert_array_equal(mine[key], theirs[key])
