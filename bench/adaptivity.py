"""Adaptivity and quads against Blender's own remeshers, on the bench pairs at /256.

For each pair and each adaptivity 0, 0.25, 0.5, 0.75, 1: Blender's geometry-nodes SDF boolean (Mesh to SDF Grid x2,
SDF Grid Boolean, Grid to Mesh with that Adaptivity) and AASDF's ``to_mesh(quads=True, adaptivity=...)`` on its
fields at the same voxel size: polygons, the share of quads, and the Hausdorff p95 / max to manifold3d's exact
boolean (voxels). For each Grid to Mesh point, the AASDF adaptivities (of 0, 0.05, 0.1, 0.25, 0.4, 0.5, 0.6, 0.75, 0.8,
0.85, 0.9, 0.95, 1) that give fewer polygons at a lower p95: AASDF's curve lies below that point there. Seconds: AASDF's
``to_mesh(quads=True, adaptivity=a)`` against today's ``to_mesh()`` (triangles), alternating rounds
(``bench/paired.py``), medians; and the add-on's ``aasdf.boolean`` (keep faces off, both fields cached: the boolean,
the surface, its attributes and the written object) at each adaptivity. Beside them Blender's Voxel Remesh (the
operator, on the exact boolean at the same voxel size): its polygons and share of quads. Voxel = the pair's
bounding-box diagonal / 256.

    .venv/bin/python bench/adaptivity.py [--repeat 3] [--cases cube ...]
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
from tests.metrics import exact_boolean, hausdorff  # noqa: E402
from tests.support import cad_pairs, plate_and_bores  # noqa: E402

RESOLUTION = 256
ADAPTIVITIES = (0.0, 0.25, 0.5, 0.75, 1.0)
OUR_ADAPTIVITIES = (0.0, 0.05, 0.1, 0.25, 0.4, 0.5, 0.6, 0.75, 0.8, 0.85, 0.9, 0.95, 1.0)  # the points of AASDF's curve


def cases() -> dict:
    """name -> (operation, a, b): the closed bench pairs of ``bench/keep_faces.py``."""
    cad = cad_pairs()
    return {
        "plate - 4 bores": ("DIFFERENCE", *plate_and_bores()),
        "cube - bore": cad["cube - bore"],
        "fandisk - cylinder": cad["fandisk - cylinder"],
        "rocker-arm - cube": cad["rocker-arm - cube"],
        "hex prism & sphere": cad["hex prism & sphere"],
    }


def _error(verts, tris, exact, voxel) -> tuple[float, float]:
    d = hausdorff(verts, tris, *exact, n=100_000)
    return d["p95"] / voxel, d["max"] / voxel


def voxel_remesh(exact, voxel) -> dict:
    """Blender's Voxel Remesh operator on the exact boolean: polygons and share of quads."""
    obj = baselines.mesh_object("remesh", *exact)
    obj.data.remesh_voxel_size = voxel
    obj.data.remesh_voxel_adaptivity = 0.0
    bpy.context.view_layer.objects.active = obj
    with bpy.context.temp_override(active_object=obj, object=obj):
        bpy.ops.object.voxel_remesh()
    sizes = np.empty(len(obj.data.polygons), np.int32)
    obj.data.polygons.foreach_get("loop_total", sizes)
    bpy.data.objects.remove(obj, do_unlink=True)
    return {"faces": len(sizes), "quads": float(np.mean(sizes == 4)) if len(sizes) else 0.0}


def grid_to_mesh(a, b, op, voxel, adaptivity, exact) -> dict:
    out = baselines.gn_sdf_boolean(a, b, op, voxel, adaptivity=adaptivity)
    p95, worst = _error(out["verts"], out["tris"], exact, voxel)
    return {"faces": out["faces"], "p95": p95, "max": worst, "seconds": out["seconds"]}


def aasdf(field, adaptivity, exact, voxel) -> dict:
    from aasdf.engine.quads import triangulate

    verts, faces, sizes = field.to_mesh(quads=True, adaptivity=adaptivity)
    p95, worst = _error(verts, triangulate(faces, sizes), exact, voxel)
    return {"faces": len(sizes), "quads": float(np.mean(sizes == 4)), "p95": p95, "max": worst}


def extraction_seconds(field, repeat) -> dict:
    """Median seconds of ``to_mesh()`` (today: triangles) and of ``to_mesh(quads=True, adaptivity=a)``, rounds
    alternating their order."""
    runs = {"today": lambda: field.to_mesh()}
    runs.update({a: (lambda a=a: field.to_mesh(quads=True, adaptivity=a)) for a in ADAPTIVITIES})
    times = {k: [] for k in runs}
    for r in range(repeat + 1):  # the first round warms up
        for key in list(runs) if r % 2 else list(runs)[::-1]:
            t0 = time.perf_counter()
            runs[key]()
            if r:
                times[key].append(time.perf_counter() - t0)
    return {k: statistics.median(v) for k, v in times.items()}


def addon_seconds(a, b, op, voxel, repeat) -> dict:
    """Median seconds of ``aasdf.boolean`` (keep faces off) at each adaptivity with both fields cached: the boolean,
    the surface, its attributes and the written object (each round's order turned a step), and the faces written."""
    from aasdf.aasdf_addon import cache, pipeline

    cache.clear()
    first, second = baselines.mesh_object("A", *a), baselines.mesh_object("B", *b)
    bpy.context.view_layer.update()
    times, faces = {x: [] for x in ADAPTIVITIES}, {}
    for r in range(repeat + 1):  # the first round builds the fields and warms up
        # turned a step each round: no run repeats the one before (that would be the result the add-on keeps)
        for adaptivity in ADAPTIVITIES[r % len(ADAPTIVITIES) :] + ADAPTIVITIES[: r % len(ADAPTIVITIES)]:
            for obj in list(bpy.context.view_layer.objects):
                if obj is not None:
                    obj.select_set(obj in (first, second))
            bpy.context.view_layer.objects.active = first
            bpy.context.view_layer.update()
            t0 = time.perf_counter()
            status = bpy.ops.aasdf.boolean(
                operation=op, voxel_size=voxel, hide_inputs=False, keep_faces=False, adaptivity=adaptivity
            )
            seconds = time.perf_counter() - t0
            assert status == {"FINISHED"}, status
            result = bpy.data.objects[pipeline.last_run["object"]]
            faces[adaptivity] = len(result.data.polygons)
            bpy.data.objects.remove(result, do_unlink=True)
            if r:
                times[adaptivity].append(seconds)
    for obj in (first, second):
        bpy.data.objects.remove(obj, do_unlink=True)
    return {x: (statistics.median(times[x]), faces[x]) for x in ADAPTIVITIES}


def dominated_by(gn: dict, ours: dict) -> str:
    """The AASDF adaptivities with fewer polygons and a lower p95 than a Grid to Mesh point ("-": none)."""
    better = [f"{a:g}" for a, o in ours.items() if o["faces"] < gn["faces"] and o["p95"] < gn["p95"]]
    return ", ".join(better) or "-"


def main(argv=None):
    parser = argparse.ArgumentParser()
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--cases", nargs="*")
    args = parser.parse_args(argv)
    from bench.addon import register

    register()
    from aasdf import engine

    bpy.ops.wm.read_homefile(use_empty=True)
    chosen = {k: v for k, v in cases().items() if not args.cases or any(c in k for c in args.cases)}
    ops = {"UNION": engine.union, "INTERSECT": engine.intersection, "DIFFERENCE": engine.difference}
    print("# Adaptivity and quads\n")
    print(f"{platform.machine()}, {os.cpu_count()} cores, Blender {bpy.app.version_string}, /{RESOLUTION}")
    curves, times, addon_rows, remesh_rows = [], [], [], []
    for name, (op, a, b) in chosen.items():
        voxel = baselines.diagonal(a, b) / RESOLUTION
        exact = exact_boolean(op, *a, *b)
        field = ops[op](*engine.build_fields([a, b], voxel_size=voxel))
        seconds = extraction_seconds(field, args.repeat)
        ours = {a: aasdf(field, a, exact, voxel) for a in OUR_ADAPTIVITIES}
        for adaptivity in ADAPTIVITIES:
            gn = grid_to_mesh(a, b, op, voxel, adaptivity, exact)
            o = ours[adaptivity]
            curves.append(
                f"| {name} | {adaptivity:g} | {gn['faces']:,} | {gn['p95']:.3f} / {gn['max']:.2f} | {o['faces']:,} | "
                f"{o['quads']:.3f} | {o['p95']:.3f} / {o['max']:.2f} | {dominated_by(gn, ours)} |"
            )
            print(curves[-1], flush=True)
        extra = ", ".join(f"{a:g}: {o['faces']:,} ({o['p95']:.3f})" for a, o in ours.items() if a not in ADAPTIVITIES)
        curves.append(f"| {name} | {extra} | | | | | | |")
        ratio = " | ".join(f"{seconds[a]:.3f} ({seconds[a] / seconds['today']:.1f}x)" for a in ADAPTIVITIES)
        times.append(f"| {name} | {seconds['today']:.3f} | {ratio} |")
        run = addon_seconds(a, b, op, voxel, args.repeat)
        cells = " | ".join(f"{run[x][0]:.2f} ({run[x][0] / run[0.0][0]:.2f}x, {run[x][1]:,})" for x in ADAPTIVITIES)
        addon_rows.append(f"| {name} | {cells} |")
        remesh_rows.append((name, voxel_remesh(exact, voxel), ours[0.0]))
    print(
        "\n| pair | adaptivity | Grid to Mesh polygons | p95 / max | AASDF polygons | quads | p95 / max | "
        "AASDF below it at |"
    )
    print("|---|---|---|---|---|---|---|---|")
    print("\n".join(curves))
    print("\n| pair | to_mesh() today s | " + " | ".join(f"quads, adaptivity {a:g}" for a in ADAPTIVITIES) + " |")
    print("|---|---|" + "---|" * len(ADAPTIVITIES))
    print("\n".join(times))
    print("\n| pair | " + " | ".join(f"aasdf.boolean s, adaptivity {a:g} (faces)" for a in ADAPTIVITIES) + " |")
    print("|---|" + "---|" * len(ADAPTIVITIES))
    print("\n".join(addon_rows))
    print("\n| pair | Voxel Remesh polygons | Voxel Remesh quads | AASDF polygons | AASDF quads |")
    print("|---|---|---|---|---|")
    for name, remesh, o in remesh_rows:
        print(f"| {name} | {remesh['faces']:,} | {remesh['quads']:.3f} | {o['faces']:,} | {o['quads']:.3f} |")


if __name__ == "__main__":
    main()
