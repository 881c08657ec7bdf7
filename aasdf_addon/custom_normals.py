"""Custom normals carried by the faces a result keeps: an operand's custom (split) normals, where it has them, on the
corners of its kept faces; every other corner keeps Blender's own normal (a zero vector in
``Mesh.normals_split_custom_set``).

A face given back whole (``polygons``) copies its corners' normals; a kept triangle (whole or a piece of one) reads
them off its source triangle by its corners' barycentric weights (exact at the source's corners), normalised. Both
turn with the operand's placement (the inverse transpose of its matrix) and face the way the result's face does (a
subtracted operand's faces are turned over). New faces, along the seams, get none: their shading follows the surface.
Arrays only; ``bridge`` reads the normals (``Operand.custom_normals``) and writes them.
"""

import numpy as np

from . import runtime


def present(operands) -> bool:
    return any(operand.custom_normals is not None for operand in operands)


def _normal_matrix(operand) -> np.ndarray:
    """(3, 3) float64: local directions to world normals (the inverse transpose of the placement)."""
    return np.linalg.inv(np.asarray(operand.matrix, dtype=np.float64)[:3, :3]).T


def _unit(v: np.ndarray) -> np.ndarray:
    length = np.linalg.norm(v, axis=-1, keepdims=True)
    return np.where(length > 0.0, v / np.maximum(length, 1e-30), 0.0).astype(np.float32)


def _world(operands) -> list:
    """Each operand's (L, 3) custom normals in world space (unit; one zero row where it has none)."""
    out = []
    for operand in operands:
        if operand.custom_normals is None:
            out.append(np.zeros((1, 3), np.float32))
        else:
            local = np.asarray(operand.custom_normals, dtype=np.float64).reshape(-1, 3)
            out.append(_unit(local @ _normal_matrix(operand).T))
    return out


def kept_corner_normals(operands, verts, tris, kept: dict, sources) -> np.ndarray | None:
    """(3F, 3) float32 normals of the F faces' corners (``tris`` into ``verts``): a kept face's from its source's
    custom normals, zeros elsewhere; None when no operand has custom normals.

    Args:
        kept: ``AdaptiveField.kept_surface``'s dict (its ``kept`` mask).
        sources: (field ids (F,), source triangles (F,), corner weights (F, 3, 3)), as ``transfer`` reads them.
    """
    if kept is None or not present(operands):
        return None
    field_ids, triangle_ids, bary = (np.asarray(a) for a in sources)
    has = np.asarray(kept["kept"], dtype=bool) & (field_ids >= 0) & (field_ids < len(operands)) & (triangle_ids >= 0)
    with_normals = np.array([operand.custom_normals is not None for operand in operands])
    has &= with_normals[np.clip(field_ids, 0, len(operands) - 1)]
    out = np.zeros((len(tris), 3, 3), dtype=np.float32)
    rows = np.flatnonzero(has)
    if not len(rows):
        return out.reshape(-1, 3)
    values = _world(operands)
    first = np.cumsum([0] + [len(v) for v in values])
    corners = np.concatenate(
        [
            np.asarray(op.corners, dtype=np.int32) if op.custom_normals is not None else np.zeros((len(op.tris), 3))
            for op in operands
        ]
    ).astype(np.int64)
    tri_first = np.cumsum([0] + [len(op.tris) for op in operands])
    stacked_corners = (corners + np.repeat(first[:-1], np.diff(tri_first))[:, None]).astype(np.int32)
    stacked = (tri_first[field_ids[rows]] + triangle_ids[rows]).astype(np.int64)
    normals = (
        runtime.engine()
        .interpolate_corners(
            np.concatenate(values), stacked_corners, stacked, np.ascontiguousarray(bary[rows], dtype=np.float32)
        )
        .reshape(-1, 3, 3)
    )
    # facing the result's face: turned over where the operand's face was (a subtracted operand's)
    v = np.asarray(verts, dtype=np.float64)[np.asarray(tris)[rows]]
    facing = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
    turned = np.einsum("ij,ij->i", facing, normals.sum(axis=1)) < 0.0
    out[rows] = _unit(np.where(turned[:, None, None], -normals, normals))
    return out.reshape(-1, 3)


def whole_face_normals(operands, corner_operand, loops, flip_per_corner) -> np.ndarray:
    """(C, 3) float32 normals of whole faces' corners (operand and own corner of each), copied from the operands'
    custom normals (zeros for an operand without), turned over where the face is (``flip_per_corner``: its corners
    run against its source's; a mirrored operand's run so unturned, its normals placed by the mirror already: they
    came back inverted)."""
    out = np.zeros((len(loops), 3), dtype=np.float32)
    mirrored = np.array([np.linalg.det(np.asarray(op.matrix, np.float64)[:3, :3]) < 0.0 for op in operands])
    for k, world in enumerate(_world(operands)):
        rows = np.flatnonzero(corner_operand == k)
        if len(rows) and operands[k].custom_normals is not None:
            out[rows] = world[loops[rows]]
    turned = np.asarray(flip_per_corner, dtype=bool) != mirrored[np.asarray(corner_operand, dtype=np.int64)]
    return np.where(turned[:, None], -out, out)
