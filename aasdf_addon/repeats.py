"""Faces that repeat an earlier face of the same mesh: the same corner positions, in the same turn.

A Mirror modifier on the plane a mesh is already symmetric about (its Merge off) lays every face on another one. The
repeated copy is the same surface and winding number inside, but as a defect everywhere it left no face to keep and
sent the whole mesh down the slow path (a subdivided box minus a cylinder: 0 of its faces kept, 6.2 s against 0.8 s
remeshed). Its triangles are left out of the operand, so its first copy is kept as a clean mesh's would be. A face
and its reverse (opposite turns) both stay: together they are a wall of no thickness, not one surface.
"""

import numpy as np

from . import runtime

# An odd multiplier for the faces' hashes (a 64-bit prime's digits); hashes that agree are checked corner by corner.
_MIX = np.uint64(0x9E3779B97F4A7C15)


def repeated_faces(verts: np.ndarray, corner_vert: np.ndarray, loop_start: np.ndarray) -> np.ndarray:
    """(P,) bool the faces (``loop_start`` (P,) into the corners ``corner_vert``) whose corners' positions (``verts``
    (V, 3)) an earlier face has in the same turn, whatever corner either starts at."""
    count = len(loop_start)
    if count < 2:
        return np.zeros(count, dtype=bool)
    groups = runtime.engine().meshcheck.position_groups(verts)[1]  # one id per distinct position
    position = groups[corner_vert]
    sizes = np.diff(np.r_[loop_start, len(corner_vert)])
    face = np.repeat(np.arange(count), sizes)
    k = np.arange(len(corner_vert)) - loop_start[face]
    least = np.minimum.reduceat(position, loop_start)
    start = np.minimum.reduceat(np.where(position == least[face], k, len(corner_vert)), loop_start)
    turned = (k - start[face]) % sizes[face]  # each corner's place counted from the face's least position
    canonical = np.empty_like(position)
    canonical[loop_start[face] + turned] = position
    powers = np.cumprod(np.full(int(sizes.max()), _MIX, dtype=np.uint64))
    with np.errstate(over="ignore"):
        terms = (canonical.astype(np.uint64) + np.uint64(1)) * powers[k]
        key = np.add.reduceat(terms, loop_start) ^ sizes.astype(np.uint64)
    _, first, inverse = np.unique(key, return_index=True, return_inverse=True)
    earlier = first[inverse.reshape(-1)]
    out = earlier != np.arange(count)
    rows = np.flatnonzero(out)  # (hashes that agree: the same corners, checked)
    same = sizes[rows] == sizes[earlier[rows]]
    rows, same = rows[same], np.ones(int(same.sum()), dtype=bool)
    if len(rows):
        at = np.repeat(np.arange(len(rows)), sizes[rows])
        step = np.arange(len(at)) - np.repeat(np.cumsum(sizes[rows]) - sizes[rows], sizes[rows])
        equal = canonical[loop_start[rows][at] + step] == canonical[loop_start[earlier[rows]][at] + step]
        same = np.logical_and.reduceat(equal, np.cumsum(sizes[rows]) - sizes[rows])
    out[:] = False
    out[rows[same]] = True
    return out
