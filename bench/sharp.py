"""Sharp-edge benchmark: marching cubes, AASDF's sharp extraction and Blender's geometry-nodes SDF pipeline on CAD-like
booleans, against manifold3d's exact booleans, at creases and overall.

For each pair of ``tests.support.cad_pairs`` (both operands normalised to bounding-box diagonal 1, voxel 1/256) it
prints, in voxels, the two-sided Hausdorff max and p95 over the whole surface and at the creases (the samples of
either surface within two voxels of an exact crease, the exact boolean's edges folding by more than 30 degrees), the
triangle count, and the seconds: ``to_mesh`` alone (marching cubes against sharp, in alternating rounds, the ratio the
median of the rounds' ratios) and the whole pipeline (both fields, boolean, sharp surface) against the geometry-nodes
pipeline (Mesh to SDF Grid x2, SDF Grid Boolean, Grid to Mesh; alternating rounds, ``bench/paired.py``). Timings on
this shared machine drift by 10-20 %: they are indicative. ``--results`` also writes the table into that file's
section (``## Sharp edges``: replaced, or added before ``## Accuracy``).

    .venv/bin/python bench/sharp.py [--cases ...] [--repeat 5] [--samples 200000] [--no-gn] [--results bench/RESULTS.md]
"""

from __future__ import annotations

import argparse
import functools
import os
import sys
import textwrap
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
os.environ.setdefault("WARP_CACHE_PATH", str(ROOT / ".warp-cache"))

import warp as wp  # noqa: E402
from scipy.spatial import cKDTree  # noqa: E402

import engine  # noqa: E402
from bench.paired import paired  # noqa: E402
from tests.metrics import crease_points, exact_boolean, sample_surface, unsigned_distance  # noqa: E402
from tests.support import cad_pairs  # noqa: E402

OPS = {"UNION": engine.union, "INTERSECT": engine.intersection, "DIFFERENCE": engine.difference}
RES = 256
CREASE_BAND = 2.0  # voxels around the exact creases


def deviation(mesh, exact, creases: cKDTree, h: float, n: int) -> dict:
    """Two-sided distances (voxels) between ``mesh`` and ``exact`` from ``n`` samples on each: max and p95 overall and
    over the samples within CREASE_BAND voxels of an exact crease."""
    both, near = [], []
    for k, (source, target) in enumerate(((mesh, exact), (exact, mesh))):
        points = sample_surface(*source, n, seed=k)
        d = unsigned_distance(*target, points).astype(np.float64) / h
        both.append(d)
        near.append(d[creases.query(points)[0] < CREASE_BAND * h])
    overall, at_creases = np.concatenate(both), np.concatenate(near)
    return {
        "max": overall.max(),
        "p95": max(np.percentile(d, 95) for d in both),
        "crease_max": at_creases.max(initial=0.0),
        "crease_p95": max(np.percentile(d, 95) for d in near if len(d)),
    }


def aasdf_pipeline(a, b, op, h, sharp=True):
    start = time.perf_counter()
    fa, fb = engine.build_fields([a, b], voxel_size=h)
    verts, tris = OPS[op](fa, fb).to_mesh(sharp=sharp)
    return {"verts": verts, "tris": tris, "seconds": time.perf_counter() - start}


def timed_to_mesh(field, sharp):
    start = time.perf_counter()
    verts, tris = field.to_mesh(sharp=sharp)
    return {"verts": verts, "tris": tris, "seconds": time.perf_counter() - start}


def _ratio(pair: dict) -> str:
    return f"{pair['ratio']:.2f}x, {pair['low']:.2f}-{pair['high']:.2f}"


def emit(lines: list, line: str) -> None:
    print(line, flush=True)
    lines.append(line)


def run(names, repeat, samples, with_gn) -> list:
    """Print the table (markdown) and return its lines."""
    baselines = None
    if with_gn:
        from bench import baselines  # needs bpy
    lines = []
    emit(lines, f"# Sharp edges at /{RES}")
    emit(lines, "")
    about = (
        "`bench/sharp.py`: the CAD-like pairs of `tests.support.cad_pairs` (each operand normalised to bounding-box "
        f"diagonal 1, voxel 1/{RES}) against manifold3d's exact booleans, two-sided Hausdorff distance in voxels from "
        f"{samples:,} samples on each surface, overall and at the creases (samples within {CREASE_BAND:g} voxels of an "
        "exact crease folding by more than 30 degrees). Marching cubes is `to_mesh(sharp=False)`, AASDF sharp "
        "`to_mesh()`, GN the geometry-nodes SDF pipeline (Mesh to SDF Grid x2, SDF Grid Boolean, Grid to Mesh) at the "
        "same voxel size. Seconds: `to_mesh` alone (sharp against marching cubes) and the whole pipeline (both "
        f"fields, boolean, sharp surface) against GN, medians of {repeat} alternating rounds after a warm-up; a ratio "
        "is the median of the rounds' ratios, with the smallest and largest."
    )
    for line in textwrap.wrap(about, width=120):
        emit(lines, line)
    emit(lines, "")
    header = (
        "| pair | method | max | p95 | max at creases | p95 at creases | triangles | to_mesh s (vs MC) "
        "| pipeline s (vs GN) |"
    )
    emit(lines, header)
    emit(lines, "|" + "|".join(["---"] * (header.count("|") - 1)) + "|")
    pairs = cad_pairs()
    for name in names:
        op, a, b = pairs[name]
        exact = exact_boolean(op, *a, *b)
        h = 1.0 / RES
        creases = cKDTree(crease_points(*exact, angle=30.0, step=0.1 * h))
        fa, fb = engine.build_fields([a, b], voxel_size=h)
        field = OPS[op](fa, fb)
        meshing = paired(
            functools.partial(timed_to_mesh, field, True), functools.partial(timed_to_mesh, field, False), repeat
        )
        rows = [
            ("marching cubes", meshing["theirs"], f"{meshing['theirs']['seconds']:.3f}", ""),
            (
                "AASDF sharp",
                meshing["ours"],
                f"{meshing['ours']['seconds']:.3f} ({_ratio(meshing)})",
                "",
            ),
        ]
        if baselines is not None:
            pipeline = paired(
                functools.partial(aasdf_pipeline, a, b, op, h),
                functools.partial(baselines.gn_sdf_boolean, a, b, op, h),
                repeat,
            )
            ours, gn = pipeline["ours"], pipeline["theirs"]
            rows[1] = (
                rows[1][0],
                rows[1][1],
                rows[1][2],
                f"{ours['seconds']:.3f} ({_ratio(pipeline)})",
            )
            rows.append(("GN SDF pipeline", gn, "", f"{gn['seconds']:.3f}"))
        for method, result, mesh_s, pipe_s in rows:
            d = deviation((result["verts"], result["tris"]), exact, creases, h, samples)
            quality = f"{d['max']:.2f} | {d['p95']:.3f} | {d['crease_max']:.2f} | {d['crease_p95']:.3f}"
            label = name.replace("|", "\\|")  # a markdown table cell
            emit(lines, f"| {label} | {method} | {quality} | {len(result['tris']):,} | {mesh_s} | {pipe_s} |")
    return lines


def write_section(path: Path, lines: list) -> None:
    """Put ``lines`` (their title made a ``##`` section) into ``path`` in place of its ``## Sharp edges`` section, or
    before its ``## Accuracy`` section (at the end if it has none)."""
    section = ["#" + lines[0], *lines[1:]]
    text = path.read_text(encoding="utf-8").splitlines()
    start = next((i for i, line in enumerate(text) if line.startswith("## Sharp edges")), None)
    if start is None:
        start = end = next((i for i, line in enumerate(text) if line.startswith("## Accuracy")), len(text))
    else:
        end = next((i for i in range(start + 1, len(text)) if text[i].startswith("## ")), len(text))
    section.append("")
    path.write_text("\n".join(text[:start] + section + text[end:]).rstrip("\n") + "\n", encoding="utf-8")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", nargs="+", default=list(cad_pairs()))
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--samples", type=int, default=200_000)
    parser.add_argument("--no-gn", action="store_true", help="skip the geometry-nodes pipeline (no bpy needed)")
    parser.add_argument("--results", type=Path, help="also write the table into this file's 'Sharp edges' section")
    args = parser.parse_args(argv)
    wp.config.quiet = True
    lines = run(args.cases, args.repeat, args.samples, not args.no_gn)
    if args.results is not None:
        write_section(args.results, lines)


if __name__ == "__main__":
    main()
