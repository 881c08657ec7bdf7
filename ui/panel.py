"""The AASDF tab of the 3D Viewport's sidebar: the boolean, a CSG tree, the last run's numbers, the cache and debug.

Every ``draw()`` here only reads settings and stored numbers (``pipeline.last_run``, the cache's running totals) and
places operators; buttons whose operator cannot run stay visible and are greyed by its ``poll()``, whose message is the
tooltip. Sub-panels hang below ``AASDF_PT_main`` through ``bl_parent_id``.
"""

import bpy

from ..aasdf_addon import cache, pipeline, preferences, runtime
from ..aasdf_addon.properties import OPERATIONS

OPERATION_ICONS = {"UNION": "SELECT_EXTEND", "INTERSECT": "SELECT_INTERSECT", "DIFFERENCE": "SELECT_SUBTRACT"}
STAGE_LABELS = {
    "read": "Read",
    "key": "Key",
    "fields": "Fields",
    "booleans": "Booleans",
    "surface": "Surface",
    "attributes": "Attributes",
    "write": "Write",
}


class SidebarPanel:
    bl_space_type, bl_region_type, bl_category, bl_context = "VIEW_3D", "UI", "AASDF", "objectmode"


class SubPanel(SidebarPanel):
    bl_parent_id = "AASDF_PT_main"


class AASDF_PT_main(SidebarPanel, bpy.types.Panel):
    bl_label = "SDF Boolean"

    def draw(self, context):
        layout = self.layout
        layout.use_property_split, layout.use_property_decorate = True, False
        settings = context.scene.aasdf
        row = layout.row(align=True)
        row.scale_y = 1.4
        for ident, label, _ in OPERATIONS:
            op = row.operator("aasdf.boolean", text=label, icon=OPERATION_ICONS[ident])
            op.operation = ident
            _field_settings(op, settings)
            op.blend, op.blend_mode, op.debug_volume = settings.blend, settings.blend_mode, settings.debug_volume
            op.keep_faces = settings.keep_faces
        col = layout.column()
        col.prop(settings, "voxel_size")
        sub = col.column()
        sub.active = settings.voxel_size == 0.0  # Resolution is used only without a voxel size
        sub.prop(settings, "resolution")
        col.prop(settings, "levels")
        col.prop(settings, "padding")
        col.prop(settings, "blend")
        sub = col.column()
        sub.active = settings.blend > 0.0
        sub.prop(settings, "blend_mode")
        col.prop(settings, "thickness")
        col.prop(settings, "sharp_edges")
        col.prop(settings, "keep_faces")
        col.prop(settings, "adaptivity")
        col.prop(settings, "hide_inputs")


def _field_settings(op, settings):
    """Give an operator the scene's field and result settings."""
    op.voxel_size, op.resolution, op.levels = settings.voxel_size, settings.resolution, settings.levels
    op.padding, op.thickness, op.sharp_edges = settings.padding, settings.thickness, settings.sharp_edges
    op.hide_inputs, op.adaptivity = settings.hide_inputs, settings.adaptivity


class AASDF_PT_main_offset(SubPanel, bpy.types.Panel):
    bl_label = "Offset and Shell"

    def draw(self, context):
        layout = self.layout
        layout.use_property_split, layout.use_property_decorate = True, False
        settings = context.scene.aasdf
        layout.prop(settings, "offset_distance")
        op = layout.operator("aasdf.offset", text="Offset Active", icon="MOD_SKIN")
        _field_settings(op, settings)
        op.distance, op.hide_inputs = settings.offset_distance, False
        layout.prop(settings, "wall")
        layout.prop(settings, "shell_side")
        op = layout.operator("aasdf.shell", text="Shell Active", icon="MOD_SOLIDIFY")
        _field_settings(op, settings)
        op.wall, op.side, op.hide_inputs = settings.wall, settings.shell_side, False


def draw_tree_settings(layout, tree):
    """A CSG tree's settings, messages and Evaluate button (shared with the node editor's sidebar)."""
    layout.prop(tree, "auto_update")
    col = layout.column()
    col.prop(tree, "voxel_size")
    sub = col.column()
    sub.active = tree.voxel_size == 0.0
    sub.prop(tree, "resolution")
    col.prop(tree, "levels")
    col.prop(tree, "padding")
    col.prop(tree, "sharp_edges")
    col.prop(tree, "hide_inputs")
    if tree.message:
        box = layout.box()
        box.alert = True
        box.label(text=tree.message, icon="ERROR")
    layout.operator("aasdf.evaluate_tree", text="Evaluate", icon="FILE_REFRESH").tree = tree.name


class AASDF_PT_main_tree(SubPanel, bpy.types.Panel):
    bl_label = "CSG Tree"

    def draw(self, context):
        layout = self.layout
        layout.use_property_split, layout.use_property_decorate = True, False
        settings = context.scene.aasdf
        layout.label(text="New Tree from Selection")
        row = layout.row(align=True)
        for ident, label, _ in OPERATIONS:
            row.operator("aasdf.tree_from_selection", text=label, icon=OPERATION_ICONS[ident]).operation = ident
        layout.prop(settings, "tree")
        if settings.tree is not None:
            draw_tree_settings(layout, settings.tree)


class AASDF_PT_main_stats(SubPanel, bpy.types.Panel):
    bl_label = "Last Run"

    def draw(self, context):
        layout = self.layout
        run = pipeline.last_run
        if not run:
            layout.label(text="No boolean has run yet", icon="INFO")
            return
        col = layout.column(align=True)
        col.label(text=f"{run['object']} ({run['source']})", icon="OBJECT_DATA")
        col.label(text=f"Total: {run['seconds']:.2f} s")
        if run.get("unchanged"):
            col.label(text="Nothing changed: the result was left as it was", icon="CHECKMARK")
        for stage, seconds in run["stages"].items():
            col.label(text=f"  {STAGE_LABELS.get(stage, stage)}: {seconds:.3f} s")
        col = layout.column(align=True)
        col.label(text=f"Field nodes: {run['nodes']:,}")
        for level, count in enumerate(run["level_counts"]):
            col.label(text=f"  Level {level}: {count:,}")
        col = layout.column(align=True)
        col.label(text=f"Triangles: {run['triangles']:,}")
        col.label(text=f"Voxel size: {run['voxel_size']:.4g}")
        col.label(text=f"Fields from cache: {run['cache_hits']}/{run['operands']}")


class AASDF_PT_main_cache(SubPanel, bpy.types.Panel):
    bl_label = "Cache"

    def draw(self, context):
        layout = self.layout
        stats = cache.stats()
        prefs = preferences.get(context)
        limit = f" of {prefs.cache_limit_mb:,} MB" if prefs is not None else ""
        row = layout.row()
        row.label(text=f"{stats['entries']} fields, {stats['bytes'] / 2**20:.1f} MB{limit}")
        row.operator("aasdf.clear_cache", text="Clear", icon="TRASH")
        pooled = runtime.pooled_bytes()
        if pooled:  # pages of freed arrays the next evaluation reuses, within the limit
            layout.label(text=f"Kept for the next run: {pooled / 2**20:.1f} MB")


class AASDF_PT_main_debug(SubPanel, bpy.types.Panel):
    bl_label, bl_options = "Debug", {"DEFAULT_CLOSED"}

    def draw(self, context):
        layout = self.layout
        layout.use_property_split, layout.use_property_decorate = True, False
        settings = context.scene.aasdf
        layout.prop(settings, "debug_volume")
        op = layout.operator("aasdf.debug_volume", text="Debug Volume of Active", icon="VOLUME_DATA")
        op.voxel_size, op.resolution = settings.voxel_size, settings.resolution
        op.levels, op.padding = settings.levels, settings.padding
