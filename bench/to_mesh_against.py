"""``to_mesh`` time of this checkout (sharp surfaces by default) against another checkout's ``to_mesh`` on the same
fields, each side in a worker process of its own, in alternating rounds.

The cases are the CAD-like pairs of ``tests.support.cad_pairs`` (their boolean at voxel 1/256) and single meshes
(``name.obj``, normalised to diagonal 1, voxel 1/256). Each worker builds the case's field once with its own engine,
extracts once to warm up, then times one extraction per request. The ratio is the median of the rounds' ratios (ours
first in even rounds, theirs first in odd ones), with the smallest and largest. Timings drift on a shared machine:
they are indicative.

With ``--adaptivity A`` this checkout extracts ``to_mesh(quads=True, adaptivity=A)`` and the other its plain
``to_mesh()``: what an adaptivity costs against the extraction of another commit (issue #38 counts from the one it was
filed at, 7c6829f).

    git worktree add /tmp/before <commit>
    .venv/bin/python bench/to_mesh_against.py --before /tmp/before [--repeat 9] [--cases "cube - bore" spot.obj ...]
    .venv/bin/python bench/to_mesh_against.py --before /tmp/before --adaptivity 0.5 --cases "plate - 4 bores"
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
    import numpy as np
    import warp as wp

    wp.config.quiet = True
    wp.config.kernel_cache_dir = cache
    import engine

    sys.path.insert(0, str(ROOT))  # this checkout's test shapes (engine imported already): both sides use the same
    from tests.support import cad_pairs, load_mesh, normalised, plate_and_bores

    ops = {"UNION": engine.union, "INTERSECT": engine.intersection, "DIFFERENCE": engine.difference}
    h = 1.0 / 256
    ours = Path(root).resolve() == ROOT
    fields = {}
    for line in sys.stdin:
        name, _, adaptivity = line.strip().partition("@")
        options = {"quads": True, "adaptivity": float(adaptivity)} if adaptivity and ours else {}
        if name not in fields:
            if name.endswith(".obj"):
                fields[name] = engine.build_field(*normalised(load_mesh(name)), voxel_size=h)
            else:
                op, a, b = {**cad_pairs(), "plate - 4 bores": ("DIFFERENCE", *plate_and_bores())}[name]
                corners = np.concatenate([a[0], b[0]])  # the plate at its own diagonal / 256, as bench/adaptivity.py
                voxel = h if name in cad_pairs() else float(np.linalg.norm(np.ptp(corners, axis=0))) / 256
                pair = (engine.build_field(*a, voxel_size=voxel), engine.build_field(*b, voxel_size=voxel))
                fields[name] = ops[op](*pair)
            fields[name].to_mesh(**options)
        start = time.perf_counter()
        mesh = fields[name].to_mesh(**options)
        seconds = time.perf_counter() - start
        print("@@" + json.dumps({"seconds": seconds, "triangles": len(mesh[-1])}), flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--worker", nargs=2, help=argparse.SUPPRESS)
    parser.add_argument("--before", type=Path, help="the other checkout")
    parser.add_argument("--repeat", type=int, default=9)
    parser.add_argument("--adaptivity", type=float, help="this checkout's polygons at this adaptivity")
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
        request = name if args.adaptivity is None else f"{name}@{args.adaptivity}"
        after, before = alternate(ours, theirs, request, args.repeat)
        ratio, low, high = round_ratios([r["seconds"] for r in after], [r["seconds"] for r in before])
        label = name.replace("|", "\\|")
        print(
            f"| {label} | {after[0]['triangles']:,} | {statistics.median(r['seconds'] for r in after):.3f} "
            f"| {statistics.median(r['seconds'] for r in before):.3f} | {ratio:.2f}x ({low:.2f}-{high:.2f}) |",
            flush=True,
        )


if __name__ == "__main__":
    main()
