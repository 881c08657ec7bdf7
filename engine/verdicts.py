"""A leaf's first verdicts kept from one boolean to the next, so that moving an operand re-judges only near the seams.

The first round of :func:`.keep.kept_triangles` judges every triangle of a leaf whole: a scan's 70 k triangles, most
of them far from any other operand. When the next boolean has the same expression over the same fields and only
placements changed (an operand dragged, turned, or the leaf itself placed elsewhere), a triangle's verdict cannot
change where every other leaf's surface stays farther than the move from it. The bound is Lipschitz's: the other
leaf's surface, seen from this leaf's frame, moved by at most ``shift`` (the largest displacement of its box's corners
under the change of relative placement, in world units), so its distance to every point of the triangle changed by
at most ``shift`` and its sign not at all where the distance was larger. A triangle kept whole stays kept while its
least distance less the shifts is above the band and its slack; a triangle dropped whole stays dropped when the
expression did not cross anywhere on it (buried in another operand: signs only) or its own mesh ruled it out (a
defect). Partly kept triangles, and any triangle the bound cannot settle, are judged again from scratch.

Only leaves whose distances are exact where they are read can move (meshes, read through their BVH): a moved field
read through its interpolant alone (an offset) gives no bound, and nothing is reused. An open or messy mesh's sign
may also jump away from its triangles, about its defect edges (:mod:`.jumps`): a triangle's margin beside one is at
most its gap to those spheres (:func:`.jumps.clear_of`). The distances are kept to ``REUSE_VOXELS`` beyond the band
so that moves of a few voxels (a drag's steps) still find them. Points a judge keeps clear of as of a defect of the
leaf's own (where a join gave faces up: :mod:`.carried`, :mod:`.rejoin`) count in its margins: a record holds where
the points near the leaf are the same, each in the frame of the leaf it lies on (one that moved with its leaf is
bounded by that leaf's shift).

Written by hand: a record per leaf of three arrays over its triangles and the placements they were found at.
"""

from __future__ import annotations

import threading
import weakref
from dataclasses import dataclass

import numpy as np

from .expression import Operation, leaves
from .ondemand import Refiner
from .rounds import DROPPED, KEPT, UNKNOWN  # (a piece's status, as the judge's rounds set it)
from .sources import distances_to_each, mesh_distances

# Distances are found up to this many voxels beyond the band in a first round, so that a verdict survives moves of
# this much less what it used (a drag's steps are a few voxels at the working resolution).
REUSE_VOXELS = 8.0
# Avoided points this many voxels apart or less are the same (one point placed, then brought back to its leaf).
SAME_VOXELS = 1e-3


@dataclass
class Record:
    """What a leaf's first round found, and where everything was: ``key`` (:func:`_setting`), ``fields`` weak
    references to the leaves' identities (:func:`_lineage`: one that cannot pass to a field built later), ``frames`` the
    leaves' placements (4, 4), per source triangle ``status`` (KEPT, DROPPED, or UNKNOWN: split or not to be reused),
    ``flip`` and ``margin`` (the least distance of another leaf's surface over the triangle, a lower bound), and
    ``avoided`` the points its judge kept clear of near the leaf, each in the frame of the leaf it lies on
    (:func:`avoided_near`)."""

    key: tuple
    fields: list
    frames: list
    status: np.ndarray
    flip: np.ndarray
    margin: np.ndarray
    avoided: np.ndarray


# unplaced source mesh -> {leaf index: Record}; entries go with their sources (a field dropped from the cache)
_RECORDS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()
_LOCK = threading.Lock()


def _lineage(leaf):
    """A leaf's identity: its values array, or where it was built on demand its refiner (:mod:`.ondemand`: a field
    refined further has the same nodes where both are built, and the judge reads it as built: a verdict whose other
    surfaces are farther than the band reads the same signs off either)."""
    refiner = leaf.refiner or leaf.built_by
    return refiner if isinstance(refiner, Refiner) else leaf.values


def _structure(expression):
    """The tree's operations with its leaves as their identities (the same fields, placed anywhere)."""
    if isinstance(expression, Operation):
        return (expression.op, expression.blend, _structure(expression.a), _structure(expression.b))
    return id(_lineage(expression))


def _setting(expression, index: int, voxel: float, band: float) -> tuple:
    return (_structure(expression), index, float(voxel), float(band))


_IDENTITY = np.eye(4)
_IDENTITY.flags.writeable = False


def _frame(leaf) -> np.ndarray:
    return _IDENTITY if leaf.placement is None else leaf.placement.matrix


def _corners(leaf) -> np.ndarray:
    """(8, 4) homogeneous corners of a box around the leaf's surface in its own frame."""
    sources = list(leaf.sources.values())
    if len(sources) == 1 and len(sources[0].verts):
        lo, hi = sources[0].verts.min(axis=0), sources[0].verts.max(axis=0)
    else:
        lo, hi = leaf.frame_bounds
    pick = np.array([[(k >> a) & 1 for a in range(3)] for k in range(8)], dtype=bool)
    return np.c_[np.where(pick, hi, lo), np.ones(8)]


def _shift(own_then, own_now, then, now, corners) -> float:
    """World units the other leaf's surface moved as seen from this leaf (both placements changed to ``*_now``)."""
    seen_then = corners @ (np.linalg.inv(own_then) @ then).T
    seen_now = corners @ (np.linalg.inv(own_now) @ now).T
    scale = float(np.cbrt(abs(np.linalg.det(own_now[:3, :3]))))
    return scale * float(np.linalg.norm((seen_now - seen_then)[:, :3], axis=1).max())


def _shifts(record: Record, every: list, index: int, exact: list) -> float | None:
    """The largest move of another leaf seen from leaf ``index`` since the record, None when one that moved is not
    read exactly or this leaf's scale changed."""
    own_then, own_now = record.frames[index], _frame(every[index])
    if not np.isclose(abs(np.linalg.det(own_then[:3, :3])), abs(np.linalg.det(own_now[:3, :3])), rtol=1e-9):
        return None
    largest = 0.0
    for j, leaf in enumerate(every):
        if j == index:
            continue
        moved = _shift(own_then, own_now, record.frames[j], _frame(leaf), _corners(leaf))
        if moved > 0.0 and not exact[j]:
            return None
        largest = max(largest, moved)
    return largest


def avoided_near(every: list, bvhs: list, index: int, avoid, reach: float, device) -> np.ndarray:
    """(P, 4) the points of ``avoid`` (the boolean's frame; None: none) within ``reach`` of leaf ``index``'s triangles,
    each as the leaf it lies nearest to (among ``every`` leaf with a BVH in ``bvhs``, where they are placed) and its
    place in that leaf's own frame, sorted: what a record's verdicts were judged clear of. An avoided point counts
    as a defect in the margins; one that moved with its leaf moved as that leaf's surface did (within the shift)."""
    if avoid is None or not len(avoid):
        return np.zeros((0, 4))
    points = np.asarray(avoid, dtype=np.float32)
    points = points[mesh_distances(bvhs[index], points, reach, device) < reach]
    owner = np.argmin(distances_to_each(bvhs, points, reach, device), axis=0)
    out = np.zeros((len(points), 4))
    out[:, 0] = owner
    for j in np.unique(owner):
        rows, placement = owner == j, every[j].placement
        own = points[rows].astype(np.float64)
        out[rows, 1:] = own if placement is None else placement.to_local(own)
    return out[np.lexsort(out.T[::-1])]


def _same_points(a: np.ndarray, b: np.ndarray, tolerance: float) -> bool:
    """Whether two sorted point sets are the same within ``tolerance`` (float rounding of their placement)."""
    return a.shape == b.shape and (not len(a) or float(np.abs(a - b).max()) <= tolerance)


def _record_of(source, expression, index: int, voxel: float, band: float) -> Record | None:
    """Leaf ``index``'s record (or mark) where it was made in the same setting over the same fields, else None."""
    with _LOCK:
        record = _RECORDS.get(source, {}).get(index)
    every = leaves(expression)
    if (
        record is None
        or record.key != _setting(expression, index, voxel, band)
        or any(ref() is not _lineage(leaf) for ref, leaf in zip(record.fields, every, strict=True))
    ):
        return None
    return record


def reused(
    source, expression, index: int, voxel: float, band: float, slack: np.ndarray, exact: list, avoided: np.ndarray
):
    """Verdicts of leaf ``index``'s source triangles that hold as the last boolean over the same fields found them.

    Args:
        source: The leaf's unplaced source mesh (the record's key).
        expression: The boolean's expression; ``index`` the leaf's place among its leaves.
        voxel, band: The result's voxel size and the judge's band.
        slack: (T,) each triangle's slack in its first round.
        exact: Per leaf, whether its distances are read exactly (a BVH; where its sign may jump, its jump spheres
            bound the margins).
        avoided: The points the judge keeps clear of near the leaf (:func:`avoided_near`): the record's must be the
            same.
    Returns:
        ``(status, flip, margin)``: (T,) int8 KEPT or DROPPED where reused, UNKNOWN elsewhere; (T,) bool; (T,) float32
        the lower bound of the other leaves' distance now (for the next record), or None when nothing is reusable.
    """
    record = _record_of(source, expression, index, voxel, band)
    every = leaves(expression)
    if (
        record is None
        or len(record.status) != len(slack)
        or not _same_points(record.avoided, avoided, SAME_VOXELS * voxel)
    ):
        return None
    shift = _shifts(record, every, index, exact)
    if shift is None:
        return None
    margin = record.margin - np.float32(shift)
    holds_kept = (record.status == KEPT) & (margin > band + slack)
    holds_dropped = (record.status == DROPPED) & (margin > 0.0)
    status = np.where(holds_kept, KEPT, np.where(holds_dropped, DROPPED, UNKNOWN)).astype(np.int8)
    return status, record.flip, margin


def remember(source, expression, index: int, voxel: float, band: float, status, flip, margin, avoided) -> None:
    """Keep a leaf's first-round verdicts (``status`` UNKNOWN where split or not to be reused) with its source, and
    the points ``avoided`` near it (:func:`avoided_near`)."""
    every = leaves(expression)
    record = Record(
        _setting(expression, index, voxel, band),
        [weakref.ref(_lineage(leaf)) for leaf in every],
        [_frame(leaf) for leaf in every],
        np.asarray(status, dtype=np.int8),
        np.asarray(flip, dtype=bool),
        np.asarray(margin, dtype=np.float32),
        np.asarray(avoided, dtype=np.float64).reshape(-1, 4),
    )
    with _LOCK:
        _RECORDS.setdefault(source, {})[index] = record


def worth_recording(source, expression, index: int, voxel: float, band: float) -> bool:
    """Whether leaf ``index``'s judge should record its first verdicts for the next boolean (:func:`remember`): the
    same fields were judged before (a record, or the mark of :func:`mark_judged`) and either verdicts were kept (a
    drag goes on) or the leaves were placed elsewhere then (a drag begins). A first boolean over them leaves a mark
    alone: reading every sample as far as a record needs costs up to twice its first round (the bunny's 69 k
    triangles beside spot: 69 against 37 ms), which only moves get back."""
    record = _record_of(source, expression, index, voxel, band)
    if record is None:
        return False
    if len(record.status):
        return True
    every = leaves(expression)
    return any(not np.array_equal(then, _frame(leaf)) for then, leaf in zip(record.frames, every, strict=True))


def mark_judged(source, expression, index: int, voxel: float, band: float) -> None:
    """Mark leaf ``index`` judged over these fields at their placements, no verdict kept (:func:`worth_recording`)."""
    nothing = np.zeros(0)
    remember(source, expression, index, voxel, band, nothing, nothing, nothing, np.zeros((0, 4)))


def forget() -> None:
    """Drop every record (the next boolean of each leaf judges all its triangles)."""
    with _LOCK:
        _RECORDS.clear()
