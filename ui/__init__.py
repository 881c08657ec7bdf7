"""Panels and menus: ``draw()`` only reads settings and places operators. ``aasdf_addon.registration`` registers
everything in ``classes``, in order (a parent panel before its sub-panels), and calls ``register()``/``unregister()``
for what is not a class (the node editor's Add menu entries)."""

from . import node_editor
from .node_editor import (
    AASDF_MT_csg_add_boolean,
    AASDF_MT_csg_add_field,
    AASDF_MT_csg_add_input,
    AASDF_MT_csg_add_output,
    AASDF_PT_csg_tree,
)
from .panel import (
    AASDF_PT_main,
    AASDF_PT_main_cache,
    AASDF_PT_main_debug,
    AASDF_PT_main_offset,
    AASDF_PT_main_stats,
    AASDF_PT_main_tree,
)

classes = (
    AASDF_PT_main,
    AASDF_PT_main_offset,
    AASDF_PT_main_tree,
    AASDF_PT_main_stats,
    AASDF_PT_main_cache,
    AASDF_PT_main_debug,
    AASDF_MT_csg_add_input,
    AASDF_MT_csg_add_boolean,
    AASDF_MT_csg_add_field,
    AASDF_MT_csg_add_output,
    AASDF_PT_csg_tree,
)


def register():
    node_editor.register()


def unregister():
    node_editor.unregister()
