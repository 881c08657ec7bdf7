"""An adaptive surface's merged faces that pass through other faces: a failure of the merge's check.

:func:`.adaptive.simplify` merges a block's vertices into one where they lie within a tolerance of a plane, and checks
the result closed, 2-manifold, near the field's surface and facing out; where a thin part or a tight corner brings
two sheets within a few voxels, a merged face can still pass through a face of the other sheet (three-operand chains
at /192: 9 pairs at adaptivity 0.5 and 17 at 1 over 40 chains; 7 and 6 are left with this check, folds of the level
contoured).
Here the triangles with a merged corner are searched against every face (:func:`.selfcross.crossing_pairs`, once a
round has passed every other test); the corners of the highest level of each face of a pair fail, so their
components drop a level as at any failure. Pairs of faces none of whose corners merged (a fold of the surface as
extracted) are not the merge's, and are left as they are.
"""

from __future__ import annotations

import numpy as np

from .quads import triangulate
from .selfcross import crossing_pairs


def crossing_corners(position, faces, sizes, merged, levels, device) -> np.ndarray:
    """(K,) bool the clusters (``position`` (K, 3), whether each ``merged`` vertices, its ``levels``) at the corners of
    the highest level of the faces (polygons ``faces``, ``sizes``) in a pair that passes through each other, one of
    them with a merged corner."""
    bad = np.zeros(len(position), dtype=bool)
    tris = triangulate(faces, sizes).astype(np.int64)
    rows = np.flatnonzero(merged[tris[:, 0]] | merged[tris[:, 1]] | merged[tris[:, 2]])
    pairs = crossing_pairs(np.asarray(position, dtype=np.float32), tris, device, rows)
    if len(pairs):
        hit = tris[np.unique(pairs)]
        top = levels[hit]
        bad[hit[top == top.max(axis=1)[:, None]]] = True
    return bad
