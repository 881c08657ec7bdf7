"""``aasdf.boolean``: the selected mesh objects combined as an SDF boolean into a new object. Also
``aasdf.debug_volume`` (the active mesh's field as a Volume object) and ``aasdf.clear_cache``.

The active object is the first operand. DIFFERENCE is the active object minus all the others; UNION and INTERSECT
take them all. The operators read their settings, hand them to ``aasdf_addon.pipeline`` (which the CSG node tree uses
as well) and report what it did.
"""

import bpy

from ..aasdf_addon import cache, pipeline, runtime
from ..aasdf_addon.pipeline import last_run  # noqa: F401  (scripts read ``operators.boolean.last_run``)
from ..aasdf_addon.properties import (
    blend_property,
    debug_volume_property,
    hide_inputs_property,
    levels_property,
    operation_property,
    padding_property,
    resolution_property,
    voxel_size_property,
)


def mesh_operands(context) -> list:
    """The active mesh object (selected or not) followed by the other selected mesh objects."""
    active = context.active_object
    first = [active] if active is not None and active.type == "MESH" else []
    return first + [obj for obj in context.selected_objects if obj.type == "MESH" and obj not in first]


class AASDF_OT_boolean(bpy.types.Operator):
    """Combine the active mesh with the other selected meshes as an SDF boolean, into a new object"""

    bl_idname, bl_label, bl_options = "aasdf.boolean", "SDF Boolean", {"REGISTER", "UNDO"}

    operation: operation_property()
    voxel_size: voxel_size_property()
    resolution: resolution_property()
    levels: levels_property()
    padding: padding_property()
    blend: blend_property()
    debug_volume: debug_volume_property()
    hide_inputs: hide_inputs_property()

    @classmethod
    def poll(cls, context):
        if context.mode != "OBJECT":
            cls.poll_message_set("Switch to Object Mode to run an SDF boolean")
            return False
        obj = context.active_object
        if obj is None or obj.type != "MESH":
            cls.poll_message_set("Needs an active mesh object")
            return False
        if len(mesh_operands(context)) < 2:
            cls.poll_message_set("Select at least two mesh objects")
            return False
        return True

    def execute(self, context):
        engine = runtime.engine()  # lazy: keeps registration fast
        operands = mesh_operands(context)
        output = pipeline.Output(
            f"{operands[0].name}.aasdf", hide_inputs=self.hide_inputs, debug_volume=self.debug_volume
        )
        try:
            numbers = pipeline.run(
                context,
                operands,
                pipeline.boolean_plan(self.operation, len(operands), self.blend),
                pipeline.FieldSettings.of(self),
                output,
                source="aasdf.boolean",
                operation=self.operation,
            )
        except engine.AasdfError as err:
            self.report({"ERROR"}, str(err))
            return {"CANCELLED"}
        if numbers.get("empty"):
            self.report({"WARNING"}, "The boolean result is empty: nothing was added")
            return {"CANCELLED"}
        for warning in numbers["warnings"]:
            self.report({"WARNING"}, warning)
        self.report(
            {"INFO"},
            f"{numbers['object']}: {self.operation.lower()} of {len(operands)} objects in {numbers['seconds']:.2f} s, "
            f"{numbers['nodes']:,} field nodes, {numbers['triangles']:,} triangles, "
            f"{numbers['cache_hits']}/{len(operands)} fields from cache",
        )
        return {"FINISHED"}


class AASDF_OT_debug_volume(bpy.types.Operator):
    """Show the signed distance field of the active mesh as a Volume object, with its octree cells as points"""

    bl_idname, bl_label, bl_options = "aasdf.debug_volume", "Debug Volume", {"REGISTER", "UNDO"}

    voxel_size: voxel_size_property()
    resolution: resolution_property(default=128)
    levels: levels_property()
    padding: padding_property()

    @classmethod
    def poll(cls, context):
        if context.mode != "OBJECT":
            cls.poll_message_set("Switch to Object Mode to add a debug volume")
            return False
        obj = context.active_object
        if obj is None or obj.type != "MESH":
            cls.poll_message_set("Needs an active mesh object")
            return False
        return True

    def execute(self, context):
        from ..aasdf_addon import debug

        engine = runtime.engine()
        obj = context.active_object
        try:
            field = pipeline.object_field(context, obj, pipeline.FieldSettings.of(self))
            volume, cells = debug.add_debug_objects(context, field, obj.name)
        except engine.AasdfError as err:
            self.report({"ERROR"}, str(err))  # the pipeline names the object
            return {"CANCELLED"}
        self.report({"INFO"}, f"{volume.name}, {cells.name}: {field.node_count:,} field nodes")
        return {"FINISHED"}


class AASDF_OT_clear_cache(bpy.types.Operator):
    """Forget the cached fields of all objects (they are rebuilt when next needed)"""

    bl_idname, bl_label, bl_options = "aasdf.clear_cache", "Clear Field Cache", {"REGISTER"}

    def execute(self, context):
        count, nbytes = cache.stats()["entries"], cache.total_bytes()
        cache.clear()
        self.report({"INFO"}, f"Cleared {count} cached fields ({nbytes / 2**20:.1f} MB)")
        return {"FINISHED"}
