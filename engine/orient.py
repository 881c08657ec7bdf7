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


def patch_flips(verts: np.ndarray, tris: np.ndarray, kept: np.ndarray, flip: np.ndarray, device=None) -> np.ndarray:
    """``flip`` with every kept piece turned as the larger area of its patch is: the kept pieces joined through edges
    that two of them list in opposite directions (neighbours oriented alike).

    Args:
        verts: (V, 3) float32; tris: (T, 3) int64 pieces (a leaf's, in its source's orientation); kept, flip: (T,)
            bool each piece's verdict and whether it is turned over.
    Returns:
        (T,) bool, ``flip`` where pieces are not kept.
    """
    rows = np.flatnonzero(kept)
    if not len(rows) or not flip[rows].any() or flip[rows].all():
        return flip
    t = np.asarray(tris[rows], dtype=np.int64)
    n = len(verts)
    a, b = t.ravel(), t[:, [1, 2, 0]].ravel()
    keys, reverses = a * n + b, b * n + a
    order = np.argsort(keys, kind="stable")
    at = np.minimum(np.searchsorted(keys[order], reverses), len(keys) - 1)
    hit = keys[order][at] == reverses
    patch = connected_components(len(rows), np.flatnonzero(hit) // 3, order[at[hit]] // 3, device)
    c = verts[t].astype(np.float64)
    area = np.linalg.norm(np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0]), axis=1)
    turned = np.bincount(patch, weights=area * flip[rows], minlength=len(rows))
    total = np.bincount(patch, weights=area, minlength=len(rows))
    out = flip.copy()
    out[rows] = (2.0 * turned > total)[patch]
    return out
