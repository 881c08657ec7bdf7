"""Build time of this checkout's engine against another checkout's (an earlier commit), each in a process of its own.

``git worktree add /tmp/before <commit>`` makes the other checkout; each side is a worker process importing its own
``engine`` (no shared Warp runtime, kernel caches apart) that builds a mesh's field on request. The two build in
alternating rounds after a warm-up (ours first in even rounds, theirs first in odd ones, see ``bench/paired.py``);
the table gives median seconds, the median of the per-round ratios with its range, the same for the process CPU time
(steadier than wall time when other work shares the machine), and the signs' stage (``signs`` + ``sign_check``).
Timings on a shared machine drift: they are indicative.

    .venv/bin/python bench/against.py --before /tmp/before [--after <checkout>] [--meshes beetle.obj ...]
                                      [--resolutions 256 512] [--repeat 5]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def worker(root: str, cache: str) -> None:
    """Build the fields requested on stdin (``mesh resolution`` lines) with the engine at ``root``; one JSON line
    (prefixed ``@@``) per build on stdout."""
    sys.path.insert(0, root)
    os.environ["WARP_CACHE_PATH"] = cache
    import numpy as np
    import warp as wp

    wp.config.quiet = True
    wp.config.kernel_cache_dir = cache
    import engine

    sys.path.insert(0, str(ROOT))
    from tests.support import load_mesh  # this checkout's loader: both sides read the same meshes

    meshes = {}
    for line in sys.stdin:
        name, res = line.split()
        if name not in meshes:
            meshes[name] = load_mesh(name)
        verts, tris = meshes[name]
        h = float(np.linalg.norm(verts.max(axis=0) - verts.min(axis=0))) / int(res)
        cpu, t0 = time.process_time(), time.perf_counter()
        field = engine.build_field(verts, tris, voxel_size=h)
        seconds, cpu = time.perf_counter() - t0, time.process_time() - cpu
        signs = field.timings.get("signs", 0.0) + field.timings.get("sign_check", 0.0)
        print("@@" + json.dumps({"seconds": seconds, "cpu": cpu, "signs": signs}), flush=True)
        del field


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--before", type=Path)
    parser.add_argument("--after", type=Path, default=ROOT, help="the checkout measured (default: this one)")
    parser.add_argument("--meshes", nargs="*", default=["beetle.obj"])
    parser.add_argument("--resolutions", nargs="*", type=int, default=[256, 512])
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--worker", nargs=2, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker:
        worker(*args.worker)
        return
    if args.before is None:
        parser.error("--before is required")
    sys.path.insert(0, str(ROOT))
    from bench.child import against_workers, alternate
    from bench.paired import round_ratios

    ours, theirs = against_workers(__file__, args.before, args.after)
    print(f"{os.cpu_count()} cores; {args.before} -> {args.after}; {args.repeat} alternating rounds; times indicative")
    print()
    print("| mesh | res | before s | after s | after / before | CPU after / before | signs before s | signs after s |")
    print("|---|---|---|---|---|---|---|---|")
    for name in args.meshes:
        for res in args.resolutions:
            runs = dict(zip(("ours", "theirs"), alternate(ours, theirs, f"{name} {res}", args.repeat), strict=True))
            wall = round_ratios(*([r["seconds"] for r in runs[s]] for s in ("ours", "theirs")))
            cpu = round_ratios(*([r["cpu"] for r in runs[s]] for s in ("ours", "theirs")))
            med = {s: {key: statistics.median(r[key] for r in runs[s]) for key in ("seconds", "signs")} for s in runs}
            print(
                f"| {name} | /{res} | {med['theirs']['seconds']:.3f} | {med['ours']['seconds']:.3f} "
                f"| {wall[0]:.2f} ({wall[1]:.2f}-{wall[2]:.2f}) | {cpu[0]:.2f} ({cpu[1]:.2f}-{cpu[2]:.2f}) "
                f"| {med['theirs']['signs']:.3f} | {med['ours']['signs']:.3f} |",
                flush=True,
            )
    ours.close()
    theirs.close()


if __name__ == "__main__":
    main()
