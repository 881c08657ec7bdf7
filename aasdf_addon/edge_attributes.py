"""Edge attributes of kept faces: UV seams, sharp edges and edge creases of the operands, where a result edge is one of
their own edges.

An edge of the result whose two ends are vertices of one operand's kept faces, and which that operand has as an edge,
takes the operand's values of ``uv_seam``, ``sharp_edge`` and ``crease_edge``, and of any other edge attribute it has
(bevel weights: :mod:`.generic_attributes`). Such an edge is sharp where its source's is, whatever its fold (every
fold past 30 degrees was marked sharp too, and a smooth-shaded low-polygon cylinder came back flat); the other edges
are sharp where the surface folds. Arrays only: ``bridge`` reads the operands' edges and writes the result's.
"""

import numpy as np

# name -> (Blender's attribute type, numpy dtype) of the edge attributes carried over
EDGE_ATTRIBUTES = {"uv_seam": ("BOOLEAN", bool), "sharp_edge": ("BOOLEAN", bool), "crease_edge": ("FLOAT", np.float32)}


def known_columns(operands) -> dict:
    """name -> (numpy dtype, per operand its (E,) values or None) of the edge attributes of EDGE_ATTRIBUTES some
    operand has."""
    names = sorted({name for op in operands for name in op.edge_attributes})
    return {name: (EDGE_ATTRIBUTES[name][1], [op.edge_attributes.get(name) for op in operands]) for name in names}


def kept_edge_values(
    kept: dict, operands, edge_verts: np.ndarray, columns: dict | None = None, fill: dict | None = None
) -> dict:
    """Per result edge, its source edge's attribute values.

    Args:
        kept: The kept surface's vertex sources (``vertex_field``, ``vertex_id``; ``AdaptiveField.kept_surface``).
        operands: ``bridge.Operand`` per field id, with ``edge_verts``.
        edge_verts: (E, 2) int result vertex pairs.
        columns: name -> (numpy dtype, per operand its (E_k, ...) edge values or None: zeros); default: the
            operands' ``edge_attributes`` (:func:`known_columns`).
        fill: name -> the value of an edge that is no operand's, where it is not zero.
    Returns:
        name -> (E, ...) values (``fill``'s or zeros where the edge is no operand's) for each attribute of ``columns``.
    """
    columns = known_columns(operands) if columns is None else columns
    if not columns or not len(edge_verts):
        return {}
    rows, source_edge = source_edges(kept, operands, edge_verts)
    out = {}
    for name, (dtype, parts) in columns.items():
        shape = next((np.shape(p)[1:] for p in parts if p is not None), ())
        stacked = np.concatenate(
            [
                np.zeros((len(op.edge_verts), *shape), dtype) if p is None else np.asarray(p, dtype=dtype)
                for op, p in zip(operands, parts, strict=True)
            ]
        )
        values = np.zeros((len(edge_verts), *shape), dtype=dtype)
        if fill is not None and name in fill:
            values[:] = fill[name]
        values[rows] = stacked[source_edge]
        out[name] = values
    return out


def source_edges(kept: dict, operands, edge_verts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(rows, source_edge)``: the result edges (rows of ``edge_verts``) that are an operand's own edge between two
    of its kept vertices, and that edge's row among all the operands' edges, stacked in order."""
    if not len(edge_verts) or not operands:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    field, vertex = kept["vertex_field"].astype(np.int64), kept["vertex_id"].astype(np.int64)
    a, b = edge_verts[:, 0].astype(np.int64), edge_verts[:, 1].astype(np.int64)
    rows = np.flatnonzero((field[a] == field[b]) & (field[a] >= 0) & (vertex[a] >= 0) & (vertex[b] >= 0))
    rows = rows[field[a[rows]] < len(operands)]
    width = 1 + max(len(op.verts) for op in operands)
    source_keys = np.concatenate(
        [_keys(k, op.edge_verts[:, 0], op.edge_verts[:, 1], width) for k, op in enumerate(operands)]
    )
    order = np.argsort(source_keys)
    wanted = _keys(field[a[rows]], vertex[a[rows]], vertex[b[rows]], width)
    at = np.minimum(np.searchsorted(source_keys[order], wanted), max(len(order) - 1, 0))
    found = len(order) > 0
    hit = (source_keys[order][at] == wanted) if found else np.zeros(len(rows), dtype=bool)
    return rows[hit], order[at[hit]]


def _keys(operand, u, v, width: int) -> np.ndarray:
    u, v = np.asarray(u, dtype=np.int64), np.asarray(v, dtype=np.int64)
    return (np.asarray(operand, dtype=np.int64) * width + np.minimum(u, v)) * width + np.maximum(u, v)
