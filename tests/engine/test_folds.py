"""The edges along which a kept surface folds (engine/edges.py ``fold_edges``): marked sharp in Blender where kept
faces meet at an angle or meet the new faces along the seams."""

import numpy as np

from engine import fold_edges, surface_edges
from tests.support import box_mesh, cylinder_mesh, uv_sphere


def _by_hand(verts, tris, degrees: float) -> set:
    """The folds by brute force: every edge's two faces found by a dictionary, their unit normals compared."""
    v = np.asarray(verts, dtype=np.float64)
    n = np.cross(v[tris[:, 1]] - v[tris[:, 0]], v[tris[:, 2]] - v[tris[:, 0]])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    faces = {}
    for t, tri in enumerate(np.asarray(tris).tolist()):
        for k in range(3):
            faces.setdefault(tuple(sorted((tri[k], tri[(k + 1) % 3]))), []).append(t)
    return {e for e, (f, g) in faces.items() if float(n[f] @ n[g]) < np.cos(np.radians(degrees))}


def test_a_box_folds_along_its_twelve_edges_and_a_ball_nowhere():
    verts, tris = box_mesh(half=(1.0, 0.5, 0.25))
    folds = fold_edges(verts, tris)
    assert {tuple(e) for e in folds.tolist()} == _by_hand(verts, tris, 30.0) and len(folds) == 12
    assert not len(fold_edges(*uv_sphere(1.0, rings=24, segments=48)))  # (7.5 degrees between faces at most)


def test_folds_are_those_past_the_angle_on_a_shaken_mesh_and_none_on_an_open_one():
    # an 8-sided cylinder: its walls meet at 45 degrees, its caps at 90; found edges given or not, the same
    verts, tris = cylinder_mesh(1.0, 2.0, segments=8)
    for degrees, count in ((30.0, 24), (60.0, 16)):  # (measured: 8 wall edges, 16 rim edges)
        folds = fold_edges(verts, tris, degrees)
        assert {tuple(e) for e in folds.tolist()} == _by_hand(verts, tris, degrees) and len(folds) == count
    rng = np.random.default_rng(3)
    shaken = uv_sphere(1.0, rings=12, segments=24)[0] * rng.uniform(0.8, 1.2, (1, 1)) + rng.normal(0, 0.06, (266, 3))
    verts, tris = shaken.astype(np.float32), uv_sphere(1.0, rings=12, segments=24)[1]
    edges = surface_edges(tris, len(verts))
    for degrees in (10.0, 20.0, 30.0):
        folds = fold_edges(verts, tris, degrees, edges=edges)
        assert {tuple(e) for e in folds.tolist()} == _by_hand(verts, tris, degrees)
    assert 200 < len(fold_edges(verts, tris, 20.0)) < len(edges[0])  # measured: 581 of 792, not all
    assert not len(fold_edges(verts, tris[1:]))  # open: not a surface whose edges pair up
