"""Render the README's pictures headless with the ``bpy`` module (Cycles on the CPU) into ``docs/images/``.

Each picture is made from a fresh empty scene: the add-on registered from this repository (as the batch script
does), the inputs built, ``bpy.ops.aasdf.boolean`` run as a user would, and a fixed camera framing the result.
Small sizes, few samples and Cycles' denoiser keep each PNG under 200 KB; the seed, the sample count and every
placement are fixed, so an unchanged result renders an unchanged picture.

    .venv/bin/python tools/render_pictures.py [--only demo open-bunny blend octree sharp adaptivity] [--samples 24]
"""

from __future__ import annotations

import argparse
import importlib.util
import math
import sys
import time
from pathlib import Path

import bpy
import numpy as np
from mathutils import Vector

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench import baselines  # noqa: E402
from tests.support import cad_pairs, load_mesh, uv_sphere  # noqa: E402

OUT = ROOT / "docs" / "images"
SIZE = (640, 400)
PICTURES = ("demo", "open-bunny", "blend", "octree", "textured", "sharp", "kept-faces", "adaptivity")
# The direction the sharp picture's camera looks from, at the origin.
SHARP_VIEW = (0.0, -1.0, 0.6)


# ---- scene ----


def register_addon():
    """The add-on from this repository, registered as the package ``aasdf`` (as ``aasdf_batch.py`` does)."""
    if hasattr(bpy.types, "AASDF_OT_boolean"):
        return
    spec = importlib.util.spec_from_file_location("aasdf", ROOT / "__init__.py", submodule_search_locations=[str(ROOT)])
    package = importlib.util.module_from_spec(spec)
    sys.modules["aasdf"] = package
    spec.loader.exec_module(package)
    if "aasdf" not in bpy.context.preferences.addons:
        bpy.context.preferences.addons.new().module = "aasdf"
    package.register()


def fresh_scene(samples: int):
    bpy.ops.wm.read_homefile(use_empty=True)
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = samples
    scene.cycles.seed = 0
    scene.cycles.use_denoising = True
    scene.render.resolution_x, scene.render.resolution_y = SIZE
    scene.render.resolution_percentage = 100
    scene.render.film_transparent = False
    scene.render.image_settings.file_format = "PNG"
    scene.render.image_settings.color_mode = "RGB"
    scene.render.image_settings.compression = 100
    world = bpy.data.worlds.new("World")
    world.node_tree.nodes["Background"].inputs["Color"].default_value = (0.32, 0.33, 0.35, 1.0)
    world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.6
    scene.world = world
    for name, rotation, energy in (("Key", (0.7, 0.2, 0.8), 3.5), ("Fill", (1.1, -0.4, -2.2), 1.2)):
        light = bpy.data.lights.new(name, "SUN")
        light.energy = energy
        light.angle = 0.15
        sun = bpy.data.objects.new(name, light)
        sun.rotation_euler = rotation
        scene.collection.objects.link(sun)
    return scene


def material(name: str, color, roughness: float = 0.45, attribute: str | None = None):
    mat = bpy.data.materials.new(name)
    bsdf = mat.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (*color, 1.0)
    bsdf.inputs["Roughness"].default_value = roughness
    if attribute is not None:  # colour from a face-corner attribute
        node = mat.node_tree.nodes.new("ShaderNodeAttribute")
        node.attribute_name = attribute
        mat.node_tree.links.new(node.outputs["Color"], bsdf.inputs["Base Color"])
    return mat


def assign(obj, mat):
    obj.data.materials.clear()
    obj.data.materials.append(mat)
    if "material_index" in obj.data.attributes:
        obj.data.attributes.remove(obj.data.attributes["material_index"])


def frame(objects, direction=(1.0, -1.3, 0.8), distance=2.9, ortho=False):
    """A camera looking along ``-direction`` at the objects' bounding box, ``distance`` half-diagonals away."""
    scene = bpy.context.scene
    corners = np.concatenate([[o.matrix_world @ Vector(c) for c in o.bound_box] for o in objects])
    lo, hi = corners.min(axis=0), corners.max(axis=0)
    centre, radius = Vector((lo + hi) / 2.0), float(np.linalg.norm(hi - lo)) / 2.0
    cam = bpy.data.cameras.new("Camera")
    cam.lens = 50.0
    if ortho:  # the box seen along z, filling the frame
        cam.type = "ORTHO"
        aspect = scene.render.resolution_x / scene.render.resolution_y
        cam.ortho_scale = 1.04 * max(hi[0] - lo[0], (hi[1] - lo[1]) * aspect)
    camera = bpy.data.objects.new("Camera", cam)
    camera.location = centre + Vector(direction).normalized() * distance * radius
    camera.rotation_euler = (centre - camera.location).to_track_quat("-Z", "Y").to_euler()
    scene.collection.objects.link(camera)
    scene.camera = camera


def label(text: str, location, size: float):
    curve = bpy.data.curves.new(text, "FONT")
    curve.body, curve.size, curve.align_x = text, size, "CENTER"
    obj = bpy.data.objects.new(text, curve)
    obj.location = location
    obj.rotation_euler = (math.radians(90.0), 0.0, 0.0)
    bpy.context.scene.collection.objects.link(obj)
    obj.data.materials.append(material(f"{text} ink", (1.0, 1.0, 1.0), 0.8))
    return obj


def render(name: str):
    path = OUT / f"{name}.png"
    bpy.context.scene.render.filepath = str(path)
    began = time.perf_counter()
    bpy.ops.render.render(write_still=True)
    print(
        f"render_pictures: {path.relative_to(ROOT)} ({path.stat().st_size / 1024:.0f} KB, "
        f"{time.perf_counter() - began:.1f} s)"
    )


def boolean(operation: str, objects, **settings):
    for obj in bpy.context.view_layer.objects:
        obj.select_set(obj in objects)
    bpy.context.view_layer.objects.active = objects[0]
    assert bpy.ops.aasdf.boolean(operation=operation, **settings) == {"FINISHED"}
    return bpy.context.active_object


def z_up(verts):
    """An OBJ's y-up coordinates turned z-up (a rotation about x: triangles keep their orientation)."""
    return np.ascontiguousarray(verts[:, [0, 2, 1]] * np.float32([1.0, -1.0, 1.0]))


def hide_inputs_from_render(*objects):
    for obj in objects:
        obj.hide_render = True


def mesh(name, verts, tris):
    obj = baselines.mesh_object(name, verts, tris)
    obj.data.shade_smooth()
    bpy.context.view_layer.update()  # the view layer lists the new object
    return obj


# ---- pictures ----


def picture_demo(samples):
    """``make demo``: the cow minus a sphere."""
    fresh_scene(samples)
    cow_v, cow_t = load_mesh("cow.obj")
    sphere_v, sphere_t = load_mesh("sphere.obj")
    cow, sphere = mesh("cow", z_up(cow_v), cow_t), mesh("sphere", z_up(sphere_v), sphere_t)
    result = boolean("DIFFERENCE", [cow, sphere], resolution=256)
    hide_inputs_from_render(cow, sphere)
    result.data.shade_smooth()
    assign(result, material("clay", (0.75, 0.52, 0.36)))
    frame([result], direction=(0.8, -1.2, 1.0), distance=2.4)
    render("demo")


def picture_open_bunny(samples):
    """The open Stanford bunny united with a ball, by AASDF (left) and by Blender's SDF nodes (right): the holes in
    the bunny's base make it a thin shell for the SDF nodes, which their boolean drops."""
    fresh_scene(samples)
    verts, tris = load_mesh("stanford-bunny.obj")
    verts = z_up((verts - verts.mean(axis=0)) * 10.0)  # about 1.5 units across
    lo, hi = verts.min(axis=0), verts.max(axis=0)
    ball_v, ball_t = uv_sphere(0.38, center=(hi[0] + 0.05, lo[1] + 0.2, lo[2] + 0.38), rings=48, segments=96)
    bunny, ball = mesh("bunny", verts, tris), mesh("ball", ball_v, ball_t)
    voxel = float(np.linalg.norm(np.maximum(hi, ball_v.max(0)) - np.minimum(lo, ball_v.min(0)))) / 256
    ours = boolean("UNION", [bunny, ball], voxel_size=voxel)
    ours.data.shade_smooth()
    hide_inputs_from_render(bunny, ball)
    theirs = baselines.gn_sdf_boolean((verts, tris), (ball_v, ball_t), "UNION", voxel)
    shift = np.float32([2.3, 0.0, 0.0])
    gn = mesh("Blender SDF nodes", theirs["verts"] + shift, theirs["tris"])
    clay = material("clay", (0.72, 0.70, 0.66))
    assign(ours, clay)
    assign(gn, clay)
    z = float(lo[2]) - 0.3
    middle = 0.5 * float(lo[0] + ball_v[:, 0].max())
    texts = [label("AASDF", (middle, 0.0, z), 0.2), label("Blender SDF nodes", (middle + shift[0], 0.0, z), 0.2)]
    frame([ours, gn, *texts], direction=(0.1, -1.0, 0.25), distance=2.9)
    render("open-bunny")


def picture_sharp(samples):
    """A CAD boolean, the fandisk minus a cylinder (``tests.support.cad_pairs``, each operand's diagonal 1) at voxel
    1/128, three ways: AASDF's sharp surface (left: Sharp Edges on, the default; its reconstructed creases marked
    sharp, smooth elsewhere), AASDF's marching cubes (middle: Sharp Edges off) and Blender's geometry-nodes SDF
    pipeline (right) at the same voxel size. The last two are shaded smooth by angle (30 degrees), as a user would
    shade them. Half the resolution of ``bench/sharp.py``, so that the rounding of the creases shows at this size."""
    fresh_scene(samples)
    scene = bpy.context.scene
    scene.render.resolution_x, scene.render.resolution_y = 960, 340
    _op, (part_v, part_t), (bore_v, bore_t) = cad_pairs()["fandisk - cylinder"]
    part, bore = mesh("fandisk", part_v, part_t), mesh("cylinder", bore_v, bore_t)
    voxel = 1.0 / 128
    sharp = boolean("DIFFERENCE", [part, bore], voxel_size=voxel, hide_inputs=False)
    marching = boolean("DIFFERENCE", [part, bore], voxel_size=voxel, sharp_edges=False, hide_inputs=False)
    theirs = baselines.gn_sdf_boolean((part_v, part_t), (bore_v, bore_t), "DIFFERENCE", voxel)
    gn = mesh("Blender SDF nodes", theirs["verts"], theirs["tris"])
    hide_inputs_from_render(part, bore)
    step = 0.78
    clay = material("clay", (0.70, 0.71, 0.74), 0.4)
    for k, obj in enumerate((sharp, marching, gn)):
        obj.location.x += (k - 1) * step
        assign(obj, clay)
        if obj is not sharp:
            obj.data.shade_smooth()
            obj.data.set_sharp_from_angle(angle=math.radians(30.0))
    bpy.context.view_layer.update()
    z = float(part_v[:, 2].min()) - 0.08
    y = float(part_v[:, 1].min())
    for k, text in enumerate(("AASDF (sharp)", "marching cubes", "Blender SDF nodes")):
        label(text, ((k - 1) * step, y, z), 0.05)
    # a long lens from far away, so that the three parts are seen alike
    cam = bpy.data.cameras.new("Camera")
    cam.lens = 90.0
    camera = bpy.data.objects.new("Camera", cam)
    direction = Vector(SHARP_VIEW).normalized()
    camera.location = direction * 6.3
    camera.rotation_euler = (-direction).to_track_quat("-Z", "Y").to_euler()
    scene.collection.objects.link(camera)
    scene.camera = camera
    render("sharp")


def checker(name: str, colors, scale: float):
    """A material whose colour is a checker pattern over the mesh's UV map."""
    mat = bpy.data.materials.new(name)
    tree = mat.node_tree
    bsdf = tree.nodes["Principled BSDF"]
    bsdf.inputs["Roughness"].default_value = 0.5
    pattern = tree.nodes.new("ShaderNodeTexChecker")
    pattern.inputs["Scale"].default_value = scale
    pattern.inputs["Color1"].default_value = (*colors[0], 1.0)
    pattern.inputs["Color2"].default_value = (*colors[1], 1.0)
    coords = tree.nodes.new("ShaderNodeUVMap")
    coords.uv_map = "UVMap"
    tree.links.new(coords.outputs["UV"], pattern.inputs["Vector"])
    tree.links.new(pattern.outputs["Color"], bsdf.inputs["Base Color"])
    return mat


def picture_textured(samples):
    """Spot, textured through its UV map, minus a textured ball: before (left) and after (right). The result's faces
    keep their source faces' materials and UVs, so both textures continue across the cut."""
    fresh_scene(samples)
    bpy.ops.wm.obj_import(filepath=str(ROOT / "samples" / "spot.obj"))  # with its UV map
    spot = bpy.context.selected_objects[0]
    spot.data.shade_smooth()
    spot.data.materials.append(checker("cow hide", [(0.85, 0.82, 0.75), (0.15, 0.12, 0.10)], 12.0))
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.45, location=(0.25, -0.25, 0.55), segments=48, ring_count=24)
    ball = bpy.context.active_object
    ball.data.shade_smooth()
    ball.data.materials.append(checker("ball", [(0.85, 0.35, 0.10), (0.95, 0.85, 0.30)], 8.0))
    bpy.context.view_layer.update()
    result = boolean("DIFFERENCE", [spot, ball], resolution=256)
    result.location.x += 1.4  # after, on the right; the inputs stay where they were, before
    bpy.context.view_layer.update()
    frame([spot, ball, result], direction=(0.35, -1.0, 0.4), distance=2.9)
    render("textured")


def baselines_box(center, half):
    from tests.support import box_mesh

    return box_mesh(half=half, center=center, subdivisions=2)


def picture_blend(samples):
    """A blended union: spot and a sphere, blend radius 0.15."""
    fresh_scene(samples)
    verts, tris = load_mesh("spot.obj")
    spot = mesh("spot", z_up(verts), tris)
    sphere = mesh("ball", *uv_sphere(0.3, center=(0.0, 0.25, 0.72), rings=48, segments=96))
    result = boolean("UNION", [spot, sphere], resolution=256, blend=0.15)
    hide_inputs_from_render(spot, sphere)
    result.data.shade_smooth()
    assign(result, material("glaze", (0.30, 0.50, 0.72), 0.3))
    frame([result], direction=(1.6, -0.5, 0.5), distance=3.1)
    render("blend")


def picture_octree(samples):
    """The debug cells of spot's field at /128, cut by the plane through its middle: finest cells along the surface,
    coarser ones away from it; inside cells warm, outside cells cool, lighter for coarser levels."""
    fresh_scene(samples)
    verts, tris = load_mesh("spot.obj")
    verts = z_up(verts)
    spot = mesh("spot", verts, tris)
    for obj in bpy.context.view_layer.objects:
        obj.select_set(obj == spot)
    bpy.context.view_layer.objects.active = spot
    assert bpy.ops.aasdf.debug_volume(resolution=128) == {"FINISHED"}
    cells = bpy.data.objects["spot.cells"]
    n = len(cells.data.vertices)
    centres = np.empty(3 * n, np.float32)
    cells.data.vertices.foreach_get("co", centres)
    centres = centres.reshape(-1, 3)
    sizes, levels, sdf, leaf = (np.empty(n, dt) for dt in (np.float32, np.int32, np.float32, bool))
    for name, values in (("size", sizes), ("level", levels), ("sdf", sdf), ("leaf", leaf)):
        cells.data.attributes[name].data.foreach_get("value", values)
    # the leaves crossing the plane z = z0 tile the slice
    z0 = float(np.median(verts[:, 2]))
    keep = np.flatnonzero((np.abs(centres[:, 2] - z0) < 0.5 * sizes) & leaf)
    corners = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], np.float32) * 0.46
    quad_v = np.empty((len(keep), 4, 3), np.float32)
    quad_v[:, :, :2] = centres[keep, None, :2] + corners[None] * sizes[keep, None, None]
    quad_v[:, :, 2] = z0
    inside = sdf[keep] < 0.0
    shade = 1.0 - 0.75 * levels[keep] / max(1, levels.max())
    colour = np.where(inside[:, None], [0.85, 0.42, 0.18], [0.16, 0.42, 0.80]) * (0.45 + 0.55 * (1 - shade))[:, None]
    slab = bpy.data.meshes.new("slice")
    slab.from_pydata(quad_v.reshape(-1, 3), [], np.arange(4 * len(keep)).reshape(-1, 4))
    attr = slab.color_attributes.new("level", "FLOAT_COLOR", "CORNER")
    rgba = np.concatenate([np.repeat(colour, 4, axis=0), np.ones((4 * len(keep), 1))], axis=1).astype(np.float32)
    attr.data.foreach_set("color", rgba.ravel())
    obj = bpy.data.objects.new("slice", slab)
    bpy.context.scene.collection.objects.link(obj)
    obj.data.materials.append(material("cells", (1, 1, 1), 0.9, attribute="level"))
    for other in (spot, cells, bpy.data.objects["spot.sdf"]):
        other.hide_render = True
    frame([obj], direction=(0.0, -0.0001, 1.0), ortho=True)
    bpy.context.scene.cycles.samples = min(samples, 8)  # flat colours: few samples, and a smaller PNG
    render("octree")


def wireframe(obj, thickness: float):
    """A dark wire over ``obj``'s edges (a copy of it with a Wireframe modifier), as the viewport's wireframe shows
    them."""
    wire = obj.copy()
    wire.data = obj.data.copy()
    bpy.context.scene.collection.objects.link(wire)
    modifier = wire.modifiers.new("Wire", "WIREFRAME")
    modifier.thickness, modifier.use_even_offset, modifier.use_replace = thickness, False, True
    assign(wire, material("wire", (0.02, 0.02, 0.03), 0.9))
    return wire


def picture_kept_faces(samples):
    """A low-poly part (a plate of quads with a UV checker) minus a bore, three ways, left to right: Blender's Boolean
    modifier (Exact solver), AASDF keeping the plate's own faces (new faces only along the seam), AASDF remeshed."""
    fresh_scene(samples)
    bpy.context.scene.render.resolution_x, bpy.context.scene.render.resolution_y = 960, 360
    bpy.ops.mesh.primitive_cube_add(size=2.0)
    plate = bpy.context.active_object
    plate.scale = (1.0, 1.0, 0.25)
    bpy.ops.object.transform_apply(scale=True)
    bpy.ops.object.mode_set(mode="EDIT")
    bpy.ops.mesh.subdivide(number_cuts=2)
    bpy.ops.object.mode_set(mode="OBJECT")
    plate.data.materials.append(checker("checker", [(0.9, 0.88, 0.82), (0.2, 0.45, 0.75)], 16.0))
    bpy.ops.mesh.primitive_cylinder_add(vertices=24, radius=0.45, depth=1.5, location=(0.2, 0.1, 0.0))
    bore = bpy.context.active_object
    bpy.context.view_layer.update()
    results = []
    exact = plate.copy()
    exact.data = plate.data.copy()
    bpy.context.scene.collection.objects.link(exact)
    modifier = exact.modifiers.new("Boolean", "BOOLEAN")
    modifier.operation, modifier.solver, modifier.object = "DIFFERENCE", "EXACT", bore
    bpy.context.view_layer.update()
    evaluated = exact.evaluated_get(bpy.context.evaluated_depsgraph_get())
    exact.data = bpy.data.meshes.new_from_object(evaluated)  # applied: the cutter stays where it cut
    exact.modifiers.remove(modifier)
    results.append(exact)
    for keep in (True, False):
        results.append(boolean("DIFFERENCE", [plate, bore], resolution=256, keep_faces=keep, hide_inputs=False))
    hide_inputs_from_render(plate, bore)
    for k, obj in enumerate(results):
        obj.location.x += 2.6 * (k - 1)
        bpy.context.view_layer.update()
        wireframe(obj, 0.006).location = obj.location
    bpy.context.view_layer.update()
    frame(results, direction=(0.0, -1.0, 1.4), distance=2.75)
    render("kept-faces")


def picture_adaptivity(samples):
    """A plate minus a bore, remeshed at 1/96 of its diagonal, three ways, left to right, in wireframe: AASDF at
    adaptivity 0 (a quad per voxel), AASDF at adaptivity 1, the geometry nodes' Grid to Mesh at its Adaptivity 1."""
    fresh_scene(samples)
    bpy.context.scene.render.resolution_x, bpy.context.scene.render.resolution_y = 960, 360
    bpy.ops.mesh.primitive_cube_add(size=2.0)
    plate = bpy.context.active_object
    plate.scale = (1.0, 1.0, 0.25)
    bpy.ops.object.transform_apply(scale=True)
    bpy.ops.mesh.primitive_cylinder_add(vertices=64, radius=0.45, depth=1.5, location=(0.2, 0.1, 0.0))
    bore = bpy.context.active_object
    bpy.context.view_layer.update()
    voxel = float(np.linalg.norm([2.0, 2.0, 1.5])) / 96
    results = [
        boolean("DIFFERENCE", [plate, bore], voxel_size=voxel, keep_faces=False, adaptivity=a, hide_inputs=False)
        for a in (0.0, 1.0)
    ]
    baselines.gn_sdf_boolean(plate, bore, "DIFFERENCE", voxel, keep=True, adaptivity=1.0)
    host = bpy.data.objects["gn_sdf_boolean"]
    evaluated = host.evaluated_get(bpy.context.evaluated_depsgraph_get())
    grid = bpy.data.objects.new("Grid to Mesh", bpy.data.meshes.new_from_object(evaluated))
    bpy.context.scene.collection.objects.link(grid)
    bpy.data.objects.remove(host, do_unlink=True)
    results.append(grid)
    hide_inputs_from_render(plate, bore)
    for k, obj in enumerate(results):
        assign(obj, material("part", (0.8, 0.78, 0.72)))
        obj.location.x += 2.6 * (k - 1)
        bpy.context.view_layer.update()
        wireframe(obj, 0.004).location = obj.location
    bpy.context.view_layer.update()
    frame(results, direction=(0.0, -1.0, 1.4), distance=2.75)
    render("adaptivity")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", nargs="+", choices=PICTURES, default=list(PICTURES))
    parser.add_argument("--samples", type=int, default=24)
    args = parser.parse_args(argv)
    OUT.mkdir(parents=True, exist_ok=True)
    register_addon()
    for name in args.only:
        globals()[f"picture_{name.replace('-', '_')}"](args.samples)


if __name__ == "__main__":
    main()
