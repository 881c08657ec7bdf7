"""Evaluation of an ``AASDF CSG`` tree: validate, then walk it once bottom-up through the shared pipeline.

``plan_tree`` checks the whole tree before any work starts: every input socket connected, each Object node on an
object with geometry, each Collection node on a collection with such objects, Output nodes with distinct names of
objects that are not their own inputs. Problems are written on their nodes (``node.message``) and raised together as
``AasdfError``, so the previous results stay as they are. A valid output becomes a plan (``aasdf_addon.plan``) over its
operands, the distinct (object, thickness) inputs below it in depth-first order.

``evaluate_tree`` then runs each output's plan through ``pipeline.run`` (read, key, cache, build, combine, extract,
write), writing or updating the result object in place: the path ``aasdf.boolean`` takes. An output whose object still
shows the result of the same inputs, as it was written, is left as it is (``aasdf_addon.unchanged``): evaluating an
unchanged tree again, or after its file was saved and opened again, reads and keys the inputs and does nothing else.
"""

from dataclasses import dataclass, field

import bpy

from . import nodes, pipeline, plan, runtime
from .bridge import result_collection
from .operands import is_operand, refusal


@dataclass
class OutputPlan:
    """What one Output node computes."""

    node_name: str
    object_name: str
    operands: list  # distinct plan.Input (a mesh object and its thickness), field_id = index
    plan: tuple
    collection: object = None  # where a new result object goes
    errors: dict = field(default_factory=dict)


def _linked_nodes(socket) -> list:
    """The nodes feeding an input socket, first linked first, through reroutes and muted nodes (what Blender passes
    through them: their internal links, none for a muted node without inputs); muted or invalid links do not
    count."""
    found = []
    for link in sorted(socket.links, key=lambda link: link.multi_input_sort_id):
        if link.is_muted or not link.is_valid:
            continue
        node = link.from_node
        if node.bl_idname == "NodeReroute":
            found += _linked_nodes(node.inputs[0])
        elif node.mute:
            for inner in node.internal_links:
                if inner.to_socket == link.from_socket:
                    found += _linked_nodes(inner.from_socket)
        else:
            found.append(node)
    return found


def result_names(tree) -> set:
    """Names of the objects the tree's Output nodes write."""
    return {node.object_name for node in tree.nodes if node.bl_idname == nodes.OUTPUT and node.object_name}


def _tree_results(skip=None) -> dict:
    """{result object name: the CSG tree whose Output node writes it} over every tree but ``skip``."""
    return {
        name.strip(): other
        for other in bpy.data.node_groups
        if other.bl_idname == nodes.TREE and other != skip
        for name in result_names(other)
    }


def _loop_through_trees(tree) -> list:
    """The names of the other trees through which ``tree`` reads its own results back (one reads an object another
    writes, and so on round to ``tree``: Auto Update would evaluate them by turns without end), in order; empty
    where there is no such loop. (Within one tree an Output may read another's result: they are ordered.)"""
    writes = _tree_results()

    def read_by(current) -> set:
        names = {node.object.name for node in current.nodes if node.bl_idname == nodes.OBJECT and node.object}
        for node in current.nodes:
            if node.bl_idname == nodes.COLLECTION and node.collection is not None:
                names |= {obj.name for obj in collection_meshes(node.collection, result_names(current))}
        return names

    visited = set()

    def back_to_tree(current) -> list | None:
        for name in sorted(read_by(current)):
            writer = writes.get(name)
            if writer is None or writer == current:
                continue
            if writer == tree:
                return []
            if writer.name not in visited:
                visited.add(writer.name)
                found = back_to_tree(writer)
                if found is not None:
                    return [writer.name, *found]
        return None

    return back_to_tree(tree) or []


def free_result_name(name: str) -> str:
    """``name``, or ``name.001``, ``name.002``... where a CSG tree writes it already (a second tree from the same
    selection)."""
    taken = _tree_results()
    found, k = name, 0
    while found in taken:
        k += 1
        found = f"{name}.{k:03d}"
    return found


def collection_meshes(collection, exclude=()) -> list:
    """Objects with geometry (``is_operand``) of a collection and its children, except those named in
    ``exclude`` (the tree's results)."""
    return [obj for obj in collection.all_objects if is_operand(obj) and obj.name not in exclude]


def input_objects(tree) -> tuple[set, set]:
    """(session_uids of the input objects, session_uids of the input collections) of a tree, for Auto Update."""
    objects, collections = set(), set()
    exclude = result_names(tree)
    for node in tree.nodes:
        if node.bl_idname == nodes.OBJECT and node.object is not None:
            objects.add(node.object.session_uid)
        elif node.bl_idname == nodes.COLLECTION and node.collection is not None:
            collections.add(node.collection.session_uid)
            objects |= {obj.session_uid for obj in collection_meshes(node.collection, exclude)}
    return objects, collections


def plan_tree(tree) -> list[OutputPlan]:
    """Validate a tree and plan each Output node; problems go on the nodes and are raised together.

    Raises:
        AasdfError: Listing every problem as ``node: message``.
    """
    engine = runtime.engine()
    errors = {}  # node name -> message
    outputs = [node for node in tree.nodes if node.bl_idname == nodes.OUTPUT]
    exclude = result_names(tree)
    if not outputs:
        tree.message = "Add an Output node"
        raise engine.AasdfError("add an Output node")  # (the caller names the tree)
    loop = _loop_through_trees(tree)
    if loop:
        tree.message = f"Reads its own results through {', '.join(repr(name) for name in loop)}: a loop"
        raise engine.AasdfError(
            f"the trees {', '.join(repr(name) for name in [tree.name, *loop])} read each other's "
            "results: a loop that would be evaluated without end; take one of those inputs out"
        )
    seen, elsewhere = {}, _tree_results(skip=tree)
    for node in outputs:
        name = node.object_name.strip()
        if not name:
            errors[node.name] = "Name the result object"
        elif name in seen:
            errors[node.name] = errors[seen[name]] = f"Another Output node also writes '{name}'"
        elif name in elsewhere:
            errors[node.name] = f"The tree '{elsewhere[name].name}' also writes '{name}': name another result object"
        else:
            seen[name] = node.name

    plans = []
    for out in outputs:
        operands = []
        linked = _linked_nodes(out.inputs[0])
        if not linked:
            errors[out.name] = "Connect the 'Field' input"
            steps = None
        else:
            steps = _plan_node(linked[0], operands, errors, exclude)
        target = bpy.data.objects.get(out.object_name)
        if target is not None and target.type != "MESH":
            errors[out.name] = f"'{target.name}' exists and is not a mesh object"
        elif target is not None and target in [item.obj for item in operands]:
            errors[out.name] = f"'{target.name}' is also an input of this output"
        first = operands[0].obj if operands else None
        collection = result_collection(first, bpy.context.view_layer)
        plans.append(OutputPlan(out.name, out.object_name, operands, steps, collection))

    plans = _in_order(plans, errors)
    _set_messages(tree, errors)
    if errors:
        tree.message = f"{len(errors)} node(s) need attention"
        raise engine.AasdfError("; ".join(f"{name}: {message}" for name, message in errors.items()))
    return plans


def _in_order(plans: list, errors: dict) -> list:
    """The plans ordered so that an Output reading another's result object comes after it (evaluated in the nodes'
    order, it read the result as it was before this evaluation); Outputs whose results feed each other round a loop
    get a message instead (each evaluation would change the others')."""
    writer = {item.object_name: k for k, item in enumerate(plans)}
    needs = [
        {writer[op.obj.name] for op in item.operands if writer.get(op.obj.name, k) != k} for k, item in enumerate(plans)
    ]
    order, done = [], set()
    while len(order) < len(plans):
        ready = [k for k in range(len(plans)) if k not in done and needs[k] <= done]
        if not ready:
            for k in set(range(len(plans))) - done:
                errors[plans[k].node_name] = "Its result feeds another Output whose result feeds it: break the loop"
            return plans
        order += ready
        done |= set(ready)
    return [plans[k] for k in order]


def _operand(obj, thickness, operands) -> tuple:
    item = plan.Input(obj, float(thickness))
    if item not in operands:
        operands.append(item)
    return ("field", operands.index(item))


def _plan_node(node, operands, errors, exclude, path=()):
    """The plan of the field a node outputs, adding its mesh objects to ``operands``; ``None`` on a problem (a node
    on ``path``, the nodes it feeds, feeds itself: Blender keeps a node's link to itself valid)."""
    kind = node.bl_idname
    if node.name in path:
        errors[node.name] = "Its output comes back to its own input: remove the loop of links"
        return None
    path = (*path, node.name)
    if kind == nodes.OBJECT:
        obj = node.object
        if obj is None:
            errors[node.name] = "Choose an object"
            return None
        if not is_operand(obj):
            errors[node.name] = refusal(obj)
            return None
        return _operand(obj, node.thickness, operands)
    if kind == nodes.COLLECTION:
        collection = node.collection
        if collection is None:
            errors[node.name] = "Choose a collection"
            return None
        meshes = collection_meshes(collection, exclude)
        if not meshes:
            errors[node.name] = f"Collection '{collection.name}' has no objects with geometry"
            return None
        return ("boolean", "UNION", 0.0, "ROUND", [_operand(obj, node.thickness, operands) for obj in meshes])
    if kind in nodes.BOOLEAN_NODES:
        children = []
        for socket in node.inputs:
            linked = _linked_nodes(socket)
            if not linked:
                errors[node.name] = f"Connect the '{socket.name}' input"
            children += [_plan_node(child, operands, errors, exclude, path) for child in linked]
        if node.name in errors or None in children:
            return None
        return ("boolean", nodes.BOOLEAN_NODES[kind], float(node.blend), node.blend_mode, children)
    if kind in (nodes.OFFSET, nodes.SHELL):
        linked = _linked_nodes(node.inputs[0])
        if not linked:
            errors[node.name] = "Connect the 'Field' input"
            return None
        child = _plan_node(linked[0], operands, errors, exclude, path)
        if child is None:
            return None
        if kind == nodes.OFFSET:
            return ("offset", float(node.distance), child)
        if not node.wall > 0.0:
            errors[node.name] = "Set a Wall thicker than 0"
            return None
        return ("shell", float(node.wall), node.side, child)
    errors[node.name] = f"A {node.bl_label} node cannot feed an SDF input"
    return None


def _set_messages(tree, errors):
    """Write each node's message (empty when fine), touching only those that change."""
    for node in tree.nodes:
        if isinstance(node, nodes.CsgNode):
            message = errors.get(node.name, "")
            if node.message != message:
                node.message = message
    if not errors and tree.message:
        tree.message = ""


def evaluate_tree(context, tree) -> list[dict]:
    """Evaluate every Output node of a CSG tree and write its result object.

    Args:
        context: The caller's context (preferences, depsgraph, scene).
        tree: An ``AASDF CSG`` node tree.
    Returns:
        One ``pipeline.last_run``-style dict per output; an empty result has ``"empty": True`` and writes nothing, an
        output left as it was ``"unchanged": True``.
    Raises:
        AasdfError: Invalid tree (nothing written) or an engine error (message on the Output node; earlier outputs
            are written, this one keeps its previous result).
    """
    engine = runtime.engine()
    follow_renames(tree)
    plans = plan_tree(tree)
    settings = pipeline.FieldSettings.of(tree)
    runs = []
    for output_plan in plans:
        out = tree.nodes[output_plan.node_name]
        output = pipeline.Output(
            output_plan.object_name,
            target=bpy.data.objects.get(output_plan.object_name),
            collection=output_plan.collection,
            select=False,
            hide_inputs=tree.hide_inputs,
            sharp=tree.sharp_edges,
            keep_faces=out.keep_faces,
            reuse=True,
            adaptivity=out.adaptivity,
        )
        try:
            numbers = pipeline.run(
                context, output_plan.operands, output_plan.plan, settings, output, source=tree.name, operation="TREE"
            )
        except engine.AasdfError as err:
            out.message = str(err)
            tree.message = f"{out.name}: {err}"
            raise engine.AasdfError(f"{out.name}: {err}") from err
        written = bpy.data.objects.get(numbers["object"])
        if written is not None and not numbers.get("empty"):
            out.result, out.written = written, written.name
        if numbers.get("empty"):
            out.message = "The result is empty: the previous result is kept"
        elif numbers.get("warnings"):
            out.message = "; ".join(numbers["warnings"])
        runs.append(numbers)
    return runs


def follow_renames(tree) -> None:
    """Keep each Output node and the object it wrote last naming each other: the object renamed (in the Outliner) is
    followed by the node; the node's name changed is taken by the object, unless another object has that name (then
    the output writes into that one, as asked). Otherwise a new object would take the name and the renamed or old one
    stay behind, no longer updated."""
    for node in tree.nodes:
        if node.bl_idname != nodes.OUTPUT or node.result is None or not node.written:
            continue
        obj, name = node.result, node.object_name.strip()
        if name == node.written and obj.name != name:
            node.object_name = obj.name
        elif name and name != node.written and obj.name == node.written and name not in bpy.data.objects:
            obj.name = name
        if obj.name == node.object_name.strip():  # (in step again, should the evaluation fail)
            node.written = obj.name
