"""Kept pieces turned the way their patch is: a piece turned unlike the pieces it is joined to is turned their way.

The judge (:mod:`.keep`) turns each kept triangle by its own field's side of it, read a band in front of and behind
it where the shell crosses itself: in a part thinner than two bands that reads the far side's field, and a triangle
can come out turned the wrong way. Two neighbours of a consistently oriented mesh that are both on the result's
surface face its outside alike (the outside lies on one side of both across their shared edge). A piece turned
unlike the pieces joined to it through edges the two list in opposite directions lists, once turned, a directed edge
its neighbour lists too, and the join gave up both faces and those about them: on Suzanne and the beetle (shells that
cross themselves) 3 % and 3 % of what should be kept. Here each such patch of kept pieces is turned as most of its
area is.

Written by hand: a sort of the pieces' edge keys and Warp's connected components over the matches.
"""

from __future__ import annotations

import numpy as np

from .components import connected_components
from .meshcheck import any_corner


def patch_flips(verts: np.ndarray, tris: np.ndarray, kept: np.ndarray, flip: np.ndarray, device=None) -> np.ndarray:
    """``flip`` with every kept piece turned as the larger area of its patch is: the kept pieces joined through edges
    that two of them list in opposite directions (neighbours oriented alike).

    The patches are read about the pieces of the fewer turn first (:func:`_about_fewer`): a scan's 808 k kept pieces
    with 34 turned need none of the rest's edges (2.2 s -> 0.04 s). Where that leaves a patch undecided, every kept
    piece's patch is found (:func:`_all_patches`). Both give the same turns.

    Args:
        verts: (V, 3) float32; tris: (T, 3) int64 pieces (a leaf's, in its source's orientation); kept, flip: (T,)
            bool each piece's verdict and whether it is turned over.
    Returns:
        (T,) bool, ``flip`` where pieces are not kept.
    """
    rows = np.flatnonzero(kept)
    if not len(rows) or not flip[rows].any() or flip[rows].all():
        return flip
    t, turned = np.asarray(tris[rows], dtype=np.int64), flip[rows]
    decided = _about_fewer(verts, t, turned, device)
    out = flip.copy()
    out[rows] = decided if decided is not None else _all_patches(verts, t, turned, device)
    return out


# Vertex rings of pieces about the pieces of the fewer turn in which their patches are read first.
RINGS = 3


def _about_fewer(verts: np.ndarray, t: np.ndarray, turned: np.ndarray, device) -> np.ndarray | None:
    """Each piece's turn (``t`` (K, 3) pieces, ``turned`` (K,)) from the patches within RINGS vertex rings of the
    pieces of the fewer turn, or None where one is undecided there:

    - a patch found whole (none of its pieces in the last ring: the edges of the others lead to pieces found) turns as
      its larger area does, summed in the same order as :func:`_all_patches` sums it;
    - a patch that goes on beyond takes the other turn where its pieces of that turn found outweigh all the pieces of
      the fewer turn (so do its pieces of that turn everywhere: its whole patch has at most that much of the fewer);
    - pieces farther out and the rest of their patches have the other turn already.

    (The patches found join no two pieces that all the pieces' patches would not: an edge's pieces listing it both
    ways are joined either way.)"""
    fewer = turned if 2 * int(np.count_nonzero(turned)) <= len(turned) else ~turned
    near, last = fewer.copy(), fewer.copy()
    for _ in range(RINGS):
        on = np.zeros(len(verts), dtype=bool)
        on[t[near]] = True
        grown = any_corner(on, t)
        last, near = grown & ~near, grown
    rows = np.flatnonzero(near)
    area, patch, n = _areas(verts, t[rows]), _patches(t[rows], len(verts), device), len(rows)
    sums = lambda mask: np.bincount(patch, weights=area * mask, minlength=n)  # noqa: E731
    held = np.bincount(patch, weights=fewer[rows], minlength=n) > 0  # the patches with a piece of the fewer turn
    beyond = np.bincount(patch, weights=last[rows], minlength=n) > 0
    outweighs = sums(~fewer[rows]) > float(_areas(verts, t[fewer]).sum())
    if (held & beyond & ~outweighs).any():
        return None
    other = not bool(turned[np.argmax(fewer)])
    turn = np.where(beyond, other, 2.0 * sums(turned[rows]) > sums(np.ones(n, dtype=bool)))
    out = turned.copy()
    out[rows] = np.where(held[patch], turn[patch], turned[rows])
    return out


def _all_patches(verts: np.ndarray, t: np.ndarray, turned: np.ndarray, device) -> np.ndarray:
    """Each piece's turn from every kept piece's patch: as the larger area of its patch."""
    patch = _patches(t, len(verts), device)
    area = _areas(verts, t)
    turned_area = np.bincount(patch, weights=area * turned, minlength=len(t))
    total = np.bincount(patch, weights=area, minlength=len(t))
    return (2.0 * turned_area > total)[patch]


def _patches(t: np.ndarray, n: int, device) -> np.ndarray:
    """(K,) each piece's patch (the smallest piece of it): pieces joined where one lists an edge the first piece
    listing it the other way lists (a sort of the pieces' edge keys, Warp's connected components over the matches)."""
    a, b = t.ravel(), t[:, [1, 2, 0]].ravel()
    keys, reverses = a * n + b, b * n + a
    order = np.argsort(keys, kind="stable")
    at = np.minimum(np.searchsorted(keys[order], reverses), len(keys) - 1)
    hit = keys[order][at] == reverses
    return connected_components(len(t), np.flatnonzero(hit) // 3, order[at[hit]] // 3, device)


def _areas(verts: np.ndarray, t: np.ndarray) -> np.ndarray:
    """(K,) float64 the pieces' doubled areas."""
    c = verts[t].astype(np.float64)
    return np.linalg.norm(np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0]), axis=1)
