"""Between Blender objects and numpy arrays: operands read out, results written back. The only module of the
pipeline that touches Blender's mesh data.

``read_operands`` reads each object's evaluated geometry (modifiers applied) in its local space with ``foreach_get``,
with its world matrix, into an :class:`Operand`; ``to_world`` moves vertices to world space in one matrix product.
``write_result_object`` builds a new mesh object with ``foreach_set`` (``update_result_object`` gives an existing one
new mesh data, in place). Nothing here loops over vertices in Python.
"""

from dataclasses import dataclass, field

import bpy
import numpy as np

from . import generic_attributes, repeats
from .edge_attributes import EDGE_ATTRIBUTES, kept_edge_values, known_columns, source_edges
from .transfer import OPERAND_ATTRIBUTE

# Attributes carried by name (or written by the add-on itself), never as generic ones (:mod:`.generic_attributes`).
NAMED_ATTRIBUTES = {"position", "material_index", "sharp_face", "custom_normal", OPERAND_ATTRIBUTE, *EDGE_ATTRIBUTES}
# Blender's own attributes, hidden from the attribute list, that sculpting keeps per face and per vertex: carried.
SCULPT_ATTRIBUTES = {".sculpt_face_set", ".sculpt_mask"}


@dataclass(eq=False)
class Operand:
    """One input object as read for a run: its evaluated local geometry and world matrix, and what its result faces
    carry over (per triangle of ``tris``: its face and its three corners; per face: material slot and shading; UV
    maps and colour attributes by name)."""

    obj: object  # the original object
    uid: int  # its session_uid: the cache's key for the object
    verts: np.ndarray  # (V, 3) float32, local space
    tris: np.ndarray  # (T, 3) int32 vertex indices of the loop triangles
    matrix: np.ndarray  # (4, 4) float64 world matrix
    corners: np.ndarray = None  # (T, 3) int32 face-corner (loop) indices of each triangle
    faces: np.ndarray = None  # (T,) int32 face (polygon) of each triangle
    face_material: np.ndarray = None  # (P,) int32 material slot of each face
    face_smooth: np.ndarray = None  # (P,) bool smooth shading of each face
    materials: list = field(default_factory=list)  # the object's slots' materials (None: an empty slot)
    uv_maps: dict = field(default_factory=dict)  # name -> (L, 2) float32 per corner
    colors: dict = field(default_factory=dict)  # name -> (domain "POINT" | "CORNER", data type, (N, 4) float32)
    corner_count: int = 0  # the mesh's face corners (loops)
    loop_start: np.ndarray = None  # (P,) int32 first corner of each face
    corner_vert: np.ndarray = None  # (L,) int32 vertex of each corner
    edge_verts: np.ndarray = None  # (E, 2) int32 vertices of each edge
    edge_attributes: dict = field(default_factory=dict)  # name -> (E,) values (``edge_attributes.EDGE_ATTRIBUTES``)
    custom_normals: np.ndarray = None  # (L, 3) float32 per corner, local space, where the mesh has custom normals
    shown: dict = field(default_factory=dict)  # "uv_render", "uv_active", "color_render", "color_active": names
    generic: dict = field(default_factory=dict)  # name -> (domain, data type, values): ``generic_attributes``

    @property
    def name(self) -> str:
        return self.obj.name

    def world(self) -> tuple[np.ndarray, np.ndarray]:
        """(V, 3) float32 world-space vertices and (T, 3) int32 triangles, outward as in local space."""
        return to_world(self.verts, self.tris, self.matrix)


def read_operands(objects, depsgraph) -> list[Operand]:
    """The evaluated geometry (modifiers applied), world matrix and carried attributes of each mesh object."""
    operands = []
    for obj in objects:
        evaluated = obj.evaluated_get(depsgraph)
        operands.append(read_mesh_operand(evaluated, np.array(evaluated.matrix_world, dtype=np.float64)))
    return operands


def read_mesh_operand(evaluated, matrix) -> Operand:
    """An evaluated object's mesh (``to_mesh()``: a mesh, or a text, curve, surface or metaball as Blender meshes it)
    read as an operand placed by ``matrix`` (4, 4) float64."""
    obj = evaluated.original
    mesh = evaluated.to_mesh()
    try:
        verts, tris, corners, faces = _triangles(mesh)
        corner_vert = _attribute(mesh, ".corner_vert", "value", np.int32, len(mesh.loops))
        repeated = repeats.repeated_faces(verts, corner_vert, _get(mesh.polygons, "loop_start", np.int32))
        if repeated.any():  # (a face laid on an earlier one: left out, :mod:`.repeats`)
            keep = ~repeated[faces]
            tris, corners, faces = tris[keep], corners[keep], faces[keep]
        operand = Operand(
            obj,
            obj.session_uid,
            verts,
            tris,
            matrix,
            corners=corners,
            faces=faces,
            face_material=_attribute(mesh, "material_index", "value", np.int32, len(mesh.polygons)),
            face_smooth=~_attribute(mesh, "sharp_face", "value", bool, len(mesh.polygons)),
            # as the evaluated object shows them (a Set Material node's too), each the file's own material
            materials=[None if slot.material is None else slot.material.original for slot in evaluated.material_slots],
            corner_count=len(mesh.loops),
            loop_start=_get(mesh.polygons, "loop_start", np.int32),
            corner_vert=corner_vert,
            edge_verts=_attribute(mesh, ".edge_verts", "value", np.int32, len(mesh.edges), 2),
        )
        for name, (_, dtype) in EDGE_ATTRIBUTES.items():
            if name in mesh.attributes:
                operand.edge_attributes[name] = _attribute(mesh, name, "value", dtype, len(mesh.edges))
        for layer in mesh.uv_layers:
            operand.uv_maps[layer.name] = _attribute(mesh, layer.name, "vector", np.float32, len(mesh.loops), 2)
        operand.shown = _shown(mesh)
        for attr in mesh.color_attributes:
            if attr.domain in ("POINT", "CORNER"):
                values = _get(attr.data, "color", np.float32, 4)
                operand.colors[attr.name] = (attr.domain, attr.data_type, values)
        if mesh.has_custom_normals:  # the normals Blender shades with, the custom ones applied
            operand.custom_normals = _get(mesh.corner_normals, "vector", np.float32, 3)
        operand.generic = _generic_attributes(mesh, {*NAMED_ATTRIBUTES, *operand.uv_maps, *operand.colors})
    finally:
        evaluated.to_mesh_clear()
    return operand


def _generic_attributes(mesh, taken) -> dict:
    """name -> (domain, data type, values) of the mesh's attributes carried as :mod:`.generic_attributes` (none of
    the names ``taken``, nor internal but sculpting's face sets and mask, nor of another domain or type than it
    carries)."""
    out = {}
    for attribute in mesh.attributes:
        name, domain, kind = attribute.name, attribute.domain, attribute.data_type
        internal = attribute.is_internal or name.startswith(".")
        if name in taken or domain not in generic_attributes.DOMAINS or internal and name not in SCULPT_ATTRIBUTES:
            continue
        if kind in generic_attributes.TYPES:
            prop, dtype, width, _ = generic_attributes.TYPES[kind]
            out[name] = (domain, kind, _get(attribute.data, prop, dtype, width))
    return out


def _triangles(mesh) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A mesh as Blender triangulates it: (V, 3) float32 vertices, (T, 3) int32 triangles (vertex indices), their
    (T, 3) int32 corners (loops) and (T,) int32 faces. Read through the attribute arrays where it can:
    ``loop_triangles``' own properties go item by item (26 ms for the three of them on 70 k triangles, against
    0.1 ms); a mesh of triangles alone is its own triangulation."""
    mesh.calc_loop_triangles()
    faces = _get(mesh.loop_triangle_polygons, "value", np.int32)
    # every face a triangle, in order (a face of fewer than 3 corners, which Blender's validation removes, breaks the
    # order: then the triangles are read)
    if len(mesh.loops) == 3 * len(faces) and np.array_equal(faces, np.arange(len(mesh.polygons), dtype=np.int32)):
        corners = (3 * faces[:, None] + np.arange(3, dtype=np.int32)).astype(np.int32)
    else:
        corners = _get(mesh.loop_triangles, "loops", np.int32, 3)
    verts = _attribute(mesh, "position", "vector", np.float32, len(mesh.vertices), 3)
    return verts, _attribute(mesh, ".corner_vert", "value", np.int32, len(mesh.loops))[corners], corners, faces


def _get(collection, prop, dtype, width=1) -> np.ndarray:
    """One property of every item of an RNA collection, by ``foreach_get``."""
    values = np.empty(len(collection) * width, dtype=dtype)
    collection.foreach_get(prop, values)
    return values.reshape(-1, width) if width > 1 else values


def _attribute(mesh, name, prop, dtype, count, width=1) -> np.ndarray:
    """A mesh attribute's values (zeros when the mesh has no such attribute)."""
    attribute = mesh.attributes.get(name)
    if attribute is None:
        return np.zeros((count, width) if width > 1 else count, dtype=dtype)
    return _get(attribute.data, prop, dtype, width)


def evaluated_local_mesh(obj, depsgraph) -> tuple[np.ndarray, np.ndarray]:
    """The evaluated (modifiers applied) triangles of a mesh object in its local space.

    Args:
        obj: A mesh object (original or evaluated).
        depsgraph: The evaluated depsgraph, e.g. ``context.evaluated_depsgraph_get()``.
    Returns:
        (V, 3) float32 local vertex positions and (T, 3) int32 triangles (polygons split into loop triangles).
    """
    evaluated = obj.evaluated_get(depsgraph)
    mesh = evaluated.to_mesh()
    try:
        verts, tris, _corners, _faces = _triangles(mesh)
    finally:
        evaluated.to_mesh_clear()
    return verts, tris


def world_matrix(obj, depsgraph) -> np.ndarray:
    """(4, 4) float64 evaluated world matrix of ``obj``."""
    return np.array(obj.evaluated_get(depsgraph).matrix_world, dtype=np.float64)


def to_world(verts, tris, matrix) -> tuple[np.ndarray, np.ndarray]:
    """Apply a (4, 4) world matrix to (V, 3) vertices; a mirroring matrix also flips the triangles' winding.

    Returns:
        (V, 3) float32 world-space vertices and (T, 3) int32 triangles, outward as in local space.
    """
    matrix = np.asarray(matrix, dtype=np.float64)
    world = (np.asarray(verts, dtype=np.float64) @ matrix[:3, :3].T + matrix[:3, 3]).astype(np.float32)
    tris = np.asarray(tris, dtype=np.int32)
    if np.linalg.det(matrix[:3, :3]) < 0.0:
        tris = tris[:, ::-1]
    return world, np.ascontiguousarray(tris)


def evaluated_mesh(obj, depsgraph) -> tuple[np.ndarray, np.ndarray]:
    """The evaluated geometry of a mesh object in world space: (V, 3) float32 vertices, (T, 3) int32 triangles."""
    verts, tris = evaluated_local_mesh(obj, depsgraph)
    return to_world(verts, tris, world_matrix(obj, depsgraph))


def world_bounds(objects, depsgraph) -> tuple[np.ndarray, np.ndarray]:
    """(min, max) world corners of the evaluated bounding boxes of ``objects`` (float64 (3,) each)."""
    corners = []
    for obj in objects:
        evaluated = obj.evaluated_get(depsgraph)
        local = np.array([tuple(c) for c in evaluated.bound_box], dtype=np.float64)
        corners.append(to_world(local, np.zeros((0, 3), np.int32), evaluated.matrix_world)[0])
    points = np.concatenate(corners).astype(np.float64)
    return points.min(axis=0), points.max(axis=0)


def _set_attribute(mesh, name, prop, values, collection, rna_prop):
    """Fill a built-in attribute from a numpy array, or the RNA collection where the attribute is not exposed."""
    attribute = mesh.attributes.get(name)
    if attribute is not None:
        attribute.data.foreach_set(prop, values.ravel())
    else:
        collection.foreach_set(rna_prop, values.ravel())


def _cache_edges(mesh, edge_cache) -> None:
    """Store a mesh's edges (their vertex pairs and each corner's edge) in ``edge_cache``, when one is given."""
    edge_verts, corner_edge = mesh.attributes.get(".edge_verts"), mesh.attributes.get(".corner_edge")
    if edge_cache is None or edge_verts is None or corner_edge is None:
        return
    pairs = np.empty(2 * len(mesh.edges), dtype=np.int32)
    edge_verts.data.foreach_get("value", pairs)
    corners = np.empty(len(mesh.loops), dtype=np.int32)
    corner_edge.data.foreach_get("value", corners)
    edge_cache["edge_verts"], edge_cache["corner_edge"] = pairs, corners


def _set_cached_edges(mesh, edge_cache) -> bool:
    """Give a mesh the edges cached for its triangles and update it; False when there is nothing to reuse."""
    if not edge_cache or "edge_verts" not in edge_cache or len(edge_cache["corner_edge"]) != len(mesh.loops):
        return False
    mesh.edges.add(len(edge_cache["edge_verts"]) // 2)
    edge_verts, corner_edge = mesh.attributes.get(".edge_verts"), mesh.attributes.get(".corner_edge")
    if edge_verts is None or corner_edge is None:
        return False
    edge_verts.data.foreach_set("value", edge_cache["edge_verts"])
    corner_edge.data.foreach_set("value", edge_cache["corner_edge"])
    mesh.update()
    return True


def _mirrored_edges(edge_cache):
    """The edges of triangles ``to_world`` flipped (a, b, c -> c, b, a): each triangle's first two corners swap edges;
    ``None`` (Blender derives them, nothing kept) when there are none yet."""
    if not edge_cache or "edge_verts" not in edge_cache:
        return None
    corner_edge = np.asarray(edge_cache["corner_edge"]).reshape(-1, 3)[:, [1, 0, 2]]
    return {"edge_verts": edge_cache["edge_verts"], "corner_edge": np.ascontiguousarray(corner_edge).ravel()}


def result_mesh(name, verts, tris, attributes=None, edge_cache=None):
    """A new mesh datablock from arrays.

    Args:
        name: Name of the mesh.
        verts: (V, 3) float32 vertices.
        tris: (F, 3) int32 triangles.
        attributes: What the faces carry (``transfer.face_attributes``): ``materials`` (the slots, ``None`` an empty
            one), ``material_index`` (F,), ``smooth`` (F,) bool, ``operand`` (F,) int (written as the face attribute
            ``transfer.OPERAND_ATTRIBUTE``), ``uv_maps`` {name: (3F, 2)} and ``colors`` {name: (data type, (3F, 4))}
            per corner, ``generic`` {name: (domain, data type, values)} (``generic_attributes.carried``),
            ``creases`` (E, 2) vertex pairs of edges to mark sharp (``sharp_edge``), ``polygons``
            (sizes (Q,), corner vertices) of faces written before the triangles (``polygons.as_polygons``: then
            every face and corner array covers them first); any may be missing (default: flat faces, no materials).
        edge_cache: Optional dict kept with these triangles: an empty one receives the edges Blender derives, a filled
            one gives them back, so writing the same triangles again skips deriving them.
    Returns:
        The new ``bpy.types.Mesh``.
    """
    attributes = attributes or {}
    verts = np.ascontiguousarray(verts, dtype=np.float32).reshape(-1, 3)
    tris = np.ascontiguousarray(tris, dtype=np.int32).reshape(-1, 3)
    mesh = bpy.data.meshes.new(name)
    # The contiguous attribute arrays take numpy buffers directly: ~10x faster than the per-element RNA collections.
    mesh.vertices.add(len(verts))
    _set_attribute(mesh, "position", "vector", verts, mesh.vertices, "co")
    sizes, corner_vert = attributes.get("polygons") or (np.zeros(0, np.int32), np.zeros(0, np.int32))
    corners = np.concatenate([np.asarray(corner_vert, dtype=np.int32), tris.ravel()])
    mesh.loops.add(len(corners))
    _set_attribute(mesh, ".corner_vert", "value", corners, mesh.loops, "vertex_index")
    mesh.polygons.add(len(sizes) + len(tris))
    poly_starts = np.cumsum(np.r_[0, sizes[:-1]]).astype(np.int32) if len(sizes) else np.zeros(0, np.int32)
    starts = np.r_[poly_starts, len(corner_vert) + np.arange(0, tris.size, 3)].astype(np.int32)
    mesh.polygons.foreach_set("loop_start", starts)
    for material in attributes.get("materials", ()):
        mesh.materials.append(material)
    if not _set_cached_edges(mesh, edge_cache):
        mesh.update(calc_edges=True)
        _cache_edges(mesh, edge_cache)
    if len(starts):
        _write_attributes(mesh, attributes, len(starts), len(verts))
    return mesh


def _write_attributes(mesh, attributes: dict, faces: int, vertex_count: int) -> None:
    """What the faces carry (``result_mesh``'s ``attributes``) written into ``mesh`` (its ``faces`` and
    ``vertex_count`` vertices made, its edges derived)."""
    creases = attributes.get("creases")
    if creases is not None and len(creases):
        _mark_sharp_edges(mesh, creases, vertex_count)
    if attributes.get("kept_edges") is not None:
        _carry_edge_attributes(mesh, *attributes["kept_edges"])
    if attributes.get("material_index") is not None:
        _new_attribute(mesh, "material_index", "INT", "FACE", "value", attributes["material_index"], np.int32)
    smooth = attributes.get("smooth")
    if smooth is None or not np.all(smooth):  # meshes without a "sharp_face" attribute are smooth
        # the attribute directly: Mesh.shade_flat() takes ~0.2 s on a million faces
        sharp = np.ones(faces, dtype=bool) if smooth is None else ~np.asarray(smooth, dtype=bool)
        _new_attribute(mesh, "sharp_face", "BOOLEAN", "FACE", "value", sharp, bool)
    if attributes.get("operand") is not None:
        _new_attribute(mesh, OPERAND_ATTRIBUTE, "INT", "FACE", "value", attributes["operand"], np.int32)
    for uv_name, values in attributes.get("uv_maps", {}).items():
        _new_attribute(mesh, uv_name, "FLOAT2", "CORNER", "vector", values, np.float32)
    for color_name, (kind, values) in attributes.get("colors", {}).items():
        layer = mesh.color_attributes.new(color_name, kind, "CORNER")
        layer.data.foreach_set("color", np.ascontiguousarray(values, dtype=np.float32).ravel())
    for name, (domain, kind, values) in attributes.get("generic", {}).items():
        prop, dtype, _width, _ = generic_attributes.TYPES[kind]
        _new_attribute(mesh, name, kind, domain, prop, values, dtype)
    _show(mesh, attributes.get("shown", {}))
    if attributes.get("custom_normals") is not None:  # zero vectors: Blender's own normal there
        mesh.normals_split_custom_set(np.ascontiguousarray(attributes["custom_normals"], dtype=np.float32))


def _shown(mesh) -> dict:
    """The names of a mesh's rendered and active UV maps and colour attributes."""
    shown = {"uv_render": next((layer.name for layer in mesh.uv_layers if layer.active_render), None)}
    shown["uv_active"] = mesh.uv_layers.active.name if mesh.uv_layers.active is not None else None
    colors = mesh.color_attributes
    shown["color_active"] = colors.active_color_name or None
    render = colors.render_color_index
    shown["color_render"] = colors[render].name if 0 <= render < len(colors) else None
    return shown


def _show(mesh, shown: dict) -> None:
    """Render and make active the UV map and colour attribute ``shown`` names (:func:`_shown`), where the mesh has
    them; else its first ones (what exporters and the viewport show)."""
    uv, colors = mesh.uv_layers, mesh.color_attributes
    if len(uv):
        uv[shown.get("uv_render") if shown.get("uv_render") in uv else 0].active_render = True
        uv.active = uv[shown.get("uv_active") if shown.get("uv_active") in uv else 0]
    if len(colors):
        names = [attribute.name for attribute in colors]
        render, active = shown.get("color_render"), shown.get("color_active")
        colors.render_color_index = names.index(render) if render in names else 0
        colors.active_color_index = names.index(active) if active in names else 0


def _mark_sharp_edges(mesh, creases, vertex_count):
    """Set ``sharp_edge`` on the mesh's edges between the vertex pairs ``creases`` (E, 2): only edges whose two
    vertices both lie on some crease are looked up among the creases' sorted keys (a few thousand of ~10^5 edges)."""
    pairs = np.empty(2 * len(mesh.edges), dtype=np.int32)
    mesh.attributes[".edge_verts"].data.foreach_get("value", pairs)
    pairs = pairs.reshape(-1, 2)
    creases = np.asarray(creases, dtype=np.int64).reshape(-1, 2)
    on_crease = np.zeros(vertex_count, dtype=bool)
    on_crease[creases.ravel()] = True
    candidates = np.flatnonzero(on_crease[pairs[:, 0]] & on_crease[pairs[:, 1]])
    ends = pairs[candidates].astype(np.int64)
    keys = ends.min(axis=1) * vertex_count + ends.max(axis=1)
    wanted = np.sort(creases.min(axis=1) * vertex_count + creases.max(axis=1))
    at = np.minimum(np.searchsorted(wanted, keys), len(wanted) - 1)
    sharp = np.zeros(len(pairs), dtype=bool)
    sharp[candidates[wanted[at] == keys]] = True
    _new_attribute(mesh, "sharp_edge", "BOOLEAN", "EDGE", "value", sharp, bool)


def _carry_edge_attributes(mesh, kept, operands):
    """The operands' UV seams, sharp edges and edge creases on the result's edges that are theirs (sharp where their
    source's is, not where they fold: :mod:`.edge_attributes`), and their other edge attributes (bevel weights),
    written whatever their values."""
    pairs = _get(mesh.attributes[".edge_verts"].data, "value", np.int32, 2)
    if "sharp_edge" in mesh.attributes:  # the folds marked (``_mark_sharp_edges``): not on the operands' own edges
        folded = _get(mesh.attributes["sharp_edge"].data, "value", bool)
        rows = np.flatnonzero(folded)  # (only those looked up: a few thousand of the bunny's 100 k edges)
        folded[rows[source_edges(kept, operands, pairs[rows])[0]]] = False
        mesh.attributes["sharp_edge"].data.foreach_set("value", folded)
    generic = generic_attributes.edge_columns(operands)
    columns = {name: (generic_attributes.TYPES[kind][1], parts) for name, (kind, parts) in generic.items()}
    fill = generic_attributes.edge_fill(generic)
    for name, values in kept_edge_values(kept, operands, pairs, {**known_columns(operands), **columns}, fill).items():
        if name in generic:
            prop, dtype, _width, _ = generic_attributes.TYPES[generic[name][0]]
            _new_attribute(mesh, name, generic[name][0], "EDGE", prop, values, dtype)
            continue
        kind, dtype = EDGE_ATTRIBUTES[name]
        if name == "sharp_edge" and name in mesh.attributes:
            values = values | _get(mesh.attributes[name].data, "value", bool)
        if values.any():
            _new_attribute(mesh, name, kind, "EDGE", "value", values, dtype)


def _new_attribute(mesh, name, kind, domain, prop, values, dtype):
    """Fill attribute ``name`` (created when missing) from a numpy array."""
    attribute = mesh.attributes.get(name) or mesh.attributes.new(name, kind, domain)
    attribute.data.foreach_set(prop, np.ascontiguousarray(values, dtype=dtype).ravel())


def write_result_object(context, name, verts, tris, attributes=None, *, collection=None, select=True, edge_cache=None):
    """Create a mesh object from arrays, linked next to the active object, made active and the only selection.

    Args:
        context: The operator's context (the result goes beside its active object: :func:`result_collection`).
        name: Name of the new object and mesh.
        verts: (V, 3) float32 world-space vertices (the object gets the identity transform).
        tris: (F, 3) int32 triangles.
        attributes: As for ``result_mesh``.
        collection: Collection receiving the object instead of the active object's (or the scene's).
        select: Make the new object active and the only selection; ``False`` leaves the selection alone.
        edge_cache: As for ``result_mesh``.
    Returns:
        The new ``bpy.types.Object``.
    """
    mesh = result_mesh(name, verts, tris, attributes, edge_cache)
    obj = bpy.data.objects.new(name, mesh)
    if collection is None:
        collection = result_collection(context.active_object, context.view_layer)
    (collection or context.scene.collection).objects.link(obj)
    if select:
        for other in context.selected_objects:
            other.select_set(False)
        obj.select_set(True)
        context.view_layer.objects.active = obj
    return obj


def result_collection(obj, view_layer):
    """The collection a result written beside ``obj`` goes to: ``obj``'s first collection that this file owns (not
    linked from a library: it takes no object) and that ``view_layer`` shows (not excluded nor disabled, and none of
    its parents: a result there is neither seen nor selectable); None (the scene's collection) where none is."""
    if obj is None:
        return None
    shown, todo = [], [view_layer.layer_collection]
    while todo:  # the layer collections not excluded nor hidden, their children looked at in turn
        layer = todo.pop()
        if layer.exclude or layer.hide_viewport or layer.collection.hide_viewport:
            continue
        shown.append(layer.collection)
        todo.extend(layer.children)
    for collection in obj.users_collection:
        if collection.library is None and any(collection == other for other in shown):
            return collection
    return None


def update_result_object(obj, verts, tris, attributes=None, edge_cache=None):
    """Give an existing mesh object new mesh data from world-space arrays, in place (same object, new mesh).

    The vertices are moved into the object's local space, so the result sits where the booleans put it whatever the
    object's transform. The previous mesh is removed when nothing else uses it, and the new one takes its name.

    Args:
        obj: A mesh object.
        verts, tris, attributes, edge_cache: As for ``write_result_object``.
    Returns:
        ``obj``.
    """
    matrix = np.array(obj.matrix_world, dtype=np.float64)
    if not np.allclose(matrix, np.eye(4)):
        verts, tris = to_world(verts, tris, np.linalg.inv(matrix))
        if np.linalg.det(matrix[:3, :3]) < 0.0:
            edge_cache = _mirrored_edges(edge_cache)
    old = obj.data
    name = old.name
    obj.data = result_mesh(name, verts, tris, attributes, edge_cache)
    if old.users == 0:
        bpy.data.meshes.remove(old)
        obj.data.name = name
    return obj
