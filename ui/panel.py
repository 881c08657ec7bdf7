"""The AASDF tab of the 3D Viewport's sidebar: the scene's field settings, and a Debug sub-panel."""

import bpy

from ..aasdf_addon import cache
from ..aasdf_addon.properties import OPERATIONS


class AASDF_PT_main(bpy.types.Panel):
    bl_label, bl_category, bl_context = "SDF Boolean", "AASDF", "objectmode"
    bl_space_type, bl_region_type = "VIEW_3D", "UI"

    def draw(self, context):
        layout = self.layout
        layout.use_property_split, layout.use_property_decorate = True, False
        settings = context.scene.aasdf
        layout.prop(settings, "resolution")
        layout.prop(settings, "voxel_size")
        layout.prop(settings, "levels")
        layout.prop(settings, "padding")
        layout.prop(settings, "blend")
        layout.prop(settings, "hide_inputs")
        row = layout.row(align=True)
        for ident, label, _ in OPERATIONS:
            op = row.operator("aasdf.boolean", text=label)
            op.operation = ident
            op.voxel_size, op.resolution, op.levels = settings.voxel_size, settings.resolution, settings.levels
            op.padding, op.blend, op.hide_inputs = settings.padding, settings.blend, settings.hide_inputs
            op.debug_volume = settings.debug_volume


class AASDF_PT_main_debug(bpy.types.Panel):
    bl_label, bl_parent_id, bl_options = "Debug", "AASDF_PT_main", {"DEFAULT_CLOSED"}
    bl_space_type, bl_region_type, bl_context = "VIEW_3D", "UI", "objectmode"

    def draw(self, context):
        layout = self.layout
        layout.use_property_split, layout.use_property_decorate = True, False
        settings = context.scene.aasdf
        layout.prop(settings, "debug_volume")
        op = layout.operator("aasdf.debug_volume", text="Debug Volume of Active")
        op.voxel_size, op.resolution = settings.voxel_size, settings.resolution
        op.levels, op.padding = settings.levels, settings.padding
        megabytes = cache.total_bytes() / 2**20
        layout.operator("aasdf.clear_cache", text=f"Clear Field Cache ({megabytes:.1f} MB)")
