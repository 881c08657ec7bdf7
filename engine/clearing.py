"""Faces left passing through others after the join and the tiling: the operands' triangles judged again clear of
them, round after round while any are left.

The tiling (:mod:`.uncross`) mends a place where new faces pass through others by making its new faces again; it gives
up only kept faces smaller than :data:`.uncross.SMALL_AREA_VOXELS`. Where a larger kept face is in the way (a messy
mesh's face beside another operand's thin part, or beside its own crossing), the place stays. There the operands'
triangles are judged again clear of the faces left crossing (:func:`.keep.kept_triangles`' ``avoid``, as :mod:`.rejoin`
judges clear of where a join gave faces up): the face in the way is split, its part there made new surface, which
tiles. The new band can leave places of its own beside those it mended; they are judged clear of too, in the next
round, up to ``CLEAR_ROUNDS`` (cow ∪ a turned teapot at /384: 193 pairs after the join,
128 after the tiling, 87 after one round, none after two; the kept surface 1.9-2.1 -> 2.4-2.7 s for the second
round's judge, join and tiling).
"""

from __future__ import annotations

import numpy as np

from .carried import carried
from .keep import kept_triangles

# Rounds of judging clear of the faces left crossing (each a judge, a join and a tiling).
CLEAR_ROUNDS = 3


def cleared(field, joined, surface: dict, finish, crossed) -> dict:
    """``surface`` (a kept surface of ``field``, tiled, with faces left crossing: ``stats["crossing_at"]``), or the
    surface ``finish(joined(judged, avoid))`` makes of the triangles judged clear of those faces and of the points
    carried (:mod:`.carried`), round after round clear of the faces each leaves too, up to ``CLEAR_ROUNDS``, none
    left, or a round that leaves only places judged clear of already (the next would be the same): the one that leaves
    the fewest pairs crossing (or, with more, no longer ``crossed`` where the best before was). A round may leave more
    than the one before, at places of its new band, which the next clears (cow ∪ a large box turned about it at /384:
    88 pairs at the cow's head, where it passes through itself; 96 after a round, none after two). A round whose join
    falls back ends the rounds, its reason in the surface's ``stats["clearing_ended"]``."""
    best = surface
    avoid = np.concatenate([carried(field), surface["stats"]["crossing_at"]])
    for _ in range(CLEAR_ROUNDS):
        again = joined(kept_triangles(field, avoid=avoid), avoid)
        if again["stats"]["kept_fallback"]:  # (the surface kept says why: ``clearing_ended``)
            best["stats"]["clearing_ended"] = again["stats"]["kept_fallback"]
            break
        again = finish(again)
        left, found = again["stats"]["crossing_left"], again["stats"]["crossing_at"]
        if left < best["stats"]["crossing_left"] or crossed(best) and not crossed(again):
            best = again
        if not left or _among(found, avoid):  # none left, or the next round would judge as this one did
            break
        avoid = np.concatenate([avoid, found])
    return best


def _among(points: np.ndarray, others: np.ndarray) -> bool:
    """Whether each of ``points`` (P, 3) is one of ``others`` (Q, 3), to the bit (spot minus a placed beetle at /128:
    the same 7 places left crossing round after round)."""
    rows = lambda a: np.ascontiguousarray(a, dtype=np.float32).view(np.dtype((np.void, 12))).ravel()  # noqa: E731
    return bool(np.isin(rows(points), rows(others)).all())
