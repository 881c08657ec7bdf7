"""Source regions: which triangles of an operand a merged polygon may span (``AdaptiveField.to_mesh(adaptivity=...,
regions=...)``). A region is a run of an operand's triangles with one material, one value of every integer or
boolean face attribute (a part id: :mod:`.generic_attributes`) and, for every UV map, one UV island: triangles joined
across an edge whose two ends have the same UVs on both sides. Adaptivity merges the remeshed surface's cells only
within a region, so a merged polygon never spans a material border, a part's border or a UV seam. Arrays only.
"""

import numpy as np

from . import generic_attributes, runtime


def source_regions(operands) -> dict:
    """{operand index: (T,) int64 region of each of its triangles} (the engine's field id k is ``operands[k]``)."""
    return {k: _regions(op) for k, op in enumerate(operands)}


def _regions(op) -> np.ndarray:
    tris = np.asarray(op.tris, dtype=np.int64)
    n = len(tris)
    if n == 0:
        return np.zeros(0, np.int64)
    material = np.asarray(op.face_material, dtype=np.int64)[op.faces] if op.face_material is not None else None
    # each triangle side (a, b) with its corners; a shared edge is seen from its two triangles, ends swapped
    a, b = tris.ravel(), tris[:, [1, 2, 0]].ravel()
    corner_a = np.asarray(op.corners, dtype=np.int64).ravel()
    corner_b = np.asarray(op.corners, dtype=np.int64)[:, [1, 2, 0]].ravel()
    key = np.minimum(a, b) * np.int64(len(op.verts)) + np.maximum(a, b)
    order = np.argsort(key, kind="stable")
    pair = np.flatnonzero(key[order][1:] == key[order][:-1])
    s, t = order[pair], order[pair + 1]  # two sides of one edge
    joined = np.ones(len(pair), dtype=bool)
    for uv in op.uv_maps.values():
        uv = np.asarray(uv, dtype=np.float32).reshape(-1, 2)
        same_a = np.where(a[s] == a[t], corner_a[t], corner_b[t])  # t's corner at s's first end
        same_b = np.where(a[s] == a[t], corner_b[t], corner_a[t])
        joined &= np.abs(uv[corner_a[s]] - uv[same_a]).max(axis=1) <= 1e-6
        joined &= np.abs(uv[corner_b[s]] - uv[same_b]).max(axis=1) <= 1e-6
    face_s, face_t = s // 3, t // 3
    if material is not None:
        joined &= material[face_s] == material[face_t]
    for domain, kind, values in op.generic.values():
        if domain == "FACE" and not generic_attributes.TYPES[kind][3]:  # a label: integers and booleans
            per_tri = np.asarray(values)[op.faces].reshape(n, -1)
            joined &= (per_tri[face_s] == per_tri[face_t]).all(axis=1)
    return runtime.engine().connected_components(n, face_s[joined], face_t[joined])
