"""The kept triangles of every operand judged (:func:`.keep.kept_triangles`) as one mesh, for the join
(:func:`.hybrid.hybrid_surface`): the sources' own vertex positions, one vertex per position within a piece, and what
each face and corner reads off its source (its triangle, its corners' weights)."""

from __future__ import annotations

import numpy as np

from .meshcheck import compacted, position_groups


def kept_mesh(kept: list[dict]) -> dict:
    """The kept triangles of every leaf as one mesh: ``verts`` (K, 3) float32 (the sources' own positions),
    ``tris`` (T, 3) int64 (flipped where the result needs), and per face its ``field_id`` and ``triangle_id`` (the
    index among the triangles the operand's field was built from: a piece of a split one names it), per vertex its
    ``vertex_field`` and ``vertex_id`` (index among the source's vertices; -1 for a split's midpoint)."""
    parts = {k: [] for k in ("verts", "tris", "field_id", "triangle_id", "vertex_field", "vertex_id", "corner_bary")}
    base = 0
    for leaf in kept:
        source, rows = leaf["source"], np.flatnonzero(leaf["kept"])
        tris = leaf["tris"][rows].astype(np.int64)
        tris[leaf["flip"][rows]] = tris[leaf["flip"][rows]][:, [0, 2, 1]]
        parts["corner_bary"].append(_corner_barycentrics(leaf["verts"], tris, source.tris[leaf["parent"][rows]]))
        used, local = _welded(leaf["verts"], tris)
        parts["verts"].append(leaf["verts"][used])
        parts["tris"].append(local + base)
        parts["field_id"].append(np.full(len(rows), leaf["field_id"], dtype=np.int32))
        parts["triangle_id"].append(source.triangle_ids[leaf["parent"][rows]])
        parts["vertex_field"].append(np.full(len(used), leaf["field_id"], dtype=np.int32))
        parts["vertex_id"].append(np.where(used < len(source.verts), used, -1).astype(np.int32))
        base += len(used)
    if not parts["verts"]:
        empty = {"verts": np.zeros((0, 3), np.float32), "tris": np.zeros((0, 3), np.int64)}
        empty["corner_bary"] = np.zeros((0, 3, 3), np.float32)
        return {**empty, **{k: np.zeros(0, np.int32) for k in ("field_id", "triangle_id", "vertex_field", "vertex_id")}}
    return {k: np.concatenate(v) for k, v in parts.items()}


def _welded(verts: np.ndarray, tris: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(used, local)``: the vertices the triangles use, one per position (the least index of those at it: a source
    vertex before a split's midpoint), in the order of their indices, and the triangles on them ((T, 3) int64). Pieces
    of a mesh made of patches whose borders repeat each other's vertices (a teapot's) are one piece here, not two
    kept loops side by side that no voxel surface lies between."""
    used, local = compacted(tris, len(verts))
    first, at = position_groups(verts[used])
    order = np.argsort(first)
    rank = np.empty(len(first), dtype=np.int64)
    rank[order] = np.arange(len(first))
    return used[first[order]], rank[at.reshape(-1)][local.reshape(-1)].reshape(-1, 3)


def _corner_barycentrics(verts, tris, source_tris) -> np.ndarray:
    """(F, 3, 3) float32: each corner of each face as weights of its source triangle's corners (projected onto its
    plane); a corner that is one of those corners gets exactly 1 there, so what it reads off them (UVs, colours) is
    the source's own value, bit for bit. Only faces with a corner that is none of their source's (pieces of split
    triangles) are projected."""
    exact = tris[:, :, None] == source_tris[:, None, :]  # (F, corner, source corner)
    bary = exact.astype(np.float32)
    on_source = [exact[:, k, 0] | exact[:, k, 1] | exact[:, k, 2] for k in range(3)]  # (3-long axes reduce slowly)
    rows = np.flatnonzero(~(on_source[0] & on_source[1] & on_source[2]))
    if not len(rows):
        return bary
    a, b, c = (verts[source_tris[rows, k]].astype(np.float64) for k in range(3))
    e0, e1 = b - a, c - a
    d00, d01, d11 = (e0 * e0).sum(1), (e0 * e1).sum(1), (e1 * e1).sum(1)
    den = np.maximum(d00 * d11 - d01 * d01, 1e-300)[:, None]
    d = verts[tris[rows]].astype(np.float64) - a[:, None, :]  # (R, 3 corners, 3)
    v = d11[:, None] * np.einsum("fkj,fj->fk", d, e0) - d01[:, None] * np.einsum("fkj,fj->fk", d, e1)
    w = d00[:, None] * np.einsum("fkj,fj->fk", d, e1) - d01[:, None] * np.einsum("fkj,fj->fk", d, e0)
    v, w = v / den, w / den
    projected = np.stack([1.0 - v - w, v, w], axis=2)
    bary[rows] = np.where(exact[rows].any(axis=2, keepdims=True), bary[rows], projected).astype(np.float32)
    return bary
