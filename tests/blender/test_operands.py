"""Operands as users have them, headless: text, curves, surfaces, metaballs and geometry-node instances taking part by
their evaluated geometry, and transforms that cannot place a field (a zero scale, NaN) refused by name, or taken as a
sheet when given a thickness, through the operator, the CSG tree and the batch script."""

import math
import subprocess
import sys
from pathlib import Path

import bpy
import numpy as np
import pytest

from aasdf.aasdf_addon import cache, nodes, pipeline
from tests.blender.scene import add_mesh_object, select, world_arrays
from tests.metrics import exact_boolean, hausdorff, merge_vertices, mesh_area, mesh_volume, unsigned_distance
from tests.support import box_mesh, is_watertight, uv_sphere

ROOT = Path(__file__).resolve().parents[2]
BLOCK = box_mesh(half=(1.2, 0.6, 0.3))


def local_state(obj):
    """What an input must keep: its world matrix and, for a mesh, its vertices."""
    verts = np.empty(3 * len(obj.data.vertices), dtype=np.float32) if obj.type == "MESH" else np.zeros(0)
    if obj.type == "MESH":
        obj.data.vertices.foreach_get("co", verts)
    return np.array(obj.matrix_world), verts


def text_object(name="Text", extrude=0.15, location=(-1.0, -0.3, 0.2)):
    """An extruded text "AB" crossing the block's top face."""
    curve = bpy.data.curves.new(name, "FONT")
    curve.body, curve.extrude, curve.size = "AB", extrude, 0.8
    obj = bpy.data.objects.new(name, curve)
    bpy.context.scene.collection.objects.link(obj)
    obj.location = location
    bpy.context.view_layer.update()
    return obj


def bevelled_circle(name="Ring"):
    """A Bezier circle of radius 0.5 with a round bevel 0.12 thick, crossing the block's top face."""
    curve = bpy.data.curves.new(name, "CURVE")
    curve.dimensions, curve.bevel_depth, curve.bevel_resolution = "3D", 0.12, 4
    spline = curve.splines.new("BEZIER")
    spline.bezier_points.add(3)
    for point, (x, y) in zip(spline.bezier_points, ((0.5, 0), (0, 0.5), (-0.5, 0), (0, -0.5)), strict=True):
        point.co = (x, y, 0.0)
        point.handle_left_type = point.handle_right_type = "AUTO"
    spline.use_cyclic_u = True
    obj = bpy.data.objects.new(name, curve)
    bpy.context.scene.collection.objects.link(obj)
    obj.location = (0.3, 0.0, 0.3)
    obj.rotation_euler = (0.4, 0.0, 0.0)
    bpy.context.view_layer.update()
    return obj


def surface_sphere(name="Surface"):
    bpy.ops.surface.primitive_nurbs_surface_sphere_add(radius=0.4, location=(0.8, 0.0, 0.3))
    obj = bpy.context.active_object
    obj.name = name
    return obj


def metaball(name="Meta"):
    bpy.ops.object.metaball_add(type="BALL", radius=0.5, location=(-0.8, 0.0, 0.3))
    obj = bpy.context.active_object
    obj.name = name
    obj.data.resolution = 0.05
    bpy.context.view_layer.update()
    return obj


# ---- every geometry object is an operand ----


# The targets at resolution 256 (text, bevelled curve); surface and metaball at 128. Measured: volumes within
# 3e-7 (text), 6e-5, 2.3e-4, 4e-5 of the exact ones; Hausdorff p95 0.0035, 0.0017, 0.0095, 0.0044 voxels.
@pytest.mark.parametrize(
    ("make", "resolution"), [(text_object, 256), (bevelled_circle, 256), (surface_sphere, 128), (metaball, 128)]
)
def test_a_non_mesh_cutter_takes_part_by_its_evaluated_geometry(make, resolution, fresh_cache):
    block = add_mesh_object("Block", *BLOCK)
    cutter = make()
    before = local_state(cutter)
    select(block, cutter, active=block)
    assert bpy.ops.aasdf.boolean(operation="DIFFERENCE", resolution=resolution, hide_inputs=False) == {"FINISHED"}
    verts, tris = world_arrays(bpy.context.active_object)
    exact = exact_boolean("DIFFERENCE", *BLOCK, *world_arrays(cutter))
    assert mesh_volume(*exact) < mesh_volume(*BLOCK) - 0.01  # the cutter does cut
    assert is_watertight(tris)
    assert mesh_volume(verts, tris) == pytest.approx(mesh_volume(*exact), rel=0.01)
    voxel = pipeline.last_run["voxel_size"]
    distance = hausdorff(verts, tris, *exact, n=50_000)["p95"]
    assert distance < 0.03 * voxel
    np.testing.assert_array_equal(local_state(cutter)[0], before[0])


def test_the_tree_takes_a_text_and_a_collection_of_curves(fresh_cache):
    block = add_mesh_object("Block", *BLOCK)
    text, ring = text_object(), bevelled_circle()
    curves = bpy.data.collections.new("Curves")
    bpy.context.scene.collection.children.link(curves)
    bpy.context.scene.collection.objects.unlink(ring)
    curves.objects.link(ring)
    tree = bpy.data.node_groups.new("Engrave", nodes.TREE)
    tree.resolution, tree.levels, tree.padding = 256, 4, 1
    base, blade = tree.nodes.new(nodes.OBJECT), tree.nodes.new(nodes.OBJECT)
    base.object, blade.object = block, text
    rings = tree.nodes.new(nodes.COLLECTION)
    rings.collection = curves
    difference, output = tree.nodes.new(nodes.DIFFERENCE), tree.nodes.new(nodes.OUTPUT)
    tree.links.new(base.outputs[0], difference.inputs["Base"])
    tree.links.new(blade.outputs[0], difference.inputs["Cutters"])
    tree.links.new(rings.outputs[0], difference.inputs["Cutters"])
    tree.links.new(difference.outputs[0], output.inputs[0])
    assert bpy.ops.aasdf.evaluate_tree(tree="Engrave") == {"FINISHED"}
    verts, tris = world_arrays(bpy.data.objects["CSG Result"])
    cutters = exact_boolean("UNION", *world_arrays(text), *world_arrays(ring))
    exact = exact_boolean("DIFFERENCE", *BLOCK, *cutters)
    assert is_watertight(tris)
    assert mesh_volume(verts, tris) == pytest.approx(mesh_volume(*exact), rel=0.01)


def test_a_text_field_is_cached_by_its_evaluated_geometry(fresh_cache):
    block = add_mesh_object("Block", *BLOCK)
    text = text_object()
    select(block, text)
    bpy.ops.aasdf.boolean(operation="DIFFERENCE", resolution=96, hide_inputs=False)
    assert pipeline.last_run["fields_built"] == 2
    text.location.x += 0.1  # moved: its field is placed, not built again
    select(block, text)
    bpy.ops.aasdf.boolean(operation="DIFFERENCE", resolution=96, hide_inputs=False)
    assert pipeline.last_run["fields_built"] == 0
    text.data.body = "AC"  # another geometry: another field
    bpy.context.view_layer.update()
    select(block, text)
    bpy.ops.aasdf.boolean(operation="DIFFERENCE", resolution=96, hide_inputs=False)
    assert pipeline.last_run["fields_built"] == 1


def instancer(name="Scatter"):
    """A cube mesh whose geometry nodes put an ico sphere of radius 0.3 on each of its 8 corners (instances only)."""
    bpy.ops.mesh.primitive_cube_add(size=2.0)
    obj = bpy.context.active_object
    obj.name = name
    tree = bpy.data.node_groups.new("Scatter", "GeometryNodeTree")
    tree.interface.new_socket("Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
    tree.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    group_in, group_out = tree.nodes.new("NodeGroupInput"), tree.nodes.new("NodeGroupOutput")
    points, on_points = tree.nodes.new("GeometryNodeMeshToPoints"), tree.nodes.new("GeometryNodeInstanceOnPoints")
    ico = tree.nodes.new("GeometryNodeMeshIcoSphere")
    ico.inputs["Radius"].default_value, ico.inputs["Subdivisions"].default_value = 0.3, 3
    tree.links.new(group_in.outputs[0], points.inputs[0])
    tree.links.new(points.outputs[0], on_points.inputs["Points"])
    tree.links.new(ico.outputs[0], on_points.inputs["Instance"])
    tree.links.new(on_points.outputs[0], group_out.inputs[0])
    obj.modifiers.new("Scatter", "NODES").node_group = tree
    bpy.context.view_layer.update()
    return obj


def test_instances_made_by_geometry_nodes_are_realized(fresh_cache):
    block = add_mesh_object("Block", *box_mesh(half=(1.4, 1.4, 1.4)))
    scatter = instancer()
    bpy.ops.mesh.primitive_ico_sphere_add(subdivisions=3, radius=0.3)  # one of the instances, as a plain mesh
    ball = mesh_volume(*world_arrays(bpy.context.active_object))
    select(block, scatter, active=block)
    assert bpy.ops.aasdf.boolean(operation="DIFFERENCE", resolution=128, hide_inputs=False) == {"FINISHED"}
    verts, tris = world_arrays(bpy.context.active_object)
    # a ball cut out at each of the 8 corners of the instancer's cube, all inside the block
    assert mesh_volume(verts, tris) == pytest.approx(2.8**3 - 8 * ball, rel=0.01)
    assert len(scatter.data.vertices) == 8 and len(scatter.modifiers) == 1


def test_a_mesh_with_instances_keeps_its_own_uv_maps_colours_and_custom_normals(fresh_cache):
    # the instances lack the mesh's second UV map, colour and custom normals: those were dropped from the whole
    # operand (its own faces too), and the custom normals ran past the corners (an IndexError where a face was kept)
    scatter = instancer()
    mesh = scatter.data
    mesh.uv_layers.new(name="Second")
    mesh.color_attributes.new("Paint", "FLOAT_COLOR", "CORNER")
    mesh.polygons.foreach_set("use_smooth", [True] * len(mesh.polygons))
    mesh.normals_split_custom_set([tuple(p.normal) for p in mesh.polygons for _ in range(p.loop_total)])
    scatter.modifiers["Scatter"].node_group.nodes.new("GeometryNodeJoinGeometry")
    tree = scatter.modifiers["Scatter"].node_group
    join, group_in, group_out = (tree.nodes[name] for name in ("Join Geometry", "Group Input", "Group Output"))
    tree.links.new(tree.nodes["Instance on Points"].outputs[0], join.inputs[0])
    tree.links.new(group_in.outputs[0], join.inputs[0])  # the cube itself too
    tree.links.new(join.outputs[0], group_out.inputs[0])
    bpy.context.view_layer.update()
    ball = add_mesh_object("Ball", *uv_sphere(0.6, rings=16, segments=32), location=(0.0, 0.0, 1.2))
    select(scatter, ball, active=scatter)
    assert bpy.ops.aasdf.boolean(operation="UNION", resolution=64, hide_inputs=False) == {"FINISHED"}
    result = bpy.context.active_object.data
    assert {layer.name for layer in result.uv_layers} >= {"UVMap", "Second"} and "Paint" in result.color_attributes
    normals = np.empty(len(result.loops) * 3, dtype=np.float32)
    result.corner_normals.foreach_get("vector", normals)
    assert np.abs(np.linalg.norm(normals.reshape(-1, 3), axis=1) - 1.0).max() < 1e-3  # (36 zero-length before)


def test_surfaces_that_enclose_nothing_and_objects_without_geometry_are_refused_by_name(fresh_cache):
    block = add_mesh_object("Block", *BLOCK)
    flat = text_object("Label", extrude=0.0, location=(-1.0, -0.3, 0.0))
    ring = bevelled_circle("Wire")
    ring.data.bevel_depth = 0.0
    camera = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    bpy.context.scene.collection.objects.link(camera)
    # why there are no faces, where it can be told: each was "has no faces: give it an extrusion or a bevel"
    blank = text_object("Blank", extrude=0.2)
    blank.data.body = "  "
    bare = bpy.data.objects.new("Bare", bpy.data.curves.new("Bare", "CURVE"))
    bare.data.bevel_depth = 0.1
    balls = [bpy.data.objects.new(name, bpy.data.metaballs.new(name)) for name in ("Blob", "Blob.001")]
    for k, ball in enumerate(balls):
        ball.data.elements.new().co = (1.0 + 0.8 * k, 0.0, 0.0)
    for obj in (bare, *balls):
        bpy.context.scene.collection.objects.link(obj)
    # an empty mesh and one of points alone: each was "The mesh is empty: it has no vertices or no triangles"
    hollow, dots = add_mesh_object("Hollow", [], []), add_mesh_object("Dots", [(0.0, 0.0, 0.0), (1.0, 0.0, 0.0)], [])
    bpy.context.view_layer.update()
    objects = len(bpy.data.objects)
    cases = {
        flat: "'Label' encloses no volume: give it a thickness or close it",
        ring: "'Wire' has no faces: give it an extrusion or a bevel",
        camera: "'Camera' is a camera and has no geometry: use a mesh, text, curve, surface or metaball object",
        blank: "'Blank' has no characters: type some text into it",
        bare: "'Bare' has no splines: draw one into it",
        balls[1]: "'Blob.001' is part of the metaball 'Blob', whose object makes their surface: use 'Blob'",
        hollow: r"'Hollow' has no faces \(after its modifiers\): add some to it, or leave it out of the selection",
        dots: r"'Dots' has no faces \(after its modifiers\)",
    }
    for cutter, message in cases.items():
        select(block, cutter, active=block)
        with pytest.raises(RuntimeError, match=message):
            bpy.ops.aasdf.boolean(operation="DIFFERENCE", resolution=64)
    assert len(bpy.data.objects) == objects and not block.hide_get()
    # a thickness gives the flat text a wall, as a plane gets one: a cut 0.1 deep into the top face (z = 0.3)
    flat.location.z = 0.3
    bpy.context.view_layer.update()
    select(block, flat)
    assert bpy.ops.aasdf.boolean(operation="DIFFERENCE", resolution=192, thickness=0.2) == {"FINISHED"}
    verts, tris = world_arrays(bpy.context.active_object)
    label = merge_vertices(*world_arrays(flat))
    # the wall's lower half under the letters, and a quarter disc of radius 0.1 along their outlines where the
    # outlines' discs do not overlap (across a thin stroke, in a corner: measured 9 % less than all of them)
    slab, rims = 0.1 * mesh_area(*label), boundary_length(*label) * math.pi * 0.1**2 / 4
    assert is_watertight(tris)
    assert slab + 0.7 * rims < mesh_volume(*BLOCK) - mesh_volume(verts, tris) < slab + rims


def boundary_length(verts, tris):
    """Total length of the edges that only one triangle uses."""
    edges = np.sort(np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]]), axis=1)
    unique, counts = np.unique(edges, axis=0, return_counts=True)
    once = unique[counts == 1]
    return float(np.linalg.norm(verts[once[:, 0]] - verts[once[:, 1]], axis=1).sum())


# ---- transforms ----


def flat_cutter(name="Cutter", scale=(1.0, 1.0, 0.0)):
    """A box 3 x 3 x 1 through the block's middle, flattened by its scale."""
    obj = add_mesh_object(name, *box_mesh(half=(1.5, 1.5, 0.5)))
    obj.scale = scale
    bpy.context.view_layer.update()
    return obj


def nan_cutter():
    obj = add_mesh_object("Cutter", *uv_sphere(0.5, rings=8, segments=16))
    obj.location = (float("nan"), 0.0, 0.0)
    bpy.context.view_layer.update()
    return obj


def nan_vertex():  # (with the resolution's voxel size: it read "The inputs have no extent: set a Voxel Size")
    verts, tris = uv_sphere(0.5, rings=8, segments=16)
    verts[3] = (np.nan, 0.0, 0.0)
    return add_mesh_object("Cutter", verts, tris)


def parent_flattened():
    parent = bpy.data.objects.new("Parent", None)
    bpy.context.scene.collection.objects.link(parent)
    parent.scale = (1.0, 1.0, 0.0)
    obj = add_mesh_object("Cutter", *uv_sphere(0.5, rings=8, segments=16))
    obj.parent, obj.rotation_euler = parent, (0.5, 0.3, 0.0)
    bpy.context.view_layer.update()
    return obj


TRANSFORMS = [
    (flat_cutter, "'Cutter' is flat: its scale is 0 along Z; give it a thickness or a non-zero scale"),
    (
        lambda: flat_cutter(scale=(0.0, 1.0, 0.0)),
        "'Cutter' has no volume and no area: its scale is 0 along X and Z; give it a non-zero scale",
    ),
    (nan_cutter, r"'Cutter' has a transform that is not a number \(NaN or infinite"),
    (nan_vertex, r"Cutter: The mesh has 1 vertices with NaN or infinite coordinates"),
    (parent_flattened, r"'Cutter' is flat: its transform \(with its parents'\) squashes it; give it a thickness"),
]


@pytest.mark.parametrize(("make", "message"), TRANSFORMS)
def test_a_transform_that_cannot_place_a_field_is_refused_by_name(make, message, fresh_cache):
    block = add_mesh_object("Block", *box_mesh(half=(1.0, 1.0, 1.0)))
    cutter = make()
    before = [local_state(obj) for obj in (block, cutter)]
    objects = len(bpy.data.objects)
    select(block, cutter)
    with pytest.raises(RuntimeError, match=message):
        bpy.ops.aasdf.boolean(operation="DIFFERENCE", resolution=64)
    assert len(bpy.data.objects) == objects and not block.hide_get() and not cutter.hide_get()
    assert cache.stats()["builds"] == 0  # before any work
    for obj, (matrix, verts) in zip((block, cutter), before, strict=True):
        np.testing.assert_array_equal(local_state(obj)[0], matrix)
        np.testing.assert_array_equal(local_state(obj)[1], verts)


def test_a_flat_cutter_with_a_thickness_cuts_a_slot(fresh_cache):
    block = add_mesh_object("Block", *box_mesh(half=(1.0, 1.0, 1.0)))
    cutter = flat_cutter()
    select(block, cutter)
    assert bpy.ops.aasdf.boolean(operation="DIFFERENCE", resolution=96, thickness=0.2) == {"FINISHED"}
    verts, tris = world_arrays(bpy.context.active_object)
    assert is_watertight(tris)
    assert mesh_volume(verts, tris) == pytest.approx(8.0 - 2.0 * 2.0 * 0.2, rel=0.01)  # a slot 0.2 wide through it
    assert np.array(cutter.scale).tolist() == [1.0, 1.0, 0.0]


def test_the_tree_refuses_a_flat_input_or_result_and_takes_a_thickness(fresh_cache):
    block = add_mesh_object("Block", *box_mesh(half=(1.0, 1.0, 1.0)))
    cutter = flat_cutter()
    tree = bpy.data.node_groups.new("Slot", nodes.TREE)
    tree.resolution = 96
    base, blade = tree.nodes.new(nodes.OBJECT), tree.nodes.new(nodes.OBJECT)
    base.object, blade.object = block, cutter
    difference, output = tree.nodes.new(nodes.DIFFERENCE), tree.nodes.new(nodes.OUTPUT)
    tree.links.new(base.outputs[0], difference.inputs["Base"])
    tree.links.new(blade.outputs[0], difference.inputs["Cutters"])
    tree.links.new(difference.outputs[0], output.inputs[0])
    with pytest.raises(RuntimeError, match="'Cutter' is flat: its scale is 0 along Z; give it a thickness"):
        bpy.ops.aasdf.evaluate_tree(tree="Slot")
    assert "CSG Result" not in bpy.data.objects and cache.stats()["builds"] == 0
    blade.thickness = 0.2
    assert bpy.ops.aasdf.evaluate_tree(tree="Slot") == {"FINISHED"}
    result = bpy.data.objects["CSG Result"]
    assert mesh_volume(*world_arrays(result)) == pytest.approx(7.2, rel=0.01)
    vertices = len(result.data.vertices)
    result.scale = (1.0, 0.0, 1.0)  # a result object that cannot take the mesh back to its own space
    bpy.context.view_layer.update()
    with pytest.raises(RuntimeError, match="'CSG Result' is flat: its scale is 0 along Y: it receives the result"):
        bpy.ops.aasdf.evaluate_tree(tree="Slot")
    assert len(result.data.vertices) == vertices


# ---- batch ----


def run_batch(*args):
    return subprocess.run(
        [sys.executable, str(ROOT / "aasdf_batch.py"), *map(str, args)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=240,
        check=False,
    )


def read_ply(path):
    """Vertices and triangles of a PLY written by the batch script, imported into an empty scene."""
    bpy.ops.wm.read_homefile(use_empty=True)
    bpy.ops.wm.ply_import(filepath=str(path))
    return merge_vertices(*world_arrays(bpy.context.selected_objects[0]))


# the batch script's options over the add-on's operands: its Blender calls run on every Blender in
# tests/blender/test_batch.py (a .blend's objects, a .ply written) and test_batch_jobs.py (an operand refused),
# texts and flat objects through the operator in the tests above
@pytest.mark.newest_blender
def test_the_batch_script_takes_a_text_and_refuses_a_flat_object_until_it_has_a_thickness(tmp_path):
    block = add_mesh_object("Block", *box_mesh(half=(1.0, 1.0, 1.0)))
    flat_cutter("Flat")
    text = text_object(location=(-0.8, -0.3, 0.9))
    camera = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    bpy.context.scene.collection.objects.link(camera)
    exact = exact_boolean("DIFFERENCE", *world_arrays(block), *world_arrays(text))
    scene = tmp_path / "scene.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(scene), copy=True)
    out = tmp_path / "out.ply"

    done = run_batch("--blend", scene, "--operation", "difference", "--objects", "Block", "Flat", "--output", out)
    assert done.returncode == 1 and "'Flat' is flat: its scale is 0 along Z; give it a thickness" in done.stderr
    assert "Traceback" not in done.stderr and not out.exists()
    done = run_batch("--blend", scene, "--operation", "difference", "--objects", "Block", "Camera", "--output", out)
    assert done.returncode == 2 and "'Camera' is a camera and has no geometry" in done.stderr and not out.exists()

    # with a thickness: the flat object a slot 0.2 wide through the block (z = 0), the text engraved in its top; the
    # text encloses a volume, so the thickness leaves it as it is
    done = run_batch(
        "--blend", scene, "--operation", "difference", "--objects", "Block", "Flat", "Text", "--thickness", 0.2,
        "--resolution", 192, "--output", out,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr[-2000:]
    verts, tris = read_ply(out)
    assert is_watertight(tris)
    assert mesh_volume(verts, tris) == pytest.approx(mesh_volume(*exact) - 2.0 * 2.0 * 0.2, rel=0.01)


# ---- duplicates at any scale ----


def ring_of_duplicates(scales):
    """A cube and linked duplicates of one sphere mesh in a ring through its top face, at the given scales."""
    cube = add_mesh_object("Cube", *box_mesh(half=(1.0, 1.0, 1.0)))
    first = add_mesh_object("Ball", *uv_sphere(0.2, rings=16, segments=32))
    balls = [first] + [first.copy() for _ in scales[1:]]
    for k, (ball, scale) in enumerate(zip(balls, scales, strict=True)):
        if k:
            bpy.context.scene.collection.objects.link(ball)
        turn = 2.0 * math.pi * k / len(scales)
        ball.location, ball.scale = (0.6 * math.cos(turn), 0.6 * math.sin(turn), 1.0), (scale,) * 3
    bpy.context.view_layer.update()
    return cube, balls


def exact_ring(cube, balls):
    cutters = world_arrays(balls[0])
    for ball in balls[1:]:
        cutters = exact_boolean("UNION", *cutters, *world_arrays(ball))
    return exact_boolean("DIFFERENCE", *world_arrays(cube), *cutters)


# the cache's keys for duplicates at other scales: the Blender calls (linked duplicates, their scale and matrices)
# run on every Blender in tests/blender/test_boolean.py::test_duplicates_of_one_geometry_share_one_field
@pytest.mark.newest_blender
def test_duplicates_at_one_scale_share_a_field_wherever_a_field_of_the_mesh_was_built(fresh_cache):
    cube, balls = ring_of_duplicates([1.5] * 10)
    balls[0].scale = (1.0, 1.0, 1.0)  # first used at scale 1: its field is cached at that scale
    bpy.context.view_layer.update()
    select(cube, balls[0])
    bpy.ops.aasdf.boolean(operation="DIFFERENCE", voxel_size=0.02, hide_inputs=False)
    assert pipeline.last_run["fields_built"] == 2
    balls[0].scale = (1.5, 1.5, 1.5)
    bpy.context.view_layer.update()
    select(cube, *balls, active=cube)
    bpy.ops.aasdf.boolean(operation="DIFFERENCE", voxel_size=0.02, hide_inputs=False)
    # the ten balls' one field at scale 1.5, the cube's cached (10 when each was keyed by its world matrix)
    assert pipeline.last_run["fields_built"] == 1
    verts, tris = world_arrays(bpy.context.active_object)
    assert is_watertight(tris)
    # measured within 4.2e-5 of the exact volume (at voxel 0.02)
    assert mesh_volume(verts, tris) == pytest.approx(mesh_volume(*exact_ring(cube, balls)), rel=1.2e-4)
    # and from scratch: the cube's field and the balls' one
    cache.clear()
    select(cube, *balls, active=cube)
    bpy.ops.aasdf.boolean(operation="DIFFERENCE", voxel_size=0.02, hide_inputs=False)
    assert pipeline.last_run["fields_built"] == 2


@pytest.mark.newest_blender  # as the test above
def test_duplicates_at_ten_scales_build_a_field_per_ladder_step(fresh_cache):
    scales = [1.05 + 0.05 * k for k in range(10)]  # 1.05 to 1.5: ladder steps 0 to 2 (2^(1/4) apart)
    cube, balls = ring_of_duplicates(scales)
    select(cube, *balls, active=cube)
    bpy.ops.aasdf.boolean(operation="DIFFERENCE", voxel_size=0.02, hide_inputs=False)
    # the cube's, one per step and the first ball's own (measured 4; 11 when each scale beyond 9 % had its own)
    assert pipeline.last_run["fields_built"] <= 1 + 4
    verts, tris = world_arrays(bpy.context.active_object)
    # measured within 1.6e-5 of the exact volume (at voxel 0.02)
    assert mesh_volume(verts, tris) == pytest.approx(mesh_volume(*exact_ring(cube, balls)), rel=5e-5)


def test_a_cutter_scaled_off_the_voxel_ladder_leaves_the_result_at_the_voxel_size_asked(fresh_cache):
    """A cube minus a block, then the block scaled by 0.95 (its cached field placed there: within half a ladder step),
    remeshed: the result's lattice is the voxel size asked, the cube's nodes its own. The block's finer spacing was
    the result's: the cube was resampled at it, with 2.2 times the nodes and 10 % more faces (a move of the block:
    0.43-0.53 s against 0.26-0.29 now)."""
    cube = add_mesh_object("Cube", *box_mesh(half=(1.0, 1.0, 1.0)))
    block = add_mesh_object("Block", *box_mesh(half=(0.4, 0.3, 0.5)), location=(0.1, 0.05, 0.9))
    voxel = 0.0135
    select(cube, block)
    bpy.ops.aasdf.boolean(operation="DIFFERENCE", voxel_size=voxel, hide_inputs=False, keep_faces=False)
    nodes, faces = pipeline.last_run["nodes"], len(bpy.context.active_object.data.polygons)
    block.scale = (0.95,) * 3
    bpy.context.view_layer.update()
    select(cube, block)
    bpy.ops.aasdf.boolean(operation="DIFFERENCE", voxel_size=voxel, hide_inputs=False, keep_faces=False)
    assert pipeline.last_run["fields_built"] == 0  # the block's field placed at its new scale
    ratios = pipeline.last_run["nodes"] / nodes, len(bpy.context.active_object.data.polygons) / faces
    assert ratios[0] < 1.2 and ratios[1] < 1.05, ratios  # measured 1.061 and 0.995 (2.24 and 1.105 before)
    verts, tris = world_arrays(bpy.context.active_object)
    exact = exact_boolean("DIFFERENCE", *world_arrays(cube), *world_arrays(block))
    corner = np.abs(verts - block.location) - 0.5 * np.asarray(block.dimensions)
    away = np.linalg.norm(np.maximum(corner, 0.0), axis=1) > 3 * voxel  # farther than 3 voxels from the block
    off = unsigned_distance(*exact, verts[away])
    assert away.sum() > 100_000 and off.max() < 0.1 * voxel, off.max() / voxel  # measured 0.057 (the cube's corners)


def test_the_poll_and_a_tree_from_the_selection_take_a_text(fresh_cache):
    block = add_mesh_object("Block", *BLOCK)
    text = text_object()
    select(text, block)  # the text active: the base
    assert bpy.ops.aasdf.boolean.poll() and bpy.ops.aasdf.offset.poll() and bpy.ops.aasdf.debug_volume.poll()
    camera = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    bpy.context.scene.collection.objects.link(camera)
    select(camera, block)
    assert not bpy.ops.aasdf.boolean.poll()  # an active object without geometry
    select(block, text, camera)  # the camera is left out of a tree: a node cannot hold it
    assert bpy.ops.aasdf.tree_from_selection(operation="DIFFERENCE") == {"FINISHED"}
    tree = next(tree for tree in bpy.data.node_groups if tree.bl_idname == nodes.TREE)
    assert sorted(node.object.name for node in tree.nodes if node.bl_idname == nodes.OBJECT) == ["Block", "Text"]
    assert "Block.csg" in bpy.data.objects


def _cube(name, size, location=(0.0, 0.0, 0.0), collection=None):
    obj = add_mesh_object(name, *box_mesh(half=(size / 2,) * 3), location=location, collection=collection)
    bpy.context.view_layer.update()
    return obj


def test_instancing_on_vertices_and_a_collection_instance_take_part_by_their_instances(fresh_cache):
    # the instances were dropped (a mesh instancing rivets on its vertices cut as its own mesh alone; points alone were
    # "The mesh is empty"), and an empty instancing a collection was refused as "an empty and has no geometry"
    block = _cube("Block", 2.0)
    rivets = add_mesh_object("Rivets", [(0.5, 0.5, 1.0), (-0.5, 0.5, 1.0), (0.5, -0.5, 1.0), (-0.5, -0.5, 1.0)], [])
    rivets.instance_type = "VERTS"
    _cube("Rivet", 0.4).parent = rivets
    bpy.context.view_layer.update()
    select(block, rivets)
    assert bpy.ops.aasdf.boolean(operation="DIFFERENCE", resolution=128, hide_inputs=False) == {"FINISHED"}
    assert mesh_volume(*world_arrays(bpy.context.active_object)) == pytest.approx(8.0 - 4 * 0.4 * 0.4 * 0.2, abs=2e-3)
    asset = bpy.data.collections.new("Bolt")
    _cube("Bolt", 0.5, collection=asset)
    asset.objects.link(bpy.data.objects.new("Lamp", bpy.data.lights.new("Lamp", "POINT")))  # (no geometry: left out)
    instance = bpy.data.objects.new("BoltInstance", None)
    instance.instance_type, instance.instance_collection = "COLLECTION", asset
    bpy.context.scene.collection.objects.link(instance)
    instance.location = (1.0, 1.0, 1.0)
    bpy.context.view_layer.update()
    select(block, instance)
    assert bpy.ops.aasdf.boolean(operation="DIFFERENCE", resolution=128, hide_inputs=False) == {"FINISHED"}
    assert mesh_volume(*world_arrays(bpy.context.active_object)) == pytest.approx(8.0 - 0.25**3, abs=2e-3)
    empty = bpy.data.collections.new("Lights")
    empty.objects.link(bpy.data.objects.new("Lamp2", bpy.data.lights.new("Lamp2", "POINT")))
    instance.instance_collection = empty
    bpy.context.view_layer.update()
    select(block, instance)
    with pytest.raises(RuntimeError, match="'BoltInstance' instances no geometry"):
        bpy.ops.aasdf.boolean(operation="DIFFERENCE", resolution=128, hide_inputs=False)
    # a collection disabled in viewports is instanced as nothing: said so (it was "its collection has no mesh ...")
    instance.instance_collection, asset.hide_viewport = asset, True
    bpy.context.view_layer.update()
    select(block, instance)
    with pytest.raises(RuntimeError, match="'BoltInstance' instances the collection 'Bolt', which is disabled in vi"):
        bpy.ops.aasdf.boolean(operation="DIFFERENCE", resolution=128, hide_inputs=False)
