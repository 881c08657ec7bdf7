"""An open mesh's inside can reach past its bounding box across its holes (``engine/build.py`` grows its domain).

Two open tubes side by side, overlapping (Blender's Array modifier on a cylinder without caps, its copies half a
width apart): past their ends each one's winding number adds the other's, and the inside bulges out of their
bounding box. Outside the domain counts as outside: the inside reached the domain's edge at /96-/160 and the surface
was cut there, open at /160 with every offset of it (the scene's tubes, 1.7 long, at voxel 0.0156: 166 open
vertices)."""

import numpy as np
import pytest

import engine
from engine.build import inside_at_edges
from tests.metrics import mesh_volume, winding_inside
from tests.support import cylinder_mesh, is_watertight

SEGMENTS = 46


def _open_tubes(shift: float = 0.31):
    """Two tubes (radius 0.3, length 1.7, no caps) along z, the second ``shift`` along x."""
    verts, tris = cylinder_mesh(0.3, 1.7, segments=SEGMENTS)
    verts, tris = verts[: 2 * SEGMENTS], tris[: 2 * SEGMENTS]  # the sides alone
    other = verts + np.array([shift, 0.0, 0.0], dtype=np.float32)
    return np.concatenate([verts, other]), np.concatenate([tris, tris + len(verts)])


@pytest.mark.parametrize("resolution", [128, 160])
def test_open_tubes_overlapping_give_a_closed_surface_past_their_ends(resolution):
    verts, tris = _open_tubes()
    h = float(np.linalg.norm(verts.max(axis=0) - verts.min(axis=0))) / resolution
    (field,) = engine.build_fields([(verts, tris)], voxel_size=h)
    assert not inside_at_edges(field).any()
    out_verts, out_tris = field.to_mesh()
    assert is_watertight(out_tris)
    # the inside bulges past the tubes' ends (where the domain cut it), and the surface holds what the winding
    # number puts inside: a Monte Carlo volume of {w >= 1/2} over a box grown past the bulge
    assert out_verts[:, 2].max() > verts[:, 2].max() + 2 * h and out_verts[:, 2].min() < verts[:, 2].min() - 2 * h
    lo, hi = verts.min(axis=0) - 0.3, verts.max(axis=0) + 0.3
    points = np.random.default_rng(0).uniform(lo, hi, (200_000, 3)).astype(np.float32)
    inside = np.count_nonzero(winding_inside(verts, tris, points, accuracy=4.0)) / len(points) * np.prod(hi - lo)
    assert mesh_volume(out_verts, out_tris) == pytest.approx(inside, rel=0.01)


@pytest.mark.parametrize(("resolution", "distance"), [(160, 0.1), (128, 0.05)])
def test_offsets_of_the_tubes_are_closed(resolution, distance):
    # at /160 the cut surface and every offset of it were open; at /128 the offset by 0.05 was (3 octets of the new
    # surface outside the band found top-down, fieldops.BAND_ROUNDS), where the tubes were closed
    verts, tris = _open_tubes()
    h = float(np.linalg.norm(verts.max(axis=0) - verts.min(axis=0))) / resolution
    (field,) = engine.build_fields([(verts, tris)], voxel_size=h)
    assert is_watertight(engine.offset(field, distance).to_mesh()[1])
