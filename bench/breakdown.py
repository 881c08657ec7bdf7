"""Where the time and the memory go: one boolean profiled stage by stage, next to Blender's SDF pipeline.

The case is the scaling benchmark's: spot ∪ spot shifted by 0.3 of its diagonal, voxel = combined diagonal / 512 (and
/ 256 with ``--resolutions``). Each side runs in a fresh process of its own:

- AASDF: after a warm-up at a coarse voxel size (kernels loaded), three runs of the whole pipeline; the wall seconds
  of building both operands (at the same time, as the add-on does: ``build_fields``), and for each stage of
  ``build_field`` (the two builds' own wall seconds added up: they overlap), of the boolean and of ``to_mesh`` the
  median wall seconds, and for the first run
  the resident memory after each step and its peak within the step (sampled every 2 ms), with the bytes each field
  stores per node.
- GN (Mesh to SDF Grid ×2 → SDF Grid Boolean → Grid to Mesh): after a warm-up, three runs; median seconds (and the
  node tree's own execution time), resident memory before and the peak during the first run.

Both start from the same Python + numpy; the runtime each needs (Warp's library and kernels, Blender as a module) is
shown as its own row, so what the data costs can be told apart from what loading the runtime costs.

    .venv/bin/python bench/breakdown.py [--resolutions 512] [--repeat 3]
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.child import run_child  # noqa: E402

COMMON = r"""
import json, statistics, sys, threading, time
sys.path.insert(0, sys.argv[1])
res, repeat = int(sys.argv[2]), int(sys.argv[3])
import numpy as np
from tests.support import load_mesh


def rss_mb():
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * 4096 / 2**20


class Peak:
    # Highest resident memory while the block runs (a thread samples it every 2 ms).
    def __enter__(self):
        self.top, self.running = rss_mb(), True
        self.thread = threading.Thread(target=self.sample, daemon=True)
        self.thread.start()
        return self

    def sample(self):
        while self.running:
            self.top = max(self.top, rss_mb())
            time.sleep(0.002)

    def __exit__(self, *exc):
        self.running = False
        self.thread.join()
        self.top = max(self.top, rss_mb())


a = load_mesh("spot.obj")
b = (a[0] + np.float32([0.3 * float(np.linalg.norm(a[0].max(0) - a[0].min(0))), 0, 0]), a[1])
pts = np.vstack([a[0], b[0]])
h = float(np.linalg.norm(pts.max(0) - pts.min(0))) / res
out = {"base": rss_mb()}
"""

AASDF = r"""
import warp as wp
wp.config.quiet = True
import engine
fa, fb = engine.build_fields([a, b], voxel_size=4 * h)
engine.union(fa, fb).to_mesh()
del fa, fb
out["runtime"] = rss_mb()
steps, stages, walls = [], [], []
for run in range(repeat):
    t_start = time.perf_counter()
    times = {}
    record = []
    t0 = time.perf_counter()
    with Peak() as p:
        fa, fb = engine.build_fields([a, b], voxel_size=h)  # at the same time, as the add-on does
    times["builds a and b (at the same time)"] = time.perf_counter() - t0
    record.append(("build a and b", rss_mb(), p.top))
    with Peak() as p:
        c = engine.union(fa, fb)
    record.append(("boolean", rss_mb(), p.top))
    t0 = time.perf_counter()
    with Peak() as p:
        verts, tris = c.to_mesh()
    times["to_mesh"] = time.perf_counter() - t0
    record.append(("to_mesh", rss_mb(), p.top))
    walls.append(time.perf_counter() - t_start)
    for name, f in (("build", fa), ("build", fb), ("boolean", c)):
        for k, v in f.timings.items():
            times[f"{name}: {k}"] = times.get(f"{name}: {k}", 0.0) + v
    stages.append(times)
    if run == 0:
        steps = record
        arrays = (c.codes, c.values, c.proj, c.child, c.source, c.tri)
        out["bytes_per_node"] = sum(x.capacity for x in arrays if x is not None) / c.node_count
        out["nodes"] = {"a": fa.node_count, "b": fb.node_count, "result": c.node_count}
        out["triangles"] = int(len(tris))
    del fa, fb, c, verts, tris
out["seconds"] = statistics.median(walls)
out["stages"] = {k: statistics.median(s.get(k, 0.0) for s in stages) for k in stages[0]}
out["steps"] = steps
print("RESULT " + json.dumps(out))
"""

GN = r"""
import bpy
from bench import baselines
baselines.gn_sdf_boolean(a, b, "UNION", 4 * h)
out["runtime"] = rss_mb()
seconds, modifier = [], []
for run in range(repeat):
    with Peak() as p:
        r = baselines.gn_sdf_boolean(a, b, "UNION", h)
    seconds.append(r["seconds"])
    modifier.append(r["stage_seconds"]["modifier"])
    if run == 0:
        out["steps"] = [("whole pipeline", rss_mb(), p.top)]
        out["triangles"] = int(len(r["tris"]))
out["seconds"] = statistics.median(seconds)
out["modifier_seconds"] = statistics.median(modifier)
print("RESULT " + json.dumps(out))
"""


def child(script: str, res: int, repeat: int) -> dict:
    return run_child(COMMON + script, res, repeat)


def report(res: int, repeat: int) -> None:
    ours, gn = child(AASDF, res, repeat), child(GN, res, repeat)
    total = ours["seconds"]
    print(
        f"\n## spot ∪ spot at /{res}: AASDF {total:.2f} s, GN SDF pipeline {gn['seconds']:.2f} s "
        f"(node tree {gn['modifier_seconds']:.2f} s), ratio {total / gn['seconds']:.2f}x\n"
    )
    print("| AASDF stage (wall s, median; split kernels use both cores) | s | share |")
    print("|---|---|---|")
    for name, seconds in sorted(ours["stages"].items(), key=lambda kv: -kv[1]):
        if seconds >= 0.005:
            print(f"| {name} | {seconds:.3f} | {100 * seconds / total:.0f} % |")
    print(
        f"\nNodes: {ours['nodes']['a']:,} + {ours['nodes']['b']:,} operands, {ours['nodes']['result']:,} result; "
        f"{ours['bytes_per_node']:.0f} bytes stored per node; {ours['triangles']:,} triangles "
        f"(GN {gn['triangles']:,}).\n"
    )
    print("| resident memory (MB) | AASDF after | AASDF peak within | GN after | GN peak within |")
    print("|---|---|---|---|---|")
    print(f"| Python + numpy + meshes | {ours['base']:.0f} | | {gn['base']:.0f} | |")
    print(f"| runtime loaded (Warp + kernels / bpy) | {ours['runtime']:.0f} | | {gn['runtime']:.0f} | |")
    rows = max(len(ours["steps"]), len(gn["steps"]))
    for i in range(rows):
        left = ours["steps"][i] if i < len(ours["steps"]) else None
        right = gn["steps"][i] if i < len(gn["steps"]) else None
        cells = [
            f"{left[1]:.0f} | {left[2]:.0f}" if left else " | ",
            f"{right[1]:.0f} | {right[2]:.0f}" if right else " | ",
        ]
        label = (left[0] if left else "") + (f" / GN {right[0]}" if right else "")
        print(f"| {label} | {cells[0]} | {cells[1]} |")
    peak_ours = max(s[2] for s in ours["steps"])
    peak_gn = max(s[2] for s in gn["steps"])
    print(
        f"\nPeak: AASDF {peak_ours:.0f} MB ({peak_ours - ours['runtime']:.0f} MB above its runtime), "
        f"GN {peak_gn:.0f} MB ({peak_gn - gn['runtime']:.0f} MB above its runtime)."
    )
    sys.stdout.flush()


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--resolutions", type=int, nargs="+", default=[512])
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args(argv)
    print(
        f"# Breakdown — {platform.processor() or platform.machine()}, {os.cpu_count()} cores; medians of "
        f"{args.repeat} runs after a warm-up, each side in a fresh process"
    )
    for res in args.resolutions:
        report(res, args.repeat)


if __name__ == "__main__":
    main()
