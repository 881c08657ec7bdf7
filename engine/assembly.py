"""The parts of a kept surface as one surface: the kept faces, the voxel faces left and the strips joining them
(:func:`assembled`), or the voxel surface alone where nothing is kept or the join fails (:func:`voxel_surface_only`),
as :func:`.hybrid.hybrid_surface` returns them."""

from __future__ import annotations

import numpy as np

from .edges import surface_edges
from .meshcheck import compacted


def voxel_surface_only(verts, tris, why: str, failed: bool = True) -> dict:
    """A voxel surface as :func:`hybrid_surface` returns one, nothing kept (``why`` in its stats, and whether a join
    ``failed``: ``stats["join_failed"]``, False where there was nothing to keep)."""
    n_f, n_v = len(tris), len(verts)
    return {
        "verts": np.asarray(verts, dtype=np.float32),
        "tris": np.asarray(tris, dtype=np.int32),
        "kept": np.zeros(n_f, dtype=bool),
        "field_id": np.full(n_f, -1, np.int32),
        "triangle_id": np.full(n_f, -1, np.int32),
        "vertex_field": np.full(n_v, -1, np.int32),
        "vertex_id": np.full(n_v, -1, np.int32),
        "corner_bary": np.zeros((n_f, 3, 3), np.float32),
        "voxel_face": np.arange(n_f, dtype=np.int64),
        "stats": {"kept_faces": 0, "new_faces": n_f, "kept_fallback": why, "join_failed": failed},
    }


def assembled(points, kept, k_tris, k_alive, voxel, strips, voxel_verts, voxel_tris, device) -> dict:
    """The kept faces, the voxel faces left (``voxel``: all of them and which are left) and the strips as one
    surface on the vertices they use, or the voxel surface alone if that is not closed and consistently oriented."""
    v_rows = np.flatnonzero(voxel[1])
    tris = np.concatenate([k_tris[k_alive], voxel[0][v_rows], strips.astype(np.int64)])
    used, local = compacted(tris, len(points))
    tris = local.astype(np.int32)
    if surface_edges(tris, len(used), device) is None:
        return voxel_surface_only(voxel_verts, voxel_tris, "the join is not a closed oriented surface")
    n_k, n_kept = len(kept["verts"]), int(k_alive.sum())
    n_new = len(tris) - n_kept
    from_kept = used < n_k
    vertex_field = np.full(len(used), -1, np.int32)
    vertex_id = np.full(len(used), -1, np.int32)
    vertex_field[from_kept] = kept["vertex_field"][used[from_kept]]
    vertex_id[from_kept] = kept["vertex_id"][used[from_kept]]
    return {
        "verts": points[used],
        "tris": tris,
        "kept": np.r_[np.ones(n_kept, bool), np.zeros(n_new, bool)],
        "field_id": np.r_[kept["field_id"][k_alive], np.full(n_new, -1, np.int32)],
        "triangle_id": np.r_[kept["triangle_id"][k_alive], np.full(n_new, -1, np.int32)],
        "vertex_field": vertex_field,
        "vertex_id": vertex_id,
        "corner_bary": np.concatenate([kept["corner_bary"][k_alive], np.zeros((n_new, 3, 3), np.float32)]),
        "voxel_face": np.r_[np.full(n_kept, -1), v_rows, np.full(len(strips), -1)].astype(np.int64),
        "stats": {"kept_faces": n_kept, "new_faces": n_new, "strip_faces": len(strips)}
        | {"kept_fallback": "", "join_failed": False},
    }
