"""The add-on as a user meets it: `aasdf.boolean` cold, warm and re-run, against the geometry-nodes SDF pipeline.

For each case and finest spacing (combined bounding-box diagonal / 256 and / 512, given to both as an explicit voxel
size so that moving an operand does not change it), in one ``bpy`` process with the add-on registered:

- **cold**: field cache and boolean memo cleared, both fields built, boolean, surface, result object written;
- **moved**: the second operand moved a little (a new position every run: its cached field is placed there, nothing
  is built); **turned**: the same, turned 17 degrees about two axes;
- **re-run**: nothing changed (the redo panel, a script calling the operator again): cached fields and boolean;
- **GN SDF**: Mesh to SDF Grid ×2 → SDF Grid Boolean → Grid to Mesh on fresh objects (geometry nodes keeps no
  per-operand grid, so moving an operand re-evaluates all of it).

Each round runs all four, GN first in odd rounds and last in even ones (``bench/paired.py``: the machine's speed drifts
within minutes); times are medians of ``--repeat`` rounds (default 5) after a warm-up, wall clock around the operator
call (it includes reading the evaluated meshes and writing the result object). Ratios are the median of the rounds'
ratios to that round's GN SDF time, with the smallest and largest in brackets.

Then the stages of the cold and moved cases (the fields, and the output after the boolean, each against the round's
GN SDF time), and a drag: ``--drag-moves`` (10) successive moves of the cutter through a CSG tree, the tree evaluated
after each, against as many geometry-nodes evaluations.

    .venv/bin/python bench/addon.py [--cases bunny-spot spheres spheres-100k] [--resolutions 256 512] [--repeat 5]
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
os.environ.setdefault("WARP_CACHE_PATH", str(ROOT / ".warp-cache"))

import bpy  # noqa: E402
import numpy as np  # noqa: E402

from bench import baselines  # noqa: E402
from bench.paired import round_ratios  # noqa: E402
from bench.pipeline import cases as pipeline_cases  # noqa: E402
from tests.conftest import load_addon_package  # noqa: E402

OPERATION = "DIFFERENCE"

# The stages after the boolean: the result's surface, the attributes its faces carry over, writing it into Blender.
OUTPUT_STAGES = ("surface", "attributes", "write")


def cases() -> dict:
    """Two of the pipeline benchmark's cases, the same meshes placed the same way, and a pair of 100 k-triangle
    spheres."""
    from tests.support import uv_sphere

    every = pipeline_cases()
    dense = uv_sphere(1.0, rings=224, segments=224), uv_sphere(1.0, center=(0.9, 0.2, 0.1), rings=224, segments=224)
    return {"bunny-spot": every["bunny+spot"], "spheres": every["two spheres"], "spheres-100k": dense}


def decorate(obj, name, materials: int = 2):
    """What a modelled object carries: ``materials`` materials (faces take them in turn) and a UV map, so the
    result's faces have something to carry over."""
    mesh = obj.data
    for k in range(materials):
        mesh.materials.append(bpy.data.materials.new(f"{name}.{k}"))
    index = (np.arange(len(mesh.polygons)) % materials).astype(np.int32)
    mesh.attributes.new("material_index", "INT", "FACE").data.foreach_set("value", index)
    corner_vert = np.empty(len(mesh.loops), np.int32)
    mesh.attributes[".corner_vert"].data.foreach_get("value", corner_vert)
    co = np.empty(3 * len(mesh.vertices), np.float32)
    mesh.vertices.foreach_get("co", co)
    uv = co.reshape(-1, 3)[corner_vert, :2]
    mesh.attributes.new("UVMap", "FLOAT2", "CORNER").data.foreach_set("vector", uv.ravel())


def register():
    from aasdf.aasdf_addon.preferences import ADDON_ID

    aasdf = load_addon_package()
    if ADDON_ID not in bpy.context.preferences.addons:
        bpy.context.preferences.addons.new().module = ADDON_ID
    aasdf.register()
    return aasdf


def _select(first, second):
    for obj in bpy.context.view_layer.objects:
        obj.select_set(False)
    first.select_set(True)
    second.select_set(True)
    bpy.context.view_layer.objects.active = first


def _run_operator(first, second, voxel_size):
    """Seconds of one ``aasdf.boolean`` call; its result object is removed afterwards."""
    from aasdf.aasdf_addon import pipeline

    _select(first, second)
    t0 = time.perf_counter()
    status = bpy.ops.aasdf.boolean(operation=OPERATION, voxel_size=voxel_size, hide_inputs=False)
    seconds = time.perf_counter() - t0
    if status != {"FINISHED"}:
        raise RuntimeError(f"aasdf.boolean returned {status}")
    numbers = dict(pipeline.last_run)
    bpy.data.objects.remove(bpy.data.objects[numbers["object"]], do_unlink=True)
    return seconds, numbers


def _clear_cache():
    from aasdf.aasdf_addon import cache

    cache.clear()  # fields and the last result


def _turn(obj, step: int):
    """Turn an object 17 degrees about x and y (a new small extra angle each step, so each run is a new pose)."""
    obj.rotation_euler = (np.radians(17.0 + 0.1 * step), np.radians(17.0), 0.0)


def measure(a, b, voxel_size, repeat):
    """Cold, one operand moved, one operand turned, nothing changed, and the geometry-nodes pipeline, in rounds."""
    bpy.ops.wm.read_homefile(use_empty=True)
    first = baselines.mesh_object("operand_a", *a)
    second = baselines.mesh_object("operand_b", *b)
    decorate(first, "a")
    decorate(second, "b")
    bpy.context.view_layer.update()
    diag = float(np.linalg.norm(b[0].max(0) - b[0].min(0)))
    out = {"cold": [], "moved": [], "turned": [], "rerun": [], "gn": [], "attributes": []}
    stages = {"cold": [], "moved": []}
    built = {}
    step = 0

    def gn_run(k):
        matrix = np.array(second.matrix_world, dtype=np.float64)
        moved = ((b[0] @ matrix[:3, :3].T + matrix[:3, 3]).astype(np.float32), b[1])
        gn = baselines.gn_sdf_boolean(a, moved, OPERATION, voxel_size)
        if k:
            out["gn"].append(gn["seconds"])

    for k in range(repeat + 1):  # the first round warms up
        if k % 2 == 1:
            gn_run(k)
        _clear_cache()
        seconds, numbers = _run_operator(first, second, voxel_size)
        built["cold"] = numbers["fields_built"]
        if k:
            out["cold"].append(seconds)
            out["attributes"].append(numbers["stages"]["attributes"] / seconds)
            stages["cold"].append(numbers["stages"])
        for case in ("moved", "turned"):
            step += 1
            second.location.x = 1.0e-3 * diag * step
            if case == "turned":
                _turn(second, step)
            bpy.context.view_layer.update()
            seconds, numbers = _run_operator(first, second, voxel_size)
            built[case] = numbers["fields_built"]
            if k:
                out[case].append(seconds)
                if case == "moved":
                    stages["moved"].append(numbers["stages"])
        seconds, numbers = _run_operator(first, second, voxel_size)
        built["rerun"] = numbers["fields_built"]
        if k:
            out["rerun"].append(seconds)
        if k % 2 == 0:
            gn_run(k)
        second.rotation_euler = (0.0, 0.0, 0.0)
        bpy.context.view_layer.update()
    medians = {key: statistics.median(v) for key, v in out.items()}
    for key in ("cold", "moved", "turned", "rerun"):
        medians[f"{key}_ratio"] = round_ratios(out[key], out["gn"])
    for key, runs in stages.items():
        medians[f"{key}_stages"] = {name: statistics.median(run[name] for run in runs) for name in runs[0]}
        # what every evaluation pays whatever its fields cost, as a share of the geometry nodes' whole run
        output = [sum(run[name] for name in OUTPUT_STAGES) for run in runs]
        medians[f"{key}_output_ratio"] = round_ratios(output, out["gn"])
        medians[f"{key}_fields_ratio"] = round_ratios([run["fields"] for run in runs], out["gn"])
    return medians, built


def drag(a, b, voxel_size, moves: int = 10, repeat: int = 3, keep_faces: bool = True) -> dict:
    """A drag through a CSG tree: ``moves`` successive moves of the cutter, the tree evaluated after each, against as
    many geometry-nodes evaluations; ``repeat`` alternating rounds. Returns seconds per drag, the ratios and the
    seconds per stage of a drag (the median drag's, summed over its moves)."""
    from aasdf.aasdf_addon import cache, csg, nodes, pipeline

    bpy.ops.wm.read_homefile(use_empty=True)
    first = baselines.mesh_object("operand_a", *a)
    second = baselines.mesh_object("operand_b", *b)
    bpy.context.view_layer.update()
    tree = bpy.data.node_groups.new("Drag", nodes.TREE)
    tree.voxel_size = voxel_size
    node_a, node_b = tree.nodes.new(nodes.OBJECT), tree.nodes.new(nodes.OBJECT)
    node_a.object, node_b.object = first, second
    difference, output = tree.nodes.new(nodes.DIFFERENCE), tree.nodes.new(nodes.OUTPUT)
    output.keep_faces = keep_faces
    tree.links.new(node_a.outputs[0], difference.inputs["Base"])
    tree.links.new(node_b.outputs[0], difference.inputs["Cutters"])
    tree.links.new(difference.outputs[0], output.inputs[0])
    diag = float(np.linalg.norm(b[0].max(0) - b[0].min(0)))
    ours, theirs, built, stages = [], [], [], []

    def our_drag():
        t0, before = time.perf_counter(), cache.stats()["builds"]
        summed = {}
        for step in range(moves):
            second.location.x = 0.01 * diag * step
            bpy.context.view_layer.update()
            csg.evaluate_tree(bpy.context, tree)
            for name, seconds in pipeline.last_run["stages"].items():
                summed[name] = summed.get(name, 0.0) + seconds
        built.append(cache.stats()["builds"] - before)
        stages.append(summed)
        return time.perf_counter() - t0

    def their_drag():
        t0 = time.perf_counter()
        for step in range(moves):
            moved = (b[0] + np.float32([0.01 * diag * step, 0.0, 0.0]), b[1])
            baselines.gn_sdf_boolean(a, moved, OPERATION, voxel_size)
        return time.perf_counter() - t0

    _clear_cache()
    csg.evaluate_tree(bpy.context, tree)  # the cold evaluation before the drag starts, and a warm-up
    their_drag()
    for k in range(repeat):
        if k % 2:
            theirs.append(their_drag())
            ours.append(our_drag())
        else:
            ours.append(our_drag())
            theirs.append(their_drag())
    middle = sorted(range(len(ours)), key=ours.__getitem__)[len(ours) // 2]
    return {
        "ours": statistics.median(ours),
        "theirs": statistics.median(theirs),
        "ratio": round_ratios(ours, theirs),
        "built": max(built),
        "stages": stages[middle],
    }


def machine() -> str:
    return f"{platform.machine()}, {os.cpu_count()} cores, bpy {bpy.app.version_string}, warp on cpu"


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", nargs="+", default=["bunny-spot", "spheres", "spheres-100k"])
    parser.add_argument("--resolutions", nargs="+", type=int, default=[256, 512])
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--drag-moves", type=int, default=10)
    args = parser.parse_args(argv)
    register()
    all_cases = cases()
    print(f"# Add-on benchmark — {machine()}; {OPERATION.lower()}, {args.repeat} rounds after a warm-up\n")
    header = (
        "| case | res | GN SDF s | cold s | cold / GN | moved s | moved / GN | turned s | turned / GN "
        "| re-run s | re-run / GN | fields built cold / moved / turned / re-run | attributes (share of cold) |"
    )
    print(header)
    print("|" + "|".join(["---"] * (header.count("|") - 1)) + "|")
    stage_rows = []
    for name in args.cases:
        a, b = all_cases[name]
        pts = np.vstack([a[0], b[0]])
        diag = float(np.linalg.norm(pts.max(0) - pts.min(0)))
        for res in args.resolutions:
            if name == "spheres-100k" and res != 256:
                continue
            m, built = measure(a, b, diag / res, args.repeat)
            cold, moved, turned, rerun = (m[f"{key}_ratio"] for key in ("cold", "moved", "turned", "rerun"))
            print(
                f"| {name} | /{res} | {m['gn']:.2f} | {m['cold']:.2f} | {_ratio(cold, 2)} | {m['moved']:.2f} "
                f"| {_ratio(moved, 2)} | {m['turned']:.2f} | {_ratio(turned, 2)} | {m['rerun']:.3f} "
                f"| {_ratio(rerun, 3)} | {built['cold']} / {built['moved']} / {built['turned']} / {built['rerun']} "
                f"| {100 * m['attributes']:.1f} % |",
                flush=True,
            )
            stage_rows += [
                (name, res, key, m[f"{key}_stages"], m[f"{key}_fields_ratio"], m[f"{key}_output_ratio"])
                for key in ("cold", "moved")
            ]
    print("\n## Seconds per stage (median), cold and one operand moved\n")
    print(f"Against the round's GN SDF time: the fields, and the output ({' + '.join(OUTPUT_STAGES)}).\n")
    names = list(stage_rows[0][3]) if stage_rows else []
    print("| case | res | run | " + " | ".join(names) + " | fields / GN | output / GN |")
    print("|" + "|".join(["---"] * (len(names) + 5)) + "|")
    for name, res, key, stages, fields, output in stage_rows:
        row = " | ".join(f"{stages[n]:.3f}" for n in names)
        print(f"| {name} | /{res} | {key} | {row} | {_ratio(fields, 2)} | {_ratio(output, 2)} |")
    a, b = all_cases["bunny-spot"]
    pts = np.vstack([a[0], b[0]])
    voxel = float(np.linalg.norm(pts.max(0) - pts.min(0))) / 256
    d = drag(a, b, voxel, moves=args.drag_moves, repeat=max(1, args.repeat // 2))
    print(f"\n## A drag through a CSG tree: {args.drag_moves} moves of the cutter, bunny - spot, /256\n")
    print("| AASDF s | GN SDF s | AASDF / GN | fields built during the drag |")
    print("|---|---|---|---|")
    print(f"| {d['ours']:.2f} | {d['theirs']:.2f} | {_ratio(d['ratio'], 2)} | {d['built']} |")


def _ratio(r, digits: int) -> str:
    """ "0.91× (0.80–1.02)": the median of the rounds' ratios, then the smallest and largest."""
    return f"{r[0]:.{digits}f}× ({r[1]:.{digits}f}–{r[2]:.{digits}f})"


if __name__ == "__main__":
    main()
