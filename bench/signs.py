"""Signs benchmark: inside and outside against the exact winding number, and build time, before and after.

For each test mesh (``../shared/meshes``) and finest spacing (bounding-box diagonal / 256 and / 512) it builds the
field with this checkout's engine and with an earlier one (``--before``, a checkout of another commit, e.g. ``git
worktree add /tmp/signs-before ca3f939``, imported as its own package), in alternating rounds (``bench/paired.py``:
median times, the median of the per-round ratios and its range), and measures each field's ``sample`` on a point set:
half uniform in the mesh's bounding box grown by 5 % of its diagonal on every side, half near the surface (area-
weighted surface samples moved by normal noise of one voxel and of four). The reference is the exact distance to the
triangles, negative where the exact winding number (``tests.metrics.winding_numbers``: every triangle's solid angle,
float64) is at least 1/2 in absolute value; it costs points x triangles, so large meshes get fewer points
(``--work``). Columns: sign agreement on points farther than 2 voxels from the surface, the far field's p95 relative
error (farther than 4 voxels), the near surface's p99 error in voxels (within 1 voxel), build seconds. Timings on this
shared machine drift: they are indicative.

    .venv/bin/python bench/signs.py [--before /tmp/signs-before] [--meshes beetle.obj ...] [--resolutions 256 512]
                                    [--repeat 3] [--work 4e8]
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
os.environ.setdefault("WARP_CACHE_PATH", str(ROOT / ".warp-cache"))

import warp as wp  # noqa: E402

import engine  # noqa: E402
from bench.paired import paired  # noqa: E402
from tests.metrics import unsigned_distance, winding_numbers  # noqa: E402
from tests.support import SHARED_MESHES, load_mesh, sample_points  # noqa: E402

MAX_POINTS = 20_000


def load_engine(root: Path, name: str = "engine_before"):
    """The ``engine`` package of another checkout, imported as ``name`` (its Warp modules get their own names)."""
    init = root / "engine" / "__init__.py"
    if not init.exists():
        raise SystemExit(f"No engine at {root}: make one with `git worktree add {root} <commit>`.")
    spec = importlib.util.spec_from_file_location(name, init, submodule_search_locations=[str(init.parent)])
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module


def accuracy(field, points, dist, inside) -> dict:
    """Sign agreement beyond 2 voxels, far-field p95 relative error, near-surface p99 error in voxels."""
    h = field.voxel_size
    exact = np.where(inside, -dist, dist)
    got = field.sample(points).astype(np.float64)
    err = np.abs(got - exact)
    beyond, far, near = dist > 2.0 * h, dist > 4.0 * h, dist < h
    return {
        "sign": float(np.mean((got[beyond] < 0.0) == inside[beyond])),
        "far_p95": float(np.percentile(err[far] / dist[far], 95)),
        "near_p99": float(np.percentile(err[near], 99) / h),
    }


def timed(eng, verts, tris, h: float, keep: dict, key: str):
    def run():
        t0 = time.perf_counter()
        field = eng.build_field(verts, tris, voxel_size=h)
        seconds = time.perf_counter() - t0
        keep[key] = field
        return {"seconds": seconds}

    return run


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--before", type=Path, default=Path("/tmp/signs-before"))
    parser.add_argument("--meshes", nargs="*", default=sorted(p.name for p in SHARED_MESHES.glob("*.obj")))
    parser.add_argument("--resolutions", nargs="*", type=int, default=[256, 512])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--work", type=float, default=4e8, help="most point-triangle pairs of exact winding numbers")
    args = parser.parse_args()
    wp.config.quiet = True
    before = load_engine(args.before)
    print(f"machine: {os.cpu_count()} cores, warp {wp.__version__} on cpu; before = {args.before}; times indicative")
    print()
    print(
        "| mesh | res | points | sign before | sign after | far p95 before | far p95 after | near p99 before (vox) "
        "| near p99 after (vox) | build before (s) | build after (s) | after / before (range) |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for name in args.meshes:
        verts, tris = load_mesh(name)
        diag = float(np.linalg.norm(verts.max(axis=0) - verts.min(axis=0)))
        for res in args.resolutions:
            h = diag / res
            n = int(min(MAX_POINTS, args.work / len(tris)))
            points = sample_points(verts, tris, h, n)
            dist = unsigned_distance(verts, tris, points).astype(np.float64)
            inside = np.abs(winding_numbers(verts, tris, points)) >= 0.5
            fields = {}
            run = paired(
                timed(engine, verts, tris, h, fields, "after"),
                timed(before, verts, tris, h, fields, "before"),
                args.repeat,
            )
            old = accuracy(fields["before"], points, dist, inside)
            new = accuracy(fields["after"], points, dist, inside)
            print(
                f"| {name} | /{res} | {n} | {100 * old['sign']:.2f} % | {100 * new['sign']:.2f} % "
                f"| {100 * old['far_p95']:.1f} % | {100 * new['far_p95']:.1f} % "
                f"| {old['near_p99']:.2f} | {new['near_p99']:.2f} "
                f"| {run['theirs']['seconds']:.3f} | {run['ours']['seconds']:.3f} "
                f"| {run['ratio']:.2f} ({run['low']:.2f}-{run['high']:.2f}) |",
                flush=True,
            )


if __name__ == "__main__":
    main()
