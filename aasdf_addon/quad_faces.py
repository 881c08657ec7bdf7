"""Remeshed surfaces written as quads, as Blender's Voxel Remesh writes them.

The engine gives a remeshed surface as polygons (``AdaptiveField.to_mesh(quads=True)``: the quads first, then
triangles). The add-on's stages work on triangles (each face's source, its attributes, its edges), so the polygons are
first taken apart into their fans (:func:`fans`: quad k is rows 2k and 2k + 1, ``a b c`` and ``a c d``), and put back
together just before writing (:func:`quads_back`): a quad whose two halves carry the same material, shading and operand
(and face attributes), and the same UVs, colours and corner attributes at the two corners they share, is written as one
face. A quad across a seam of its sources (a UV island's edge, a colour border, a material change) stays two triangles,
each with its own corner values. Arrays only; ``bridge.result_mesh`` writes the layout (``attributes["polygons"]``).
"""

import numpy as np

from .generic_attributes import agree

# Corner values of the two halves at a shared corner agree within this fraction of the first half's mean UV edge
# (plus an absolute 1e-6: a map that is zero everywhere); farther apart, a seam runs along the diagonal.
UV_TOLERANCE = 0.05


# Corner colours agree within this (a byte colour's step is 1/255).
COLOR_TOLERANCE = 0.5 / 255.0


def fans(faces, sizes) -> tuple[np.ndarray, int]:
    """(T, 3) int32 triangles of polygons whose quads come first (``to_mesh(quads=True)``), each quad ``a b c d``
    as rows ``a b c``, ``a c d``, and the number of quads."""
    faces, sizes = np.asarray(faces, dtype=np.int32), np.asarray(sizes)
    count = int(np.count_nonzero(sizes == 4))
    quads = faces[: 4 * count].reshape(-1, 4)
    halves = np.take(quads, [0, 1, 2, 0, 2, 3], axis=1).reshape(-1, 3)
    return np.concatenate([halves, faces[4 * count :].reshape(-1, 3)]), count


def quads_back(result: dict, quads: int) -> dict:
    """``result`` (``pipeline.extract`` with ``attributes``, its first ``2 * quads`` triangles the halves of quads)
    with each quad whose halves agree (:func:`mergeable`) written as one face: those faces first
    (``attributes["polygons"]``), then the triangles left, each attribute in that layout. Polygons already there
    (``polygons.as_polygons``: an operand's faces kept whole, before the triangles) stay first."""
    attrs = result["attributes"]
    if not quads:
        return result
    sizes, corner_vert = attrs.get("polygons") or (np.zeros(0, np.int32), np.zeros(0, np.int32))
    faces_before, corners_before = len(sizes), int(np.sum(sizes))
    triangles = _triangles_part(attrs, faces_before, corners_before)
    tris = result["tris"]
    first = 2 * np.flatnonzero(mergeable(triangles, quads))
    if not len(first):
        return result
    rest = np.ones(len(tris), dtype=bool)
    rest[first] = rest[first + 1] = False
    corners = (3 * first[:, None] + np.array([0, 1, 2, 5])).ravel()  # a b c, d
    corner_rest = np.repeat(rest, 3)
    out = dict(attrs)
    out["polygons"] = (
        np.r_[sizes, np.full(len(first), 4)].astype(np.int32),
        np.r_[corner_vert, np.take(tris, corners)].astype(np.int32),
    )

    def faces(values):
        mine = values[faces_before:]
        return np.concatenate([values[:faces_before], mine[first], np.compress(rest, mine, axis=0)])

    def corner_values(values):
        mine = values[corners_before:]
        parts = (values[:corners_before], np.take(mine, corners, axis=0), np.compress(corner_rest, mine, axis=0))
        return np.concatenate(parts)

    for name in ("material_index", "smooth", "operand"):
        if attrs.get(name) is not None:
            out[name] = faces(attrs[name]).astype(attrs[name].dtype)
    out["uv_maps"] = {k: corner_values(v) for k, v in attrs.get("uv_maps", {}).items()}
    out["colors"] = {k: (kind, corner_values(v)) for k, (kind, v) in attrs.get("colors", {}).items()}
    out["generic"] = {
        name: (domain, kind, faces(v) if domain == "FACE" else corner_values(v) if domain == "CORNER" else v)
        for name, (domain, kind, v) in attrs.get("generic", {}).items()
    }
    if attrs.get("custom_normals") is not None:
        out["custom_normals"] = corner_values(attrs["custom_normals"])
    edges = _polygon_edges(result["edges"], first, rest) if not faces_before else {}
    return {**result, "tris": np.compress(rest, tris, axis=0), "attributes": out, "edges": edges}


def _triangles_part(attrs: dict, faces_before: int, corners_before: int) -> dict:
    """The attributes of the triangles alone, after the polygons written before them."""
    out = {name: attrs[name][faces_before:] for name in ("material_index", "smooth", "operand") if name in attrs}
    out["uv_maps"] = {k: v[corners_before:] for k, v in attrs.get("uv_maps", {}).items()}
    out["colors"] = {k: (kind, v[corners_before:]) for k, (kind, v) in attrs.get("colors", {}).items()}
    out["generic"] = {
        name: (domain, kind, v[faces_before:] if domain == "FACE" else v[corners_before:] if domain == "CORNER" else v)
        for name, (domain, kind, v) in attrs.get("generic", {}).items()
    }
    return out


def _polygon_edges(edges: dict, first, rest) -> dict:
    """The triangles' edge cache (``bridge.result_mesh``: ``edge_verts`` flat pairs, ``corner_edge`` per corner)
    for the polygons: each quad's corners take their halves' outer edges (``a b``, ``b c`` of the first, ``c d``,
    ``d a`` of the second), the diagonals go and the edges are numbered again. Empty when there is none to reuse."""
    if not edges or "corner_edge" not in edges:
        return {}
    corner_edge = np.asarray(edges["corner_edge"]).reshape(-1, 3)
    quad_edges = np.take(corner_edge, (3 * first[:, None] + np.array([0, 1, 4, 5])).ravel())  # a b, b c | c d, d a
    used = np.concatenate([quad_edges, np.compress(rest, corner_edge, axis=0).ravel()])
    keep = np.zeros(len(edges["edge_verts"]) // 2, dtype=bool)
    keep[used] = True
    number = np.cumsum(keep, dtype=np.int32) - 1  # (int32 sums: 3 times as fast as a bool array's default)
    pairs = np.compress(keep, np.asarray(edges["edge_verts"]).reshape(-1, 2), axis=0)  # (rows by a mask: 4x)
    return {"edge_verts": pairs.ravel(), "corner_edge": number[used]}


def mergeable(attrs: dict, quads: int) -> np.ndarray:
    """(quads,) bool: the quads whose two halves (rows 2k, 2k + 1) carry the same face attributes and the same
    corner attributes at their shared corners (``a`` and ``c``: corners 0 and 2 of the first, 0 and 1 of the
    second)."""
    ok = np.ones(quads, dtype=bool)
    for name in ("material_index", "smooth", "operand"):
        values = attrs.get(name)
        if values is not None and len(values):
            ok &= values[0 : 2 * quads : 2] == values[1 : 2 * quads : 2]
    for values in attrs.get("uv_maps", {}).values():
        uv = np.asarray(values, dtype=np.float32)[: 6 * quads].reshape(quads, 6, 2)
        u, v = uv[:, :, 0], uv[:, :, 1]  # (column by column: reductions over rows of 2 or 3 are several times slower)
        scale = sum(np.hypot(u[:, (k + 1) % 3] - u[:, k], v[:, (k + 1) % 3] - v[:, k]) for k in range(3)) / 3.0
        jump = np.maximum(_gap(uv[:, 0], uv[:, 3]), _gap(uv[:, 2], uv[:, 4]))
        ok &= jump <= UV_TOLERANCE * scale + 1e-6
    for _kind, values in attrs.get("colors", {}).values():
        rgba = np.asarray(values, dtype=np.float32)[: 6 * quads].reshape(quads, 6, 4)
        ok &= np.maximum(_gap(rgba[:, 0], rgba[:, 3]), _gap(rgba[:, 2], rgba[:, 4])) <= COLOR_TOLERANCE
    return ok & agree(attrs.get("generic", {}), quads)


def _gap(a, b) -> np.ndarray:
    """(N,) the largest difference of rows ``a`` and ``b`` (N, W), column by column."""
    gap = np.abs(a[:, 0] - b[:, 0])
    for k in range(1, a.shape[1]):
        gap = np.maximum(gap, np.abs(a[:, k] - b[:, k]))
    return gap
