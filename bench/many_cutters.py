"""A plate minus a grid of bores, each bore an object of its own (a perforated panel), in Blender: ``aasdf.boolean``
with kept faces and remeshed (the field cache cleared before each run: read to write, the fields built), beside the
Boolean modifier's Exact and Manifold solvers on a collection of the bores. Seconds (medians of ``--repeat`` rounds,
kept and remeshed in turn), faces written, and the add-on's stages. The plate is 2 x 2 x 0.2, the bores 24-sided,
0.06 in radius and 0.6 long, on a square grid; voxel = the plate's diagonal / 256.

    .venv/bin/python bench/many_cutters.py [--bores 36 100] [--repeat 2]
"""

from __future__ import annotations

import argparse
import os
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
from bench.addon import register  # noqa: E402
from tests.support import box_mesh, cylinder_mesh  # noqa: E402

RESOLUTION = 256


def panel(count: int) -> tuple:
    """The plate and ``count`` bores on a square grid."""
    side = int(np.ceil(np.sqrt(count)))
    xs = np.linspace(-0.7, 0.7, side)
    bores = [cylinder_mesh(0.06, 0.6, segments=24, center=(xs[i % side], xs[i // side], 0.0)) for i in range(count)]
    return box_mesh(half=(1.0, 1.0, 0.1)), bores


def _objects(plate, bores) -> list:
    objects = [baselines.mesh_object("Plate", *plate)]
    objects += [baselines.mesh_object(f"Bore{k}", *bore) for k, bore in enumerate(bores)]
    bpy.context.view_layer.update()
    return objects


def aasdf(plate, bores, keep: bool) -> dict:
    """One ``aasdf.boolean`` run, the cache cleared first: seconds, faces, the stages; its objects removed after."""
    from aasdf.aasdf_addon import cache, pipeline

    cache.clear()
    objects = _objects(plate, bores)
    for obj in bpy.context.view_layer.objects:
        obj.select_set(obj in objects)
    bpy.context.view_layer.objects.active = objects[0]
    voxel = float(np.linalg.norm([2.0, 2.0, 0.6])) / RESOLUTION
    began = time.perf_counter()
    status = bpy.ops.aasdf.boolean(operation="DIFFERENCE", voxel_size=voxel, hide_inputs=False, keep_faces=keep)
    seconds = time.perf_counter() - began
    assert status == {"FINISHED"}, status
    result = bpy.data.objects[pipeline.last_run["object"]]
    out = {"seconds": seconds, "faces": len(result.data.polygons), "stages": dict(pipeline.last_run["stages"])}
    for obj in [*objects, result]:
        bpy.data.objects.remove(obj, do_unlink=True)
    return out


def modifier(plate, bores, solver: str) -> dict:
    """The Boolean modifier (Difference, a collection of the bores) evaluated: seconds and faces."""
    objects = _objects(plate, bores)
    bores_collection = bpy.data.collections.new("Bores")
    bpy.context.scene.collection.children.link(bores_collection)
    for obj in objects[1:]:
        for collection in obj.users_collection:
            collection.objects.unlink(obj)
        bores_collection.objects.link(obj)
    boolean = objects[0].modifiers.new("Boolean", "BOOLEAN")
    boolean.operation, boolean.operand_type, boolean.collection = "DIFFERENCE", "COLLECTION", bores_collection
    boolean.solver = solver
    began = time.perf_counter()
    evaluated = objects[0].evaluated_get(bpy.context.evaluated_depsgraph_get())
    faces = len(evaluated.data.polygons)
    seconds = time.perf_counter() - began
    for obj in objects:
        bpy.data.objects.remove(obj, do_unlink=True)
    bpy.data.collections.remove(bores_collection)
    return {"seconds": seconds, "faces": faces}


def main(argv=None):
    parser = argparse.ArgumentParser()
    parser.add_argument("--bores", type=int, nargs="*", default=[36, 100])
    parser.add_argument("--repeat", type=int, default=2)
    args = parser.parse_args(argv)
    register()
    print("| bores | kept s (faces) | remeshed s (faces) | kept / remeshed | Exact s (faces) | Manifold s (faces) |")
    print("|---|---|---|---|---|---|")
    for count in args.bores:
        plate, bores = panel(count)
        aasdf(plate, bores, True)  # kernels loaded once
        runs = {True: [], False: []}
        for r in range(args.repeat):
            for keep in (True, False) if r % 2 else (False, True):
                runs[keep].append(aasdf(plate, bores, keep))
        solvers = {}
        for solver in ("EXACT", "MANIFOLD"):
            modifier(plate, bores, solver)
            solvers[solver] = modifier(plate, bores, solver)
        kept, remeshed = (statistics.median(run["seconds"] for run in runs[k]) for k in (True, False))
        stages = {
            k: round(statistics.median(run["stages"][k] for run in runs[True]), 2) for k in runs[True][0]["stages"]
        }
        print(
            f"| {count} | {kept:.2f} ({runs[True][0]['faces']:,}) | {remeshed:.2f} ({runs[False][0]['faces']:,}) | "
            f"{kept / remeshed:.2f}x | {solvers['EXACT']['seconds']:.2f} ({solvers['EXACT']['faces']:,}) | "
            f"{solvers['MANIFOLD']['seconds']:.2f} ({solvers['MANIFOLD']['faces']:,}) |",
            flush=True,
        )
        print(f"  kept stages (s): {stages}", flush=True)


if __name__ == "__main__":
    main()
