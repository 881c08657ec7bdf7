"""Whole-pipeline benchmark: AASDF against Blender's SDF geometry nodes and Boolean modifier, side by side.

For each case (bunny+spot, rocker-arm+cube, fandisk+cylinder, two spheres), operation and finest spacing (combined
bounding-box diagonal / 256 and / 512) it prints, in one run: AASDF's time per stage (both fields, built at the
same time as the add-on builds them; boolean; to_mesh), Blender's geometry-nodes pipeline (Mesh to SDF Grid ×2 →
SDF Grid Boolean → Grid to Mesh, threshold 0) at the same voxel size, and the Boolean modifier with its Exact and
Manifold solvers; the result's triangles, its volume error and two-sided Hausdorff p95 (in voxels) against the exact
boolean from manifold3d (where the inputs are closed), and whether it is watertight. AASDF and the geometry-nodes
pipeline run in turns (``--repeat`` rounds after a warm-up, see ``bench/paired.py``): their times are medians, the
ratio is the median of the per-round ratios, with the smallest and largest beside it. The modifier's times are
medians of three runs of its own.

    .venv/bin/python bench/pipeline.py [--cases ...] [--ops UNION DIFFERENCE] [--resolutions 256 512] [--repeat 5]
"""

from __future__ import annotations

import argparse
import functools
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
os.environ.setdefault("WARP_CACHE_PATH", str(ROOT / ".warp-cache"))

import warp as wp  # noqa: E402

import engine  # noqa: E402
from bench import baselines  # noqa: E402
from bench.paired import paired  # noqa: E402
from tests.metrics import exact_boolean, hausdorff, mesh_volume  # noqa: E402
from tests.support import box_mesh, is_watertight, load_mesh, uv_sphere  # noqa: E402

OPS = {"UNION": engine.union, "INTERSECT": engine.intersection, "DIFFERENCE": engine.difference}


def cylinder_mesh(radius=1.0, height=2.0, segments=96, center=(0.0, 0.0, 0.0)):
    """A closed, outward-oriented cylinder along z."""
    ang = np.linspace(0.0, 2.0 * np.pi, segments, endpoint=False)
    ring = np.stack([radius * np.cos(ang), radius * np.sin(ang)], axis=1)
    bottom = np.c_[ring, np.full(segments, -height / 2)]
    top = np.c_[ring, np.full(segments, height / 2)]
    verts = np.vstack([bottom, top, [[0, 0, -height / 2], [0, 0, height / 2]]]) + np.asarray(center)
    i = np.arange(segments)
    j = (i + 1) % segments
    cb, ct = 2 * segments, 2 * segments + 1
    sides = np.r_[np.c_[i, j, segments + j], np.c_[i, segments + j, segments + i]]
    caps = np.r_[np.c_[np.full(segments, cb), j, i], np.c_[np.full(segments, ct), segments + i, segments + j]]
    return verts.astype(np.float32), np.r_[sides, caps].astype(np.int32)


def _fit(mesh, like, scale, shift):
    """Scale ``mesh`` to ``scale`` times the diagonal of ``like`` and centre it at like's centre + shift·diag."""
    v, t = mesh
    lv = like[0]
    size = np.linalg.norm(lv.max(0) - lv.min(0))
    own = np.linalg.norm(v.max(0) - v.min(0))
    centre = 0.5 * (lv.max(0) + lv.min(0))
    out = (v - 0.5 * (v.max(0) + v.min(0))) * (scale * size / own) + centre + np.asarray(shift) * size
    return out.astype(np.float32), t


def cases():
    spot = load_mesh("spot.obj")
    rocker = load_mesh("rocker-arm.obj")
    fandisk = load_mesh("fandisk.obj")
    return {
        "bunny+spot": (_fit(load_mesh("stanford-bunny.obj"), spot, 0.8, (0.25, 0.0, 0.0)), spot),
        "rocker-arm+cube": (rocker, _fit(box_mesh(subdivisions=2), rocker, 0.45, (0.0, 0.15, 0.2))),
        "fandisk+cylinder": (fandisk, _fit(cylinder_mesh(), fandisk, 0.45, (0.1, 0.0, 0.2))),
        "two spheres": (uv_sphere(1.0, rings=48, segments=96), uv_sphere(1.0, center=(1.2, 0.0, 0.0))),
    }


def machine() -> str:
    return f"{platform.machine()}, {os.cpu_count()} cores, warp {wp.__version__} on cpu, bpy 5.0.1"


def _median(fn, repeat):
    runs = [fn() for _ in range(repeat)]
    order = np.argsort([r["seconds"] for r in runs])
    return runs[order[len(runs) // 2]]


def aasdf_pipeline(a, b, op, h):
    t0 = time.perf_counter()
    fa, fb = engine.build_fields([a, b], voxel_size=h)  # at the same time, as the add-on builds its operands
    t2 = time.perf_counter()
    result = OPS[op](fa, fb)
    t3 = time.perf_counter()
    verts, tris = result.to_mesh()
    t4 = time.perf_counter()
    return {
        "verts": verts,
        "tris": tris,
        "seconds": t4 - t0,
        "stages": f"{t2 - t0:.2f}+{t3 - t2:.2f}+{t4 - t3:.2f}",
        "nodes": result.node_count,
    }


def quality(res, exact, h):
    if len(res["tris"]) == 0:
        return "—", "—", False
    closed = is_watertight(res["tris"])
    if exact is None:
        return "—", "—", closed
    vol_err = mesh_volume(res["verts"], res["tris"]) / mesh_volume(*exact) - 1.0
    p95 = hausdorff(res["verts"], res["tris"], *exact, n=100_000)["p95"] / h
    return f"{100 * vol_err:+.2f}%", f"{p95:.2f}", closed


def run(selected, ops, resolutions, repeat):
    print(f"# Pipeline benchmark — {machine()}; AASDF and GN in {repeat} alternating rounds after a warm-up\n")
    header = (
        "| case | op | res | method | seconds | stages (build a and b+boolean+mesh) | vs GN | triangles "
        "| volume err | Hausdorff p95 (voxels) | watertight |"
    )
    print(header)
    print("|" + "|".join(["---"] * (header.count("|") - 1)) + "|")
    all_cases = cases()
    for name in selected:
        a, b = all_cases[name]
        diag = float(np.linalg.norm(np.vstack([a[0], b[0]]).max(0) - np.vstack([a[0], b[0]]).min(0)))
        for op in ops:
            try:
                exact = exact_boolean(op, *a, *b)
            except ValueError:
                exact = None  # an open operand: manifold3d has no exact answer
            modifier_rows = []
            for solver in ("EXACT", "MANIFOLD"):
                r = _median(functools.partial(baselines.boolean_modifier, a, b, op, solver), min(repeat, 3))
                modifier_rows.append((solver, r))
            for res in resolutions:
                h = diag / res
                pair = paired(
                    functools.partial(aasdf_pipeline, a, b, op, h),
                    functools.partial(baselines.gn_sdf_boolean, a, b, op, h),
                    repeat,
                )
                ours, gn = pair["ours"], pair["theirs"]
                rows = [("AASDF", ours, ours["stages"]), ("GN SDF pipeline", gn, "")]
                rows += [(f"Boolean {s.title()}", r, "") for s, r in modifier_rows]
                for method, r, stages in rows:
                    vol, p95, closed = quality(r, exact, h)
                    if r is ours:
                        ratio = f"{pair['ratio']:.2f}x ({pair['low']:.2f}-{pair['high']:.2f})"
                    else:
                        ratio = f"{r['seconds'] / gn['seconds']:.2f}x"
                    print(
                        f"| {name} | {op} | /{res} | {method} | {r['seconds']:.3f} | {stages} | {ratio} "
                        f"| {len(r['tris']):,} | {vol} | {p95} | {'yes' if closed else 'no'} |"
                    )
                    sys.stdout.flush()


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", nargs="+", default=list(cases()))
    parser.add_argument("--ops", nargs="+", default=["UNION", "DIFFERENCE"])
    parser.add_argument("--resolutions", nargs="+", type=int, default=[256, 512])
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args(argv)
    wp.config.quiet = True
    run(args.cases, args.ops, args.resolutions, args.repeat)


if __name__ == "__main__":
    main()
