"""Which objects are operands, and their evaluated geometry read whatever their type.

Every object with geometry takes part by what Blender evaluates it to: a mesh, a text, a curve (its extrusion or
bevel), a surface or a metaball (``evaluated_get(depsgraph).to_mesh()``), plus the instances its modifiers, geometry
nodes or instancing (on its vertices or faces) make, realized into the same local space; an empty that instances a
collection takes part by its instances. ``read_operands`` gives one ``bridge.Operand`` per object,
so the cache keys fields by this evaluated geometry and places them by the object's transform, as for meshes. Objects
without geometry (other empties, cameras, lights) are refused by name, as is a text or curve that evaluates to no
faces.
"""

import bpy
import numpy as np

from . import bridge, runtime

# Object types whose evaluated geometry becomes a mesh.
GEOMETRY_TYPES = ("MESH", "CURVE", "FONT", "SURFACE", "META")
KINDS = {
    "EMPTY": "an empty",
    "CAMERA": "a camera",
    "LIGHT": "a light",
    "LIGHT_PROBE": "a light probe",
    "SPEAKER": "a speaker",
    "ARMATURE": "an armature",
    "LATTICE": "a lattice",
}
OPERAND_TYPES_TEXT = "mesh, text, curve, surface or metaball"


def is_operand(obj) -> bool:
    """Whether ``obj`` is an object whose geometry can take part (whatever its data holds right now): one with
    geometry, or an empty that instances a collection (a linked asset)."""
    return obj is not None and (obj.type in GEOMETRY_TYPES or _instances_collection(obj))


def _instances_collection(obj) -> bool:
    """Whether ``obj`` is an empty instancing a collection."""
    return obj.type == "EMPTY" and obj.instance_type == "COLLECTION" and obj.instance_collection is not None


def refusal(obj) -> str:
    """The sentence refusing an object that has no geometry."""
    kind = KINDS.get(obj.type, f"of type {obj.type.replace('_', ' ').lower()}")
    return f"'{obj.name}' is {kind} and has no geometry: use a {OPERAND_TYPES_TEXT} object"


def not_evaluated(obj, depsgraph) -> bool:
    """Whether Blender leaves ``obj`` unevaluated (disabled in viewports, in a collection excluded from the view layer
    or disabled, or not in the view layer at all) while it has something to evaluate: a metaball, modifiers shown in
    the viewport, shape keys, constraints, a parent or animation (read as it is, it lost them: an Array's copies, a
    Geometry Nodes mesh, a cutter where it was before its parent moved). A static mesh of its own is read as it is."""
    if obj.evaluated_get(depsgraph).is_evaluated:
        return False
    data = obj.data
    return (
        obj.type == "META"
        or any(modifier.show_viewport for modifier in obj.modifiers)
        or getattr(data, "shape_keys", None) is not None
        or len(obj.constraints) > 0
        or obj.parent is not None
        or _animated(obj)
        or _animated(data)
    )


def _animated(block) -> bool:
    """Whether an object's or its data's animation (an action, drivers or NLA tracks) may move or change it."""
    animation = getattr(block, "animation_data", None)
    return animation is not None and (
        animation.action is not None or len(animation.drivers) > 0 or len(animation.nla_tracks) > 0
    )


def unevaluated(obj) -> str:
    """The sentence refusing an object Blender does not evaluate (:func:`not_evaluated`)."""
    return (
        f"'{obj.name}' is not evaluated (it is disabled in viewports, its collection is excluded or disabled, or it is "
        "not in this view layer), so its modifiers, shape keys, constraints, parent or animation would be left out: "
        "enable it (hide it with H instead) or link it into the scene"
    )


def selected_operands(context) -> list:
    """The active object (selected or not) when it has geometry, followed by the other selected objects."""
    active = context.active_object
    first = [active] if is_operand(active) else []
    return first + [obj for obj in context.selected_objects if obj not in first]


def read_operands(objects, depsgraph) -> list:
    """One ``bridge.Operand`` per object: its evaluated geometry in its own space (its instances realized into it),
    its world matrix and what its faces carry.

    Raises:
        AasdfError: Naming the objects that have no geometry or that Blender does not evaluate (:func:`not_evaluated`),
            or a text or curve that evaluates to no faces.
    """
    engine = runtime.engine()
    refused = [refusal(obj) for obj in objects if not is_operand(obj)]
    refused += [unevaluated(obj) for obj in objects if is_operand(obj) and not_evaluated(obj, depsgraph)]
    if refused:
        raise engine.AasdfError("; ".join(refused))
    operands = []
    for obj in objects:
        evaluated = obj.evaluated_get(depsgraph)
        matrix = np.array(evaluated.matrix_world, dtype=np.float64)
        pieces = instance_pieces(evaluated, matrix, depsgraph)
        operand = None if obj.type == "EMPTY" else bridge.read_mesh_operand(evaluated, matrix)
        if pieces and (operand is None or not len(operand.tris)):  # (instances alone: the first stands for it)
            operand = pieces.pop(0)
            operand.obj, operand.uid, operand.matrix = obj, obj.session_uid, matrix
        if operand is None:
            raise engine.AasdfError(no_instances(obj))
        if pieces:
            operand = joined(operand, pieces)
        if not len(operand.tris):
            raise engine.AasdfError(no_faces(obj))
        operands.append(operand)
    return operands


def no_instances(obj) -> str:
    """The sentence refusing an empty that instances nothing: its collection has no geometry, or is disabled in
    viewports (Blender instances nothing of it there)."""
    collection = obj.instance_collection
    if collection is not None and collection.hide_viewport and any(map(is_operand, collection.all_objects)):
        return (
            f"'{obj.name}' instances the collection '{collection.name}', which is disabled in viewports, so Blender "
            "instances nothing of it: enable it in viewports"
        )
    return f"'{obj.name}' instances no geometry: its collection has no {OPERAND_TYPES_TEXT}"


def no_faces(obj) -> str:
    """The sentence refusing an object that evaluates to no faces, saying why where it can: a mesh without faces (or
    whose modifiers remove them), a metaball whose surface its family's base makes (Blender meshes a family as its base
    object, the one named without a number), a text without characters, a curve without splines."""
    name = obj.name
    if obj.type == "MESH":
        return f"'{name}' has no faces (after its modifiers): add some to it, or leave it out of the selection"
    if obj.type == "META":
        base = bpy.data.objects.get(name.rsplit(".", 1)[0])
        if base is not None and base is not obj and base.type == "META":
            family = base.name
            return f"'{name}' is part of the metaball '{family}', whose object makes their surface: use '{family}'"
    if obj.type == "FONT" and not obj.data.body.strip():
        return f"'{name}' has no characters: type some text into it"
    if obj.type in ("CURVE", "SURFACE") and not len(obj.data.splines):
        return f"'{name}' has no splines: draw one into it"
    return f"'{name}' has no faces: give it an extrusion or a bevel (its Geometry settings) or fill it"


def instance_pieces(evaluated, matrix, depsgraph) -> list:
    """The instances ``evaluated`` makes (geometry nodes, instancing modifiers, instancing on its vertices or faces,
    a collection it instances), each with geometry read as an operand in the object's own space; empty when it makes
    none or its matrix has no inverse (refused later by ``transforms``)."""
    nodes = any(modifier.type == "NODES" for modifier in evaluated.modifiers)
    if not nodes and not evaluated.particle_systems and evaluated.instance_type == "NONE":
        return []
    try:
        to_local = np.linalg.inv(matrix)
    except np.linalg.LinAlgError:
        return []
    if not np.all(np.isfinite(to_local)):
        return []
    pieces = []
    for instance in depsgraph.object_instances:
        if not instance.is_instance or instance.parent is None or instance.parent.original != evaluated.original:
            continue
        if instance.object.type not in GEOMETRY_TYPES:  # (a light or an empty in an instanced collection)
            continue
        placed = to_local @ np.array(instance.matrix_world, dtype=np.float64)
        piece = bridge.read_mesh_operand(instance.object, placed)
        if len(piece.tris):
            piece.verts, piece.tris = bridge.to_world(piece.verts, piece.tris, placed)
            pieces.append(piece)
    return pieces


def joined(operand, pieces):
    """``operand`` with the geometry of ``pieces`` (operands already in its space) appended: vertices, triangles,
    corners and faces renumbered; the operand's UV maps, colours, custom normals and other attributes kept, zeros for a
    part that lacks one (zero custom normals: Blender's own there), as Blender's Join does. (Kept only where every part
    had them, a geometry-nodes instance dropped the base mesh's second UV map and its colours, and its custom normals
    ran past their corners: an IndexError.)"""
    parts = [operand, *pieces]
    vert_offsets = np.cumsum([0] + [len(p.verts) for p in parts])[:-1]
    corner_offsets = np.cumsum([0] + [p.corner_count for p in parts])[:-1]
    face_offsets = np.cumsum([0] + [len(p.face_material) for p in parts])[:-1]
    operand.verts = np.concatenate([p.verts for p in parts]).astype(np.float32)
    operand.tris = _renumbered([p.tris for p in parts], vert_offsets)
    operand.corners = _renumbered([p.corners for p in parts], corner_offsets)
    operand.faces = _renumbered([p.faces for p in parts], face_offsets)
    operand.face_material = np.concatenate([p.face_material for p in parts]).astype(np.int32)
    operand.face_smooth = np.concatenate([p.face_smooth for p in parts])
    operand.corner_count = sum(p.corner_count for p in parts)
    operand.loop_start = _renumbered([p.loop_start for p in parts], corner_offsets)
    operand.corner_vert = _renumbered([p.corner_vert for p in parts], vert_offsets)
    operand.edge_verts = _renumbered([p.edge_verts for p in parts], vert_offsets).reshape(-1, 2)
    operand.edge_attributes = {
        name: np.concatenate([p.edge_attributes.get(name, np.zeros(len(p.edge_verts), values.dtype)) for p in parts])
        for name, values in operand.edge_attributes.items()
    }
    corners = lambda p: p.corner_count  # noqa: E731
    operand.uv_maps = {name: _filled(parts, lambda p, n=name: p.uv_maps.get(n), corners) for name in operand.uv_maps}
    operand.colors = {
        name: (domain, data_type, _filled(parts, lambda p, n=name, d=domain: _of(p.colors, n, d), _count(domain)))
        for name, (domain, data_type, _values) in operand.colors.items()
    }
    operand.generic = {
        name: (domain, kind, _filled(parts, lambda p, n=name, d=(domain, kind): _of(p.generic, n, *d), _count(domain)))
        for name, (domain, kind, _values) in operand.generic.items()
    }
    if operand.custom_normals is not None:
        operand.custom_normals = _filled(parts, lambda p: p.custom_normals, corners)
    return operand


def _of(attributes: dict, name: str, *kind):
    """An attribute's values where it is of ``kind`` (its leading entries: domain, data type), else None."""
    found = attributes.get(name)
    return found[-1] if found is not None and tuple(found[: len(kind)]) == kind else None


def _count(domain: str):
    """The number of a part's elements in ``domain``."""
    return lambda p: {"POINT": len(p.verts), "EDGE": len(p.edge_verts), "FACE": len(p.face_material)}.get(
        domain, p.corner_count
    )


def _filled(parts, values_of, count_of) -> np.ndarray:
    """Each part's values (``values_of``), zeros shaped as the first's for a part without them."""
    first = values_of(parts[0])
    return np.concatenate(
        [
            found if (found := values_of(p)) is not None else np.zeros((count_of(p), *first.shape[1:]), first.dtype)
            for p in parts
        ]
    )


def _renumbered(arrays, offsets) -> np.ndarray:
    """Index arrays of several parts as one int32 array, each part's indices shifted by its offset."""
    return np.concatenate([array + offset for array, offset in zip(arrays, offsets, strict=True)]).astype(np.int32)
