"""Every other attribute of the operands carried over: bevel weights, vertex creases, a painted weight, a part id.

The attributes the add-on knows by name (materials, shading, UV maps, colours, seams, sharp edges, edge creases,
custom normals) are carried by ``transfer``, ``polygons`` and ``edge_attributes``. Here is everything else an operand's
mesh holds that Blender lets a user make: a float, float2, vector, colour, integer, 8-bit integer, 2D integer, boolean,
quaternion (rotation) or 4x4 matrix attribute on points, edges, faces or face corners (:data:`TYPES`), and sculpting's
face sets and mask (hidden: ``bridge.SCULPT_ATTRIBUTES``). Each comes back on the result under its own name, domain and
type:

- a face takes its source face's value (a kept face its own, a new face the face of the operand it came from), as the
  material does;
- a face corner and a point take the value at that point of its face's source triangle: floats interpolated by the
  corner's weights on that triangle, integers, booleans, rotations and matrices the value of the triangle's nearest
  corner (a blend of rotations is no rotation; a kept face's corners and a kept vertex: their own values, bit for
  bit);
- an edge of the result that is one of an operand's own edges (both ends its kept vertices) takes that edge's value,
  other edges zero, as seams and creases do (:func:`.edge_attributes.kept_edge_values`; a remeshed result has none).

An attribute some operands lack (or hold on another domain or of another type than the first operand that has it)
reads Blender's default on their faces: zero (False), the identity rotation or matrix (:data:`IDENTITY`). String
attributes are not carried. Arrays only: ``bridge``
reads the operands' attributes (``Operand.generic``: name -> (domain, data type, values)) and writes the result's.
"""

import numpy as np

from . import runtime, transfer

# Blender data type -> (the ``foreach_get`` property, numpy dtype, values per item, interpolated between corners)
TYPES = {
    "FLOAT": ("value", np.float32, 1, True),
    "FLOAT2": ("vector", np.float32, 2, True),
    "FLOAT_VECTOR": ("vector", np.float32, 3, True),
    "FLOAT_COLOR": ("color", np.float32, 4, True),
    "BYTE_COLOR": ("color", np.float32, 4, True),
    "INT": ("value", np.int32, 1, False),
    "INT8": ("value", np.int8, 1, False),
    "INT32_2D": ("value", np.int32, 2, False),
    "INT16_2D": ("value", np.int16, 2, False),
    "BOOLEAN": ("value", bool, 1, False),
    "QUATERNION": ("value", np.float32, 4, False),
    "FLOAT4X4": ("value", np.float32, 16, False),
}
# The value Blender gives a new element of these types (w x y z; a matrix column after column), where zero is not.
IDENTITY = {"QUATERNION": np.array([1, 0, 0, 0], np.float32), "FLOAT4X4": np.eye(4, dtype=np.float32).ravel()}
DOMAINS = ("POINT", "EDGE", "FACE", "CORNER")
# Corner values of two quad halves agree within this share of the attribute's range over the result (plus 1e-6).
FLOAT_TOLERANCE = 1e-3


def carried_names(operands) -> dict:
    """name -> (domain, data type) of the attributes carried: each name as the first operand holding it has it (UV
    map and colour names of any operand left to ``transfer``)."""
    taken = {name for op in operands for name in (*op.uv_maps, *op.colors)}
    out = {}
    for op in operands:
        for name, (domain, kind, _values) in op.generic.items():
            if name not in taken and name not in out:
                out[name] = (domain, kind)
    return out


def _own(op, name, domain, kind):
    """The operand's values of the attribute, or None where it lacks it (or holds it otherwise)."""
    found = op.generic.get(name)
    return found[2] if found is not None and found[:2] == (domain, kind) else None


def defaults(count: int, kind: str) -> np.ndarray:
    """``count`` elements of Blender's default value of data type ``kind``: zero, or the identity (:data:`IDENTITY`)."""
    _prop, dtype, width, _ = TYPES[kind]
    out = np.zeros((count, width) if width > 1 else count, dtype=dtype)
    if kind in IDENTITY:
        out[:] = IDENTITY[kind]
    return out


def carried(operands, sources, tris, n_verts: int, kept=None) -> dict:
    """The result's values of every carried attribute but the edges' (left to the write: :func:`edge_columns`).

    Args:
        operands: ``bridge.Operand`` per field id.
        sources: (field ids (F,), source triangles (F,), corner weights (F, 3, 3)) of the result's F triangles.
        tris: (F, 3) the result's triangles; ``n_verts`` its vertices.
        kept: The kept surface's vertex sources (``vertex_field``, ``vertex_id``: a kept vertex takes its own value),
            or None.
    Returns:
        name -> (domain, data type, values): (F,) per face, (3F,) per corner (face after face), (V,) per point (a
        second axis for types of several values).
    """
    names = {name: found for name, found in carried_names(operands).items() if found[0] != "EDGE"}
    if not names:  # (most meshes: nothing to gather)
        return {}
    field_ids, triangle_ids, bary = (np.asarray(a) for a in sources)
    first = np.cumsum([0] + [len(op.tris) for op in operands])
    has = (field_ids >= 0) & (field_ids < len(operands)) & (triangle_ids >= 0)
    stacked = np.where(has, first[np.where(has, field_ids, 0)] + triangle_ids, 0).astype(np.int64)
    weights = np.where(has[:, None, None], np.asarray(bary, dtype=np.float32), np.float32(0.0))
    out = {}
    for name, (domain, kind) in names.items():
        own = [_own(op, name, domain, kind) for op in operands]
        if domain == "FACE":
            per_tri = [
                defaults(len(op.faces), kind) if v is None else v[op.faces] for op, v in zip(operands, own, strict=True)
            ]
            per_tri, values = np.concatenate(per_tri), defaults(len(has), kind)
            values[has] = per_tri[stacked[has]]
        else:
            index = [op.corners if domain == "CORNER" else op.tris for op in operands]
            values = _at_corners(kind, own, index, stacked, weights, has)
            if domain == "POINT":
                holds = np.array([v is not None for v in own])[np.where(has, field_ids, 0)] & has
                values = _at_points(values, np.repeat(holds, 3), own, (tris, n_verts, kept), kind)
        out[name] = (domain, kind, values.astype(TYPES[kind][1]))
    return out


def _at_corners(kind, own, index, stacked, weights, has) -> np.ndarray:
    """(3F, ...) one attribute at the result's corners, read off each face's source triangle (``index``: per operand
    its triangles' indices into its values): interpolated (``transfer``'s kernel), else the nearest corner's."""
    _prop, dtype, width, smooth = TYPES[kind]
    parts = [
        (ix, v) if v is not None else (np.zeros_like(ix), defaults(1, kind)) for ix, v in zip(index, own, strict=True)
    ]
    values, rows = transfer.stacked_parts(parts, width, dtype)
    if not len(rows) or not len(stacked):
        return defaults(3 * len(stacked), kind)
    if smooth:
        values = values.astype(np.float32)
        found = transfer.within_sources(runtime.engine().interpolate_corners(values, rows, stacked, weights), values)
    else:
        nearest = np.argmax(weights, axis=2)  # (F, 3) the source corner each result corner is nearest
        found = values[rows[stacked][np.arange(len(stacked))[:, None], nearest]].reshape(-1, width)
        found[np.repeat(~has, 3)] = defaults(1, kind).reshape(-1, width)
    return found if width > 1 else found[:, 0]


def _at_points(corner_values, holds, own, surface, kind) -> np.ndarray:
    """(V, ...) a point attribute at the result's vertices (``surface``: its triangles, vertex count and kept vertex
    sources or None): a corner's value at each (its corners read one source point), a corner whose face's operand
    ``holds`` the attribute where there is one (a vertex on a seam is in both operands' faces), a kept vertex's own."""
    tris, n_verts, kept = surface
    out = defaults(n_verts, kind)
    vertex = np.asarray(tris, dtype=np.int64).ravel()
    out[vertex] = corner_values
    out[vertex[holds]] = corner_values[holds]
    if kept is None:
        return out
    field, source = np.asarray(kept["vertex_field"], np.int64), np.asarray(kept["vertex_id"], np.int64)
    for k, v in enumerate(own):
        rows = np.flatnonzero((field == k) & (source >= 0))
        if v is not None and len(rows):
            out[rows] = v[source[rows]]
    return out


def edge_columns(operands) -> dict:
    """name -> (data type, per operand its (E,) edge values: Blender's default where it lacks them) of the edge
    attributes carried."""
    out = {}
    for name, (domain, kind) in carried_names(operands).items():
        if domain == "EDGE":
            own = [_own(op, name, domain, kind) for op in operands]
            parts = [
                defaults(len(op.edge_verts), kind) if v is None else v for op, v in zip(operands, own, strict=True)
            ]
            out[name] = (kind, parts)
    return out


def edge_fill(columns: dict) -> dict:
    """name -> the value of a result edge that is no operand's, for the attributes of ``columns``
    (:func:`edge_columns`) whose default is not zero."""
    return {name: IDENTITY[kind] for name, (kind, _parts) in columns.items() if kind in IDENTITY}


def whole_faces(values: dict, operands, whole: dict, rest, corner_rest) -> dict:
    """The carried ``values`` in ``polygons.as_polygons``' layout: the faces kept whole first (face and corner values
    copied from their own face and corners), then the triangles left (``rest``, ``corner_rest``)."""
    if not values:
        return {}
    corner_operand = np.repeat(whole["field"], whole["sizes"])
    corners = [np.flatnonzero(corner_operand == k) for k in range(len(operands))]  # each operand's, once
    out = {}
    for name, (domain, kind, v) in values.items():
        own = [_own(op, name, domain, kind) for op in operands]
        if domain == "FACE":
            parts = [
                defaults(len(op.loop_start), kind) if p is None else p for op, p in zip(operands, own, strict=True)
            ]
            first = np.cumsum([0] + [len(p) for p in parts])
            v = np.concatenate([np.concatenate(parts)[first[whole["field"]] + whole["face"]], v[rest]])
        elif domain == "CORNER":
            copied = defaults(len(whole["loops"]), kind)
            for rows, values_k in zip(corners, own, strict=True):
                if values_k is not None and len(rows):
                    copied[rows] = values_k[whole["loops"][rows]]
            v = np.concatenate([copied, v[corner_rest]])
        out[name] = (domain, kind, v)
    return out


def agree(values: dict, quads: int) -> np.ndarray:
    """(quads,) bool: the quads whose halves (rows 2k, 2k + 1) carry the same face values and, at their shared corners
    (``a`` and ``c``), the same corner values (floats within FLOAT_TOLERANCE of their range)."""
    ok = np.ones(quads, dtype=bool)
    for domain, kind, v in values.values():
        if domain == "FACE":
            same = v[0 : 2 * quads : 2] == v[1 : 2 * quads : 2]
            ok &= same.reshape(quads, -1).all(axis=1)
        elif domain == "CORNER":
            six = np.asarray(v[: 6 * quads]).reshape(quads, 6, -1)
            a, b = six[:, [0, 2]], six[:, [3, 4]]
            if TYPES[kind][3]:
                span = float(np.ptp(v)) if len(v) else 0.0
                ok &= (np.abs(a - b) <= FLOAT_TOLERANCE * span + 1e-6).all(axis=(1, 2))
            else:
                ok &= (a == b).all(axis=(1, 2))
    return ok
