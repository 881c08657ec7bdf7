"""A kept surface made coarse and tiled again, its merges held back about faces left crossing on adaptive surfaces.

At an adaptivity, the new faces of a seam's band merge within a tolerance up to 1.5 voxels (:func:`.coarsen.coarsened`);
where the band is tight (a narrow cut, three surfaces meeting), merged faces a few voxels long can pass through each
other and through the faces beside them, at places no tiling and no relaxation mends (:mod:`.uncross`, :mod:`.relax`):
((ball - cylinder) - box at /256 and adaptivity 1: 5-8 pairs of faces 1-4 voxels long). There the surface is made again
with the new vertices within ``HOLD_VOXELS`` of those faces held where they are, so the place keeps the voxel
surface's fine faces, which tile as at adaptivity 0; the wider reach where the nearer one leaves pairs crossing.
"""

from __future__ import annotations

from .coarsen import coarsened
from .uncross import uncrossed
from .zipper import nearest_points

# Voxels about the faces left crossing within which the vertices stay (one reach after the other, while pairs stay).
HOLD_VOXELS = (4.0, 12.0)


def finished(field, surface: dict, adaptivity: float, regions) -> dict:
    """``surface`` (a joined kept surface of ``field``) made coarse where flat (``adaptivity``, ``regions`` as
    :func:`.coarsen.coarsened` takes them) and tiled again where faces pass through each other; on an adaptive surface
    with faces left crossing, made again with the merges about them held back, where fewer pairs are left."""
    out = _made(field, surface, adaptivity, regions, None)
    for reach in HOLD_VOXELS if adaptivity > 0.0 else ():
        if not out["stats"]["crossing_left"]:
            break
        near = nearest_points(out["stats"]["crossing_at"], surface["verts"], reach * field.voxel_size, field.device)
        again = _made(field, surface, adaptivity, regions, near >= 0)
        if again["stats"]["crossing_left"] < out["stats"]["crossing_left"]:
            out = again
    return out


def _made(field, surface: dict, adaptivity: float, regions, held) -> dict:
    """:func:`.coarsen.coarsened` (its ``held`` vertices staying), then :func:`.uncross.uncrossed`."""
    return uncrossed(coarsened(field, surface, adaptivity, regions, held), field.voxel_size, field.device)
