"""The judge's split rounds: a leaf's partly keepable pieces split and judged again until they are small.

Each round splits the pieces still to be decided (:meth:`.slivers.Splitter.split`: longest-edge bisection, strips
cut along their long edges) and judges the new ones (:func:`judge_unknown`). A split reaches only the pieces that
share an edge with a split one, so a piece that shares no corner with any piece still to be decided is never touched
again: each round sets those aside, and the next one reads only the pieces about the seams (with every piece of a
strip parent that has one there: its pieces are zipped together). A scan's or a CAD part's tens of thousands of
triangles, all but a few hundred decided in the first round, no longer pass through each round's array passes (the
fandisk's 12,946: 11,936 set aside after its first round; its judge on a move 65 -> 60 ms, the rocker arm's 44 -> 38).
"""

from __future__ import annotations

import numpy as np

from .meshcheck import any_corner
from .samples import edge_turns

UNKNOWN, KEPT, DROPPED = 0, 1, 2
# Pieces are looked for to set aside where those still to be split are fewer than 1 in this many (where more are,
# nearly every piece touches one: the plate's bores, whose pieces all lie near its faces, paid 0.2 ms a round for none).
ASIDE_SHARE = 4


def judge_unknown(judge, verts, tris, parent, flip, status, split_edge: float) -> bool:
    """Judge the pieces of status UNKNOWN (``judge``: keep's ``_Judge``): each becomes KEPT, DROPPED, or stays
    UNKNOWN (partly keepable and larger than ``split_edge``: to be split); ``status`` and ``flip`` set in place.
    Returns whether there were any."""
    todo = np.flatnonzero(status == UNKNOWN)
    if not len(todo):
        return False
    longest, turn = edge_turns(verts, tris[todo])
    kept, partly, flip[todo] = judge.judge(verts, tris[todo], parent[todo], longest, turn)
    split = partly & ~kept & (longest > split_edge)
    status[todo] = np.where(kept, KEPT, np.where(split, UNKNOWN, DROPPED))
    return True


def split_rounds(judge, splitter, pieces: tuple, split_edge: float, rounds: int) -> tuple:
    """Up to ``rounds`` rounds of splitting the UNKNOWN ``pieces`` (``verts, tris, parent, flip, status, ends``:
    keep's arrays of a leaf, ``ends`` per vertex) and judging their pieces, until none is left to split.

    Returns the pieces after them (the same tuple; the pieces set aside first, in the order they were), with any still
    UNKNOWN after the last round as they are."""
    verts, tris, parent, flip, status, ends = pieces
    aside = []
    for _ in range(rounds):
        mark = status == UNKNOWN
        if not mark.any():
            break
        live = _live(tris, parent, mark, len(verts), splitter.strip) if ASIDE_SHARE * mark.sum() < len(tris) else None
        if live is not None and not live.all():
            aside.append(tuple(a[~live] for a in (tris, parent, flip, status)))
            tris, parent, flip, status, mark = tris[live], parent[live], flip[live], status[live], mark[live]
        verts, tris, parent, flip, status, ends = splitter.split(
            verts, tris, mark, parent, flip, status, ends, UNKNOWN, DROPPED
        )
        if not judge_unknown(judge, verts, tris, parent, flip, status, split_edge):
            break
    if aside:
        live = (tris, parent, flip, status)
        tris, parent, flip, status = (np.concatenate([a[k] for a in aside] + [live[k]]) for k in range(4))
    return verts, tris, parent, flip, status, ends


def _live(tris, parent, mark, n_verts: int, strip) -> np.ndarray:
    """(T,) bool the pieces a split of the ``mark``ed ones can reach: those with a corner on one, and every piece of a
    strip parent (``strip``: per source triangle) one of whose pieces is such."""
    touched = np.zeros(n_verts, dtype=bool)
    touched[tris[mark]] = True
    live = any_corner(touched, tris)
    strips = strip[parent]
    if strips.any():
        held = np.zeros(len(strip), dtype=bool)
        held[parent[live & strips]] = True
        live |= held[parent]
    return live
