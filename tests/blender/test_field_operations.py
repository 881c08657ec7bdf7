"""Field operations and surface options in Blender: offset, shell, thickness, blend mode, sharp edges, and surfaces
that enclose nothing, through the operators, the CSG tree and the batch script."""

import subprocess
import sys
from pathlib import Path

import bpy
import numpy as np
import pytest

from aasdf.aasdf_addon import cache, nodes, pipeline
from tests.blender.scene import add_mesh_object, select, world_arrays
from tests.metrics import merge_vertices, mesh_volume, to_manifold
from tests.support import box_mesh, is_watertight, uv_sphere

ROOT = Path(__file__).resolve().parents[2]
SPHERE = uv_sphere(1.0, rings=32, segments=64)


def plane(name="Plane", size=3.0, z=0.0):
    """A square of two triangles: a surface that encloses nothing."""
    h = size / 2
    verts = np.array([[-h, -h, z], [h, -h, z], [h, h, z], [-h, h, z]], dtype=np.float32)
    return add_mesh_object(name, verts, np.array([[0, 1, 2], [0, 2, 3]], dtype=np.int32))


# ---- offset and shell ----


def test_offset_grows_and_shrinks_the_active_mesh_from_its_cached_field(fresh_cache):
    ball = add_mesh_object("Ball", *SPHERE)
    select(ball)
    assert bpy.ops.aasdf.offset(distance=0.25, resolution=96) == {"FINISHED"}
    grown = bpy.data.objects["Ball.offset"]
    assert pipeline.last_run["fields_built"] == 1
    verts, tris = world_arrays(grown)
    assert is_watertight(tris)
    # the sphere mesh's own volume grown by 0.25: about a sphere of radius 1.25
    assert mesh_volume(verts, tris) == pytest.approx(4 / 3 * np.pi * 1.25**3, rel=0.02)
    select(ball)
    assert bpy.ops.aasdf.offset(distance=-0.5, resolution=96) == {"FINISHED"}
    assert pipeline.last_run["fields_built"] == 0  # the cached field, offset again
    verts, tris = world_arrays(bpy.context.active_object)
    assert mesh_volume(verts, tris) == pytest.approx(4 / 3 * np.pi * 0.5**3, rel=0.03)
    assert not ball.hide_get()  # offset keeps its input in view by default


def test_shell_hollows_the_active_mesh(fresh_cache):
    ball = add_mesh_object("Ball", *SPHERE)
    select(ball)
    assert bpy.ops.aasdf.shell(wall=0.2, side="INSIDE", resolution=96) == {"FINISHED"}
    verts, tris = world_arrays(bpy.data.objects["Ball.shell"])
    assert is_watertight(tris)
    outer = mesh_volume(*world_arrays(ball))
    assert mesh_volume(verts, tris) == pytest.approx(outer - 4 / 3 * np.pi * 0.8**3, rel=0.02)


def test_offsets_and_shells_that_cannot_work_are_refused_or_warned(fresh_cache):
    ball = add_mesh_object("Ball", *SPHERE)
    select(ball)
    objects = len(bpy.data.objects)
    assert bpy.ops.aasdf.offset(distance=-1.5, resolution=64) == {"CANCELLED"}  # shrunk away: a warning
    assert len(bpy.data.objects) == objects
    with pytest.raises(RuntimeError, match="finite number"):
        bpy.ops.aasdf.offset(distance=float("nan"))
    # a wall under two voxels: refused before any field is built, named as the setting is
    built = fresh_cache.stats()["builds"]
    with pytest.raises(RuntimeError, match=r"A Wall of 0\.001 is thinner than two voxels .* use a Wall of at least"):
        bpy.ops.aasdf.shell(wall=0.001, resolution=64)
    assert len(bpy.data.objects) == objects
    assert fresh_cache.stats()["builds"] == built


# ---- thickness and surfaces that enclose nothing ----


def test_a_plane_cutter_is_refused_until_it_has_a_thickness(fresh_cache):
    block = add_mesh_object("Block", *box_mesh(half=(1.0, 1.0, 1.0)))
    cutter = plane()
    select(block, cutter)
    objects = len(bpy.data.objects)
    with pytest.raises(RuntimeError, match="'Plane' encloses no volume: give it a thickness or close it"):
        bpy.ops.aasdf.boolean(operation="DIFFERENCE", resolution=96)
    assert len(bpy.data.objects) == objects and not block.hide_get()  # nothing added, nothing hidden
    select(block, cutter)
    assert bpy.ops.aasdf.boolean(operation="DIFFERENCE", resolution=96, thickness=0.2) == {"FINISHED"}
    verts, tris = world_arrays(bpy.context.active_object)
    assert is_watertight(tris)
    assert mesh_volume(verts, tris) == pytest.approx(8.0 - 4.0 * 0.2, rel=0.02)  # a slot 0.2 wide through it


def test_a_plane_arrayed_over_itself_is_refused_as_a_plane_and_shelled_with_a_thickness(fresh_cache):
    # two copies of a plane overlapping on one plane (an Array modifier): the part covered twice read as a lens-shaped
    # solid whose surface touched the sheet, and its shell came out open; a flat mesh encloses no volume
    sheet = plane()
    modifier = sheet.modifiers.new("Array", "ARRAY")
    modifier.count, modifier.relative_offset_displace = 2, (0.47, 0.0, 0.0)
    bpy.context.view_layer.update()
    select(sheet)
    objects = len(bpy.data.objects)
    with pytest.raises(RuntimeError, match="'Plane' encloses no volume: give it a thickness or close it"):
        bpy.ops.aasdf.shell(wall=0.15, resolution=64)
    assert len(bpy.data.objects) == objects
    select(sheet)
    assert bpy.ops.aasdf.shell(wall=0.15, resolution=64, thickness=0.6) == {"FINISHED"}
    verts, tris = world_arrays(bpy.context.active_object)
    assert is_watertight(tris)
    to_manifold(verts, tris, "shell of an arrayed plane given a thickness")


def test_an_operand_smaller_than_two_voxels_is_refused_as_such(fresh_cache):
    # closed, but no voxel lies inside it: it read "encloses no volume: give it a thickness or close it"
    block = add_mesh_object("Block", *box_mesh(half=(1.0, 1.0, 1.0)))
    speck = add_mesh_object("Speck", *box_mesh(half=(1e-3, 1e-3, 1e-3)))
    speck.location = (0.5, 0.0, 0.0)
    bpy.context.view_layer.update()
    select(block, speck)
    objects = len(bpy.data.objects)
    with pytest.raises(RuntimeError, match=r"'Speck' is smaller than two voxels \(0.002 across, voxels of 0.05"):
        bpy.ops.aasdf.boolean(operation="UNION", resolution=64)
    assert len(bpy.data.objects) == objects and not block.hide_get()


def test_a_closed_operand_with_walls_thinner_than_two_voxels_is_refused_as_such(fresh_cache):
    # a closed sheet (2 x 2 x 0.01) and a hollow box (walls 0.01) read "encloses no volume: give it a thickness or
    # close it" though both are closed
    block = add_mesh_object("Block", *box_mesh(half=(1.0, 1.0, 1.0)))
    panel = add_mesh_object("Panel", *box_mesh(half=(1.0, 1.0, 0.005)))
    outer, inner = box_mesh(half=(0.5, 0.5, 0.5)), box_mesh(half=(0.49, 0.49, 0.49))
    hollow = add_mesh_object(
        "Hollow", np.concatenate([outer[0], inner[0]]), np.concatenate([outer[1], inner[1][:, ::-1] + len(outer[0])])
    )
    objects = len(bpy.data.objects)
    select(block, panel)
    with pytest.raises(RuntimeError, match=r"'Panel' is thinner than two voxels \(0.01 thick, voxels of 0.0"):
        bpy.ops.aasdf.boolean(operation="DIFFERENCE", resolution=96)
    select(block, hollow)
    with pytest.raises(RuntimeError, match="'Hollow' is closed, but no voxel lies inside it: its walls are thinner"):
        bpy.ops.aasdf.boolean(operation="DIFFERENCE", resolution=96)
    assert len(bpy.data.objects) == objects and not block.hide_get()


def test_the_tree_refuses_a_plane_and_takes_a_thickness_per_input(fresh_cache):
    block = add_mesh_object("Block", *box_mesh(half=(1.0, 1.0, 1.0)))
    cutter = plane()
    tree = bpy.data.node_groups.new("Slot", nodes.TREE)
    tree.resolution = 96
    base, blade = tree.nodes.new(nodes.OBJECT), tree.nodes.new(nodes.OBJECT)
    base.object, blade.object = block, cutter
    difference, output = tree.nodes.new(nodes.DIFFERENCE), tree.nodes.new(nodes.OUTPUT)
    tree.links.new(base.outputs[0], difference.inputs["Base"])
    tree.links.new(blade.outputs[0], difference.inputs["Cutters"])
    tree.links.new(difference.outputs[0], output.inputs[0])
    with pytest.raises(RuntimeError, match="'Plane' encloses no volume"):
        bpy.ops.aasdf.evaluate_tree(tree="Slot")
    assert "CSG Result" not in bpy.data.objects
    blade.thickness = 0.2
    assert bpy.ops.aasdf.evaluate_tree(tree="Slot") == {"FINISHED"}
    assert mesh_volume(*world_arrays(bpy.data.objects["CSG Result"])) == pytest.approx(7.2, rel=0.02)


# ---- blend mode, sharp edges ----


def test_sharp_edges_are_marked_and_can_be_turned_off(fresh_cache):
    a = add_mesh_object("A", *box_mesh(half=(1.0, 1.0, 1.0)))
    b = add_mesh_object("B", *box_mesh(half=(0.5, 0.5, 2.0), center=(1.0, 0.0, 0.0)))
    select(a, b)
    bpy.ops.aasdf.boolean(operation="DIFFERENCE", resolution=96, hide_inputs=False, keep_faces=False)
    mesh = bpy.context.active_object.data
    sharp = np.empty(len(mesh.edges), dtype=bool)
    mesh.attributes["sharp_edge"].data.foreach_get("value", sharp)
    assert sharp.sum() > 100  # the box's and the slot's creases
    # exactly the edges the extraction reconstructed as creases, whichever way round it lists their vertices
    creases = cache.last_result()["surface"]["creases"]
    edges = np.empty(2 * len(mesh.edges), dtype=np.int32)
    mesh.attributes[".edge_verts"].data.foreach_get("value", edges)
    marked = {tuple(sorted(pair)) for pair in edges.reshape(-1, 2)[sharp].tolist()}
    assert marked == {tuple(sorted(pair)) for pair in creases.tolist()}
    select(a, b)
    bpy.ops.aasdf.boolean(operation="DIFFERENCE", resolution=96, sharp_edges=False, hide_inputs=False, keep_faces=False)
    assert "sharp_edge" not in bpy.context.active_object.data.attributes


def test_a_chamfer_blend_bevels_the_seam(fresh_cache):
    a = add_mesh_object("A", *box_mesh(half=(1.0, 1.0, 1.0)))
    b = add_mesh_object("B", *box_mesh(half=(1.0, 1.0, 1.0), center=(0.0, 0.0, 2.0)))  # on top of it
    b.scale = (0.5, 0.5, 1.0)
    bpy.context.view_layer.update()
    volumes = {}
    for mode in ("ROUND", "CHAMFER"):
        select(a, b)
        bpy.ops.aasdf.boolean(operation="UNION", resolution=96, blend=0.2, blend_mode=mode, hide_inputs=False)
        volumes[mode] = mesh_volume(*world_arrays(bpy.context.active_object))
    # both add material along the concave seam (4 long): the bevel a right triangle of legs 0.2 in section (measured
    # 10.089), the polynomial fillet less (it lies within blend / 4 of the hard seam; measured 10.030)
    hard = 8.0 + 2.0
    assert hard < volumes["ROUND"] < volumes["CHAMFER"]
    assert volumes["CHAMFER"] == pytest.approx(hard + 4.0 * 0.2**2 / 2.0, abs=0.03)


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


def write_obj(path, verts, tris):
    lines = [f"v {x} {y} {z}" for x, y, z in verts] + [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in tris]
    path.write_text("\n".join(lines) + "\n", encoding="ascii")


def read_ply(path):
    """A .ply written by the batch script, imported into an empty scene: world vertices (merged) and triangles."""
    bpy.ops.wm.read_homefile(use_empty=True)
    bpy.ops.wm.ply_import(filepath=str(path))
    return merge_vertices(*world_arrays(bpy.context.selected_objects[0]))


def rounded_box(r, size=2.0):
    """Volume of a cube of side ``size`` grown by ``r``: faces, quarter cylinders along the edges, eighth balls."""
    return size**3 + 6 * size**2 * r + 3 * np.pi * size * r**2 + 4 / 3 * np.pi * r**3


# the batch script's options over the add-on's pipeline: its Blender calls (.obj read, .ply written, exit status 1)
# run on every Blender in tests/blender/test_batch.py, thickness, offset and shell through the operators above
@pytest.mark.newest_blender
def test_batch_refuses_a_plane_and_offsets_or_shells_one_operand(tmp_path):
    block, sheet = tmp_path / "block.obj", tmp_path / "sheet.obj"
    write_obj(block, *box_mesh(half=(1.0, 1.0, 1.0)))
    write_obj(sheet, np.array([[-2, -2, 0], [2, -2, 0], [2, 2, 0], [-2, 2, 0]]), [[0, 1, 2], [0, 2, 3]])
    out = tmp_path / "out.ply"
    done = run_batch("--operation", "difference", "--inputs", block, sheet, "--resolution", 64, "--output", out)
    assert done.returncode == 1 and "encloses no volume: give it a thickness or close it" in done.stderr
    assert not out.exists()
    done = run_batch(
        "--operation", "difference", "--inputs", block, sheet, "--thickness", 0.2, "--blend-mode", "chamfer",
        "--resolution", 64, "--output", out,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr[-2000:]
    verts, tris = read_ply(out)
    assert is_watertight(tris)
    assert mesh_volume(verts, tris) == pytest.approx(8.0 - 4.0 * 0.2, rel=1.5e-4)  # measured -4.5e-5
    # a shell at least two voxels thick (voxel: the grown block's diagonal / 64)
    done = run_batch("--inputs", block, "--offset", 0.2, "--shell", 0.15, "--resolution", 64, "--output", out)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "offset +0.2 then shell 0.15" in done.stdout
    # the cube grown by 0.2 (rounded), less the cube grown by 0.05: Minkowski sums of the 2-cube and a ball
    verts, tris = read_ply(out)
    assert is_watertight(tris)
    assert mesh_volume(verts, tris) == pytest.approx(rounded_box(0.2) - rounded_box(0.05), rel=0.0025)  # +0.08 %
