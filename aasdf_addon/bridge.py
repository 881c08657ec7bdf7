"""Between Blender objects and numpy arrays: operands read out, results written back. The only module of the
pipeline that touches Blender's mesh data.

``read_operands`` reads each object's evaluated geometry (modifiers applied) in its local space with ``foreach_get``,
with its world matrix, into an :class:`Operand`; ``to_world`` moves vertices to world space in one matrix product.
``write_result_object`` builds a new mesh object with ``foreach_set`` (``update_result_object`` gives an existing one
new mesh data, in place). Nothing here loops over vertices in Python.
"""

from dataclasses import dataclass

import bpy
import numpy as np


@dataclass(eq=False)
class Operand:
    """One input object as read for a run: its evaluated local geometry and world matrix."""

    obj: object  # the original object
    uid: int  # its session_uid: the cache's key for the object
    verts: np.ndarray  # (V, 3) float32, local space
    tris: np.ndarray  # (T, 3) int32
    matrix: np.ndarray  # (4, 4) float64 world matrix

    @property
    def name(self) -> str:
        return self.obj.name

    def world(self) -> tuple[np.ndarray, np.ndarray]:
        """(V, 3) float32 world-space vertices and (T, 3) int32 triangles, outward as in local space."""
        return to_world(self.verts, self.tris, self.matrix)


def read_operands(objects, depsgraph) -> list[Operand]:
    """The evaluated geometry and world matrix of each mesh object, in order."""
    operands = []
    for obj in objects:
        verts, tris = evaluated_local_mesh(obj, depsgraph)
        operands.append(Operand(obj.original, obj.original.session_uid, verts, tris, world_matrix(obj, depsgraph)))
    return operands


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
        mesh.calc_loop_triangles()
        verts = np.empty(len(mesh.vertices) * 3, dtype=np.float32)
        mesh.vertices.foreach_get("co", verts)
        tris = np.empty(len(mesh.loop_triangles) * 3, dtype=np.int32)
        mesh.loop_triangles.foreach_get("vertices", tris)
    finally:
        evaluated.to_mesh_clear()
    return verts.reshape(-1, 3), tris.reshape(-1, 3)


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


def operand_materials(objects) -> tuple[list, np.ndarray]:
    """Material slots for a result and the slot of each operand.

    Returns:
        The distinct materials of all operands' slots, in order (plus one empty slot when some operand has no
        material but others do), and (len(objects),) int32: the slot of each operand's first material.
    """
    materials, slot_of = [], []
    firsts = [next((slot.material for slot in obj.material_slots if slot.material), None) for obj in objects]
    for obj in objects:
        for slot in obj.material_slots:
            if slot.material is not None and slot.material not in materials:
                materials.append(slot.material)
    for first in firsts:
        if first is None:
            if materials and None not in materials:
                materials.append(None)
            slot_of.append(materials.index(None) if None in materials else 0)
        else:
            slot_of.append(materials.index(first))
    return materials, np.asarray(slot_of, dtype=np.int32)


def is_smooth(obj) -> bool:
    """Whether most faces of a mesh object are smooth-shaded."""
    polygons = obj.data.polygons
    if not len(polygons):
        return False
    smooth = np.empty(len(polygons), dtype=bool)
    polygons.foreach_get("use_smooth", smooth)
    return bool(smooth.mean() >= 0.5)


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


def result_mesh(name, verts, tris, materials=(), face_material_index=None, smooth=False, edge_cache=None):
    """A new mesh datablock from arrays.

    Args:
        name: Name of the mesh.
        verts: (V, 3) float32 vertices.
        tris: (F, 3) int32 triangles.
        materials: Materials for the slots, in order (``None`` gives an empty slot).
        face_material_index: Optional (F,) int slot index of each face.
        smooth: Smooth shading for all faces.
        edge_cache: Optional dict kept with these triangles: an empty one receives the edges Blender derives, a filled
            one gives them back, so writing the same triangles again skips deriving them.
    Returns:
        The new ``bpy.types.Mesh``.
    """
    verts = np.ascontiguousarray(verts, dtype=np.float32).reshape(-1, 3)
    tris = np.ascontiguousarray(tris, dtype=np.int32).reshape(-1, 3)
    mesh = bpy.data.meshes.new(name)
    # The contiguous attribute arrays take numpy buffers directly: ~10x faster than the per-element RNA collections.
    mesh.vertices.add(len(verts))
    _set_attribute(mesh, "position", "vector", verts, mesh.vertices, "co")
    mesh.loops.add(tris.size)
    _set_attribute(mesh, ".corner_vert", "value", tris, mesh.loops, "vertex_index")
    mesh.polygons.add(len(tris))
    mesh.polygons.foreach_set("loop_start", np.arange(0, tris.size, 3, dtype=np.int32))
    for material in materials:
        mesh.materials.append(material)
    if face_material_index is not None and len(tris):
        index = mesh.attributes.get("material_index") or mesh.attributes.new("material_index", "INT", "FACE")
        index.data.foreach_set("value", np.ascontiguousarray(face_material_index, dtype=np.int32))
    if not _set_cached_edges(mesh, edge_cache):
        mesh.update(calc_edges=True)
        _cache_edges(mesh, edge_cache)
    if len(tris) and not smooth:  # meshes without a "sharp_face" attribute are smooth
        # the attribute directly: Mesh.shade_flat() takes ~0.2 s on a million faces
        sharp = mesh.attributes.get("sharp_face") or mesh.attributes.new("sharp_face", "BOOLEAN", "FACE")
        sharp.data.foreach_set("value", np.ones(len(tris), dtype=bool))
    return mesh


def write_result_object(
    context,
    name,
    verts,
    tris,
    materials=(),
    face_material_index=None,
    smooth=False,
    *,
    collection=None,
    select=True,
    edge_cache=None,
):
    """Create a mesh object from arrays, linked next to the active object, made active and the only selection.

    Args:
        context: The operator's context (its active object's first collection receives the result).
        name: Name of the new object and mesh.
        verts: (V, 3) float32 world-space vertices (the object gets the identity transform).
        tris: (F, 3) int32 triangles.
        materials: Materials for the slots, in order (``None`` gives an empty slot).
        face_material_index: Optional (F,) int slot index of each face.
        smooth: Smooth shading for all faces.
        collection: Collection receiving the object instead of the active object's (or the scene's).
        select: Make the new object active and the only selection; ``False`` leaves the selection alone.
        edge_cache: As for ``result_mesh``.
    Returns:
        The new ``bpy.types.Object``.
    """
    mesh = result_mesh(name, verts, tris, materials, face_material_index, smooth, edge_cache)
    obj = bpy.data.objects.new(name, mesh)
    if collection is None:
        active = context.active_object
        collection = active.users_collection[0] if active is not None and active.users_collection else None
    (collection or context.scene.collection).objects.link(obj)
    if select:
        for other in context.selected_objects:
            other.select_set(False)
        obj.select_set(True)
        context.view_layer.objects.active = obj
    return obj


def update_result_object(obj, verts, tris, materials=(), face_material_index=None, smooth=False, edge_cache=None):
    """Give an existing mesh object new mesh data from world-space arrays, in place (same object, new mesh).

    The vertices are moved into the object's local space, so the result sits where the booleans put it whatever the
    object's transform. The previous mesh is removed when nothing else uses it, and the new one takes its name.

    Args:
        obj: A mesh object.
        verts, tris, materials, face_material_index, smooth, edge_cache: As for ``write_result_object``.
    Returns:
        ``obj``.
    """
    matrix = np.array(obj.matrix_world, dtype=np.float64)
    if not np.allclose(matrix, np.eye(4)):
        verts, tris = to_world(verts, tris, np.linalg.inv(matrix))
    old = obj.data
    name = old.name
    obj.data = result_mesh(name, verts, tris, materials, face_material_index, smooth, edge_cache)
    if old.users == 0:
        bpy.data.meshes.remove(old)
        obj.data.name = name
    return obj
