"""Booleans that keep the operands' own faces, in Blender, beside the Boolean modifier's Exact and Manifold solvers and
AASDF remeshed: seconds (read to write, the fields built: a first run), faces, closed or not, and for closed pairs the
Hausdorff distance to manifold3d's exact boolean (max and p95, voxels), and how many pairs of its faces pass through
each other (``tests.metrics.self_intersections``). One ``bpy`` process, the add-on registered;
each case runs its four methods in turn for ``--repeat`` rounds (the order alternating, ``bench/paired.py``), times are
medians. Voxel = the pair's bounding-box diagonal / 256.

    .venv/bin/python bench/keep_faces.py [--repeat 3] [--cases plate ...]
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

from bench import baselines  # noqa: E402
from bench.addon import register  # noqa: E402
from tests.metrics import exact_boolean, hausdorff, self_intersections  # noqa: E402
from tests.support import box_mesh, cad_pairs, load_mesh, normalised, plate_and_bores, uv_sphere  # noqa: E402

RESOLUTION = 256


def cases() -> dict:
    """name -> (operation, a, b, closed): CAD pairs, a pair of scans, open scans with a ball, a low-polygon mesh that
    passes through itself with a ball, and pairs whose faces lie in each other's planes."""
    cad = cad_pairs()
    ball = normalised(uv_sphere(1.0), center=(0.2, 0.2, 0.2), diagonal=0.6)
    spot = normalised(load_mesh("spot.obj"))
    bunny = normalised(load_mesh("stanford-bunny.obj"), center=(0.25, 0.0, 0.0), diagonal=0.8)
    beetle = normalised(load_mesh("beetle.obj"))
    suzanne = normalised(load_mesh("suzanne.obj"))
    return {
        "plate - 4 bores": ("DIFFERENCE", *plate_and_bores(), True),
        "cube - bore": (*cad["cube - bore"], True),
        "fandisk - cylinder": (*cad["fandisk - cylinder"], True),
        "rocker-arm - cube": (*cad["rocker-arm - cube"], True),
        "hex prism & sphere": (*cad["hex prism & sphere"], True),
        "bunny ∪ spot (open scan)": ("UNION", bunny, spot, False),
        "beetle ∪ ball (open scan)": ("UNION", beetle, ball, False),
        "Suzanne ∪ ball (crosses itself)": ("UNION", suzanne, ball, False),
        "boxes side by side (coplanar)": (
            "UNION",
            box_mesh((1.0, 0.5, 0.5)),
            box_mesh((1.0, 0.5, 0.5), (1.0, 0, 0)),
            True,
        ),
        "rocker arm ∪ its copy (coplanar)": ("UNION", cad["rocker-arm - cube"][1], cad["rocker-arm - cube"][1], True),
    }


def run_aasdf(a, b, op, voxel, keep):
    """One ``aasdf.boolean`` run (the field cache cleared first: the fields built), read to write: seconds, faces
    written, the result's arrays and whether it is closed; its objects removed after."""
    from aasdf.aasdf_addon import cache, pipeline

    cache.clear()
    first, second = baselines.mesh_object("A", *a), baselines.mesh_object("B", *b)
    bpy.context.view_layer.update()
    for obj in bpy.context.view_layer.objects:
        obj.select_set(obj in (first, second))
    bpy.context.view_layer.objects.active = first
    t0 = time.perf_counter()
    status = bpy.ops.aasdf.boolean(operation=op, voxel_size=voxel, hide_inputs=False, keep_faces=keep)
    seconds = time.perf_counter() - t0
    assert status == {"FINISHED"}, status
    result = bpy.data.objects[pipeline.last_run["object"]]
    verts, tris = baselines.mesh_arrays(result.data)
    faces = len(result.data.polygons)
    for obj in (first, second, result):
        bpy.data.objects.remove(obj, do_unlink=True)
    return {"seconds": seconds, "faces": faces, "verts": verts, "tris": tris, "closed": baselines.is_closed(tris)}


def _modifier(a, b, op, solver):
    out = baselines.boolean_modifier(a, b, op, solver, keep=True)
    obj = bpy.data.objects.get("boolean_a")  # kept by the call: its evaluated polygons are the faces written
    faces = len(obj.evaluated_get(bpy.context.evaluated_depsgraph_get()).data.polygons) if obj else len(out["tris"])
    for name in ("boolean_a", "boolean_b"):
        if name in bpy.data.objects:
            bpy.data.objects.remove(bpy.data.objects[name], do_unlink=True)
    closed = out["closed"] and out["usable"]
    return {"seconds": out["seconds"], "faces": faces, "verts": out["verts"], "tris": out["tris"], "closed": closed}


METHODS = {
    "Exact": lambda a, b, op, voxel: _modifier(a, b, op, "EXACT"),
    "Manifold": lambda a, b, op, voxel: _modifier(a, b, op, "MANIFOLD"),
    "AASDF kept faces": lambda a, b, op, voxel: run_aasdf(a, b, op, voxel, True),
    "AASDF remeshed": lambda a, b, op, voxel: run_aasdf(a, b, op, voxel, False),
}


def measure(name, op, a, b, closed, repeat):
    voxel = baselines.diagonal(a, b) / RESOLUTION
    times = {m: [] for m in METHODS}
    last = {}
    for r in range(repeat + 1):  # the first round warms up
        order = list(METHODS) if r % 2 else list(METHODS)[::-1]
        for method in order:
            out = METHODS[method](a, b, op, voxel)
            if r:
                times[method].append(out["seconds"])
            last[method] = out
    exact = exact_boolean(op, *a, *b) if closed else None
    rows = []
    for method, out in last.items():
        error = ""
        if exact is not None and out["closed"] and len(out["tris"]):
            d = hausdorff(out["verts"], out["tris"], *exact, n=100_000)
            error = f"{d['max'] / voxel:.2f} / {d['p95'] / voxel:.3f}"
        crossings = self_intersections(out["verts"], out["tris"]) if len(out["tris"]) else 0
        rows.append((name, method, statistics.median(times[method]), out["faces"], out["closed"], error, crossings))
    return rows


def main(argv=None):
    parser = argparse.ArgumentParser()
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--cases", nargs="*")
    args = parser.parse_args(argv)
    register()
    bpy.ops.wm.read_homefile(use_empty=True)
    chosen = {k: v for k, v in cases().items() if not args.cases or any(c in k for c in args.cases)}
    print(f"keep faces: {platform.machine()}, {os.cpu_count()} cores, Blender {bpy.app.version_string}, /{RESOLUTION}")
    print("| pair | method | seconds | faces | closed | Hausdorff max / p95 (voxels) | crossing pairs |")
    print("|---|---|---|---|---|---|---|")
    for name, (op, a, b, closed) in chosen.items():
        for row in measure(name, op, a, b, closed, args.repeat):
            closed = "yes" if row[4] else "no"
            print(f"| {row[0]} | {row[1]} | {row[2]:.3f} | {row[3]:,} | {closed} | {row[5]} | {row[6]} |", flush=True)


if __name__ == "__main__":
    main()
