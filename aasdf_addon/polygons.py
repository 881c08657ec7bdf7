"""Kept polygons stay polygons: a source face whose every triangle the result kept whole comes back as that face.

The engine keeps triangles (Blender's triangulation of each operand, ``bridge.Operand.tris``). Where all the triangles
of one of an operand's faces are kept, unsplit, the result gets the face itself back: its corners in its own order
(reversed for a subtracted operand's), its material and shading, its face attributes, and every corner attribute (UV
maps, colours, others) copied from its own corners, bit for bit. The rest of the result stays triangles with the
attributes ``transfer`` gives them. Arrays only; ``bridge.result_mesh`` writes the layout (``attributes["polygons"]``).
"""

import numpy as np

from . import custom_normals, generic_attributes
from .transfer import merged_materials


def whole_faces(kept: dict, tris: np.ndarray, operands) -> dict | None:
    """The operands' faces that come back whole, from a kept surface (``AdaptiveField.kept_surface``) and its
    triangles ``tris`` (F, 3).

    Returns:
        None when there is none, else ``{"rows": (K,) the result triangles they replace, "field": (Q,) operand,
        "face": (Q,) its face, "sizes": (Q,), "corner_vert": (C,) result vertex of each corner, "loops": (C,) the
        operand's corner (loop) each copies, "flip": (Q,) bool}``.
    """
    face_first = np.cumsum([0] + [len(op.loop_start) for op in operands])  # faces numbered over the operands
    found = _source_triangles(kept, tris, operands, face_first)
    if found is None:
        return None
    rows, face, flip_of_row = found
    # one entry per whole face, its corners in its own order
    whole_faces_ = np.unique(face)
    flip = np.zeros(int(face_first[-1]), dtype=bool)
    flip[face] = flip_of_row
    operand = np.searchsorted(face_first, whole_faces_, side="right") - 1
    local = whole_faces_ - face_first[operand]
    loops, sizes = _face_loops(operands, operand, local, flip[whole_faces_])
    corner_operand = np.repeat(operand, sizes)
    source_vertex = np.empty(len(loops), np.int64)
    for k, op in enumerate(operands):
        at = np.flatnonzero(corner_operand == k)
        source_vertex[at] = op.corner_vert[loops[at]]
    vertex_field, vertex_id = kept["vertex_field"].astype(np.int64), kept["vertex_id"].astype(np.int64)
    result_vertex = _result_vertices(vertex_field, vertex_id, corner_operand, source_vertex)
    return {
        "rows": rows,
        "field": operand,
        "face": local,
        "sizes": sizes,
        "corner_vert": result_vertex,
        "loops": loops,
        "flip": flip[whole_faces_],
    }


def _source_triangles(kept: dict, tris: np.ndarray, operands, face_first) -> tuple | None:
    """The kept triangles that are their source triangle, corner for corner (turned over or not), where every
    triangle of its face is: ``(rows, face numbered over the operands, turned over)``, or None. Gathered operand by
    operand from each one's own arrays."""
    field_id, tri_id = kept["field_id"].astype(np.int64), kept["triangle_id"].astype(np.int64)
    vertex_field, vertex_id = kept["vertex_field"].astype(np.int64), kept["vertex_id"].astype(np.int64)
    rows = np.flatnonzero(kept["kept"] & (field_id >= 0) & (field_id < len(operands)))
    corners = [tris[rows, k] for k in range(3)]  # (column by column: numpy reduces a 3-long axis slowly)
    own = (vertex_id[corners[0]] >= 0) & (vertex_id[corners[1]] >= 0) & (vertex_id[corners[2]] >= 0)
    for k in range(3):
        own &= vertex_field[corners[k]] == field_id[rows]
    rows = rows[own]
    if not len(rows):
        return None
    source, face, need = (
        np.empty((len(rows), 3), np.int64),
        np.empty(len(rows), np.int64),
        np.empty(len(rows), np.int64),
    )
    for k, op in enumerate(operands):
        at = np.flatnonzero(field_id[rows] == k)
        triangle = tri_id[rows[at]]
        source[at], face[at] = op.tris[triangle], op.faces[triangle]
        need[at] = np.bincount(op.faces, minlength=len(op.loop_start))[face[at]]  # (its face's triangles)
        face[at] += face_first[k]
    corners = vertex_id[tris[rows]]
    same = np.zeros(len(rows), dtype=bool)
    turned = np.zeros(len(rows), dtype=bool)
    for k in range(3):  # the source triangle's corners, in its turn or reversed (column by column: no copies)
        first = corners[:, k] == source[:, 0]
        same |= first & (corners[:, (k + 1) % 3] == source[:, 1]) & (corners[:, (k + 2) % 3] == source[:, 2])
        turned |= first & (corners[:, (k + 2) % 3] == source[:, 1]) & (corners[:, (k + 1) % 3] == source[:, 2])
    match = same | turned
    rows, face, need, flip_of_row = rows[match], face[match], need[match], turned[match] & ~same[match]
    whole = np.bincount(face, minlength=int(face_first[-1]))[face] == need
    return (rows[whole], face[whole], flip_of_row[whole]) if whole.any() else None


def _face_loops(operands, operand, local, flip) -> tuple[np.ndarray, np.ndarray]:
    """``(loops, sizes)``: the corners (loops) of each face ``local`` of ``operand``, in its own order (reversed
    from its first corner where ``flip``), and each face's size."""
    start, sizes = np.empty(len(local), np.int64), np.empty(len(local), np.int64)
    for k, op in enumerate(operands):
        at = np.flatnonzero(operand == k)
        ends = np.r_[op.loop_start[1:], len(op.corner_vert)].astype(np.int64)
        start[at] = op.loop_start[local[at]]
        sizes[at] = ends[local[at]] - start[at]
    within = np.arange(int(sizes.sum())) - np.repeat(np.cumsum(sizes) - sizes, sizes)
    reverse = np.repeat(flip, sizes)
    return np.repeat(start, sizes) + np.where(reverse & (within > 0), np.repeat(sizes, sizes) - within, within), sizes


def _result_vertices(vertex_field, vertex_id, operand, source_vertex) -> np.ndarray:
    """The result vertex that is each (operand, source vertex): the first of the result's vertices that is it, through
    a table over (operand, source vertex)."""
    width = int(max(vertex_id.max(initial=0), source_vertex.max(initial=0))) + 1
    kept = np.flatnonzero(vertex_id >= 0)
    operands = int(max(vertex_field[kept].max(initial=0), operand.max(initial=0))) + 1
    table = np.full(operands * width, len(vertex_id) - 1, dtype=np.int64)
    np.minimum.at(table, vertex_field[kept] * width + vertex_id[kept], kept)
    return table[operand * width + source_vertex].astype(np.int32)


def as_polygons(result: dict, whole: dict, operands) -> dict:
    """``result`` (``pipeline.extract`` with ``attributes``) with the whole faces in place of their triangles: the
    faces first (``attributes["polygons"]``: sizes and corner vertices), then the triangles left, each attribute in
    that layout."""
    tris, attrs = result["tris"], result["attributes"]
    rest = np.ones(len(tris), dtype=bool)
    rest[whole["rows"]] = False
    corner_rest = np.repeat(rest, 3)
    out = dict(attrs)
    out["polygons"] = (whole["sizes"].astype(np.int32), whole["corner_vert"].astype(np.int32))
    field, face = whole["field"], whole["face"]
    _, slot_maps = merged_materials(operands)
    slot_of_face = [
        np.asarray(m)[np.clip(op.face_material, 0, len(m) - 1)] for op, m in zip(operands, slot_maps, strict=True)
    ]
    slots = _per_operand(field, face, slot_of_face)
    smooth = _per_operand(field, face, [op.face_smooth for op in operands])
    out["material_index"] = np.r_[slots, attrs["material_index"][rest]].astype(np.int32)
    out["smooth"] = np.r_[smooth.astype(bool), attrs["smooth"][rest]]
    out["operand"] = np.r_[field.astype(np.int32), attrs["operand"][rest]]
    corner_operand = np.repeat(field, whole["sizes"])
    out["uv_maps"] = {
        name: np.concatenate(
            [_corner_values(operands, corner_operand, whole["loops"], name, 2, "uv"), values[corner_rest]]
        )
        for name, values in attrs["uv_maps"].items()
    }
    out["colors"] = {
        name: (
            kind,
            np.concatenate(
                [_corner_values(operands, corner_operand, whole["loops"], name, 4, "color"), values[corner_rest]]
            ),
        )
        for name, (kind, values) in attrs["colors"].items()
    }
    out["generic"] = generic_attributes.whole_faces(attrs.get("generic", {}), operands, whole, rest, corner_rest)
    if attrs.get("custom_normals") is not None:
        flip = np.repeat(whole["flip"], whole["sizes"])
        copied = custom_normals.whole_face_normals(operands, corner_operand, whole["loops"], flip)
        out["custom_normals"] = np.concatenate([copied, attrs["custom_normals"][corner_rest]])
    return {**result, "tris": tris[rest], "attributes": out, "edges": {}}


def _per_operand(operand, index, arrays) -> np.ndarray:
    """``arrays[operand[i]][index[i]]`` for every i, in one gather over the arrays stacked."""
    first = np.cumsum([0] + [len(a) for a in arrays])
    return np.concatenate([np.asarray(a) for a in arrays])[first[operand] + index]


def _corner_values(operands, corner_operand, loops, name, width, kind) -> np.ndarray:
    """One corner attribute of the whole faces' corners, copied from the operands' own corners (zeros for an
    operand without it; a point colour read at the corner's vertex)."""
    out = np.zeros((len(loops), width), dtype=np.float32)
    for k, op in enumerate(operands):
        rows = np.flatnonzero(corner_operand == k)
        if not len(rows):
            continue
        if kind == "uv":
            values = op.uv_maps.get(name)
            if values is not None:
                out[rows] = np.asarray(values, dtype=np.float32).reshape(-1, 2)[loops[rows]]
        elif name in op.colors:
            domain, _, values = op.colors[name]
            at = loops[rows] if domain == "CORNER" else op.corner_vert[loops[rows]]
            out[rows] = np.asarray(values, dtype=np.float32).reshape(-1, 4)[at]
    return out
