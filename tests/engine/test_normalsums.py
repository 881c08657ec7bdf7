"""Faces' normals summed at their corners in Warp (engine/normalsums.py): numpy's sums exactly (the same order on the
CPU), outward on a closed sphere, zeros where no face is."""

import numpy as np

from engine.normalsums import quad_normal_sums, triangle_normal_sums
from tests.support import uv_sphere


def test_triangle_sums_are_numpys_and_point_outward_on_a_sphere():
    verts, tris = uv_sphere(1.0, rings=24, segments=48)
    points = np.concatenate([np.zeros((5, 3), np.float32), verts.astype(np.float32)])  # 5 points of no face first
    tris = tris.astype(np.int64) + 5
    corners = points[tris]
    normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    expected = np.zeros((len(points), 3))
    for k in range(3):
        np.add.at(expected[:, k], tris.ravel(), np.repeat(normals[:, k].astype(np.float64), 3))
    sums = triangle_normal_sums(points, tris, 5)
    assert sums.dtype == np.float32 and sums.shape == points.shape
    assert np.allclose(sums, expected.astype(np.float32), rtol=1e-6, atol=1e-9)
    assert not sums[:5].any()
    unit = sums[5:] / np.linalg.norm(sums[5:], axis=1, keepdims=True)
    assert np.einsum("ij,ij->i", unit, verts / np.linalg.norm(verts, axis=1, keepdims=True)).min() > 0.99


def test_quad_sums_take_the_diagonals_and_a_repeated_corner_twice():
    points = np.array([[0, 0, 0], [2, 0, 0], [2, 1, 0], [0, 1, 0], [3, 0, 0]], dtype=np.float64)
    corners = np.array([[0, 1, 2, 3], [1, 4, 2, 2]])  # a quad and a triangle given as a quad
    sums = quad_normal_sums(points, corners)
    quad = np.cross(points[2] - points[0], points[3] - points[1])  # (0, 0, 4): twice its area, up
    tri = np.cross(points[2] - points[1], points[2] - points[4])  # (0, 0, 1)
    assert np.allclose(sums[0], quad) and np.allclose(sums[3], quad)
    assert np.allclose(sums[1], quad + tri) and np.allclose(sums[4], tri)
    assert np.allclose(sums[2], quad + 2 * tri)
