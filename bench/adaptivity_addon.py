"""Adaptivity as a user meets it: the time from the combined field to the mesh in the scene, by adaptivity.

``aasdf.boolean`` with Keep Original Faces off, in one ``bpy`` process with the add-on registered, on the bench pairs
of ``bench/adaptivity.py`` at diagonal / 256. The add-on's stages after the boolean are summed: ``surface`` (the
extraction: ``to_mesh`` with quads and the adaptivity asked, creases), ``attributes`` (the faces' materials, UVs and
colours carried over from their sources) and ``write`` (the result object). Each operand carries a material and a UV
map (``bench/addon.py``; faces of two materials or UV islands would not merge). The cache is cleared before each run,
so every run builds, combines and extracts afresh; only those three stages are timed. Adaptivities run in turns, their
order reversed each round (``bench/paired.py``); ratios are the medians of the rounds' ratios to adaptivity 0, with
the smallest and largest.

    .venv/bin/python bench/adaptivity_addon.py [--repeat 7] [--cases cube ...] [--adaptivities 0.5 1]
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
os.environ.setdefault("WARP_CACHE_PATH", str(ROOT / ".warp-cache"))

import bpy  # noqa: E402

from bench import baselines  # noqa: E402
from bench.adaptivity import cases  # noqa: E402
from bench.addon import decorate, register  # noqa: E402
from bench.paired import round_ratios  # noqa: E402

OUTPUT_STAGES = ("surface", "attributes", "write")


def run(first, second, op: str, voxel: float, adaptivity: float) -> dict:
    """One remeshed ``aasdf.boolean`` from scratch: the seconds of its output stages and the polygons written (the
    result object removed after)."""
    from aasdf.aasdf_addon import cache, pipeline

    cache.clear()
    for obj in bpy.context.view_layer.objects:
        obj.select_set(obj in (first, second))
    bpy.context.view_layer.objects.active = first
    status = bpy.ops.aasdf.boolean(
        operation=op, voxel_size=voxel, hide_inputs=False, keep_faces=False, adaptivity=adaptivity
    )
    if status != {"FINISHED"}:
        raise RuntimeError(f"aasdf.boolean returned {status}")
    numbers = dict(pipeline.last_run)
    result = bpy.data.objects[numbers["object"]]
    polygons = len(result.data.polygons)
    bpy.data.objects.remove(result, do_unlink=True)
    return {"seconds": sum(numbers["stages"][k] for k in OUTPUT_STAGES), "stages": numbers["stages"], "faces": polygons}


def measure(op, a, b, adaptivities, repeat: int) -> dict:
    """Rounds of every adaptivity (0 first in odd rounds, last in even ones) after a warm-up round."""
    bpy.ops.wm.read_homefile(use_empty=True)
    first, second = baselines.mesh_object("operand_a", *a), baselines.mesh_object("operand_b", *b)
    decorate(first, "a", materials=1)
    decorate(second, "b", materials=1)
    bpy.context.view_layer.update()
    voxel = baselines.diagonal(a, b) / 256
    runs = {x: [] for x in adaptivities}
    for r in range(repeat + 1):
        for x in adaptivities if r % 2 else adaptivities[::-1]:
            out = run(first, second, op, voxel, x)
            if r:
                runs[x].append(out)
    return runs


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--repeat", type=int, default=7)
    parser.add_argument("--cases", nargs="*")
    parser.add_argument("--adaptivities", nargs="*", type=float, default=[0.5, 0.75, 1.0])
    args = parser.parse_args(argv)
    register()
    adaptivities = [0.0] + [x for x in args.adaptivities if x > 0.0]
    print("| pair | adaptivity | polygons | surface ms | attributes ms | write ms | sum ms | / adaptivity 0 |")
    print("|---|---|---|---|---|---|---|---|")
    for name, (op, a, b) in cases().items():
        if args.cases and not any(c in name for c in args.cases):
            continue
        runs = measure(op, a, b, adaptivities, args.repeat)
        base = [out["seconds"] for out in runs[0.0]]
        for x in adaptivities:
            stage = {k: 1e3 * statistics.median(out["stages"][k] for out in runs[x]) for k in OUTPUT_STAGES}
            total = [out["seconds"] for out in runs[x]]
            median, low, high = round_ratios(total, base)
            cells = [f"{runs[x][-1]['faces']:,}", *(f"{stage[k]:.1f}" for k in OUTPUT_STAGES)]
            cells += [f"{1e3 * statistics.median(total):.1f}", f"{median:.2f}x ({low:.2f}-{high:.2f})" if x else "1"]
            print(f"| {name} | {x:g} | " + " | ".join(cells) + " |", flush=True)


if __name__ == "__main__":
    main()
