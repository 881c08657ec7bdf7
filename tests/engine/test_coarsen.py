"""A kept surface's new faces collapsed where flat (engine/coarsen.py): no vertex moves, source vertices stay, the
surface stays closed and where it was, and flat parts lose most of their faces."""

from functools import partial

import numpy as np
import pytest

import engine
from engine import coarsen
from engine.coarsen import TOLERANCE_VOXELS, claimed, coarsened, collapse_flat, vertex_corners
from engine.hybrid import hybrid_surface
from tests.metrics import exact_boolean, hausdorff, to_manifold
from tests.support import box_mesh, cad_pairs, is_watertight


def _before_and_after():
    op, a, b = cad_pairs()["cube | tilted cube"]
    v = np.concatenate([a[0], b[0]])
    h = float(np.linalg.norm(v.max(0) - v.min(0))) / 256.0
    fa, fb = engine.build_fields([a, b], voxel_size=h)
    field = engine.union(fa, fb)
    verts, tris = field.to_mesh()
    before = hybrid_surface(field, verts, tris)
    return field, h, before, coarsened(field, before)


def _source_vertices(surface) -> set:
    at = surface["vertex_id"] >= 0
    return set(zip(surface["vertex_field"][at].tolist(), surface["vertex_id"][at].tolist(), strict=False))


def test_collapses_move_no_vertex_keep_source_vertices_and_stay_on_the_surface():
    field, h, before, after = _before_and_after()
    # no vertex is new or moved: every one is a vertex of the surface before, bit for bit
    old = {tuple(p) for p in before["verts"].tolist()}
    assert all(tuple(p) in old for p in after["verts"].tolist())
    # every source vertex a kept face had is still there
    assert _source_vertices(before) == _source_vertices(after)
    assert is_watertight(after["tris"])
    assert engine.surface_edges(after["tris"], len(after["verts"])) is not None  # closed, consistently oriented
    to_manifold(after["verts"], after["tris"], "coarsened surface")  # manifold3d takes it as a solid
    d = hausdorff(before["verts"], before["tris"], after["verts"], after["tris"], n=100_000)
    # measured: max 0.05 voxel, p95 2e-5 (the tolerance is 0.01 of the planes of well-shaped faces; a thin face's
    # plane bounds nothing: a strip's sliver lets its vertex go about five times as far)
    assert d["max"] <= 15 * TOLERANCE_VOXELS * h and d["p95"] <= 0.01 * h, d
    # measured: 27,926 -> 15,096 faces
    assert len(after["tris"]) < 0.7 * len(before["tris"])
    assert after["stats"]["coarsened"] == len(before["tris"]) - len(after["tris"])
    assert after["stats"]["kept_faces"] + after["stats"]["new_faces"] == len(after["tris"])


def test_faces_keep_their_sources_and_kept_faces_their_planes():
    field, h, before, after = _before_and_after()
    # kept faces stay kept faces of the same source triangles, on their planes
    kept = after["kept"]
    assert set(zip(after["field_id"][kept], after["triangle_id"][kept], strict=False)) <= set(
        zip(before["field_id"][before["kept"]], before["triangle_id"][before["kept"]], strict=False)
    )
    for field_id, source in field.sources.items():
        faces = np.flatnonzero(kept & (after["field_id"] == field_id))
        src = source.verts[source.tris[after["triangle_id"][faces]]].astype(np.float64)
        normal = np.cross(src[:, 1] - src[:, 0], src[:, 2] - src[:, 0])
        normal /= np.linalg.norm(normal, axis=1, keepdims=True)
        corners = after["verts"][after["tris"][faces]].astype(np.float64)
        off = np.abs(np.einsum("fkj,fj->fk", corners - src[:, :1], normal))
        assert off.max() < 1e-4 * h, off.max()  # measured: float rounding of the midpoints
    # new faces come from the new faces before (none turned kept)
    assert (~after["kept"]).sum() <= (~before["kept"]).sum()


def test_an_adaptivity_merges_the_seams_new_faces_across_source_triangles_within_regions():
    op, a, b = cad_pairs()["hex prism & sphere"]  # the sphere's 36,480 triangles: its band's faces each on a few
    v = np.concatenate([a[0], b[0]])
    h = float(np.linalg.norm(v.max(0) - v.min(0))) / 256.0
    fa, fb = engine.build_fields([a, b], voxel_size=h, field_ids=[0, 1])
    field = engine.intersection(fa, fb)
    at_zero, merged = field.kept_surface(), field.kept_surface(adaptivity=0.5)
    # measured: 7,208 -> 3,116 new faces, the kept ones 14,792 -> 14,718 (split pieces of one triangle merge either way)
    assert merged["stats"]["new_faces"] < 0.7 * at_zero["stats"]["new_faces"]
    assert abs(merged["stats"]["kept_faces"] - at_zero["stats"]["kept_faces"]) < 0.02 * at_zero["stats"]["kept_faces"]
    assert is_watertight(merged["tris"])
    assert engine.surface_edges(merged["tris"], len(merged["verts"])) is not None
    to_manifold(merged["verts"], merged["tris"], "merged kept surface")
    d = hausdorff(merged["verts"], merged["tris"], *exact_boolean("INTERSECT", *a, *b), n=100_000)
    # measured: max 0.19 voxel, p95 0.018 (0.17 and 0.016 at adaptivity 0)
    assert d["max"] < 0.6 * h and d["p95"] < 0.05 * h, d
    # regions: every source triangle a region of its own: no merge across two of them, only the tolerance is wider
    own = {0: np.arange(len(a[1])), 1: np.arange(len(b[1]))}
    within = field.kept_surface(adaptivity=0.5, regions=own)
    # measured: 3,116 < 5,770 <= 7,208
    assert merged["stats"]["new_faces"] < 0.7 * within["stats"]["new_faces"]
    assert within["stats"]["new_faces"] <= at_zero["stats"]["new_faces"]


@pytest.mark.parametrize("serial", [True, False])
def test_a_flat_face_collapses_to_about_its_border(serial):
    # a box, each face 32 x 32 quads split in two: a face's 124 vertices on its edges stay (their faces lie in two
    # planes), so a face needs at least 126 triangles (a polygon of 128 corners), 756 in all; the collapses one after
    # another in one thread (the CPU's way) and in rounds (CUDA's) alike
    verts, tris = box_mesh(subdivisions=32)
    normals = np.cross(verts[tris[:, 1]] - verts[tris[:, 0]], verts[tris[:, 2]] - verts[tris[:, 0]])
    axis = np.argmax(np.abs(normals), axis=1)
    group = 2 * axis + (normals[np.arange(len(tris)), axis] > 0)
    movable = np.ones(len(verts), bool)
    out, rows = collapse_flat(verts, tris, movable, group.astype(np.int64), 1e-6, "cpu", serial=serial)
    assert is_watertight(out)
    assert engine.surface_edges(out, len(verts)) is not None  # every edge in two faces, opposite ways
    # each face left is one of its box face's, on it (no vertex moved: the corners are the box's vertices)
    on = verts[out][np.arange(len(out)), :, axis[rows]]
    assert np.allclose(np.abs(on), 1.0)
    # measured: 12,288 -> 774 one after another, 804 in rounds (2,406 when a round's claims made one pass: its
    # winners a tenth of the candidates, the rounds stopped once few went)
    assert len(out) < 900, len(out)


def test_collapses_one_after_another_leave_what_the_rounds_leave(monkeypatch):
    # the same kept surface collapsed in one thread and in rounds: both closed, 2-manifold and on the surface before;
    # one after another leaves no more faces
    field, h, before, serial = _before_and_after()
    monkeypatch.setattr(coarsen, "collapse_flat", partial(coarsen.collapse_flat, serial=False))
    rounds = coarsened(field, before)
    for after in (serial, rounds):
        assert is_watertight(after["tris"])
        assert engine.surface_edges(after["tris"], len(after["verts"])) is not None
        to_manifold(after["verts"], after["tris"], "coarsened surface")
        d = hausdorff(before["verts"], before["tris"], after["verts"], after["tris"], n=50_000)
        assert d["max"] <= 15 * TOLERANCE_VOXELS * h and d["p95"] <= 0.01 * h, d
    # measured: 15,268 faces in rounds, 15,096 one after another
    assert len(serial["tris"]) <= len(rounds["tris"])


def test_a_rounds_claims_in_one_thread_are_the_passes_ones():
    # every vertex of a subdivided box a candidate (then a third of them), in a random order: the passes' winners (each
    # pass two launches, as on CUDA) and the one thread's are the same, and their closed 1-rings are disjoint
    verts, tris = box_mesh(subdivisions=24)
    n = len(verts)
    mesh = vertex_corners(tris, n, "cpu")
    rng = np.random.default_rng(7)
    for share in (1.0, 0.3):
        rows = np.flatnonzero(rng.random(n) < share).astype(np.int32)
        keys = rng.permutation(len(rows)).astype(np.int32)
        one = claimed(mesh, rows, keys, n, "cpu", in_one=True)
        assert np.array_equal(one, claimed(mesh, rows, keys, n, "cpu", in_one=False))
        rings = [np.unique(tris[(tris == u).any(axis=1)]) for u in rows[one]]
        assert len(np.concatenate(rings)) == len(np.unique(np.concatenate(rings)))
        assert one.sum() > len(rows) / 32  # (measured: 325 of 3,458, and 271 of 993)


def test_collapses_leave_no_two_faces_on_the_same_three_vertices():
    # along a thin part of the beetle's band (the bench pair, /256) two collapses left a pair of faces on the same three
    # vertices, turned opposite ways: closed by index, but a part of its own that encloses nothing
    from bench.keep_faces import cases
    from engine.defects import repeated_triangles

    _, beetle, ball, _ = cases()["beetle ∪ ball (open scan)"]
    verts = np.concatenate([beetle[0], ball[0]])
    voxel = float(np.linalg.norm(verts.max(axis=0) - verts.min(axis=0))) / 256
    kept = engine.union(*engine.build_fields([beetle, ball], voxel_size=voxel), seams=True).kept_surface()
    assert not repeated_triangles(kept["tris"], len(kept["verts"])).any()
    assert engine.surface_edges(kept["tris"], len(kept["verts"])) is not None
