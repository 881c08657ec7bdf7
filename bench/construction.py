"""Construction benchmark: the adaptive field against Blender's Mesh to SDF Grid and a dense grid, side by side.

For each mesh and finest spacing (bounding-box diagonal / 256 and / 512) it prints, in one run: the build time of
each stage of ``engine.build_field`` (finest level, each intermediate level, top level, signs), node counts per
level, the geometry-nodes Mesh to SDF Grid node (OpenVDB, narrow band of 3 voxels) at the same voxel size, and a
dense uniform grid of exact signed distances over the same domain (its node count, and its time where it fits).
AASDF's build and Mesh to SDF Grid run in turns (``--repeat`` rounds, default 5, after a warm-up; see
``bench/paired.py``): their times are medians, the ratio is the median of the per-round ratios with the smallest and
largest beside it; the machine is noted in the header.

    .venv/bin/python bench/construction.py [--meshes stanford-bunny.obj spot.obj rocker-arm.obj] [--repeat 5]
"""

from __future__ import annotations

import argparse
import functools
import os
import platform
import sys
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
os.environ.setdefault("WARP_CACHE_PATH", str(ROOT / ".warp-cache"))

import warp as wp  # noqa: E402

import engine  # noqa: E402
from bench import baselines  # noqa: E402
from bench.paired import paired  # noqa: E402
from tests.metrics import unsigned_distance  # noqa: E402
from tests.support import load_mesh  # noqa: E402

DENSE_LIMIT = 40_000_000  # dense grids above this many voxels are counted, not built


def machine() -> str:
    return f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, warp {wp.__version__} on cpu"


def timed_build(verts, tris, h) -> dict:
    """One build, timed; keeps what the table prints of the field, not the field: holding every round's field (as
    no user and no GN run does) would make each next build's memory come fresh from the system."""
    t0 = time.perf_counter()
    field = engine.build_field(verts, tris, voxel_size=h)
    seconds = time.perf_counter() - t0
    kept = ("timings", "level_counts", "node_count", "fine_dims", "bounds", "voxel_size")
    return {"seconds": seconds, "field": SimpleNamespace(**{k: getattr(field, k) for k in kept})}


def dense_grid_seconds(field, verts, tris):
    """Exact unsigned distances on every finest voxel of the domain (chunked), or None when it is too large."""
    dims = field.fine_dims
    n = int(np.prod(dims))
    if n > DENSE_LIMIT:
        return None
    lo = field.bounds[0]
    t0 = time.perf_counter()
    axes = [lo[a] + (np.arange(dims[a]) + 0.5) * field.voxel_size for a in range(3)]
    step = max(1, int(4_000_000 // (dims[1] * dims[2])))
    for x0 in range(0, dims[0], step):
        grid = np.stack(np.meshgrid(axes[0][x0 : x0 + step], axes[1], axes[2], indexing="ij"), -1).reshape(-1, 3)
        unsigned_distance(verts, tris, grid.astype(np.float32))
    return time.perf_counter() - t0


def run(meshes, resolutions, repeat):
    print(f"# Construction benchmark — {machine()}; AASDF and GN in {repeat} alternating rounds after a warm-up\n")
    header = (
        "| mesh | tris | res | voxel | AASDF build s | finest s | levels s | top s | neighbours s | signs s "
        "| nodes per level "
        "| nodes | uniform voxels | ratio | GN Mesh to SDF s | AASDF / GN | dense grid s |"
    )
    print(header)
    print("|" + "|".join(["---"] * (header.count("|") - 1)) + "|")
    for name in meshes:
        verts, tris = load_mesh(name)
        diag = float(np.linalg.norm(verts.max(0) - verts.min(0)))
        for res in resolutions:
            h = diag / res
            pair = paired(
                functools.partial(timed_build, verts, tris, h),
                functools.partial(baselines.gn_mesh_to_sdf, (verts, tris), h),
                repeat,
            )
            build_s, gn_s, field = pair["ours"]["seconds"], pair["theirs"]["seconds"], pair["ours"]["field"]
            t = field.timings  # the stages of the median run
            finest = sum(t.get(k, 0) for k in ("mesh_checks", "mesh_bvh", "finest_cells", "finest_distance"))
            levels = sum(v for k, v in t.items() if k.startswith("level_") and not k.endswith("neighbours"))
            levels += t.get("levels_structure", 0)
            neighbours = sum(v for k, v in t.items() if k.endswith("_neighbours"))
            signs = t.get("signs", 0) + t.get("sign_check", 0) + t.get("cap_lattices", 0)
            uniform = int(np.prod(field.fine_dims))
            dense = dense_grid_seconds(field, verts, tris) if res <= 256 else None
            dense_text = f"{dense:.2f}" if dense is not None else "—"
            print(
                f"| {name} | {len(tris):,} | /{res} | {h:.5f} | {build_s:.3f} | {finest:.3f} | {levels:.3f} "
                f"| {t.get('top_level', 0):.3f} | {neighbours:.3f} | {signs:.3f} | {field.level_counts} "
                f"| {field.node_count:,} | {uniform:,} | {uniform / field.node_count:.1f}x | {gn_s:.3f} "
                f"| {pair['ratio']:.2f}x ({pair['low']:.2f}-{pair['high']:.2f}) | {dense_text} |"
            )
            sys.stdout.flush()


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--meshes", nargs="+", default=["stanford-bunny.obj", "spot.obj", "rocker-arm.obj"])
    parser.add_argument("--resolutions", nargs="+", type=int, default=[256, 512])
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args(argv)
    wp.config.quiet = True
    run(args.meshes, args.resolutions, args.repeat)


if __name__ == "__main__":
    main()
