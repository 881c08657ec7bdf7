"""The last places where a kept surface's new faces pass through other faces, relaxed.

:func:`.uncross.uncrossed` tiles each place where faces pass through each other again, in rounds; a few places are
left where no tiling and no fan fits: a fold of the voxel surface beside a shallow cut, where two or three new faces
lie over their neighbours within a few degrees of one plane. Here each place left is relaxed instead:

1. a place: the faces of the crossing pairs and ``rings - 1`` rings of faces about them; its free vertices (those of
   no kept face) move, the rest stay (kept faces keep their vertices bit for bit);
2. each free vertex takes ``steps`` umbrella steps (half way to the mean of its neighbours, all at once; a quarter of
   the way in the last attempts), which unfolds a face lying over its neighbours;
3. the place is taken where no face about its moved vertices passes through another face any more, none is turned
   over or against the faces about it that was not so before (a folded face turns back), and every moved vertex lies
   within ``RELAX_VOXELS`` (or the reach the caller gives: an adaptive surface's own) of the faces about it as they
   were; else it stays as it was, for the next attempt (more rings, more steps: ``ATTEMPTS``).

Written by hand: a few vertices smoothed under these checks (no library smooths a handful of vertices of a mesh and
keeps the rest to the bit).
"""

from __future__ import annotations

import numpy as np
import warp as wp

from .components import connected_components
from .meshcheck import any_corner
from .selfcross import crossing_pairs
from .sources import mesh_distances

# A relaxed vertex stays within this many voxels of the faces about it as they were (measured on three-operand
# booleans at /256: the places left relax within 0.06-0.15 voxel of their surface at adaptivity 0).
RELAX_VOXELS = 0.3
# (rings of faces about the crossing ones, umbrella steps, the share of the way each step goes) tried one after another
# on the places still crossing. The quarter steps after the half steps: a fold of the voxel surface where three
# surfaces meet, which half steps uncross but turn a face over (a three-operand chain at /192: 3 pairs left, none with
# them). Three-eighths steps last: a fold along a box's edge where a mesh meets it, which half steps uncross but turn
# a face against those about it, and quarter steps leave crossing (Homer united with a turned box at /64: 4 pairs
# left, none with them).
ATTEMPTS = ((1, 1, 0.5), (2, 1, 0.5), (2, 2, 0.5), (1, 1, 0.25), (2, 1, 0.25), (1, 1, 0.375), (2, 1, 0.375))


def relaxed(verts, tris: np.ndarray, kept: np.ndarray, pairs: np.ndarray, voxel: float, device, reach=RELAX_VOXELS):
    """The vertices (V, 3) of a surface (``tris`` (T, 3) int64, ``kept`` (T,) bool) with the places of its crossing
    ``pairs`` ((P, 2) face rows) relaxed where that uncrosses them (module steps; a moved vertex within ``reach``
    voxels of the faces as they were); the pairs left, and how many places were relaxed."""
    verts = np.asarray(verts, dtype=np.float32).copy()
    free = np.ones(len(verts), dtype=bool)
    free[tris[kept]] = False
    places = 0
    for rings, steps, share in ATTEMPTS:
        if not len(pairs):
            break
        seeds = np.unique(pairs)
        near = np.zeros(len(tris), dtype=bool)
        near[seeds] = True
        for _ in range(rings - 1):
            near = _about(tris, near, len(verts))
        moving = np.zeros(len(verts), dtype=bool)
        moving[tris[near]] = True
        moving &= free
        touched = np.flatnonzero(any_corner(moving, tris))
        if not len(touched):
            break
        place = _places(tris[touched], len(verts), device)
        moved = _umbrella(verts, tris[touched], moving, steps, share)
        bad = _failed(verts, moved, tris, touched, place, reach * voxel, device)
        take = moving & ~np.isin(place, bad)
        if not take.any():
            continue  # the same pairs for the next attempt
        places += len(np.setdiff1d(np.unique(place[moving]), bad))
        verts[take] = moved[take]
        rows = np.union1d(seeds, touched)
        pairs = crossing_pairs(verts, tris, device, rows[~kept[rows]])  # with a new face, as the rounds count them
    return verts, pairs, places


def _about(tris: np.ndarray, faces: np.ndarray, n: int) -> np.ndarray:
    """(T,) bool the ``faces`` and every face sharing a corner with one."""
    on = np.zeros(n, dtype=bool)
    on[tris[faces]] = True
    return any_corner(on, tris)


def _places(faces: np.ndarray, n: int, device) -> np.ndarray:
    """(n,) each vertex's place: the connected piece of ``faces`` (through shared corners) it is a corner of."""
    a = faces.ravel()
    b = faces[:, [1, 2, 0]].ravel()
    return connected_components(n, a, b, device)


def _umbrella(verts: np.ndarray, faces: np.ndarray, moving: np.ndarray, steps: int, share: float) -> np.ndarray:
    """(V, 3) float32 the vertices after ``steps`` umbrella steps of the ``moving`` ones over the edges of ``faces``
    (every face about a moving vertex: each neighbour once along a closed surface's directed edges), each going
    ``share`` of the way to the mean of its neighbours."""
    a, b = faces.ravel(), faces[:, [1, 2, 0]].ravel()
    rows = np.flatnonzero(moving[a])
    a, b = a[rows], b[rows]
    count = np.bincount(a, minlength=len(verts))[moving].astype(np.float64)
    out = verts.astype(np.float64)
    for _ in range(steps):
        mean = np.stack([np.bincount(a, out[b, k], len(verts))[moving] for k in range(3)], axis=1)
        out[moving] = (1.0 - share) * out[moving] + share * mean / np.maximum(count, 1.0)[:, None]
    return out.astype(np.float32)


def _failed(verts, moved, tris, touched, place, reach: float, device) -> np.ndarray:
    """The places (ids of ``place``) where the ``moved`` vertices leave a face of ``touched`` passing through another
    face, turned over, or a moved vertex farther than ``reach`` from the ``touched`` faces as they were."""
    faces = tris[touched]
    crossing = crossing_pairs(moved, tris, device, touched)
    hit = np.zeros(len(tris), dtype=bool)
    hit[crossing.ravel()] = True
    (normal, folded), (after, turned) = (_turned(v, faces) for v in (verts, moved))
    flipped = np.einsum("ij,ij->i", normal, after) <= 0.0
    bad = hit[touched] | ((turned | flipped) & ~folded)  # a face folded before may turn back
    shifted = np.flatnonzero(np.any(moved != verts, axis=1))
    mesh = wp.Mesh(
        points=wp.array(np.ascontiguousarray(verts), dtype=wp.vec3, device=device),
        indices=wp.array(np.ascontiguousarray(faces, dtype=np.int32).ravel(), dtype=wp.int32, device=device),
    )
    far = mesh_distances(mesh, moved[shifted], 2.0 * reach, device) > reach
    return np.union1d(place[faces[bad, 0]], place[shifted[far]])


def _turned(verts: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The faces' normals (F, 3) (by area) and (F,) bool whether each is turned against the faces about its corners
    (their normals summed, without its own): a face folded over its neighbours, or one beside a crease sharper than a
    right angle."""
    p = verts.astype(np.float64)
    normal = np.cross(p[faces[:, 1]] - p[faces[:, 0]], p[faces[:, 2]] - p[faces[:, 0]])
    index, rows = np.unique(faces, return_inverse=True)
    rows = rows.reshape(faces.shape)
    at = np.stack([np.bincount(rows.ravel(), np.repeat(normal[:, k], 3), len(index)) for k in range(3)], axis=1)
    about = at[rows].sum(axis=1) - 3.0 * normal
    return normal, np.einsum("ij,ij->i", normal, about) <= 0.0
