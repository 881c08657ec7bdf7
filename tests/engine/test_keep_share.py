"""How much of what should be kept comes out kept on messy shared meshes (engine/hybrid.py, engine/zipper.py,
engine/slits.py): the issue's target is 99 % of the area of the faces farther than 3 voxels from the other operand's
surface and from the mesh's own defects, on the result's side. Defects as the issue names them: hole boundaries,
non-manifold edges, duplicated faces, and where the surface passes through itself (its kept faces stay a band from
there: :mod:`engine.keep`).

Voxel = 1/256 of the operands' bounding-box diagonal. A sample of the mesh's surface counts as kept when it lies on
a kept face of that mesh (within 1e-5: kept faces are the mesh's own triangles, or pieces of them).
"""

import numpy as np
import pytest

import engine
from engine.meshcheck import problem_faces, weld_positions
from tests.metrics import (
    distance_within,
    sample_surface,
    self_intersecting_faces,
    to_manifold,
    unsigned_distance,
    winding_inside,
)
from tests.support import load_mesh, normalised, uv_sphere


def _defects(verts, tris) -> np.ndarray:
    """(T,) bool: triangles at an open, non-manifold or misoriented edge, repeating another's corners (vertices
    at one position taken as one), or crossed by another triangle."""
    welded_verts, welded = weld_positions(verts, tris)
    welded = np.asarray(welded, dtype=np.int32)
    _, inverse, counts = np.unique(np.sort(welded, axis=1), axis=0, return_inverse=True, return_counts=True)
    problem = (counts[inverse.reshape(-1)] > 1) | problem_faces(welded, len(welded_verts)).astype(bool)
    return problem | self_intersecting_faces(verts, tris)


def _kept_share(name: str, inside_out: bool = False) -> tuple[float, dict]:
    """The mesh (turned inside out: every triangle reversed) united with a ball at /256: the share of the samples
    that should be kept that are, and the surface."""
    mesh = normalised(load_mesh(f"{name}.obj"))
    if inside_out:
        mesh = (mesh[0], mesh[1][:, ::-1].copy())
    ball = normalised(uv_sphere(1.0, rings=48, segments=96), center=(0.2, 0.2, 0.2), diagonal=0.6)
    v = np.concatenate([mesh[0], ball[0]])
    h = float(np.linalg.norm(v.max(0) - v.min(0))) / 256.0
    fa, fb = engine.build_fields([mesh, ball], voxel_size=h, field_ids=[0, 1])
    s = engine.union(fa, fb).kept_surface()
    points = sample_surface(*mesh, 60_000, seed=0)
    should = (unsigned_distance(*ball, points) > 3 * h) & ~winding_inside(*ball, points)
    defects = _defects(*mesh)
    if defects.any():
        should &= unsigned_distance(mesh[0], mesh[1][defects], points) > 3 * h
    kept = s["tris"][s["kept"] & (s["field_id"] == 0)]
    if not len(kept):  # (the voxel surface alone)
        return 0.0, s
    return float((distance_within(s["verts"], kept, points[should], h) < 1e-5).mean()), s


# measured at /256, share: teapot 0.997 (a mesh of patches repeating their border vertices), cow 1.000 (its ears
# thinner than a voxel: 0.988 while their faces were taken for internal ones, 0.9945 while a kept loop paired with a
# scrap of voxel surface was not zipped to the kept loop facing it), beetle 0.9985 (296 open and 47 non-manifold
# edges; 0.938 while the voxel surface of a thin part's far side was taken for lying over the near side's kept faces,
# 0.952 while pieces of its thin parts were turned unlike their neighbours, 0.986 with one join, 0.992 while the walls
# of gaps narrower than a voxel were taken for internal faces), Suzanne 1.000 (0.974 so: its ears and head face each
# other 0.1-1.3 voxel apart); the 99 % on each, bounds three times their shortfall but the teapot's
@pytest.mark.parametrize(("name", "least"), [("teapot", 0.99), ("cow", 0.996), ("beetle", 0.995), ("suzanne", 0.995)])
def test_messy_meshes_keep_most_of_what_should_be_kept(name, least):
    share, s = _kept_share(name)
    assert share >= least, share
    assert s["stats"]["crossing_left"] <= CROSSINGS_LEFT[name]
    assert s["stats"]["kept_fallback"] == ""
    assert engine.surface_edges(s["tris"], len(s["verts"])) is not None  # closed, consistently oriented
    assert to_manifold(s["verts"], s["tris"]).status().name == "NoError"


# pairs of faces passing through each other with a new face among them (engine/uncross.py), measured: teapot 0 (78
# before faces crossing others were tiled again, 5 before places no plane tiles were fanned, 1 before thin parts' voxel
# vertices lay at their mass points), cow 0 (37, 7: a crumpled corner where the cow's and the ball's surfaces meet),
# beetle 0 (267, 100, 82 and 31 at earlier stops; 63 while its voxel surface passed through itself at parts thinner
# than a voxel), Suzanne 0 (51)
CROSSINGS_LEFT = {"teapot": 0, "cow": 0, "beetle": 0, "suzanne": 0}


@pytest.mark.parametrize(("name", "least"), [("beetle", 0.985), ("suzanne", 0.995)])
def test_meshes_inside_out_keep_as_much(name, least):
    # measured: the beetle 0.9949 (0.9924 when the walls of its gaps narrower than a voxel were dropped; kept, its
    # join fell back to the voxel surface alone where a scrap of voxel surface across a gap had no kept border in
    # reach to give up), Suzanne 1.000; bounds three times the shortfall
    share, s = _kept_share(name, inside_out=True)
    assert share >= least, share
    assert s["stats"]["kept_fallback"] == ""
    assert engine.surface_edges(s["tris"], len(s["verts"])) is not None
    manifold = to_manifold(s["verts"], s["tris"])
    assert manifold.status().name == "NoError" and manifold.volume() > 0.0  # closed, turned outward
