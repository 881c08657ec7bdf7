"""Where a mesh passes through itself (engine/selfcross.py): the segments along which its triangles cross lie on both
crossing surfaces and join into the crossing curves; touching and neighbouring triangles do not cross; short curves
can be left out."""

import numpy as np

from engine import selfcross
from engine.selfcross import crossing_pairs, crossing_segments
from tests.metrics import self_intersections, unsigned_distance
from tests.support import box_mesh, rotation, uv_sphere


def test_two_crossing_triangles_cross_along_their_common_segment():
    verts = np.array([[0, 0, 0], [4, 0, 0], [0, 4, 0], [1, 1, -1], [1, 1, 1], [3, 1, 1]], dtype=np.float32)
    tris = np.array([[0, 1, 2], [3, 4, 5]])  # the second stands across the first's plane along x from 1 to 2
    segments = crossing_segments(verts, tris, "cpu")
    assert segments.shape == (1, 2, 3)
    ends = segments[0][np.argsort(segments[0][:, 0])]
    np.testing.assert_allclose(ends, [[1, 1, 0], [2, 1, 0]], atol=1e-6)
    touching = np.array([[0, 0, 0], [4, 0, 0], [0, 4, 0], [1, 1, 0], [1, 1, 2], [3, 1, 2]], dtype=np.float32)
    assert len(crossing_segments(touching, tris, "cpu")) == 0  # meeting the plane at a corner is no crossing


def test_two_overlapping_boxes_cross_along_closed_curves_on_both_surfaces():
    a = box_mesh(subdivisions=3)
    b = box_mesh(center=(1.0, 0.5, 0.25), subdivisions=3)
    verts = np.concatenate([a[0], b[0]]).astype(np.float32)
    tris = np.concatenate([a[1], b[1] + len(a[0])])
    segments = crossing_segments(verts, tris, "cpu")
    ends = segments.reshape(-1, 3)
    assert len(segments) > 10
    assert unsigned_distance(*a, ends).max() < 1e-5 and unsigned_distance(*b, ends).max() < 1e-5
    # the surfaces meet along the edges of the common box [0, 1] x [-0.5, 1] x [-0.75, 1] between one of a's faces
    # and one of b's: two of its edges along x (1 long), two along y (1.5) and two along z (1.75), 8.5 in all
    length = np.linalg.norm(segments[:, 1].astype(np.float64) - segments[:, 0], axis=1).sum()
    assert abs(length - 8.5) < 1e-5, length
    assert len(crossing_segments(verts, tris, "cpu", shortest=100.0)) == 0  # no curve that long
    # alone, a box and a ball pass through nothing
    assert len(crossing_segments(a[0].astype(np.float32), a[1], "cpu")) == 0
    ball = uv_sphere(1.0, rings=24, segments=48)
    assert len(crossing_segments(ball[0].astype(np.float32), ball[1], "cpu")) == 0


def test_crossing_pairs_are_each_found_once_however_many_there_are(monkeypatch):
    # two finely divided boxes through each other, one turned (no edge along another's face)
    a = box_mesh(subdivisions=24)
    b = box_mesh(center=(0.31, 0.17, 0.23), subdivisions=24)
    b = ((b[0] - (0.31, 0.17, 0.23)) @ rotation(0, 13.0).T @ rotation(2, 7.0).T + (0.31, 0.17, 0.23), b[1])
    verts = np.concatenate([a[0], b[0]]).astype(np.float32)
    tris = np.concatenate([a[1], b[1] + len(a[0])])
    pairs = crossing_pairs(verts, tris, "cpu")
    assert len(pairs) > 256 and len(pairs) == self_intersections(verts, tris)
    assert len(np.unique(np.sort(pairs, axis=1), axis=0)) == len(pairs)  # no pair twice
    assert (np.isin(pairs[:, 0], np.arange(len(a[1]))) != np.isin(pairs[:, 1], np.arange(len(a[1])))).all()
    # with rows, only the pairs with one of those faces: here a's faces
    of_a = crossing_pairs(verts, tris, "cpu", np.arange(len(a[1])))
    assert {tuple(sorted(p)) for p in of_a.tolist()} == {tuple(sorted(p)) for p in pairs.tolist()}
    # a triangle crossing more than its slots hold is searched again, with room for all
    monkeypatch.setattr(selfcross, "PAIRS_ROOM", 1)
    assert np.array_equal(crossing_pairs(verts, tris, "cpu"), pairs)


def test_crossings_looked_for_near_the_internal_triangles_are_those_of_the_whole_mesh():
    """Two finely cut boxes given as one mesh (a mesh passing through itself): its triangles inside the other box read
    internal. The crossings looked for near those alone are the whole mesh's, and the search reads a part of it."""
    from engine.defects import CROSSING_VOXELS, near_internal, own_defects
    from engine.trimeasures import triangle_measures

    a = box_mesh(subdivisions=12)
    b = box_mesh(half=(0.5, 0.5, 0.5), center=(1.2, 0.4, 0.3), subdivisions=6)
    verts = np.concatenate([a[0], b[0]]).astype(np.float32)
    tris = np.concatenate([a[1], b[1] + len(a[0])]).astype(np.int64)
    centres = verts[tris].mean(axis=1)
    inside_b = np.all(np.abs(centres - (1.2, 0.4, 0.3)) < 0.5 - 1e-6, axis=1)
    inside_a = np.all(np.abs(centres) < 1.0 - 1e-6, axis=1)
    internal = np.r_[inside_b[: len(a[1])], inside_a[len(a[1]) :]]
    assert 0 < internal.sum() < 0.2 * len(tris)
    voxel = 0.02
    near = near_internal(verts, tris, triangle_measures(verts, tris), internal, CROSSING_VOXELS * voxel, "cpu")
    assert near[internal].all() and near.sum() < 0.5 * len(tris)  # measured: 688 of 2,160 (240 internal)
    found, whole = (own_defects(verts, tris, CROSSING_VOXELS * voxel, "cpu", rows) for rows in (near, None))

    def segments(defects):
        points, parts = defects[1], defects[2]
        return np.sort(np.sort(points[parts].reshape(len(parts), -1).round(6), axis=0), axis=0)

    assert len(whole[2]) > 48 and np.array_equal(segments(found), segments(whole))  # measured 96 segments
