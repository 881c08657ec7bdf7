"""Offset benchmark: AASDF's offset against Blender's geometry nodes, and re-distancing by sweeping against the FIM.

Part ``offset``: a closed mesh (spot) grown by 2, 8 and 32 voxels (and shrunk by 8) at voxel = bounding diagonal / 256.
AASDF: build the field, ``engine.offset``, ``to_mesh``. Geometry nodes: Mesh to SDF Grid with the band the distance
needs (|distance| / voxel + 3 voxels), SDF Grid Offset, Grid to Mesh (threshold 0), at the same voxel size. Both run in
alternating rounds after a warm-up (``bench/paired.py``); a geometry-nodes run slower than ``--slow`` seconds is run
once, its time beside AASDF's median. Accuracy: every vertex of each result against the exact offset surface
(|exact signed distance to the mesh - distance|, in voxels: p95 and max), and the volume.

Part ``sweep``: ``engine.redistance`` with each ``method`` (``"sweep"``: fast sweeping on the dense top level, the FIM
on the sparse ones; ``"diagonal"``: Museth's sort-key sweeps on every level; ``"fim"``: the build's fast iterative
method) on a smooth union of two spheres (blend 0.1 of the diagonal) and on (spot | fandisk) - sphere at diagonal /
256, the second also with 3 and 2 levels (a larger dense top level), in rotating order: seconds of the whole
re-distancing and of its coarse levels, sweeps on the top level, and the accuracy against the exact distance to the
field's own surface (the same for all: a bounded BVH query makes every leaf exact after any).

    .venv/bin/python bench/offset.py [--parts offset sweep] [--resolution 256] [--repeat 3] [--slow 60]
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
os.environ.setdefault("WARP_CACHE_PATH", str(ROOT / ".warp-cache"))

import warp as wp  # noqa: E402

import engine  # noqa: E402
from bench.paired import paired, round_ratios  # noqa: E402
from tests.metrics import exact_sdf, mesh_volume  # noqa: E402
from tests.support import load_mesh, uv_sphere  # noqa: E402

OFFSETS = (2, 8, 32, -8)


def _diagonal(*meshes) -> float:
    verts = np.concatenate([m[0] for m in meshes])
    return float(np.linalg.norm(verts.max(0) - verts.min(0)))


def _surface_error(mesh, verts, distance: float, voxel: float) -> dict:
    """p95 and max (voxels) of |exact signed distance to ``mesh`` - ``distance``| at the result's vertices."""
    if len(verts) == 0:
        return {"p95": float("nan"), "max": float("nan")}
    err = np.abs(exact_sdf(*mesh, verts).astype(np.float64) - distance) / voxel
    return {"p95": float(np.percentile(err, 95)), "max": float(err.max())}


def aasdf_offset(mesh, voxel: float, distance: float) -> dict:
    t0 = time.perf_counter()
    field = engine.build_field(*mesh, voxel_size=voxel)
    t1 = time.perf_counter()
    grown = engine.offset(field, distance)
    t2 = time.perf_counter()
    verts, tris = grown.to_mesh()
    t3 = time.perf_counter()
    return {
        "seconds": t3 - t0,
        "stages": {"build": t1 - t0, "offset": t2 - t1, "to_mesh": t3 - t2},
        "verts": verts,
        "tris": tris,
        "nodes": grown.node_count,
    }


def offset_part(resolution: int, repeat: int, slow: float, offsets=OFFSETS, gn_max: int = 1 << 30) -> None:
    import bpy

    from bench import baselines  # needs bpy

    bpy.ops.wm.read_homefile(use_empty=True)
    spot = load_mesh("spot.obj")
    voxel = _diagonal(spot) / resolution
    print(f"\n### Offset: spot, voxel = diagonal / {resolution} = {voxel:.5f}; {repeat} alternating rounds")
    print("| offset (voxels) | AASDF s (build + offset + mesh) | GN s (band) | AASDF / GN | AASDF err p95 / max "
          "(voxels) | GN err p95 / max | AASDF volume | GN volume |")  # fmt: skip
    print("|---|---|---|---|---|---|---|---|")
    for k in offsets:
        d = k * voxel
        ours = lambda d=d: aasdf_offset(spot, voxel, d)  # noqa: E731
        theirs = lambda d=d: baselines.gn_sdf_offset(spot, voxel, d)  # noqa: E731
        ours()  # warm-up
        if abs(k) > gn_max:  # AASDF alone (GN's time for it measured in another run)
            runs = [ours() for _ in range(repeat)]
            run_ours = sorted(runs, key=lambda r: r["seconds"])[len(runs) // 2]
            e_ours = _surface_error(spot, run_ours["verts"], d, voxel)
            stages = ", ".join(f"{name} {s:.2f}" for name, s in run_ours["stages"].items())
            print(
                f"| {k:+d} | {run_ours['seconds']:.3f} ({stages}) | — | — | {e_ours['p95']:.3f} / {e_ours['max']:.3f} "
                f"| — | {mesh_volume(run_ours['verts'], run_ours['tris']):.5f} | — |",
                flush=True,
            )
            continue
        first = theirs()
        if first["seconds"] > slow:  # too slow to repeat: one run, beside AASDF's median
            runs = [ours() for _ in range(repeat)]
            run_ours = sorted(runs, key=lambda r: r["seconds"])[len(runs) // 2]
            run_theirs = first
            ratio = f"{run_ours['seconds'] / run_theirs['seconds']:.3f} (GN once)"
        else:
            result = paired(ours, theirs, repeat, warm_up=False)
            run_ours, run_theirs = result["ours"], result["theirs"]
            ratio = f"{result['ratio']:.3f} ({result['low']:.3f}-{result['high']:.3f})"
        e_ours = _surface_error(spot, run_ours["verts"], d, voxel)
        e_theirs = _surface_error(spot, run_theirs["verts"], d, voxel)
        stages = ", ".join(f"{name} {s:.2f}" for name, s in run_ours["stages"].items())
        print(
            f"| {k:+d} | {run_ours['seconds']:.3f} ({stages}) | {run_theirs['seconds']:.3f} "
            f"({run_theirs['band_width']}) | {ratio} | {e_ours['p95']:.3f} / {e_ours['max']:.3f} | "
            f"{e_theirs['p95']:.3f} / {e_theirs['max']:.3f} | {mesh_volume(run_ours['verts'], run_ours['tris']):.5f} | "
            f"{mesh_volume(run_theirs['verts'], run_theirs['tris']):.5f} |",
            flush=True,
        )


# ---- sweeping against the fast iterative method ----


def sweep_cases(resolution: int) -> dict:
    a = uv_sphere(1.0, rings=96, segments=192)
    b = uv_sphere(1.0, center=(1.0, 0.2, 0.1), rings=96, segments=192)
    spot, fan = load_mesh("spot.obj"), load_mesh("fandisk.obj")
    size, own = _diagonal(spot), _diagonal(fan)
    centre = spot[0].mean(0)
    fan = (((fan[0] - fan[0].mean(0)) * (0.8 * size / own) + centre + np.float32([0.15, 0.1, 0.0]) * size), fan[1])
    fan = (fan[0].astype(np.float32), fan[1])
    ball = uv_sphere(0.3 * size, center=centre + np.float32([0.0, 0.15, 0.2]) * size)

    def blend():
        diag = _diagonal(a, b)
        fa, fb = engine.build_fields([a, b], voxel_size=diag / resolution)
        return engine.union(fa, fb, blend=0.1 * diag)

    def meshes(levels):
        def make():
            h = _diagonal(spot, fan, ball) / resolution
            fa, fb, fc = engine.build_fields([spot, fan, ball], voxel_size=h, levels=levels)
            return engine.difference(engine.union(fa, fb), fc)

        return make

    return {
        "two spheres, round blend 0.1 diag": blend,
        "(spot | fandisk) - sphere": meshes(4),
        "(spot | fandisk) - sphere, 3 levels": meshes(3),
        "(spot | fandisk) - sphere, 2 levels": meshes(2),
    }


def _accuracy(field) -> dict:
    h = field.voxel_size
    verts, tris = field.to_mesh()
    rng = np.random.default_rng(1)
    uniform = rng.uniform(*field.bounds, (40_000, 3))
    face = rng.integers(0, len(tris), 20_000)
    bary = rng.dirichlet([1.0, 1.0, 1.0], 20_000)
    near = (verts[tris[face]] * bary[:, :, None]).sum(axis=1) + rng.normal(0.0, h, (20_000, 3))
    points = np.concatenate([uniform, near]).astype(np.float32)
    exact = exact_sdf(verts, tris, points).astype(np.float64)
    got, grad = field.sample(points, return_gradient=True)
    err = np.abs(got - exact)
    band, far = np.abs(exact) < 2 * h, np.abs(exact) > 8 * h
    return {
        "band_p99": float(np.percentile(err[band], 99) / h),
        "far_p95": float(np.percentile(err[far] / np.abs(exact[far]), 95)),
        "grad_p95": float(np.percentile(np.abs(np.linalg.norm(grad[: len(uniform)], axis=1) - 1.0), 95)),
    }


def _levels_seconds(field) -> float:
    return sum(v for k, v in field.timings.items() if k.startswith(("level_", "top_level")))


METHODS = ("sweep", "diagonal", "fim")


def sweep_part(resolution: int, repeat: int) -> None:
    print(f"\n### Re-distancing: the coarse levels' solvers, diagonal / {resolution}; {repeat} rounds, order rotating")
    print(
        "sweep: the dense top level by fast sweeping (8 diagonal orderings), the sparse levels by the FIM (the "
        "default); diagonal: Museth's sort-key sweeps on every level; fim: the build's FIM. Seconds: medians "
        "(coarse levels: propagation + the BVH queries that make them exact); ratios: medians of per-round ratios "
        "to fim.\n"
    )
    print(
        "| case | nodes per level | sweep s (coarse) | diagonal s (coarse) | fim s (coarse) | sweep / fim (coarse) "
        "| diagonal / fim (coarse) | top-level sweeps s / d / f | before: band p99, far p95, grad p95 | after |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|")
    for name, make in sweep_cases(resolution).items():
        field = make()
        runs = {m: [] for m in METHODS}
        for rnd in range(repeat + 1):  # the first round warms up
            order = METHODS[rnd % 3 :] + METHODS[: rnd % 3]
            for method in order:
                wp.synchronize()
                t0 = time.perf_counter()
                result = engine.redistance(field, method=method)
                wp.synchronize()
                if rnd:
                    runs[method].append((time.perf_counter() - t0, _levels_seconds(result), result))
        med = {m: (statistics.median(r[0] for r in runs[m]), statistics.median(r[1] for r in runs[m])) for m in METHODS}

        def ratio(m, k, runs=runs):
            value, low, high = round_ratios([r[k] for r in runs[m]], [r[k] for r in runs["fim"]])
            return f"{value:.2f} ({low:.2f}-{high:.2f})"

        last = {m: runs[m][-1][2] for m in METHODS}
        top = field.levels - 1
        sweeps = " / ".join(str(last[m].stats["sweeps"].get(top, 0)) for m in METHODS)
        before, after = _accuracy(field), _accuracy(last["sweep"])
        fmt = lambda e: f"{e['band_p99']:.3f} vox, {100 * e['far_p95']:.2f} %, {100 * e['grad_p95']:.2f} %"  # noqa: E731
        cells = " | ".join(f"{med[m][0]:.3f} ({med[m][1]:.3f})" for m in METHODS)
        print(
            f"| {name} | {last['sweep'].level_counts} | {cells} | {ratio('sweep', 0)} ({ratio('sweep', 1)}) | "
            f"{ratio('diagonal', 0)} ({ratio('diagonal', 1)}) | {sweeps} | {fmt(before)} | {fmt(after)} |",
            flush=True,
        )


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--parts", nargs="+", default=["offset", "sweep"], choices=["offset", "sweep"])
    parser.add_argument("--resolution", type=int, default=256)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--slow", type=float, default=60.0, help="run a slower geometry-nodes offset once")
    parser.add_argument("--offsets", nargs="+", type=int, default=list(OFFSETS), help="offsets in voxels")
    parser.add_argument("--gn-max", type=int, default=1 << 30, help="larger offsets (voxels): AASDF alone")
    args = parser.parse_args(argv)
    wp.config.quiet = True
    wp.init()
    print(f"Warp {wp.config.version} on {wp.get_device()}; timings are indicative (shared 2-core machine)")
    if "sweep" in args.parts:
        sweep_part(args.resolution, args.repeat)
    if "offset" in args.parts:
        offset_part(args.resolution, args.repeat, args.slow, args.offsets, args.gn_max)


if __name__ == "__main__":
    main()
