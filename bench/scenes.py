"""The add-on on random scenes: what a user may select, through ``aasdf.boolean``, ``aasdf.offset`` and ``aasdf.shell``.

Each scene holds 2-3 objects made the way a user makes them (Blender's primitives: cubes, UV and ico spheres,
cylinders with n-gon, fan or no caps, cones, tori, Suzanne, planes and grids; two cubes joined into one mesh; a text,
extruded or not; a Bézier circle, bevelled, extruded or neither; an empty mesh), placed, turned and scaled at random
(mirrored one time in eight), some with a subdivision, array, mirror or solidify modifier, a colour attribute, two
materials or mixed shading. One operator runs on them with random options (keep faces, adaptivity, blend,
thickness, resolution 48-128, inputs hidden or not), or a CSG tree is made of them (``aasdf.tree_from_selection``,
with keep faces and adaptivity set on its Output node), evaluated, its last input moved and the tree evaluated again,
as a drag's step. Printed per scene: the operator's outcome and, for a result,
its faces, whether every edge is in two faces opposite ways, and whether manifold3d takes it as a 2-manifold; a
refusal's message (Blender raises it as a RuntimeError); and any input whose mesh, transform or modifiers changed.
Then the sums: a scene that leaves a result open or not 2-manifold, or changes an input, is a bug.

    .venv/bin/python bench/scenes.py [--seed 1] [--count 40]
"""

from __future__ import annotations

import argparse
import hashlib
import os
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
os.environ.setdefault("WARP_CACHE_PATH", str(ROOT / ".warp-cache"))

import bpy  # noqa: E402
import numpy as np  # noqa: E402

from bench.addon import register  # noqa: E402
from tests.metrics import to_manifold  # noqa: E402

KINDS = ("cube", "sphere", "ico", "cylinder", "cone", "torus", "monkey", "plane", "grid", "text", "curve", "cubes")
KINDS += ("empty",)
WEIGHTS = (0.16, 0.12, 0.08, 0.1, 0.06, 0.1, 0.1, 0.04, 0.04, 0.06, 0.05, 0.06, 0.03)


def digest(obj) -> str:
    """What a run must leave as it was: the object's transform, data, modifiers and attribute names."""
    h = hashlib.sha1(np.array(obj.matrix_world, dtype=np.float64).tobytes())
    h.update(str((obj.type, obj.data.name if obj.data else None, [m.name for m in obj.modifiers])).encode())
    if obj.type == "MESH":
        co = np.empty(3 * len(obj.data.vertices), np.float32)
        obj.data.vertices.foreach_get("co", co)
        loops = np.empty(len(obj.data.loops), np.int32)
        obj.data.loops.foreach_get("vertex_index", loops)
        h.update(co.tobytes() + loops.tobytes() + str([a.name for a in obj.data.attributes]).encode())
    elif obj.type == "FONT":
        h.update(obj.data.body.encode())
    return h.hexdigest()


def primitive(kind: str, rng, location) -> bpy.types.Object:
    """A new object of ``kind``, made as a user makes it, active."""
    ops, size = bpy.ops, rng.uniform(0.5, 2.0)
    if kind == "cube":
        ops.mesh.primitive_cube_add(size=size, location=location)
    elif kind == "sphere":
        segments, rings = int(rng.integers(8, 40)), int(rng.integers(5, 20))
        ops.mesh.primitive_uv_sphere_add(radius=size / 2, location=location, segments=segments, ring_count=rings)
    elif kind == "ico":
        ops.mesh.primitive_ico_sphere_add(radius=size / 2, location=location, subdivisions=int(rng.integers(1, 4)))
    elif kind == "cylinder":
        fill = str(rng.choice(["NGON", "TRIFAN", "NOTHING"]))
        ops.mesh.primitive_cylinder_add(
            radius=rng.uniform(0.1, 0.8), depth=size, location=location, vertices=int(rng.integers(6, 48)),
            end_fill_type=fill,
        )  # fmt: skip
    elif kind == "cone":
        ops.mesh.primitive_cone_add(radius1=size / 2, depth=size, location=location, vertices=int(rng.integers(3, 32)))
    elif kind == "torus":
        ops.mesh.primitive_torus_add(location=location, major_radius=size / 2, minor_radius=rng.uniform(0.05, 0.35))
    elif kind == "monkey":
        ops.mesh.primitive_monkey_add(size=size, location=location)
    elif kind == "plane":
        ops.mesh.primitive_plane_add(size=size, location=location)
    elif kind == "grid":
        ops.mesh.primitive_grid_add(size=size, location=location, x_subdivisions=5, y_subdivisions=5)
    elif kind == "text":
        ops.object.text_add(location=location)
        bpy.context.active_object.data.body = str(rng.choice(["A", "Hi", "0x", "&"]))
        bpy.context.active_object.data.extrude = float(rng.choice([0.0, rng.uniform(0.02, 0.2)]))
    elif kind == "curve":
        ops.curve.primitive_bezier_circle_add(radius=size / 2, location=location)
        data = bpy.context.active_object.data
        data.bevel_depth, data.extrude = (float(rng.choice([0.0, rng.uniform(0.02, 0.2)])) for _ in range(2))
    elif kind == "cubes":  # two overlapping cubes in one mesh: it passes through itself
        ops.mesh.primitive_cube_add(size=1.0, location=location)
        first = bpy.context.active_object
        ops.mesh.primitive_cube_add(size=1.0, location=tuple(np.add(location, rng.uniform(-0.5, 0.5, 3))))
        first.select_set(True)
        bpy.context.view_layer.objects.active = first
        ops.object.join()
    else:  # a mesh without vertices
        obj = bpy.data.objects.new("empty", bpy.data.meshes.new("empty"))
        bpy.context.collection.objects.link(obj)
        bpy.context.view_layer.objects.active = obj
    return bpy.context.active_object


def random_object(index: int, rng) -> bpy.types.Object:
    """A primitive placed, turned and scaled at random, with modifiers and attributes on some meshes."""
    kind = str(rng.choice(KINDS, p=WEIGHTS))
    obj = primitive(kind, rng, tuple(rng.uniform(-0.6, 0.6, 3)))
    obj.name = f"{kind}{index}"
    obj.rotation_euler = tuple(rng.uniform(-3.2, 3.2, 3)) if rng.integers(2) else (0.0, 0.0, 0.0)
    scale = rng.uniform(0.5, 1.5, 3) if rng.integers(3) == 0 else np.full(3, rng.uniform(0.7, 1.3))
    if rng.integers(8) == 0:
        scale[rng.integers(3)] *= -1.0
    obj.scale = tuple(scale)
    if obj.type != "MESH" or not len(obj.data.polygons):
        return obj
    modifier = int(rng.integers(7))
    if modifier == 0:
        obj.modifiers.new("subdivision", "SUBSURF").levels = 1
    elif modifier == 1:
        obj.modifiers.new("array", "ARRAY").relative_offset_displace = (rng.uniform(0.3, 1.2), 0.0, 0.0)
    elif modifier == 2:
        obj.modifiers.new("mirror", "MIRROR")
    elif modifier == 3:
        obj.modifiers.new("solidify", "SOLIDIFY").thickness = rng.uniform(0.02, 0.2)
    mesh = obj.data
    if rng.integers(2):
        colour = mesh.color_attributes.new("Col", "FLOAT_COLOR", "POINT")
        colour.data.foreach_set("color", rng.uniform(0.0, 1.0, 4 * len(colour.data)).astype(np.float32))
    if rng.integers(2):
        mesh.polygons.foreach_set("use_smooth", rng.integers(0, 2, len(mesh.polygons)).astype(bool))
    if rng.integers(3) == 0:
        for k in range(2):
            mesh.materials.append(bpy.data.materials.new(f"material{index}{k}"))
        mesh.polygons.foreach_set("material_index", rng.integers(0, 2, len(mesh.polygons)).astype(np.int32))
    return obj


def result_check(obj) -> tuple[bool, bool]:
    """Whether every edge of ``obj``'s polygons is in two faces opposite ways, and whether manifold3d takes it."""
    from aasdf.engine.quads import triangulate

    mesh = obj.data
    loops = np.empty(len(mesh.loops), np.int32)
    mesh.loops.foreach_get("vertex_index", loops)
    sizes = np.empty(len(mesh.polygons), np.int32)
    mesh.polygons.foreach_get("loop_total", sizes)
    starts = np.repeat(np.cumsum(sizes) - sizes, sizes)
    within = np.arange(len(loops)) - starts
    following = loops[starts + (within + 1) % np.repeat(sizes, sizes)]
    n = np.int64(len(mesh.vertices))
    directed = np.unique(loops * n + following, return_counts=True)[1]
    undirected = np.unique(np.minimum(loops, following) * n + np.maximum(loops, following), return_counts=True)[1]
    closed = bool((undirected == 2).all() and (directed == 1).all())
    co = np.empty(3 * len(mesh.vertices), np.float32)
    mesh.vertices.foreach_get("co", co)
    try:
        to_manifold(co.reshape(-1, 3), triangulate(loops, sizes))
        manifold = True
    except Exception:  # noqa: BLE001 (manifold3d's refusal, whatever its type)
        manifold = False
    return closed, manifold


def run_scene(rng) -> dict:
    """One scene, one operator; the outcome as a dict."""
    from aasdf.aasdf_addon import pipeline

    bpy.ops.wm.read_homefile(use_empty=True)
    objects = [random_object(i, rng) for i in range(int(rng.integers(2, 4)))]
    bpy.context.view_layer.update()
    before = {obj.name: digest(obj) for obj in bpy.data.objects}
    which = str(rng.choice(["boolean", "boolean", "boolean", "offset", "shell", "tree"]))
    options = {
        "resolution": int(rng.choice([48, 64, 96, 128])),
        "adaptivity": float(rng.choice([0.0, 0.0, 0.3, 0.7])),
        "hide_inputs": bool(rng.integers(2)),
    }
    if rng.integers(4) == 0:
        options["thickness"] = float(rng.uniform(0.01, 0.1))
    with bpy.context.temp_override(selected_objects=objects, active_object=objects[0], object=objects[0]):
        try:
            if which == "boolean":
                options["operation"] = str(rng.choice(["UNION", "INTERSECT", "DIFFERENCE"]))
                options["blend"], options["keep_faces"] = (
                    float(rng.choice([0.0, 0.0, 0.05, 0.2])),
                    bool(rng.integers(4)),
                )
                status = bpy.ops.aasdf.boolean(**options)
            elif which == "tree":
                return _tree_scene(objects, options, before, rng)
            elif which == "offset":
                status = bpy.ops.aasdf.offset(distance=float(rng.uniform(-0.1, 0.2)), **options)
            else:
                status = bpy.ops.aasdf.shell(wall=float(rng.uniform(0.03, 0.1)), **options)
            outcome = {"status": "".join(status)}
        except RuntimeError as err:  # an operator's error report
            outcome = {"status": "REFUSED", "message": str(err).strip()}
    if outcome["status"] == "FINISHED":
        outcome["faces"] = len(bpy.data.objects[pipeline.last_run["object"]].data.polygons)
        outcome["closed"], outcome["manifold"] = result_check(bpy.data.objects[pipeline.last_run["object"]])
    outcome["changed"] = [name for name in before if name in bpy.data.objects and digest(bpy.data.objects[name])
                          != before[name]]  # fmt: skip
    outcome["scene"] = f"{which} of {', '.join(obj.name for obj in objects)} {options}"
    return outcome


def _tree_scene(objects, options, before: dict, rng) -> dict:
    """A CSG tree of ``objects`` (its Output node set as ``options`` say), evaluated; its last input moved by a tenth
    of its size and the tree evaluated again. The outcome of the second evaluation, the first's where it failed."""
    settings = bpy.context.scene.aasdf
    settings.resolution, settings.hide_inputs = options["resolution"], options["hide_inputs"]
    settings.thickness = options.get("thickness", 0.0)
    operation = str(rng.choice(["UNION", "INTERSECT", "DIFFERENCE"]))
    scene = f"tree {operation.lower()} of {', '.join(obj.name for obj in objects)} {options}"
    status = bpy.ops.aasdf.tree_from_selection(operation=operation, evaluate=False, auto_update=False)
    tree = settings.tree
    output = next(node for node in tree.nodes if hasattr(node, "keep_faces"))
    output.keep_faces, output.adaptivity = bool(rng.integers(4)), options["adaptivity"]
    outcome = {"status": "".join(status), "scene": f"{scene} keep faces {output.keep_faces}", "changed": []}
    for step in range(2):
        if step:  # a drag's step: the last input moved, its own change expected
            objects[-1].location = tuple(np.add(objects[-1].location, 0.1 * np.asarray(objects[-1].dimensions)))
            bpy.context.view_layer.update()
            before[objects[-1].name] = digest(objects[-1])
        try:
            outcome["status"] = "".join(bpy.ops.aasdf.evaluate_tree(tree=tree.name))
        except RuntimeError as err:
            return {**outcome, "status": "REFUSED", "message": str(err).strip()}
        result = bpy.data.objects.get(f"{objects[0].name}.csg")
        if outcome["status"] != "FINISHED" or result is None:
            return outcome
        outcome["faces"] = len(result.data.polygons)
        outcome["closed"], outcome["manifold"] = result_check(result)
        if not (outcome["closed"] and outcome["manifold"]):
            return outcome
    outcome["changed"] = [name for name in before if digest(bpy.data.objects[name]) != before[name]]
    return outcome


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--count", type=int, default=40)
    args = parser.parse_args(argv)
    register()
    rng = np.random.default_rng(args.seed)
    results, bugs = 0, 0
    for k in range(args.count):
        t0 = time.perf_counter()
        out = run_scene(rng)
        bad = out["changed"] or (out["status"] == "FINISHED" and not (out["closed"] and out["manifold"]))
        results, bugs = results + (out["status"] == "FINISHED"), bugs + bool(bad)
        detail = {key: out[key] for key in ("faces", "closed", "manifold", "message", "changed") if out.get(key)}
        print(f"{k} {out['scene']} | {out['status']} {detail} {time.perf_counter() - t0:.1f}s{' BUG' if bad else ''}")
    print(f"{args.count} scenes, {results} results, {bugs} bugs (an open or non-manifold result, a changed input)")
    return 1 if bugs else 0


if __name__ == "__main__":
    sys.exit(main())
