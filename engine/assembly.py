"""The parts of a kept surface as one surface: the kept faces, the voxel faces left and the strips joining them
(:func:`assembled`), or the voxel surface alone where nothing is kept or the join fails (:func:`voxel_surface_only`),
as :func:`.hybrid.hybrid_surface` returns them.

A join along the seams alone (its voxel surface only there) may give up kept faces where no voxel surface lies under
them: about a defect of an operand that no octet was built about, every face of a part given up round by round, the
rest still a closed surface without it. Kept faces given up away from every kept face left must have surface within a
voxel or two (:func:`_lost`), else the join is refused.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from .edges import surface_edges
from .meshcheck import any_corner, compacted
from .sources import mesh_distances
from .zipper import faces_near

# A kept face given up (away from the kept faces left) must have surface within this many voxels of its centre.
COVER_VOXELS = 2.0


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


def assembled(points, kept, k_tris, k_alive, voxel, strips, voxel_verts, voxel_tris, device, given_up=None) -> dict:
    """The kept faces, the voxel faces left (``voxel``: all of them and which are left) and the strips as one
    surface on the vertices they use, or the voxel surface alone if that is not closed and consistently oriented, or
    (``given_up``: the rows of ``k_tris`` the join gave up, with the voxel size, where its voxel surface is along the
    seams alone) where kept faces given up have no new surface about them (:func:`_lost`)."""
    v_rows = np.flatnonzero(voxel[1])
    new = np.concatenate([voxel[0][v_rows], strips.astype(np.int64)])
    if given_up is not None and _lost(points, k_tris, k_alive, new, *given_up, device):
        return voxel_surface_only(
            voxel_verts, voxel_tris, "kept faces given up where the seams' surface does not reach"
        )
    tris = np.concatenate([k_tris[k_alive], new])
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


def _lost(points, k_tris, k_alive, new, given_up, voxel: float, device) -> bool:
    """Whether a kept face given up (rows ``given_up`` of ``k_tris``) that shares no corner with a kept face left has
    no face of the joined surface (kept faces left, ``new`` faces) within COVER_VOXELS of its centre (where it borders
    kept faces left, the join paired its loop; Suzanne with a ball gives up small faces a voxel from kept ones)."""
    alive_corner = np.zeros(len(points), dtype=bool)
    alive_corner[k_tris[k_alive]] = True
    lone = given_up[~any_corner(alive_corner, k_tris[given_up])]
    if not len(lone):
        return False
    centres = points[k_tris[lone]].astype(np.float64).mean(axis=1)
    return uncovered(points, np.concatenate([k_tris[k_alive], new]), centres, voxel, device)


def uncovered(verts, tris, points, voxel: float, device) -> bool:
    """Whether a point of ``points`` (P, 3) has no triangle of ``tris`` (of ``verts``) within COVER_VOXELS."""
    reach = COVER_VOXELS * voxel
    tris = np.asarray(tris, dtype=np.int32)
    near = np.ascontiguousarray(tris[faces_near(verts, tris, points, reach)])
    if not len(near):
        return bool(len(points))
    mesh = wp.Mesh(
        points=wp.array(np.ascontiguousarray(verts, dtype=np.float32), dtype=wp.vec3, device=device),
        indices=wp.array(near.reshape(-1), dtype=wp.int32, device=device),
    )
    return bool((mesh_distances(mesh, points, reach, device) >= reach).any())
