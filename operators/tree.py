"""``aasdf.evaluate_tree``: evaluate an ``AASDF CSG`` node tree into its result objects; and
``aasdf.tree_from_selection``: a new tree that combines the selected objects, as ``aasdf.boolean`` would.

Evaluation goes through ``aasdf_addon.autoupdate.evaluate_now`` → ``aasdf_addon.csg``: the field cache, the engine's
booleans and the result writing that ``aasdf.boolean`` uses. An invalid tree (its problems are shown on the nodes) is an
error report and writes nothing.
"""

import bpy
from bpy.props import BoolProperty, StringProperty

from ..aasdf_addon import autoupdate, csg, nodes, operands, runtime
from ..aasdf_addon.properties import auto_update_property, operation_property
from .boolean import selected_operands


def _geometry_selection(context) -> list:
    """The selected objects that have geometry, the active one first."""
    return [obj for obj in selected_operands(context) if operands.is_operand(obj)]


def context_tree(context):
    """The CSG tree being edited in the node editor, else the one chosen in the sidebar (or ``None``)."""
    space = context.space_data
    tree = getattr(space, "edit_tree", None) if space is not None and space.type == "NODE_EDITOR" else None
    if nodes.is_csg_tree(tree):
        return tree
    tree = context.scene.aasdf.tree if context.scene is not None else None
    return tree if nodes.is_csg_tree(tree) else None


class AASDF_OT_evaluate_tree(bpy.types.Operator):
    """Evaluate an AASDF CSG node tree: each Output node writes or updates its result object"""

    bl_idname, bl_label, bl_options = "aasdf.evaluate_tree", "Evaluate CSG Tree", {"REGISTER", "UNDO"}

    tree: StringProperty(
        name="Tree",
        description="Name of the CSG node tree; empty: the node editor's tree, else the sidebar's",
        default="",
    )

    @classmethod
    def poll(cls, context):
        if context.mode != "OBJECT":
            cls.poll_message_set("Switch to Object Mode to evaluate a CSG tree")
            return False
        if not any(nodes.is_csg_tree(tree) for tree in bpy.data.node_groups):
            cls.poll_message_set("Create an AASDF CSG tree first")
            return False
        return True

    def execute(self, context):
        engine = runtime.engine()
        tree = bpy.data.node_groups.get(self.tree) if self.tree else context_tree(context)
        if not nodes.is_csg_tree(tree):
            self.report({"ERROR"}, f"No AASDF CSG tree named '{self.tree}'" if self.tree else "Choose a CSG tree")
            return {"CANCELLED"}
        try:
            runs = autoupdate.evaluate_now(context, tree)
        except engine.AasdfError as err:
            self.report({"ERROR"}, f"{tree.name}: {err}")
            return {"CANCELLED"}
        written = [run for run in runs if not run.get("empty")]
        for run in runs:
            if run.get("empty"):
                self.report({"WARNING"}, f"{run['object']}: the result is empty; the previous result is kept")
        if not written:
            return {"CANCELLED"}
        seconds = sum(run["seconds"] for run in written)
        built = sum(run["fields_built"] for run in written)
        count = sum(run["operands"] for run in written)
        triangles = sum(run["triangles"] for run in written)
        same = [run["object"] for run in written if run.get("unchanged")]
        self.report(
            {"INFO"},
            f"{tree.name}: {', '.join(run['object'] for run in written)} in {seconds:.2f} s, {triangles:,} triangles, "
            f"{built}/{count} fields built" + (f"; unchanged: {', '.join(same)}" if same else ""),
        )
        return {"FINISHED"}


class AASDF_OT_tree_from_selection(bpy.types.Operator):
    """Create an AASDF CSG node tree combining the selected objects (the active one first), and evaluate it"""

    bl_idname, bl_label, bl_options = "aasdf.tree_from_selection", "New CSG Tree from Selection", {"REGISTER", "UNDO"}

    operation: operation_property()
    auto_update: auto_update_property(default=True)
    evaluate: BoolProperty(name="Evaluate", description="Evaluate the new tree right away", default=True)

    @classmethod
    def poll(cls, context):
        if context.mode != "OBJECT":
            cls.poll_message_set("Switch to Object Mode to create a CSG tree")
            return False
        if len(_geometry_selection(context)) < 2:
            cls.poll_message_set("Select at least two objects")
            return False
        return True

    def execute(self, context):
        engine = runtime.engine()
        objects = _geometry_selection(context)
        active = objects[0]
        settings = context.scene.aasdf
        result = csg.free_result_name(f"{active.name}.csg")
        tree = build_tree(f"{active.name} CSG", objects, self.operation, settings.blend, result_name=result)
        tree.voxel_size, tree.resolution = settings.voxel_size, settings.resolution
        tree.levels, tree.padding, tree.hide_inputs = settings.levels, settings.padding, settings.hide_inputs
        tree.sharp_edges = settings.sharp_edges
        for node in tree.nodes:
            if node.bl_idname in nodes.BOOLEAN_NODES:
                node.blend_mode = settings.blend_mode
            elif node.bl_idname == nodes.OBJECT:
                node.thickness = settings.thickness
        settings.tree = tree
        for area in context.screen.areas if context.screen is not None else ():
            space = area.spaces.active
            if area.type == "NODE_EDITOR" and space.tree_type == nodes.TREE and space.node_tree is None:
                space.node_tree = tree
        if self.evaluate:
            try:
                autoupdate.evaluate_now(context, tree)
            except engine.AasdfError as err:
                self.report({"WARNING"}, f"{tree.name} was created but does not evaluate: {err}")
        tree.auto_update = self.auto_update
        self.report({"INFO"}, f"{tree.name}: {len(objects)} inputs, {self.operation.lower()}")
        return {"FINISHED"}


def build_tree(name, objects, operation, blend=0.0, *, result_name):
    """A new CSG tree: one Object node per object, one boolean node, one Output node (laid out left to right).

    DIFFERENCE takes the first object as its Base and the others as Cutters; UNION and INTERSECT take them all.
    """
    tree = bpy.data.node_groups.new(name, nodes.TREE)
    tree.use_fake_user = True
    kind = {op: kind for kind, op in nodes.BOOLEAN_NODES.items()}[operation]
    boolean = tree.nodes.new(kind)
    boolean.location, boolean.blend = (260.0, 0.0), blend
    for k, obj in enumerate(objects):
        node = tree.nodes.new(nodes.OBJECT)
        node.object, node.location = obj, (0.0, -150.0 * k)
        socket = boolean.inputs[0] if operation != "DIFFERENCE" or k == 0 else boolean.inputs[1]
        tree.links.new(node.outputs[0], socket)
    output = tree.nodes.new(nodes.OUTPUT)
    output.object_name, output.location = result_name, (480.0, 0.0)
    tree.links.new(boolean.outputs[0], output.inputs[0])
    return tree
