"""Every AASDF setting, declared once: property factories used by the scene's settings (``Scene.aasdf``), the
operators, the CSG tree and its nodes, so a setting has one name and one description wherever it appears. A caller may
change a factory's default or add an ``update`` callback, never its description.
"""

import bpy
from bpy.props import BoolProperty, EnumProperty, FloatProperty, IntProperty, PointerProperty, StringProperty

# (identifier, label, description) items for the boolean operation; ``sdf_difference(a, b)`` is *a minus b*.
OPERATIONS = (
    ("UNION", "Union", "Everything inside any operand"),
    ("INTERSECT", "Intersect", "Only what is inside every operand"),
    ("DIFFERENCE", "Difference", "The active (first) operand minus all the others"),
)


# How a blend shapes a seam: rounded (polynomial smooth minimum) or a flat bevel.
BLEND_MODES = (
    ("ROUND", "Round", "A rounded fillet along the seams"),
    ("CHAMFER", "Chamfer", "A flat bevel along the seams, meeting each face Blend away from the seam"),
)

# Which side of a surface a shell's wall lies on.
SHELL_SIDES = (
    ("INSIDE", "Inside", "The wall inside the surface: the outside stays where it is"),
    ("OUTSIDE", "Outside", "The wall outside the surface: the inside stays where it is"),
    ("CENTER", "Center", "The wall centred on the surface"),
)

CSG_TREE = "AASDF_NT_csg"  # bl_idname of the node tree (``aasdf_addon.nodes``)

_ALLOWED = {"default", "update"}


def _make(kind, options, overrides):
    unknown = set(overrides) - _ALLOWED
    if unknown:
        raise TypeError(f"A setting's {sorted(unknown)} are declared once, in aasdf_addon.properties")
    return kind(**{**options, **overrides})


def operation_property(**overrides):
    options = {
        "name": "Operation",
        "description": "Boolean to apply; Difference subtracts the other operands from the active (first) one",
        "items": OPERATIONS,
        "default": "DIFFERENCE",
    }
    return _make(EnumProperty, options, overrides)


def voxel_size_property(**overrides):
    options = {
        "name": "Voxel Size",
        "description": "Edge length of the finest voxels; 0 derives it from Resolution",
        "default": 0.0,
        "min": 0.0,
        "soft_max": 1.0,
        "precision": 4,
        "subtype": "DISTANCE",
    }
    return _make(FloatProperty, options, overrides)


def resolution_property(**overrides):
    options = {
        "name": "Resolution",
        "description": "Finest voxels along the diagonal of the inputs' combined bounding box (used when Voxel Size "
        "is 0)",
        "default": 256,
        "min": 8,
        "soft_max": 1024,
        "max": 8192,
    }
    return _make(IntProperty, options, overrides)


def levels_property(**overrides):
    options = {
        "name": "Levels",
        "description": "Octree levels: cells grow coarser away from the surface",
        "default": 4,
        "min": 1,
        "max": 12,
    }
    return _make(IntProperty, options, overrides)


def padding_property(**overrides):
    options = {
        "name": "Padding",
        "description": "Finest voxels kept around the surface on each side",
        "default": 1,
        "min": 1,
        "max": 32,
    }
    return _make(IntProperty, options, overrides)


def blend_property(**overrides):
    options = {
        "name": "Blend",
        "description": "Radius of the smooth blend along the seams; 0 keeps sharp edges",
        "default": 0.0,
        "min": 0.0,
        "soft_max": 1.0,
        "precision": 3,
        "subtype": "DISTANCE",
    }
    return _make(FloatProperty, options, overrides)


def blend_mode_property(**overrides):
    options = {
        "name": "Blend Mode",
        "description": "How Blend shapes the seams: a rounded fillet or a flat chamfer",
        "items": BLEND_MODES,
        "default": "ROUND",
    }
    return _make(EnumProperty, options, overrides)


def thickness_property(**overrides):
    options = {
        "name": "Thickness",
        "description": "Gives surfaces that enclose no volume (planes, sheets, single-sided scans) a wall this thick, "
        "centred on the surface; 0 uses each input as it is",
        "default": 0.0,
        "min": 0.0,
        "soft_max": 1.0,
        "precision": 4,
        "subtype": "DISTANCE",
    }
    return _make(FloatProperty, options, overrides)


def offset_distance_property(**overrides):
    options = {
        "name": "Distance",
        "description": "How far the surface moves: outwards (grow) when positive, inwards (shrink) when negative",
        "default": 0.05,
        "soft_min": -1.0,
        "soft_max": 1.0,
        "precision": 4,
        "subtype": "DISTANCE",
    }
    return _make(FloatProperty, options, overrides)


def wall_thickness_property(**overrides):
    options = {
        "name": "Wall",
        "description": "Thickness of the shell's wall (at least two voxels)",
        "default": 0.05,
        "min": 0.0,
        "soft_max": 1.0,
        "precision": 4,
        "subtype": "DISTANCE",
    }
    return _make(FloatProperty, options, overrides)


def shell_side_property(**overrides):
    options = {
        "name": "Side",
        "description": "Which side of the surface the wall lies on",
        "items": SHELL_SIDES,
        "default": "INSIDE",
    }
    return _make(EnumProperty, options, overrides)


def sharp_edges_property(**overrides):
    options = {
        "name": "Sharp Edges",
        "description": "Keep the creases of the result sharp (edges and corners reconstructed from the inputs' exact "
        "closest points, marked Sharp); off: marching cubes, every crease rounded to about a voxel",
        "default": True,
    }
    return _make(BoolProperty, options, overrides)


def keep_faces_property(**overrides):
    options = {
        "name": "Keep Original Faces",
        "description": "Keep the inputs' own faces (polygons, UVs, seams, detail finer than a voxel) wherever the "
        "result's surface is theirs, with new surface only along the seams; off: the whole result remeshed",
        "default": True,
    }
    return _make(BoolProperty, options, overrides)


def adaptivity_property(**overrides):
    options = {
        "name": "Adaptivity",
        "description": "Merge the remeshed surface's cells (with Keep Original Faces, the seams' new faces) where "
        "it is flat, into fewer, larger polygons (creases, corners and the inputs' material and UV seams kept); 0: a "
        "polygon per voxel",
        "default": 0.0,
        "min": 0.0,
        "max": 1.0,
        "subtype": "FACTOR",
    }
    return _make(FloatProperty, options, overrides)


def hide_inputs_property(**overrides):
    options = {
        "name": "Hide Inputs",
        "description": "Hide (never delete) the input objects once the result is written",
        "default": True,
    }
    return _make(BoolProperty, options, overrides)


def debug_volume_property(**overrides):
    options = {
        "name": "Debug Volume",
        "description": "Also add the result's field as a Volume object and its octree cells as points",
        "default": False,
    }
    return _make(BoolProperty, options, overrides)


def auto_update_property(**overrides):
    options = {
        "name": "Auto Update",
        "description": "Evaluate the CSG tree again shortly after an input object or a node setting changes",
        "default": False,
    }
    return _make(BoolProperty, options, overrides)


def message_property(**overrides):
    options = {"name": "Message", "description": "Problem found by the last evaluation", "default": ""}
    return _make(StringProperty, options, overrides)


class AASDF_PG_scene(bpy.types.PropertyGroup):
    """Field and result settings used by the SDF boolean operators of a scene."""

    resolution: resolution_property()
    voxel_size: voxel_size_property()
    levels: levels_property()
    padding: padding_property()
    blend: blend_property()
    blend_mode: blend_mode_property()
    thickness: thickness_property()
    sharp_edges: sharp_edges_property()
    keep_faces: keep_faces_property()
    adaptivity: adaptivity_property()
    hide_inputs: hide_inputs_property()
    debug_volume: debug_volume_property()
    offset_distance: offset_distance_property()
    wall: wall_thickness_property()
    shell_side: shell_side_property()
    tree: PointerProperty(
        name="CSG Tree",
        description="The AASDF CSG node tree shown in the sidebar",
        type=bpy.types.NodeTree,
        poll=lambda self, tree: tree.bl_idname == CSG_TREE,
    )


class AASDF_PG_object(bpy.types.PropertyGroup):
    """What AASDF keeps on an object it wrote: the key of the inputs of its result (``aasdf_addon.unchanged``)."""

    result_key: StringProperty(
        name="Result Key",
        description="Key of the inputs and settings this object's mesh was computed from, and of the mesh as written",
        default="",
        options={"HIDDEN"},
    )


# PropertyGroups in registration order (a group used by a PointerProperty must come before its user).
classes = (AASDF_PG_scene, AASDF_PG_object)


def register():
    """Attach the settings pointers; called after ``classes`` are registered."""
    bpy.types.Scene.aasdf = PointerProperty(type=AASDF_PG_scene)
    bpy.types.Object.aasdf = PointerProperty(type=AASDF_PG_object, options={"HIDDEN"})


def unregister():
    """Remove the settings pointers; called before ``classes`` are unregistered."""
    for owner in (bpy.types.Object, bpy.types.Scene):
        if hasattr(owner, "aasdf"):
            del owner.aasdf
