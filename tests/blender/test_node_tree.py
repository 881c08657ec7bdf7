"""The ``AASDF CSG`` node tree, headless: evaluation against the equivalent ``aasdf.boolean`` chain, in-place results,
the shared field cache, save and reload, invalid trees, Auto Update (handler + debounced timer) and tree creation."""

import bpy
import numpy as np
import pytest

from aasdf.aasdf_addon import autoupdate, cache, csg, nodes, pipeline
from aasdf.ui import node_editor
from tests.blender.scene import add_mesh_object, select, world_arrays
from tests.metrics import mesh_area, mesh_volume
from tests.support import is_watertight, uv_sphere

VOXEL = 0.04  # explicit: the combined bounding box must not change the spacing when an input moves
SPHERE = uv_sphere(1.0, rings=24, segments=48)
SMALL = uv_sphere(0.5, rings=16, segments=32)


def face_slots_and_centers(obj):
    mesh = obj.data
    slots = np.empty(len(mesh.polygons), dtype=np.int32)
    mesh.polygons.foreach_get("material_index", slots)
    centers = np.empty(len(mesh.polygons) * 3, dtype=np.float32)
    mesh.polygons.foreach_get("center", centers)
    return slots, centers.reshape(-1, 3)


def scene():
    """Objects A and B, and a collection ``Cutters`` with C1 and C2, each with its own material."""
    red, blue, green = (bpy.data.materials.new(name) for name in ("Red", "Blue", "Green"))
    a = add_mesh_object("A", *SPHERE, materials=[red])
    b = add_mesh_object("B", *SPHERE, location=(1.0, 0.0, 0.0), materials=[blue])
    cutters = bpy.data.collections.new("Cutters")
    bpy.context.scene.collection.children.link(cutters)
    c1 = add_mesh_object("C1", *SMALL, location=(0.5, 0.0, 0.8), collection=cutters, materials=[green])
    c2 = add_mesh_object("C2", *SMALL, location=(0.5, 0.0, -0.8), collection=cutters, materials=[green])
    return a, b, cutters, c1, c2


def build_tree(a, b, cutters, name="Tree", result="Result"):
    """Output ← Difference(Base: Union(Object A, Object B), Cutters: Collection)."""
    tree = bpy.data.node_groups.new(name, nodes.TREE)
    tree.voxel_size, tree.levels, tree.padding = VOXEL, 4, 1
    node_a, node_b = tree.nodes.new(nodes.OBJECT), tree.nodes.new(nodes.OBJECT)
    node_a.name, node_b.name = "Object A", "Object B"
    node_a.object, node_b.object = a, b
    node_c = tree.nodes.new(nodes.COLLECTION)
    node_c.collection = cutters
    union, difference = tree.nodes.new(nodes.UNION), tree.nodes.new(nodes.DIFFERENCE)
    output = tree.nodes.new(nodes.OUTPUT)
    output.object_name = result
    tree.links.new(node_a.outputs[0], union.inputs["Fields"])
    tree.links.new(node_b.outputs[0], union.inputs["Fields"])
    tree.links.new(union.outputs[0], difference.inputs["Base"])
    tree.links.new(node_c.outputs[0], difference.inputs["Cutters"])
    tree.links.new(difference.outputs[0], output.inputs[0])
    return tree


@pytest.fixture
def evaluated(fresh_cache):
    """The scene and its tree, evaluated once."""
    a, b, cutters, c1, c2 = scene()
    tree = build_tree(a, b, cutters)
    assert bpy.ops.aasdf.evaluate_tree(tree=tree.name) == {"FINISHED"}
    return tree, bpy.data.objects["Result"], (a, b, cutters, c1, c2)


# ---- evaluation ----


def test_an_input_blender_does_not_evaluate_is_refused_unless_it_has_nothing_to_evaluate(fresh_cache):
    # cutters in a collection excluded from the view layer (or disabled in viewports) are not evaluated: read as they
    # were, one with an Array modifier lost its copies, a Geometry Nodes cutter was "empty"
    a, b, cutters, c1, _ = scene()
    c1.modifiers.new("Array", "ARRAY").relative_offset_displace = (1.0, 0.0, 0.0)
    bpy.context.view_layer.layer_collection.children["Cutters"].exclude = True
    tree = build_tree(a, b, cutters)
    with pytest.raises(RuntimeError, match=r"'C1' is not evaluated .* enable it \(hide it with H instead\)"):
        bpy.ops.aasdf.evaluate_tree(tree=tree.name)
    assert "Result" not in bpy.data.objects and cache.stats()["builds"] == 0
    c1.modifiers["Array"].show_viewport = False  # nothing of its own to evaluate: read as it is
    assert bpy.ops.aasdf.evaluate_tree(tree=tree.name) == {"FINISHED"}
    assert is_watertight(world_arrays(bpy.data.objects["Result"])[1])
    holder = bpy.data.objects.new("Holder", None)
    bpy.context.scene.collection.objects.link(holder)
    c1.parent = holder  # read as it is, it would stay where it was when its parent moves
    with pytest.raises(RuntimeError, match=r"'C1' is not evaluated .* parent or animation would be left out"):
        bpy.ops.aasdf.evaluate_tree(tree=tree.name)


def test_tree_equals_the_chain_of_boolean_operators(evaluated):
    tree, result, (a, b, _, c1, c2) = evaluated
    verts, tris = world_arrays(result)
    assert is_watertight(tris)
    # A and B share one geometry, C1 and C2 another: two fields, each placed for both of its objects
    assert pipeline.last_run["source"] == "Tree" and pipeline.last_run["fields_built"] == 2
    assert pipeline.last_run["level_counts"][0] > 0 and set(pipeline.last_run["stages"]) == set(pipeline.STAGES)

    select(a, b)
    # remeshed on both sides: the chain's second step would keep the first result's faces, the tree the inputs'
    next(node for node in tree.nodes if node.bl_idname == nodes.OUTPUT).keep_faces = False
    assert bpy.ops.aasdf.evaluate_tree(tree=tree.name) == {"FINISHED"}
    verts, tris = world_arrays(result)
    chain = {"voxel_size": VOXEL, "levels": 4, "padding": 1, "hide_inputs": False, "keep_faces": False}
    bpy.ops.aasdf.boolean(operation="UNION", **chain)
    united = bpy.context.active_object
    select(united, c1, c2)
    bpy.ops.aasdf.boolean(operation="DIFFERENCE", **chain)
    chain_verts, chain_tris = world_arrays(bpy.context.active_object)
    assert len(verts) == len(chain_verts)
    assert mesh_volume(verts, tris) == pytest.approx(mesh_volume(chain_verts, chain_tris), rel=1e-3)
    # The fields of A, B, C1 and C2 came from the tree's evaluation: the chain built only its intermediate result's.
    assert cache.stats()["builds"] == 3


def test_a_muted_node_passes_on_what_blender_passes_through_it(evaluated):
    """A muted node (M in the editor) was evaluated as if it were not: muted, the Difference passes its Base on (its
    internal link, as Blender draws it), the result is the union alone; a muted Union passes its first field on."""
    tree, result, _ = evaluated
    difference = next(node for node in tree.nodes if node.bl_idname == nodes.DIFFERENCE)
    union = next(node for node in tree.nodes if node.bl_idname == nodes.UNION)
    with_cutters = mesh_volume(*world_arrays(result))
    difference.mute = True
    assert bpy.ops.aasdf.evaluate_tree(tree=tree.name) == {"FINISHED"}
    united = mesh_volume(*world_arrays(result))
    assert united > 1.04 * with_cutters  # measured 1.108x: the cutters' holes gone
    union.mute = True
    assert bpy.ops.aasdf.evaluate_tree(tree=tree.name) == {"FINISHED"}
    alone = mesh_volume(*world_arrays(result))  # sphere A alone
    assert alone == pytest.approx(mesh_volume(*world_arrays(bpy.data.objects["A"])), rel=0.01)
    assert alone < 0.8 * united  # measured 0.59


def test_a_second_tree_may_not_write_the_first_ones_result(evaluated):
    """Two trees writing one object overwrote each other's result in turn (volumes 8.71 and 7.29 by turns), silently:
    the second is refused, its Output node saying which tree writes the object."""
    tree, result, (a, b, cutters, _, _) = evaluated
    before = mesh_volume(*world_arrays(result))
    other = build_tree(a, b, cutters, name="Other")
    with pytest.raises(RuntimeError, match="The tree 'Tree' also writes 'Result'"):
        bpy.ops.aasdf.evaluate_tree(tree=other.name)
    output = next(node for node in other.nodes if node.bl_idname == nodes.OUTPUT)
    assert output.message == "The tree 'Tree' also writes 'Result': name another result object"
    assert mesh_volume(*world_arrays(result)) == before
    output.object_name = "Other result"
    assert bpy.ops.aasdf.evaluate_tree(tree=other.name) == {"FINISHED"}


def test_trees_reading_each_others_results_are_refused_as_a_loop(evaluated):
    """Tree reads A, B and the cutters, writes Result; Other grows Result into Grown. Tree reading Grown for A closes a
    loop that Auto Update evaluated by turns without end, the results growing each round: refused on both trees, the
    results left as they were, until the loop is taken out."""
    tree, result, (a, *_) = evaluated
    other = bpy.data.node_groups.new("Other", nodes.TREE)
    other.voxel_size = tree.voxel_size
    read, offset, output = (other.nodes.new(kind) for kind in (nodes.OBJECT, nodes.OFFSET, nodes.OUTPUT))
    read.object, offset.distance, output.object_name = result, 0.05, "Grown"
    other.links.new(read.outputs[0], offset.inputs[0])
    other.links.new(offset.outputs[0], output.inputs[0])
    assert bpy.ops.aasdf.evaluate_tree(tree=other.name) == {"FINISHED"}
    before = mesh_volume(*world_arrays(result))
    tree.nodes["Object A"].object = bpy.data.objects["Grown"]
    for name in ("Tree", "Other"):
        with pytest.raises(RuntimeError, match="read each other's results: a loop"):
            bpy.ops.aasdf.evaluate_tree(tree=name)
    assert tree.message == "Reads its own results through 'Other': a loop"
    assert mesh_volume(*world_arrays(result)) == before
    tree.nodes["Object A"].object = a
    assert bpy.ops.aasdf.evaluate_tree(tree=tree.name) == {"FINISHED"} and tree.message == ""


def test_result_faces_take_the_material_of_their_operand(evaluated):
    _, result, _ = evaluated
    assert [slot.material.name for slot in result.material_slots] == ["Red", "Blue", "Green"]
    slots, centers = face_slots_and_centers(result)
    assert np.all(slots[centers[:, 0] < -0.5] == 0) and np.all(slots[centers[:, 0] > 1.5] == 1)
    cut = (np.abs(centers[:, 0] - 0.5) < 0.2) & (np.abs(centers[:, 2]) > 0.2) & (np.abs(centers[:, 1]) < 0.2)
    assert cut.any() and np.all(slots[cut] == 2)  # the cut surfaces come from the collection's spheres
    operand = np.empty(len(result.data.polygons), dtype=np.int32)
    result.data.attributes["aasdf_operand"].data.foreach_get("value", operand)
    assert np.all(operand[centers[:, 0] < -0.5] == 0) and np.all(operand[centers[:, 0] > 1.5] == 1)
    assert set(np.unique(operand[cut])) <= {2, 3}  # the collection's two spheres


def test_output_updates_its_object_in_place_and_moved_inputs_build_nothing(evaluated):
    tree, result, (a, b, _, c1, _) = evaluated
    pointer, old_mesh, meshes = result.as_pointer(), result.data.name, len(bpy.data.meshes)
    before = world_arrays(result)[0]
    b.location.x += 0.2
    bpy.context.view_layer.update()
    assert bpy.ops.aasdf.evaluate_tree(tree=tree.name) == {"FINISHED"}
    assert pipeline.last_run["fields_built"] == 0 and pipeline.last_run["cache_hits"] == 4  # B's field, placed
    result = bpy.data.objects["Result"]
    assert result.as_pointer() == pointer and result.data.name == old_mesh and len(bpy.data.meshes) == meshes
    after = world_arrays(result)[0]
    assert after[:, 0].max() == pytest.approx(before[:, 0].max() + 0.2, abs=VOXEL)
    c1.location.z += 0.1  # a collection member moves: its field is placed too
    bpy.context.view_layer.update()
    bpy.ops.aasdf.evaluate_tree(tree=tree.name)
    assert pipeline.last_run["fields_built"] == 0 and pipeline.last_run["cache_hits"] == 4


def test_a_renamed_result_object_is_followed_by_its_output(evaluated):
    tree, result, (_, b, *_rest) = evaluated
    pointer, objects = result.as_pointer(), len(bpy.data.objects)
    before = world_arrays(result)[0][:, 0].max()
    result.name = "Bracket"  # renamed in the Outliner
    b.location.x += 0.2
    bpy.context.view_layer.update()
    assert bpy.ops.aasdf.evaluate_tree(tree=tree.name) == {"FINISHED"}
    assert "Result" not in bpy.data.objects and len(bpy.data.objects) == objects
    assert tree.nodes["Output"].object_name == "Bracket"
    bracket = bpy.data.objects["Bracket"]
    assert bracket.as_pointer() == pointer  # updated, not left behind
    assert world_arrays(bracket)[0][:, 0].max() == pytest.approx(before + 0.2, abs=VOXEL)
    bracket.name = "Bracket 2"  # renamed again, nothing else changed: followed, nothing done
    assert bpy.ops.aasdf.evaluate_tree(tree=tree.name) == {"FINISHED"}
    assert pipeline.last_run.get("unchanged") and tree.nodes["Output"].object_name == "Bracket 2"
    assert "Bracket" not in bpy.data.objects and len(bpy.data.objects) == objects


def test_an_output_given_a_new_name_renames_its_result_object(evaluated):
    tree, result, (a, *_rest) = evaluated
    pointer, objects = result.as_pointer(), len(bpy.data.objects)
    tree.nodes["Output"].object_name = "Part"
    assert bpy.ops.aasdf.evaluate_tree(tree=tree.name) == {"FINISHED"}
    assert "Result" not in bpy.data.objects and len(bpy.data.objects) == objects
    assert bpy.data.objects["Part"].as_pointer() == pointer
    # a name another object has: the output writes into that one, as asked, and the old result stays
    other = add_mesh_object("Other", *SMALL, location=(4.0, 0.0, 0.0))
    tree.nodes["Output"].object_name = "Other"
    assert bpy.ops.aasdf.evaluate_tree(tree=tree.name) == {"FINISHED"}
    assert bpy.data.objects["Part"].as_pointer() == pointer
    assert len(other.data.vertices) == len(bpy.data.objects["Part"].data.vertices)


def test_moved_result_object_still_shows_the_boolean_in_place(evaluated):
    tree, result, _ = evaluated
    before = world_arrays(result)[0]
    result.location = (5.0, 0.0, 0.0)
    result.rotation_euler.z = 0.5
    bpy.context.view_layer.update()
    bpy.ops.aasdf.evaluate_tree(tree=tree.name)
    assert pipeline.last_run["fields_built"] == 0
    after = world_arrays(bpy.data.objects["Result"])[0]
    np.testing.assert_allclose(after.min(axis=0), before.min(axis=0), atol=1e-4)
    np.testing.assert_allclose(after.max(axis=0), before.max(axis=0), atol=1e-4)


def _edges_match_corners(mesh) -> bool:
    """Each corner's edge joins its vertex to the next corner's, every edge once (what Blender would derive)."""
    n = len(mesh.loops)
    corner_vert, corner_edge = np.empty(n, np.int32), np.empty(n, np.int32)
    mesh.attributes[".corner_vert"].data.foreach_get("value", corner_vert)
    mesh.attributes[".corner_edge"].data.foreach_get("value", corner_edge)
    pairs = np.empty(2 * len(mesh.edges), np.int32)
    mesh.attributes[".edge_verts"].data.foreach_get("value", pairs)
    pairs = np.sort(pairs.reshape(-1, 2).astype(np.int64), axis=1)
    loop_start, loop_total = np.empty(len(mesh.polygons), np.int32), np.empty(len(mesh.polygons), np.int32)
    mesh.polygons.foreach_get("loop_start", loop_start)
    mesh.polygons.foreach_get("loop_total", loop_total)
    # each corner's next corner around its face (triangles and the quads written whole)
    within = np.arange(n) - np.repeat(loop_start, loop_total)
    following = np.repeat(loop_start, loop_total) + (within + 1) % np.repeat(loop_total, loop_total)
    heads, tails = corner_vert.astype(np.int64), corner_vert[following].astype(np.int64)
    keys = np.minimum(heads, tails) * len(mesh.vertices) + np.maximum(heads, tails)
    own = pairs[:, 0] * len(mesh.vertices) + pairs[:, 1]
    return len(np.unique(own)) == len(own) and np.array_equal(own[corner_edge], keys)


def test_result_edges_join_their_corners_also_in_a_mirrored_result_object(evaluated):
    tree, result, _ = evaluated
    assert _edges_match_corners(result.data) and not result.data.validate()
    result.scale.x = -1.0  # its vertices are written mirrored, its triangles flipped: their edges must follow
    bpy.context.view_layer.update()
    bpy.ops.aasdf.evaluate_tree(tree=tree.name)
    result = bpy.data.objects["Result"]
    assert _edges_match_corners(result.data) and not result.data.validate()
    assert is_watertight(world_arrays(result)[1])


def test_tree_is_saved_with_the_blend_and_evaluates_after_reload(evaluated, tmp_path):
    tree, result, _ = evaluated
    vertices = len(result.data.vertices)
    tree.auto_update = False
    path = str(tmp_path / "csg.blend")
    assert tree.use_fake_user
    bpy.ops.wm.save_as_mainfile(filepath=path)
    bpy.ops.wm.open_mainfile(filepath=path)
    assert cache.stats()["entries"] == 0  # file load empties the cache
    tree = bpy.data.node_groups["Tree"]
    assert tree.bl_idname == nodes.TREE and tree.use_fake_user and tree.voxel_size == pytest.approx(VOXEL)
    assert tree.nodes["Object A"].object == bpy.data.objects["A"]
    assert len(tree.links) == 5
    bpy.data.objects["Result"].data.clear_geometry()
    assert bpy.ops.aasdf.evaluate_tree(tree="Tree") == {"FINISHED"}
    assert len(bpy.data.objects["Result"].data.vertices) == vertices
    assert pipeline.last_run["fields_built"] == 2


def test_two_outputs_write_two_objects_from_shared_fields(evaluated):
    tree, _, _ = evaluated
    second = tree.nodes.new(nodes.OUTPUT)
    second.object_name = "United"
    tree.links.new(tree.nodes["Union"].outputs[0], second.inputs[0])
    runs = csg.evaluate_tree(bpy.context, tree)
    assert [run["object"] for run in runs] == ["Result", "United"]
    assert [run["fields_built"] for run in runs] == [0, 0]
    united = world_arrays(bpy.data.objects["United"])
    assert mesh_volume(*united) > mesh_volume(*world_arrays(bpy.data.objects["Result"]))


def test_an_output_reading_anothers_result_is_evaluated_after_it(evaluated):
    # created first, it was evaluated first: it read the other's result as it was before (stale, and "unchanged")
    tree, _, (a, b, *_) = evaluated
    reader = tree.nodes.new(nodes.OUTPUT)
    reader.object_name = "Grown"
    source = tree.nodes.new(nodes.OBJECT)
    source.object = bpy.data.objects["Result"]
    offset = tree.nodes.new(nodes.OFFSET)
    offset.distance = 0.1
    tree.links.new(source.outputs[0], offset.inputs[0])
    tree.links.new(offset.outputs[0], reader.inputs[0])
    tree.nodes.remove(tree.nodes["Output"])  # the writer made again after the reader: after it in the nodes' order
    writer = tree.nodes.new(nodes.OUTPUT)
    writer.object_name = "Result"
    tree.links.new(tree.nodes["Difference"].outputs[0], writer.inputs[0])
    assert [run["object"] for run in csg.evaluate_tree(bpy.context, tree)] == ["Result", "Grown"]
    before = mesh_volume(*world_arrays(bpy.data.objects["Result"]))
    b.location.x += 0.3
    bpy.context.view_layer.update()
    csg.evaluate_tree(bpy.context, tree)
    result, grown = (mesh_volume(*world_arrays(bpy.data.objects[name])) for name in ("Result", "Grown"))
    area = mesh_area(*world_arrays(bpy.data.objects["Result"]))
    assert result - before > 0.5  # (the move changed the result: 6.34 -> 7.05)
    # grown by 0.1 from the moved result (measured 1.07 times area x 0.1, curved; from the one before: 0.75)
    assert abs((grown - result) / (0.1 * area) - 1.0) < 0.15


# ---- invalid trees ----


def break_unlinked(tree, objects):
    tree.links.remove(tree.nodes["Difference"].inputs["Cutters"].links[0])
    return "Difference", "Connect the 'Cutters' input"


def break_no_object(tree, objects):
    tree.nodes["Object A"].object = None
    return "Object A", "Choose an object"


def break_non_mesh(tree, objects):
    empty = bpy.data.objects.new("Empty", None)
    bpy.context.scene.collection.objects.link(empty)
    tree.nodes["Object A"].object = empty
    return "Object A", "'Empty' is an empty and has no geometry: use a mesh, text, curve, surface or metaball object"


def break_empty_collection(tree, objects):
    cutters = objects[2]
    for obj in list(cutters.objects):
        cutters.objects.unlink(obj)
    return "Collection", "Collection 'Cutters' has no objects with geometry"


def break_same_output_name(tree, objects):
    second = tree.nodes.new(nodes.OUTPUT)
    second.object_name = "Result"
    tree.links.new(tree.nodes["Union"].outputs[0], second.inputs[0])
    return "Output.001", "Another Output node also writes 'Result'"


def break_loop_of_links(tree, objects):  # (Blender keeps a node's link to itself valid: a RecursionError before)
    offset = tree.nodes.new(nodes.OFFSET)
    tree.links.new(offset.outputs[0], offset.inputs[0])
    tree.links.new(offset.outputs[0], tree.nodes["Union"].inputs["Fields"])
    return "Offset", "Its output comes back to its own input: remove the loop of links"


def break_shell_wall_0(tree, objects):  # (the property allows 0: a ValueError from the engine before)
    shell = tree.nodes.new(nodes.SHELL)
    shell.wall = 0.0
    tree.links.new(tree.nodes["Object B"].outputs[0], shell.inputs[0])
    tree.links.new(shell.outputs[0], tree.nodes["Union"].inputs["Fields"])
    return "Shell", "Set a Wall thicker than 0"


def break_outputs_feeding_each_other(tree, objects):  # (each evaluation changed the other's result)
    second = tree.nodes.new(nodes.OUTPUT)
    second.object_name = "Loop"
    source = tree.nodes.new(nodes.OBJECT)
    source.object = bpy.data.objects["Result"]
    tree.links.new(source.outputs[0], second.inputs[0])
    bpy.ops.aasdf.evaluate_tree(tree=tree.name)
    tree.nodes["Object A"].object = bpy.data.objects["Loop"]
    return "Output", "Its result feeds another Output whose result feeds it: break the loop"


@pytest.mark.parametrize(
    "breaker",
    [
        *(break_unlinked, break_no_object, break_non_mesh, break_empty_collection, break_same_output_name),
        *(break_loop_of_links, break_shell_wall_0, break_outputs_feeding_each_other),
    ],
)
def test_invalid_tree_shows_its_message_and_keeps_the_previous_result(evaluated, breaker):
    tree, result, objects = evaluated
    mesh, vertices = result.data.name, len(result.data.vertices)
    node, message = breaker(tree, objects)
    builds = cache.stats()["builds"]
    with pytest.raises(RuntimeError, match=f"Error: Tree: {node}: {message}"):
        bpy.ops.aasdf.evaluate_tree(tree=tree.name)
    assert tree.nodes[node].message == message
    assert tree.message
    result = bpy.data.objects["Result"]
    assert result.data.name == mesh and len(result.data.vertices) == vertices
    assert cache.stats()["builds"] == builds  # refused before any work


def test_fixed_tree_clears_its_messages(evaluated):
    tree, _, (a, *_) = evaluated
    break_no_object(tree, None)
    with pytest.raises(RuntimeError, match="Choose an object"):
        bpy.ops.aasdf.evaluate_tree(tree=tree.name)
    tree.nodes["Object A"].object = a
    assert bpy.ops.aasdf.evaluate_tree(tree=tree.name) == {"FINISHED"}
    assert tree.message == "" and all(node.message == "" for node in tree.nodes)


def test_result_object_may_not_be_an_input(evaluated):
    tree, result, _ = evaluated
    tree.nodes["Object A"].object = result
    with pytest.raises(RuntimeError, match="Output: 'Result' is also an input of this output"):
        bpy.ops.aasdf.evaluate_tree(tree=tree.name)


def test_engine_error_is_shown_on_the_output_and_keeps_the_previous_result(evaluated):
    tree, result, _ = evaluated
    vertices = len(result.data.vertices)
    tree.voxel_size = 1e-6
    with pytest.raises(RuntimeError, match="Error: Tree: Output: A: .*use a larger voxel size"):
        bpy.ops.aasdf.evaluate_tree(tree=tree.name)
    assert "use a larger voxel size" in tree.nodes["Output"].message
    assert len(bpy.data.objects["Result"].data.vertices) == vertices


def test_inputs_without_extent_need_a_voxel_size(fresh_cache):
    point = ([[0.0, 0.0, 0.0]] * 3, [[0, 1, 2]])
    p, q = add_mesh_object("P", *point), add_mesh_object("Q", *point)
    select(p, q)
    bpy.ops.aasdf.tree_from_selection(operation="UNION", evaluate=False)
    with pytest.raises(RuntimeError, match="Output: The inputs have no extent: set a Voxel Size"):
        bpy.ops.aasdf.evaluate_tree(tree="P CSG")
    assert "P.csg" not in bpy.data.objects


def test_empty_result_is_a_warning_and_keeps_the_previous_result(evaluated):
    tree, result, (a, b, *_) = evaluated
    vertices = len(result.data.vertices)
    tree.nodes["Object B"].object = a  # Union(A, A) minus the cutters: still a result
    b.location.x = 10.0
    difference = tree.nodes["Difference"]
    tree.links.remove(difference.inputs["Base"].links[0])
    intersect = tree.nodes.new(nodes.INTERSECT)
    object_b = tree.nodes.new(nodes.OBJECT)
    object_b.object = b
    tree.links.new(tree.nodes["Union"].outputs[0], intersect.inputs[0])
    tree.links.new(object_b.outputs[0], intersect.inputs[0])
    tree.links.new(intersect.outputs[0], difference.inputs["Base"])
    bpy.context.view_layer.update()
    assert bpy.ops.aasdf.evaluate_tree(tree=tree.name) == {"CANCELLED"}  # A ∩ far-away B is empty
    assert "empty" in tree.nodes["Output"].message
    assert len(bpy.data.objects["Result"].data.vertices) == vertices


def test_kept_faces_that_cannot_be_joined_are_told_on_the_output(evaluated, monkeypatch):
    # a join allowed no rounds: the output's message says so, its object is the remeshed result; fixed, it clears
    import importlib

    from aasdf.aasdf_addon import runtime

    tree, result, (a, *_) = evaluated
    hybrid = importlib.import_module(runtime.engine().__name__ + ".hybrid")
    monkeypatch.setattr(hybrid, "MAX_ROUNDS", 0)
    a.location.x += 0.05
    bpy.context.view_layer.update()
    assert bpy.ops.aasdf.evaluate_tree(tree=tree.name) == {"FINISHED"}
    assert tree.nodes["Output"].message.startswith("Keep Original Faces: the seams could not be joined")
    assert is_watertight(world_arrays(bpy.data.objects["Result"])[1])
    monkeypatch.undo()
    a.location.x -= 0.05
    bpy.context.view_layer.update()
    assert bpy.ops.aasdf.evaluate_tree(tree=tree.name) == {"FINISHED"}
    assert tree.nodes["Output"].message == ""


def test_evaluate_tree_reports_unknown_trees_and_polls_for_one():
    with pytest.raises(RuntimeError, match="Create an AASDF CSG tree first"):
        bpy.ops.aasdf.evaluate_tree(tree="Nope")
    bpy.data.node_groups.new("Tree", nodes.TREE)
    with pytest.raises(RuntimeError, match="No AASDF CSG tree named 'Nope'"):
        bpy.ops.aasdf.evaluate_tree(tree="Nope")
    with pytest.raises(RuntimeError, match="Tree: .*add an Output node"):
        bpy.ops.aasdf.evaluate_tree(tree="Tree")


def test_csg_nodes_only_go_into_csg_trees():
    geometry = bpy.data.node_groups.new("Geometry", "GeometryNodeTree")
    with pytest.raises(RuntimeError):
        geometry.nodes.new(nodes.OBJECT)
    tree = bpy.data.node_groups.new("Tree", nodes.TREE)
    assert tree.nodes.new(nodes.OBJECT).bl_idname == nodes.OBJECT
    assert tree.use_fake_user  # given as soon as the tree has nodes: saved even without an editor showing it


# ---- Auto Update ----


@pytest.fixture
def clock(monkeypatch):
    """A controllable ``time.monotonic`` for the debounce."""
    now = [1000.0]
    monkeypatch.setattr(autoupdate.time, "monotonic", lambda: now[0])
    return now


def test_auto_update_marks_dirty_in_the_handler_and_evaluates_in_the_debounced_timer(evaluated, clock):
    tree, result, (a, b, _, _, c2) = evaluated
    tree.auto_update = True
    autoupdate._dirty.clear()
    unrelated = add_mesh_object("Unrelated", *SMALL, location=(5.0, 0.0, 0.0))
    unrelated.location.x += 1.0
    bpy.context.view_layer.update()
    assert not autoupdate.is_dirty(tree)  # not an input

    for _ in range(5):  # a drag: many updates, each restarting the debounce
        b.location.x += 0.04
        bpy.context.view_layer.update()
        clock[0] += 0.1
    assert autoupdate.is_dirty(tree) and bpy.app.timers.is_registered(autoupdate._on_timer)
    assert len(bpy.data.objects["Result"].data.vertices) == len(result.data.vertices)  # the handler evaluated nothing
    wait = autoupdate._on_timer()  # 0.1 s after the last change: too early
    assert wait == pytest.approx(autoupdate.DEBOUNCE - 0.1) and autoupdate.is_dirty(tree)
    clock[0] += autoupdate.DEBOUNCE + 0.01
    assert autoupdate._on_timer() is None  # evaluates, then stops
    assert not autoupdate.is_dirty(tree)
    assert pipeline.last_run["fields_built"] == 0 and pipeline.last_run["source"] == "Tree"  # B's field, placed
    assert world_arrays(bpy.data.objects["Result"])[0][:, 0].max() == pytest.approx(2.2, abs=VOXEL)
    bpy.context.view_layer.update()  # the evaluation's own writes do not mark the tree again
    assert not autoupdate.is_dirty(tree)

    c2.location.z -= 0.05  # a member of an input collection
    bpy.context.view_layer.update()
    assert autoupdate.is_dirty(tree)
    bpy.ops.aasdf.evaluate_tree(tree=tree.name)  # headless: the explicit evaluation does the timer's work
    assert not autoupdate.is_dirty(tree) and pipeline.last_run["fields_built"] == 0

    add_mesh_object("C3", *SMALL, location=(0.5, 0.8, 0.0), collection=bpy.data.collections["Cutters"])
    assert autoupdate.is_dirty(tree)  # a new member of an input collection
    bpy.ops.aasdf.evaluate_tree(tree=tree.name)
    assert pipeline.last_run["operands"] == 5 and pipeline.last_run["fields_built"] == 0  # C3: C1's geometry


def test_node_settings_mark_an_auto_update_tree_dirty(evaluated, clock):
    tree, _, _ = evaluated
    autoupdate._dirty.clear()
    tree.nodes["Difference"].blend = 0.05  # Auto Update off: nothing queued
    assert not autoupdate.is_dirty(tree)
    tree.auto_update = True
    assert autoupdate.is_dirty(tree)
    autoupdate._dirty.clear()
    tree.nodes["Difference"].blend = 0.1
    assert autoupdate.is_dirty(tree)
    autoupdate._dirty.clear()
    tree.links.remove(tree.nodes["Output"].inputs[0].links[0])
    assert autoupdate.is_dirty(tree)
    clock[0] += autoupdate.DEBOUNCE + 0.01
    assert autoupdate._on_timer() is None  # an invalid tree: its messages, no exception
    assert tree.nodes["Output"].message == "Connect the 'Field' input"


def test_unregister_removes_the_timer_and_the_menu_entry(addon, evaluated):
    tree, _, _ = evaluated
    tree.auto_update = True
    assert bpy.app.timers.is_registered(autoupdate._on_timer)
    assert node_editor.draw_add_menu in bpy.types.NODE_MT_add._dyn_ui_initialize()
    addon.unregister()
    try:
        assert not bpy.app.timers.is_registered(autoupdate._on_timer)
        assert node_editor.draw_add_menu not in bpy.types.NODE_MT_add._dyn_ui_initialize()
        assert not hasattr(bpy.types, nodes.TREE)
    finally:
        addon.register()
    assert bpy.types.NODE_MT_add._dyn_ui_initialize().count(node_editor.draw_add_menu) == 1


def test_registering_again_leaves_existing_trees_alone_until_every_type_is_there(addon, evaluated, monkeypatch):
    # Unregistering and registering the add-on's classes make Blender update the trees of its type while their node
    # types are not all there; reading their nodes then can crash Blender, so those updates do nothing (they mark no
    # tree). The tree's nodes are not read here afterwards either: Python's references to them may not survive.
    evaluated[0].auto_update = True
    seen = []
    monkeypatch.setattr(autoupdate, "tree_changed", lambda tree: seen.append(tree.name))
    addon.unregister()
    addon.register()
    assert seen == []
    assert not nodes.classes_changing


# ---- a tree from the selection ----


def test_tree_from_selection_matches_the_boolean_operator(fresh_cache):
    a = add_mesh_object("A", *SPHERE)
    b = add_mesh_object("B", *SPHERE, location=(0.8, 0.0, 0.0))
    settings = bpy.context.scene.aasdf
    settings.resolution, settings.levels, settings.padding, settings.hide_inputs = 64, 4, 1, False
    select(a, b)
    assert bpy.ops.aasdf.tree_from_selection(operation="DIFFERENCE") == {"FINISHED"}
    tree = bpy.data.node_groups["A CSG"]
    assert settings.tree == tree and tree.use_fake_user and tree.auto_update
    assert {node.bl_idname for node in tree.nodes} == {nodes.OBJECT, nodes.DIFFERENCE, nodes.OUTPUT}
    from_tree = world_arrays(bpy.data.objects["A.csg"])
    select(a, b)
    bpy.ops.aasdf.boolean(operation="DIFFERENCE", resolution=64, levels=4, padding=1, hide_inputs=False)
    assert pipeline.last_run["fields_built"] == 0  # the tree's fields, from the cache
    from_operator = world_arrays(bpy.context.active_object)
    assert len(from_tree[1]) == len(from_operator[1])
    assert mesh_volume(*from_tree) == pytest.approx(mesh_volume(*from_operator), rel=1e-6)
    select(a, b)  # a second tree from the same selection writes an object of its own
    assert bpy.ops.aasdf.tree_from_selection(operation="UNION") == {"FINISHED"}
    assert mesh_volume(*world_arrays(bpy.data.objects["A.csg.001"])) > mesh_volume(*from_tree)
    assert mesh_volume(*world_arrays(bpy.data.objects["A.csg"])) == mesh_volume(*from_tree)


def test_tree_from_selection_needs_two_meshes():
    a = add_mesh_object("A", *SMALL)
    select(a)
    with pytest.raises(RuntimeError, match="Select at least two objects"):
        bpy.ops.aasdf.tree_from_selection()
    assert not [tree for tree in bpy.data.node_groups if tree.bl_idname == nodes.TREE]
