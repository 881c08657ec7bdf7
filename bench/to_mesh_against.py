"""``to_mesh`` time of this checkout (sharp surfaces by default) against another checkout's ``to_mesh`` on the same
fields, each side in a worker process of its own, in alternating rounds.

The cases are the CAD-like pairs of ``tests.support.cad_pairs`` (their boolean at voxel 1/256) and single meshes
(``name.obj``, normalised to diagonal 1, voxel 1/256). Each worker builds the case's field once with its own engine,
extracts once to warm up, then times one extraction per request. The ratio is the median of the rounds' ratios (ours
first in even rounds, theirs first in odd ones), with the smallest and largest. Timings drift on a shared machine:
they are indicative.

    git worktree add /tmp/before <commit>
    .venv/bin/python bench/to_mesh_against.py --before /tmp/before [--repeat 9] [--cases "cube - bore" spot.obj ...]
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
    """Extract the surfaces of the cases named on stdin with the engine at ``root``; one JSON line (``@@``) each."""
    sys.path.insert(0, root)
    os.environ["WARP_CACHE_PATH"] = cache
    import warp as wp

    wp.config.quiet = True
    wp.config.kernel_cache_dir = cache
    import engine

    sys.path.insert(0, str(ROOT))  # this checkout's test shapes (engine imported already): both sides use the same
    from tests.support import cad_pairs, load_mesh, normalised

    ops = {"UNION": engine.union, "INTERSECT": engine.intersection, "DIFFERENCE": engine.difference}
    h = 1.0 / 256
    fields = {}
    for line in sys.stdin:
        name = line.strip()
        if name not in fields:
            if name.endswith(".obj"):
                fields[name] = engine.build_field(*normalised(load_mesh(name)), voxel_size=h)
            else:
                op, a, b = cad_pairs()[name]
                fields[name] = ops[op](engine.build_field(*a, voxel_size=h), engine.build_field(*b, voxel_size=h))
            fields[name].to_mesh()
        start = time.perf_counter()
        _verts, tris = fields[name].to_mesh()
        print("@@" + json.dumps({"seconds": time.perf_counter() - start, "triangles": len(tris)}), flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--worker", nargs=2, help=argparse.SUPPRESS)
    parser.add_argument("--before", type=Path, help="the other checkout")
    parser.add_argument("--repeat", type=int, default=9)
    default_cases = ["fandisk - cylinder", "rocker-arm - cube", "cube | tilted cube", "cube - bore"]
    parser.add_argument("--cases", nargs="*", default=[*default_cases, "hex prism & sphere", "spot.obj"])
    args = parser.parse_args()
    if args.worker:
        worker(*args.worker)
        return
    if args.before is None:
        parser.error("--before is required")
    sys.path.insert(0, str(ROOT))
    from bench.child import against_workers, alternate
    from bench.paired import round_ratios

    ours, theirs = against_workers(__file__, args.before)
    print(f"{os.cpu_count()} cores; before = {args.before}; {args.repeat} alternating rounds; times indicative\n")
    print("| case | triangles after | after s | before s | after / before |")
    print("|---|---|---|---|---|")
    for name in args.cases:
        after, before = alternate(ours, theirs, name, args.repeat)
        ratio, low, high = round_ratios([r["seconds"] for r in after], [r["seconds"] for r in before])
        label = name.replace("|", "\\|")
        print(
            f"| {label} | {after[0]['triangles']:,} | {statistics.median(r['seconds'] for r in after):.3f} "
            f"| {statistics.median(r['seconds'] for r in before):.3f} | {ratio:.2f}x ({low:.2f}-{high:.2f}) |",
            flush=True,
        )


if __name__ == "__main__":
    main()
