"""``aasdf.boolean``: the selected objects (meshes, texts, curves, surfaces, metaballs) combined as an SDF boolean into
a new object. Also ``aasdf.offset`` and ``aasdf.shell`` (the active object grown, shrunk or hollowed into a new
object), ``aasdf.debug_volume`` (the active object's field as a Volume object) and ``aasdf.clear_cache``.

The active object is the first operand. DIFFERENCE is the active object minus all the others; UNION and INTERSECT
take them all. The operators read their settings, hand them to ``aasdf_addon.pipeline`` (which the CSG node tree uses
as well) and report what it did.
"""

import math
import re

import bpy

from ..aasdf_addon import cache, operands, pipeline, plan, runtime
from ..aasdf_addon.pipeline import last_run  # noqa: F401  (scripts read ``operators.boolean.last_run``)
from ..aasdf_addon.properties import (
    adaptivity_property,
    blend_mode_property,
    blend_property,
    debug_volume_property,
    hide_inputs_property,
    keep_faces_property,
    levels_property,
    offset_distance_property,
    operation_property,
    padding_property,
    resolution_property,
    sharp_edges_property,
    shell_side_property,
    thickness_property,
    voxel_size_property,
    wall_thickness_property,
)


def selected_operands(context) -> list:
    """The active object (selected or not) when it has geometry, followed by the other selected objects (those
    without geometry are refused by name when the operator runs)."""
    return operands.selected_operands(context)


class GeometryPoll:
    """Poll of the operators that need an active object with geometry (a mesh, text, curve, surface or metaball)."""

    @classmethod
    def poll(cls, context):
        if context.mode != "OBJECT":
            cls.poll_message_set("Switch to Object Mode")
            return False
        if not operands.is_operand(context.active_object):
            cls.poll_message_set(f"Needs an active {operands.OPERAND_TYPES_TEXT} object")
            return False
        return True


class AASDF_OT_boolean(bpy.types.Operator):
    """Combine the active object with the other selected ones (meshes, texts, curves...) as an SDF boolean"""

    bl_idname, bl_label, bl_options = "aasdf.boolean", "SDF Boolean", {"REGISTER", "UNDO"}

    operation: operation_property()
    voxel_size: voxel_size_property()
    resolution: resolution_property()
    levels: levels_property()
    padding: padding_property()
    blend: blend_property()
    blend_mode: blend_mode_property()
    thickness: thickness_property()
    sharp_edges: sharp_edges_property()
    keep_faces: keep_faces_property()
    adaptivity: adaptivity_property()
    debug_volume: debug_volume_property()
    hide_inputs: hide_inputs_property()

    @classmethod
    def poll(cls, context):
        if context.mode != "OBJECT":
            cls.poll_message_set("Switch to Object Mode to run an SDF boolean")
            return False
        if not operands.is_operand(context.active_object):
            cls.poll_message_set(f"Needs an active {operands.OPERAND_TYPES_TEXT} object")
            return False
        if len(selected_operands(context)) < 2:
            cls.poll_message_set("Select at least two objects")
            return False
        return True

    def execute(self, context):
        objects = selected_operands(context)
        steps = plan.boolean_plan(self.operation, len(objects), self.blend, self.blend_mode)
        numbers = run(self, context, objects, steps, f"{objects[0].name}.aasdf", "The boolean result is empty")
        if numbers is None:
            return {"CANCELLED"}
        self.report(
            {"INFO"},
            f"{numbers['object']}: {self.operation.lower()} of {len(objects)} objects in {numbers['seconds']:.2f} s, "
            f"{numbers['nodes']:,} field nodes, {numbers['faces']:,} faces, "
            f"{numbers['cache_hits']}/{len(objects)} fields from cache",
        )
        return {"FINISHED"}


def run(op, context, objects, steps, name, empty_message, operation=None):
    """Run a plan for an operator ``op`` (its settings: field settings, thickness, sharp edges, hide inputs, debug
    volume) and report problems; returns the run's numbers, or None when nothing was written."""
    engine = runtime.engine()  # lazy: keeps registration fast
    output = pipeline.Output(
        name,
        hide_inputs=op.hide_inputs,
        debug_volume=getattr(op, "debug_volume", False),
        sharp=op.sharp_edges,
        keep_faces=getattr(op, "keep_faces", False),
        adaptivity=op.adaptivity,
    )
    try:
        numbers = pipeline.run(
            context,
            [plan.Input(obj, op.thickness) for obj in objects],
            steps,
            pipeline.FieldSettings.of(op),
            output,
            source=op.bl_idname,
            # bl_idname reads "AASDF_OT_offset" on a running operator, "aasdf.offset" on its class
            operation=operation or getattr(op, "operation", re.split(r"_OT_|\.", op.bl_idname)[-1].upper()),
        )
    except engine.AasdfError as err:
        op.report({"ERROR"}, str(err))
        return None
    if numbers.get("empty"):
        op.report({"WARNING"}, f"{empty_message}: nothing was added")
        return None
    for warning in numbers["warnings"]:
        op.report({"WARNING"}, warning)
    return numbers


class AASDF_OT_offset(GeometryPoll, bpy.types.Operator):
    """Grow or shrink the active object by a distance, as a new object (any distance, rounded at the edges)"""

    bl_idname, bl_label, bl_options = "aasdf.offset", "SDF Offset", {"REGISTER", "UNDO"}

    distance: offset_distance_property()
    voxel_size: voxel_size_property()
    resolution: resolution_property()
    levels: levels_property()
    padding: padding_property()
    thickness: thickness_property()
    sharp_edges: sharp_edges_property()
    adaptivity: adaptivity_property()
    hide_inputs: hide_inputs_property(default=False)

    def execute(self, context):
        if not math.isfinite(self.distance):
            self.report({"ERROR"}, f"The offset distance must be a finite number, not {self.distance}")
            return {"CANCELLED"}
        obj = context.active_object
        steps = ("offset", float(self.distance), ("field", 0))
        numbers = run(self, context, [obj], steps, f"{obj.name}.offset", "The offset leaves nothing")
        if numbers is None:
            return {"CANCELLED"}
        self.report({"INFO"}, f"{numbers['object']}: {self.distance:+.4g} in {numbers['seconds']:.2f} s")
        return {"FINISHED"}


class AASDF_OT_shell(GeometryPoll, bpy.types.Operator):
    """Hollow the active object into a shell with walls of a given thickness, as a new object (for 3D printing)"""

    bl_idname, bl_label, bl_options = "aasdf.shell", "SDF Shell", {"REGISTER", "UNDO"}

    wall: wall_thickness_property()
    side: shell_side_property()
    voxel_size: voxel_size_property()
    resolution: resolution_property()
    levels: levels_property()
    padding: padding_property()
    thickness: thickness_property()
    sharp_edges: sharp_edges_property()
    adaptivity: adaptivity_property()
    hide_inputs: hide_inputs_property(default=False)

    def execute(self, context):
        if not (math.isfinite(self.wall) and self.wall > 0.0):
            self.report({"ERROR"}, f"The wall must be a positive thickness, not {self.wall}")
            return {"CANCELLED"}
        obj = context.active_object
        steps = ("shell", float(self.wall), self.side, ("field", 0))
        numbers = run(self, context, [obj], steps, f"{obj.name}.shell", "The shell is empty")
        if numbers is None:
            return {"CANCELLED"}
        self.report({"INFO"}, f"{numbers['object']}: a {self.wall:.4g} wall in {numbers['seconds']:.2f} s")
        return {"FINISHED"}


class AASDF_OT_debug_volume(GeometryPoll, bpy.types.Operator):
    """Show the signed distance field of the active object as a Volume object, with its octree cells as points"""

    bl_idname, bl_label, bl_options = "aasdf.debug_volume", "Debug Volume", {"REGISTER", "UNDO"}

    voxel_size: voxel_size_property()
    resolution: resolution_property(default=128)
    levels: levels_property()
    padding: padding_property()

    def execute(self, context):
        from ..aasdf_addon import debug

        engine = runtime.engine()
        obj = context.active_object
        try:
            debug.openvdb_module()  # where this Blender has none (4.2), refused before any work
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
