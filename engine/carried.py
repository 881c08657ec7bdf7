"""Where a join gave a leaf's own faces up, carried to the next boolean over that leaf, so that it joins once.

A join that cannot pair a border loop gives the kept faces there up, and where they were large a second judge keeps
clear of those points (:mod:`.rejoin`): Suzanne's ears, where they pass through its head, the beetle's thin parts
beside its holes. Those places are the leaf's own (its thin parts and crossings, not a seam): the next boolean over
the same leaf (a cutter dragged beside it, the same boolean run again) fails there again, and pays a judge and a join
before its second join finds them again. Here the points a surface's judge kept clear of are remembered with each
leaf they lie on, in its own frame, where they are farther than ``FAR_VOXELS`` from every other leaf's surface (a
point at a seam is the seam's: it moves with the other operand); the next boolean at the same voxel size judges clear
of them from the first, placed where the leaf is. A point that is no longer needed costs a disc of kept faces about
it (new surface a band wide, as at a defect); one that is missing is found by the join as before.

Written by hand: a record per unplaced source mesh, as :mod:`.verdicts` keeps its verdicts.
"""

from __future__ import annotations

import threading
import weakref

import numpy as np

from .expression import leaves
from .keep import BAND_VOXELS
from .otherleaves import leaf_bvh, mesh_leaf
from .sources import distances_to_each

# A point is carried when it lies within this many voxels of its leaf's triangles (a kept face's corner: on them, up
# to float rounding) and farther than FAR_VOXELS from every other leaf's surface.
ON_VOXELS = 0.01
# Beyond the band and an avoided point's disc (about 2 voxels across) with room for a drag's step: a point nearer
# another leaf may be that seam's, which moves with it.
FAR_VOXELS = BAND_VOXELS + 6.0

# unplaced source mesh -> {voxel size: (P, 3) float64 points in the leaf's own frame}
_CARRIED: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()
_LOCK = threading.Lock()


def _mesh_leaves(field) -> list | None:
    """The leaves of ``field``'s expression with their unplaced sources, or None when one is no mesh leaf (its
    distances are not read off a mesh: no point can be told far from it)."""
    expression = getattr(field, "expression", None)
    if expression is None:
        return None
    every = leaves(expression)
    if not all(mesh_leaf(leaf) for leaf in every):
        return None
    return [(leaf, next(iter(leaf.sources.values()))) for leaf in every]


def carried(field) -> np.ndarray:
    """(P, 3) float32 the points remembered with ``field``'s leaves at its voxel size, where the leaves are placed
    now (the field's frame); empty when there are none."""
    found = [np.zeros((0, 3))]
    for leaf, source in _mesh_leaves(field) or []:
        with _LOCK:
            points = _CARRIED.get(source, {}).get(float(field.voxel_size))
        if points is not None and len(points):
            found.append(points if leaf.placement is None else leaf.placement.to_world(points))
    return np.concatenate(found).astype(np.float32)


def remember(field, avoided: np.ndarray) -> None:
    """Keep the points ``avoided`` (P, 3) (the field's frame: those the judge of ``field``'s kept surface kept clear
    of) with the leaf each lies on, where it is farther than ``FAR_VOXELS`` from every other leaf; a leaf with none
    forgets what it had at this voxel size."""
    every = _mesh_leaves(field)
    if every is None:
        return
    voxel = float(field.voxel_size)
    points = np.asarray(avoided, dtype=np.float32).reshape(-1, 3)
    far = FAR_VOXELS * voxel
    near = distances_to_each([leaf_bvh(leaf, field.device) for leaf, _ in every], points, far, field.device)
    for i, (leaf, source) in enumerate(every):
        rows = near[i] <= ON_VOXELS * voxel
        for j in range(len(every)):
            if j != i:
                rows &= near[j] >= far
        own = points[rows].astype(np.float64)
        with _LOCK:
            _CARRIED.setdefault(source, {})[voxel] = own if leaf.placement is None else leaf.placement.to_local(own)


def forget() -> None:
    """Drop every leaf's points (the next boolean of each joins as a first one)."""
    with _LOCK:
        _CARRIED.clear()
