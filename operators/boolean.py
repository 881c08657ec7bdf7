"""``aasdf.boolean``: the selected mesh objects combined as an SDF boolean into a new object. Also
``aasdf.debug_volume`` (the active mesh's field as a Volume object) and ``aasdf.clear_cache``.

The active object is the first operand. DIFFERENCE is the active object minus all the others; UNION and
INTERSECT take them all. Each operand's field comes from ``aasdf_addon.cache`` (built at most once per geometry,
transform and settings), the fields are combined as a balanced tree, and the surface is written as a new object
with the operands' materials, each face taking the material of the operand it came from. Every step is a call into
``aasdf_addon.pipeline``, which the CSG node tree (``aasdf.evaluate_tree``) uses as well.
"""

import bpy
from bpy.props import BoolProperty, EnumProperty

from ..aasdf_addon import bridge, cache, pipeline, runtime
from ..aasdf_addon.pipeline import last_run  # noqa: F401  (scripts read ``operators.boolean.last_run``)
from ..aasdf_addon.properties import (
    OPERATIONS,
    blend_property,
    levels_property,
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

    operation: EnumProperty(
        name="Operation",
        description="Boolean to apply; Difference subtracts the other selected meshes from the active one",
        items=OPERATIONS,
        default="DIFFERENCE",
    )
    voxel_size: voxel_size_property()
    resolution: resolution_property()
    levels: levels_property()
    padding: padding_property()
    blend: blend_property()
    debug_volume: BoolProperty(
        name="Debug Volume",
        description="Also add the result's field as a Volume object and its octree cells as points",
        default=False,
    )
    hide_inputs: BoolProperty(
        name="Hide Inputs",
        description="Hide (never delete) the input objects once the result is created",
        default=True,
    )

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
        run = pipeline.Run()
        operands = mesh_operands(context)
        active = operands[0]
        depsgraph = context.evaluated_depsgraph_get()
        voxel_size = pipeline.voxel_size_for(operands, depsgraph, self.voxel_size, self.resolution)
        if not voxel_size > 0.0:
            self.report({"ERROR"}, "The selected meshes have no extent: set a Voxel Size")
            return {"CANCELLED"}

        wm = context.window_manager
        wm.progress_begin(0, 2 * len(operands))
        try:
            try:
                with run.stage("fields"):
                    fields = pipeline.operand_fields(
                        context,
                        operands,
                        depsgraph,
                        voxel_size=voxel_size,
                        levels=self.levels,
                        padding=self.padding,
                        progress=lambda k, obj: self._field_progress(context, k, obj, len(operands)),
                    )
                wm.progress_update(len(operands))
                self._status(context, "SDF boolean: combining fields")
                steps = iter(range(len(operands) + 1, 2 * len(operands)))
                with run.stage("booleans"):
                    field = bridge.combine(
                        self.operation, fields, self.blend, progress=lambda: wm.progress_update(next(steps))
                    )
                with run.stage("surface"):
                    result = pipeline.surface(field, operands)
            except engine.AasdfError as err:
                self.report({"ERROR"}, str(err))
                return {"CANCELLED"}
            if len(result["tris"]) == 0:
                self.report({"WARNING"}, "The boolean result is empty: nothing was added")
                return {"CANCELLED"}
            with run.stage("write"):
                obj = pipeline.write_result(context, f"{active.name}.aasdf", result, smooth=bridge.is_smooth(active))
            if self.debug_volume:
                self._add_debug_objects(context, field, obj, engine)
            if self.hide_inputs:
                for operand in operands:
                    operand.hide_set(True)
        finally:
            wm.progress_end()
            self._status(context, None)

        numbers = pipeline.record(
            run,
            field,
            result,
            source="aasdf.boolean",
            object=obj.name,
            operation=self.operation,
            operands=len(operands),
            voxel_size=voxel_size,
        )
        self.report(
            {"INFO"},
            f"{obj.name}: {self.operation.lower()} of {len(operands)} objects in {numbers['seconds']:.2f} s, "
            f"{field.node_count:,} field nodes, {numbers['triangles']:,} triangles, "
            f"{numbers['cache_hits']}/{len(operands)} fields from cache",
        )
        return {"FINISHED"}

    def _field_progress(self, context, k, obj, count):
        self._status(context, f"SDF boolean: field of {obj.name} ({k + 1}/{count})")
        context.window_manager.progress_update(k)

    def _add_debug_objects(self, context, field, result, engine):
        from ..aasdf_addon import debug

        try:
            debug.add_debug_objects(context, field, result.name)
        except engine.AasdfError as err:  # too large for memory: the result stays
            self.report({"WARNING"}, f"No debug volume: {err}")
        context.view_layer.objects.active = result

    @staticmethod
    def _status(context, text):
        if context.workspace is not None:
            context.workspace.status_text_set(text)


class AASDF_OT_debug_volume(bpy.types.Operator):
    """Show the signed distance field of the active mesh as a Volume object, with its octree cells as points"""

    bl_idname, bl_label, bl_options = "aasdf.debug_volume", "Debug Volume", {"REGISTER", "UNDO"}

    voxel_size: voxel_size_property()
    resolution: resolution_property(
        description="Finest voxels along the diagonal of the object's bounding box (used when Voxel Size is 0)",
        default=128,
    )
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
        depsgraph = context.evaluated_depsgraph_get()
        voxel_size = pipeline.voxel_size_for([obj], depsgraph, self.voxel_size, self.resolution)
        if not voxel_size > 0.0:
            self.report({"ERROR"}, f"{obj.name} has no extent: set a Voxel Size")
            return {"CANCELLED"}
        try:
            field = cache.field_for(
                obj, depsgraph, voxel_size=voxel_size, levels=self.levels, padding=self.padding, context=context
            )
            volume, cells = debug.add_debug_objects(context, field, obj.name)
        except engine.AasdfError as err:
            self.report({"ERROR"}, f"{obj.name}: {err}")
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
