"""A boolean's kept faces along its seams alone: its voxel surface made only there (:mod:`.ondemand`).

A boolean of fields built on demand (or of meshes' fields built whole, closed or open only at holes) made with
``seams=True`` has its finest octets only where the operands' surfaces come near each other; its kept surface
(:func:`.hybrid.kept_surface`) joins the kept faces to the voxel surface there, the operands read as built. An
operand with internal faces (that passes through itself) is read at every sample: it is built whole first, and the
voxel surface made about where its faces may be given up too (its defects, crossings included, and its faces that
read internal: :func:`.ownpart.own_region`). Where the voxel surface ends short of the kept faces (the judge gave up
faces away from the seams), the whole result is made and joined instead.
"""

from __future__ import annotations

import numpy as np

from .earlyjudge import crossing_leaves
from .hybrid import kept_surface
from .ondemand import as_built, built_leaves, crosses_itself, refined
from .ownpart import own_region


def kept_along_seams(field, **options) -> dict:
    """The kept surface (:func:`.hybrid.kept_surface`, ``options`` as there) of a boolean made along its seams: its
    voxel surface there, its operands read as built (:func:`.ondemand.built_leaves`), the whole result's should the
    join fail or an operand built on demand pass through itself; with ``new_sources``: the new faces' rows and their
    ``face_sources``, read where they were made."""
    whole = lambda: _read_as_built(refined(field, view=True))  # noqa: E731
    # an operand with internal faces (it crosses itself, or reads so in a narrow groove) has its own field read at
    # every sample by the judge: built whole (its sides found here are kept with its mesh for the judge), and its
    # faces are given up about where it crosses itself, away from the seams too: the voxel surface is made about
    # there as well (marked so for the next booleans)
    early = getattr(field, "early_judge", None)  # (:mod:`.earlyjudge`: these steps taken beside the boolean)
    crossing = None if early is None else early.crossing()
    if crossing is None:
        crossing = crossing_leaves(field.expression, field.voxel_size, field.device)
    if crossing and not (early is not None and early.about(crossing)):  # (unless the boolean was made so already)
        for leaf in crossing:
            refined(leaf)
            crosses_itself(leaf, own_region(leaf, field.voxel_size), field.voxel_size)
        again = field.refiner.along_seams()  # made again: the voxel surface also about where its faces are given up
        field = again if field.placement is None else again.transformed(field.placement.matrix)
    seams = _read_as_built(as_built(field))
    surface = kept_surface(seams, **options, whole=whole)
    if not surface["stats"]["kept_fallback"] or surface["stats"].get("along_seams"):  # (made of the seams' surface)
        new = np.flatnonzero(~surface["kept"])
        surface["new_sources"] = (new, *seams.face_sources(surface["verts"], surface["tris"][new]))
    return surface


def _read_as_built(view):
    """A view of a boolean (:func:`.ondemand.as_built`) whose operands are read as built, as the kept faces' judge
    reads them."""
    view.expression = built_leaves(view.expression)
    return view
