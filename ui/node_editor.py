"""The CSG tree in the node editor: entries in its Add menu and the tree's settings in its sidebar (tab AASDF)."""

import bpy
from bl_ui import node_add_menu

from ..aasdf_addon import nodes
from .panel import draw_tree_settings


def _is_csg_editor(context) -> bool:
    space = context.space_data
    return space is not None and space.type == "NODE_EDITOR" and space.tree_type == nodes.TREE


class CsgAddMenu:
    node_types = ()

    @classmethod
    def poll(cls, context):
        return _is_csg_editor(context)

    def draw(self, context):
        for node_type in self.node_types:
            node_add_menu.add_node_type(self.layout, node_type)


class AASDF_MT_csg_add_input(CsgAddMenu, bpy.types.Menu):
    bl_label = "Input"
    node_types = (nodes.OBJECT, nodes.COLLECTION)


class AASDF_MT_csg_add_boolean(CsgAddMenu, bpy.types.Menu):
    bl_label = "Boolean"
    node_types = (nodes.UNION, nodes.INTERSECT, nodes.DIFFERENCE)


class AASDF_MT_csg_add_field(CsgAddMenu, bpy.types.Menu):
    bl_label = "Field"
    node_types = (nodes.OFFSET, nodes.SHELL)


class AASDF_MT_csg_add_output(CsgAddMenu, bpy.types.Menu):
    bl_label = "Output"
    node_types = (nodes.OUTPUT,)


def draw_add_menu(self, context):
    """Appended to ``NODE_MT_add``: the CSG nodes, only in a CSG tree."""
    if not _is_csg_editor(context):
        return
    layout = self.layout
    layout.menu(AASDF_MT_csg_add_input.__name__)
    layout.menu(AASDF_MT_csg_add_boolean.__name__)
    layout.menu(AASDF_MT_csg_add_field.__name__)
    layout.menu(AASDF_MT_csg_add_output.__name__)


class AASDF_PT_csg_tree(bpy.types.Panel):
    bl_label, bl_category = "CSG Tree", "AASDF"
    bl_space_type, bl_region_type = "NODE_EDITOR", "UI"

    @classmethod
    def poll(cls, context):
        return _is_csg_editor(context) and context.space_data.edit_tree is not None

    def draw(self, context):
        layout = self.layout
        layout.use_property_split, layout.use_property_decorate = True, False
        draw_tree_settings(layout, context.space_data.edit_tree)


def register():
    bpy.types.NODE_MT_add.remove(draw_add_menu)  # harmless when absent; never twice
    bpy.types.NODE_MT_add.append(draw_add_menu)


def unregister():
    bpy.types.NODE_MT_add.remove(draw_add_menu)
