"""The ``AASDF CSG`` node tree: procedural SDF booleans that stay live.

Input nodes (Object, Collection) give fields (each with a thickness for surfaces that enclose nothing); Union /
Intersect / Difference nodes combine them (each with a blend radius and mode); Offset grows or shrinks a field and Shell
hollows it; an Output node names the object that receives the result. Blender only stores and draws these trees: they
are evaluated by ``aasdf_addon.csg`` (``aasdf.evaluate_tree``, or Auto Update through ``aasdf_addon.autoupdate``). Every
setting that changes a result tells ``autoupdate`` that its tree changed; a tree gets a fake user as soon as it has
nodes, so it is saved with the .blend even when no editor shows it.
"""

import bpy
from bpy.props import PointerProperty, StringProperty

from .operands import is_operand
from .properties import CSG_TREE as TREE
from .properties import (
    adaptivity_property,
    auto_update_property,
    blend_mode_property,
    blend_property,
    hide_inputs_property,
    keep_faces_property,
    levels_property,
    message_property,
    offset_distance_property,
    padding_property,
    resolution_property,
    sharp_edges_property,
    shell_side_property,
    thickness_property,
    voxel_size_property,
    wall_thickness_property,
)

SOCKET = "AASDF_NS_field"
OBJECT, COLLECTION = "AASDF_N_object", "AASDF_N_collection"
UNION, INTERSECT, DIFFERENCE = "AASDF_N_union", "AASDF_N_intersect", "AASDF_N_difference"
OFFSET, SHELL = "AASDF_N_offset", "AASDF_N_shell"
OUTPUT = "AASDF_N_output"

# Boolean node type -> operation identifier of ``properties.OPERATIONS``.
BOOLEAN_NODES = {UNION: "UNION", INTERSECT: "INTERSECT", DIFFERENCE: "DIFFERENCE"}

# True while the add-on's classes are being registered or unregistered: Blender then calls the update of trees of
# the add-on's type while their node types are not all there, and reading a tree's nodes there can crash it.
classes_changing = False


def _changed(self, context):
    """Property update callback: the tree of ``self`` (a tree or a node) needs evaluating again."""
    from . import autoupdate

    autoupdate.tree_changed(self.id_data)


def is_csg_tree(tree) -> bool:
    return tree is not None and getattr(tree, "bl_idname", "") == TREE


class AASDF_NT_csg(bpy.types.NodeTree):
    """Procedural SDF booleans of objects (meshes, texts, curves, ...), evaluated into result objects"""

    bl_idname, bl_label, bl_icon = TREE, "AASDF CSG", "MOD_BOOLEAN"

    voxel_size: voxel_size_property(update=_changed)
    resolution: resolution_property(default=128, update=_changed)
    levels: levels_property(default=5, update=_changed)
    padding: padding_property(default=2, update=_changed)
    sharp_edges: sharp_edges_property(update=_changed)
    auto_update: auto_update_property(update=_changed)
    hide_inputs: hide_inputs_property(default=False)
    message: message_property()

    @classmethod
    def poll(cls, context):
        return True

    def update(self):
        """Links or nodes changed."""
        if classes_changing:
            return
        if len(self.nodes) and not self.use_fake_user:
            self.use_fake_user = True  # 0 users would not be saved
        _changed(self, None)


class AASDF_NS_field(bpy.types.NodeSocket):
    """A signed distance field"""

    bl_idname, bl_label = SOCKET, "SDF"

    def draw(self, context, layout, node, text):
        layout.label(text=text)

    @classmethod
    def draw_color_simple(cls):
        return (0.35, 0.75, 0.85, 1.0)


class CsgNode:
    """Mix-in of all CSG nodes: only in CSG trees, with the message of the last evaluation shown on the node."""

    message: message_property()

    @classmethod
    def poll(cls, ntree):
        return ntree.bl_idname == TREE

    def draw_buttons(self, context, layout):
        self.draw_settings(layout)
        if self.message:
            layout.label(text=self.message, icon="ERROR")

    def draw_settings(self, layout):
        pass


class AASDF_N_object(CsgNode, bpy.types.Node):
    """The field of an object's evaluated geometry (a mesh, text, curve, surface or metaball), in world space"""

    bl_idname, bl_label, bl_icon = OBJECT, "Object", "OBJECT_DATA"

    object: PointerProperty(
        name="Object",
        description="Object whose evaluated surface becomes a field",
        type=bpy.types.Object,
        poll=lambda self, obj: is_operand(obj),
        update=_changed,
    )
    thickness: thickness_property(update=_changed)

    def init(self, context):
        self.outputs.new(SOCKET, "Field")

    def draw_settings(self, layout):
        layout.prop(self, "object", text="")
        layout.prop(self, "thickness")


class AASDF_N_collection(CsgNode, bpy.types.Node):
    """The union of the fields of a collection's objects with geometry (child collections included)"""

    bl_idname, bl_label, bl_icon = COLLECTION, "Collection", "OUTLINER_COLLECTION"

    collection: PointerProperty(
        name="Collection",
        description="Collection whose objects with geometry are united into one field",
        type=bpy.types.Collection,
        update=_changed,
    )
    thickness: thickness_property(update=_changed)

    def init(self, context):
        self.outputs.new(SOCKET, "Field")

    def draw_settings(self, layout):
        layout.prop(self, "collection", text="")
        layout.prop(self, "thickness")


class BooleanNode(CsgNode):
    blend: blend_property(update=_changed)
    blend_mode: blend_mode_property(update=_changed)

    def draw_settings(self, layout):
        layout.prop(self, "blend")
        layout.prop(self, "blend_mode", text="")


class AASDF_N_union(BooleanNode, bpy.types.Node):
    """Union of all connected fields (a balanced tree of binary unions)"""

    bl_idname, bl_label, bl_icon = UNION, "Union", "SELECT_EXTEND"

    def init(self, context):
        self.inputs.new(SOCKET, "Fields", use_multi_input=True)
        self.outputs.new(SOCKET, "Field")


class AASDF_N_intersect(BooleanNode, bpy.types.Node):
    """Intersection of all connected fields (a balanced tree of binary intersections)"""

    bl_idname, bl_label, bl_icon = INTERSECT, "Intersect", "SELECT_INTERSECT"

    def init(self, context):
        self.inputs.new(SOCKET, "Fields", use_multi_input=True)
        self.outputs.new(SOCKET, "Field")


class AASDF_N_difference(BooleanNode, bpy.types.Node):
    """The Base field minus the union of all Cutters"""

    bl_idname, bl_label, bl_icon = DIFFERENCE, "Difference", "SELECT_SUBTRACT"

    def init(self, context):
        self.inputs.new(SOCKET, "Base")
        self.inputs.new(SOCKET, "Cutters", use_multi_input=True)
        self.outputs.new(SOCKET, "Field")


class AASDF_N_offset(CsgNode, bpy.types.Node):
    """The connected field's surface moved outwards (positive distance) or inwards (negative)"""

    bl_idname, bl_label, bl_icon = OFFSET, "Offset", "MOD_SKIN"

    distance: offset_distance_property(update=_changed)

    def init(self, context):
        self.inputs.new(SOCKET, "Field")
        self.outputs.new(SOCKET, "Field")

    def draw_settings(self, layout):
        layout.prop(self, "distance")


class AASDF_N_shell(CsgNode, bpy.types.Node):
    """A wall of the given thickness along the connected field's surface: the solid hollowed"""

    bl_idname, bl_label, bl_icon = SHELL, "Shell", "MOD_SOLIDIFY"

    wall: wall_thickness_property(update=_changed)
    side: shell_side_property(update=_changed)

    def init(self, context):
        self.inputs.new(SOCKET, "Field")
        self.outputs.new(SOCKET, "Field")

    def draw_settings(self, layout):
        layout.prop(self, "wall")
        layout.prop(self, "side", text="")


class AASDF_N_output(CsgNode, bpy.types.Node):
    """Writes the connected field's surface into the named mesh object (created when missing, else updated in place;
    a rename of either the object or the name here renames the other)"""

    bl_idname, bl_label, bl_icon = OUTPUT, "Output", "OUTPUT"

    object_name: StringProperty(
        name="Result",
        description="Name of the mesh object that receives the result",
        default="CSG Result",
        update=_changed,
    )
    keep_faces: keep_faces_property(update=_changed)
    adaptivity: adaptivity_property(update=_changed)
    # the object written last and its name then: a rename of either is followed by the other (``csg.follow_renames``)
    result: PointerProperty(type=bpy.types.Object, options={"HIDDEN"})
    written: StringProperty(options={"HIDDEN"})

    def init(self, context):
        self.inputs.new(SOCKET, "Field")

    def draw_settings(self, layout):
        layout.prop(self, "object_name", text="", icon="OBJECT_DATA")
        layout.prop(self, "keep_faces")
        layout.prop(self, "adaptivity")


classes = (
    AASDF_NT_csg,
    AASDF_NS_field,
    AASDF_N_object,
    AASDF_N_collection,
    AASDF_N_union,
    AASDF_N_intersect,
    AASDF_N_difference,
    AASDF_N_offset,
    AASDF_N_shell,
    AASDF_N_output,
)
