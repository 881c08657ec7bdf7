"""A sliver's pieces as the strip between its long edges (engine/slivers.py): splitting a cylinder's wall round after
round near a plane across it keeps the pieces a closed, consistently oriented surface over the same area, puts every
point on the wall triangles' own edges (none inside), and never puts more than a strip's pieces side by side."""

import numpy as np

import engine
from engine.slivers import Splitter, strip_parents
from tests.support import cylinder_mesh

UNKNOWN, DROPPED = 0, 2


def _area(verts, tris) -> np.ndarray:
    p = verts[tris].astype(np.float64)
    return 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)


def test_slivers_are_thin_long_triangles_among_slivers_with_their_apex_opposite_the_shortest_edge():
    verts = np.array([[0, 0, 0], [10, 0, 0], [10, 1, 0], [0, 10, 0], [20, 0, 0], [20, 1, 0]], dtype=np.float32)
    alone = np.array([[0, 1, 2], [0, 4, 3]])  # 1 wide and 10 long; a right triangle 20 by 10, no edge shared
    strip, apex = strip_parents(verts, alone, split_edge=1.5)
    assert strip.tolist() == [True, False]
    assert apex[0] == 0  # the shortest edge runs from corner 1 to corner 2
    beside_a_fat_one = np.array([[0, 1, 2], [0, 3, 1]])  # the sliver's long edge 0-1 shared with a fat triangle
    assert strip_parents(verts, beside_a_fat_one, split_edge=1.5)[0].tolist() == [False, False]
    side_by_side = np.array([[0, 1, 2], [0, 2, 5]])  # two slivers sharing their long edge 0-2
    assert strip_parents(verts, side_by_side, split_edge=1.5)[0].tolist() == [True, True]


def test_splitting_a_wall_near_a_plane_keeps_a_closed_surface_of_strips():
    verts, tris = cylinder_mesh(1.0, 2.0, segments=64)
    verts = verts.astype(np.float32)
    tris = np.asarray(tris, dtype=np.int64)
    split_edge = 0.15  # wall triangles 0.098 wide and 2 long: slivers
    splitter = Splitter(verts, tris, split_edge)
    assert splitter.strip.sum() >= 128  # the wall's 128 triangles (the caps' fans too)
    parent = np.arange(len(tris))
    flip = np.zeros(len(tris), dtype=bool)
    status = np.full(len(tris), UNKNOWN, dtype=np.int8)
    ends = np.full((len(verts), 2), -1, dtype=np.int64)
    area = _area(verts, tris).sum()
    for _ in range(8):
        # pieces within 0.3 of the plane z = 0.37 are split, the rest left as they are
        z = verts[tris][:, :, 2]
        mark = (status == UNKNOWN) & (z.min(axis=1) < 0.67) & (z.max(axis=1) > 0.07)
        if not mark.any():
            break
        verts, tris, parent, flip, status, ends = splitter.split(
            verts, tris, mark, parent, flip, status, ends, UNKNOWN, DROPPED
        )
        assert engine.surface_edges(tris, len(verts)) is not None  # closed and consistently oriented
        assert np.isclose(_area(verts, tris).sum(), area, rtol=1e-5)
        normals = np.cross(verts[tris[:, 1]] - verts[tris[:, 0]], verts[tris[:, 2]] - verts[tris[:, 0]])
        source = verts[np.asarray(cylinder_mesh(1.0, 2.0, segments=64)[1])[parent]]
        own = np.cross(source[:, 1] - source[:, 0], source[:, 2] - source[:, 0])
        assert ((normals * own).sum(axis=1) > 0).all()  # every piece faces as its source triangle
    wall = splitter.strip[parent] & (np.abs(verts[tris][:, :, 2]).max(axis=1) < 0.99)
    assert (splitter.on[tris[wall]] >= 0).all()  # the wall's points all lie on its triangles' edges
    cut = wall & (np.ptp(verts[tris][:, :, 2], axis=1) < 0.3)
    assert cut.sum() > 200  # the wall near the plane is cut into short pieces
    # a line across a wall triangle at the plane crosses at most three of its pieces (a strip; bisection's needles
    # put sixteen side by side)
    z = verts[tris][:, :, 2]
    across = wall & (z.min(axis=1) < 0.37) & (z.max(axis=1) > 0.37)
    assert np.bincount(parent[across]).max() <= 3, np.bincount(parent[across]).max()  # measured 2
