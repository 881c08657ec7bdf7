"""Scene settings of AASDF (``Scene.aasdf``) and the enum items shared by operators and panels."""

import bpy
from bpy.props import BoolProperty, FloatProperty, IntProperty, PointerProperty

# (identifier, label, description) items for the boolean operation; ``sdf_difference(a, b)`` is *a minus b*.
OPERATIONS = (
    ("UNION", "Union", ""),
    ("INTERSECT", "Intersect", ""),
    ("DIFFERENCE", "Difference", ""),
)


CSG_TREE = "AASDF_NT_csg"  # bl_idname of the node tree (``aasdf_addon.nodes``)


# The field settings, defined once for the scene's settings, the operators and the CSG tree (``overrides`` adjust
# a default, a description or add an update callback).
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
    return FloatProperty(**{**options, **overrides})


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
    return IntProperty(**{**options, **overrides})


def levels_property(**overrides):
    options = {
        "name": "Levels",
        "description": "Octree levels: cells grow coarser away from the surface",
        "default": 4,
        "min": 1,
        "max": 12,
    }
    return IntProperty(**{**options, **overrides})


def padding_property(**overrides):
    options = {
        "name": "Padding",
        "description": "Finest voxels kept around the surface on each side",
        "default": 1,
        "min": 0,
        "max": 32,
    }
    return IntProperty(**{**options, **overrides})


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
    return FloatProperty(**{**options, **overrides})


class AASDF_PG_scene(bpy.types.PropertyGroup):
    """Field and result settings used by the SDF boolean operators of a scene."""

    resolution: resolution_property()
    voxel_size: voxel_size_property()
    levels: levels_property()
    padding: padding_property()
    blend: blend_property()
    hide_inputs: BoolProperty(
        name="Hide Inputs",
        description="Hide the input objects once the result is created",
        default=True,
    )
    debug_volume: BoolProperty(
        name="Debug Volume",
        description="Also create a volume object showing the adaptive field's cells and distances",
        default=False,
    )
    tree: PointerProperty(
        name="CSG Tree",
        description="The AASDF CSG node tree shown in the sidebar",
        type=bpy.types.NodeTree,
        poll=lambda self, tree: tree.bl_idname == CSG_TREE,
    )


# PropertyGroups in registration order (a group used by a PointerProperty must come before its user).
classes = (AASDF_PG_scene,)


def register():
    """Attach the settings pointers; called after ``classes`` are registered."""
    bpy.types.Scene.aasdf = PointerProperty(type=AASDF_PG_scene)


def unregister():
    """Remove the settings pointers; called before ``classes`` are unregistered."""
    if hasattr(bpy.types.Scene, "aasdf"):
        del bpy.types.Scene.aasdf
