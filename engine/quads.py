"""Quads of the dual surface: each crossed lattice edge's quad kept whole where splitting it changes nothing.

Dual contouring (:mod:`.dual`) makes one quad per crossed lattice edge and writes it as two triangles (rows 2q and
2q + 1, split along the diagonal its vertices' planes fit best). Most of those quads are nearly planar and convex:
either diagonal gives the same surface, so they are polygons of their own, as Blender's Voxel Remesh writes them. A
quad stays two triangles where the split matters:

* its two triangles fold by more than :data:`QUAD_ANGLE` degrees across either diagonal (a crease or corner runs
  through it: every reconstructed crease edge folds by more, or it is twisted), or one split turns a triangle over
  (a non-convex quad);
* it is split around a tunnel's vertex (:func:`.meshcheck.open_tunnels`).

The test runs in ``dual._quads_kernel``, where the quad's corners are at hand (``whole``).

A quad kept whole starts at an end of the diagonal it was split along, so triangulating the polygons again (fans,
:func:`triangulate`) gives the same triangles back. The polygons
share their edges exactly as the triangles do (a merged pair only loses its inner diagonal), so they are as closed
and as 2-manifold as the triangles.
"""

from __future__ import annotations

import numpy as np

# Largest angle (degrees) between the two triangles of a quad, along either diagonal, for it to stay one polygon:
# well below the crease angle (quadric.CREASE_ANGLE, 25), so no reconstructed crease runs through a polygon; above
# the bend of a quad on a sphere of 4 voxels' radius.
QUAD_ANGLE = 20.0


def merge_pairs(tris, whole) -> tuple[np.ndarray, np.ndarray]:
    """Polygons of a dual surface: the quads flagged ``whole`` kept whole, first, then the other triangles in order.

    Args:
        tris: (T, 3) int triangles; for q < len(whole) rows 2q and 2q + 1 are the halves of quad q0 q1 q2 q3, split
            along q0-q2 (``q0 q1 q2``, ``q0 q2 q3``) or along q1-q3 (``q0 q1 q3``, ``q1 q2 q3``); the rows after
            them are triangles of their own.
        whole: (Q,) uint8 per quad (``dual.contour_dual``): 0 to leave it split, 1 or 2 to keep it whole (split
            along q0-q2 or q1-q3).
    Returns:
        ``faces`` (C,) int32 corner vertices, face after face, and ``sizes`` (P,) int32 corners per face (4 or 3).
        A quad starts at an end of its diagonal (``q0 q1 q2 q3`` or ``q1 q2 q3 q0``): its fan is its two rows.
    """
    tris = np.asarray(tris, dtype=np.int32)
    whole = np.asarray(whole)
    pairs = tris[: 2 * len(whole)].reshape(-1, 6)
    quads = np.where((whole == 1)[:, None], pairs[:, [0, 1, 2, 5]], pairs[:, [3, 4, 5, 0]])[whole > 0]
    split = pairs[whole == 0].reshape(-1, 3)
    rest = tris[2 * len(whole) :]
    faces = np.concatenate([quads.ravel(), split.ravel(), rest.ravel()])
    sizes = np.full(len(quads) + len(split) + len(rest), 3, dtype=np.int32)
    sizes[: len(quads)] = 4
    return faces, sizes


def triangulate(faces, sizes) -> np.ndarray:
    """(T, 3) int32 fans of polygons (``faces`` (C,) corners, ``sizes`` (P,)): each polygon ``a b c ...`` as
    ``a b c``, ``a c d``, ... (a quad of :func:`merge_pairs` gives back its two rows)."""
    faces = np.asarray(faces, dtype=np.int64)
    sizes = np.asarray(sizes, dtype=np.int64)
    start = np.cumsum(sizes) - sizes
    count = np.maximum(sizes - 2, 0)
    poly = np.repeat(np.arange(len(sizes)), count)
    k = np.arange(int(count.sum())) - np.repeat(np.cumsum(count) - count, count)
    first = start[poly]
    return np.stack([faces[first], faces[first + k + 1], faces[first + k + 2]], axis=1).astype(np.int32)


def polygon_edges(faces, sizes) -> np.ndarray:
    """(C, 2) int64 directed edges of polygons: each corner to the next corner of its face."""
    faces = np.asarray(faces, dtype=np.int64)
    sizes = np.asarray(sizes, dtype=np.int64)
    start = np.repeat(np.cumsum(sizes) - sizes, sizes)
    within = np.arange(len(faces)) - start
    nxt = start + (within + 1) % np.repeat(sizes, sizes)
    return np.stack([faces, faces[nxt]], axis=1)
