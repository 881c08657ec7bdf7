"""Holes in the kept faces closed by a strip across themselves (engine/slits.py): a slit always, a wider hole only
where the strip lies on the result's surface all over."""

import numpy as np
import pytest
import warp as wp

from engine.slits import FILL_VOXELS, WIDE_VOXELS, fill_slits
from engine.zipper import border_halves, loop_labels


def _sheet(hole_x, hole_y, size: int = 24):
    """A flat sheet of unit squares (z = 0, two triangles each, counter-clockwise seen from +z) with the squares in
    ``hole_x`` x ``hole_y`` (half-open ranges) left out: its points, triangles and border loops."""
    ij = np.stack(np.meshgrid(np.arange(size + 1), np.arange(size + 1), indexing="ij"), -1).reshape(-1, 2)
    points = np.c_[ij, np.zeros(len(ij))].astype(np.float32)
    at = lambda i, j: i * (size + 1) + j  # noqa: E731
    i, j = (a.ravel() for a in np.meshgrid(np.arange(size), np.arange(size), indexing="ij"))
    out = (i >= hole_x[0]) & (i < hole_x[1]) & (j >= hole_y[0]) & (j < hole_y[1])
    i, j = i[~out], j[~out]
    lower = np.stack([at(i, j), at(i + 1, j), at(i + 1, j + 1)], 1)
    upper = np.stack([at(i, j), at(i + 1, j + 1), at(i, j + 1)], 1)
    tris = np.concatenate([lower, upper])
    halves = border_halves(tris, len(points))
    nxt = np.arange(len(points), dtype=np.int64)
    nxt[halves[:, 0]] = halves[:, 1]
    members = np.unique(halves[:, 0])
    labels = loop_labels(nxt, members)
    return points, tris, halves, (nxt, members, labels)


class _Plane:
    """A field whose zero level is the sheet's plane, raised by ``bump`` (a paraboloid of that height at ``centre``,
    zero ``radius`` away)."""

    def __init__(self, bump=0.0, centre=(0.0, 0.0), radius=1.0):
        self.bump, self.centre, self.radius = bump, np.asarray(centre, dtype=np.float64), radius

    def sample(self, points, method="linear"):
        p = np.asarray(points, dtype=np.float64)
        r2 = ((p[:, :2] - self.centre) ** 2).sum(axis=1) / self.radius**2
        return (p[:, 2] - self.bump * np.maximum(1.0 - r2, 0.0)).astype(np.float32)


def _fill(hole_x, hole_y, field):
    points, tris, halves, loops = _sheet(hole_x, hole_y)
    candidates = np.unique(loops[2][loops[1]])
    fill, filled = fill_slits(points, loops, candidates, tris, halves, 1.0, wp.get_device("cpu"), field)
    return points, tris, fill, filled, loops


def test_a_slit_is_closed_by_a_strip_on_its_own_vertices():
    points, tris, fill, filled, loops = _fill((5, 13), (8, 9), None)  # 8 x 1 squares: diagonals of 1.4 voxels
    assert len(filled) == 1 and len(fill) == 2 * 8  # the hole's 18 vertices, not the sheet's outer border
    hole = loops[1][loops[2][loops[1]] == filled[0]]
    assert np.isin(fill, hole).all()
    both = np.concatenate([tris, fill])
    outer = border_halves(both, len(points))
    assert len(outer) == 4 * 24  # the hole's edges are each used once each way: only the sheet's border is left
    normal = np.cross(points[fill[:, 1]] - points[fill[:, 0]], points[fill[:, 2]] - points[fill[:, 0]])
    assert (normal[:, 2] > 0).all()  # facing the way the sheet does


@pytest.mark.parametrize(("bump", "closed"), [(0.0, True), (0.3, True), (1.0, False)])
def test_a_wider_hole_is_closed_only_where_the_strip_lies_on_the_surface(bump, closed):
    # 6 x 3 squares: the strip's diagonals are longer than FILL_VOXELS and shorter than WIDE_VOXELS
    field = _Plane(bump, centre=(9.0, 9.5), radius=3.0)
    _, _, fill, filled, _ = _fill((6, 12), (8, 11), field)
    assert (len(filled) == 1) == closed, filled
    assert FILL_VOXELS < 3.0 and np.hypot(6, 3) < WIDE_VOXELS


def test_a_hole_wider_than_the_strips_reach_stays_open():
    _, _, fill, filled, _ = _fill((4, 16), (4, 14), _Plane())  # 12 x 10 squares
    assert len(filled) == 0 and len(fill) == 0
