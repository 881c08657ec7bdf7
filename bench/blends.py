"""Wide blends: nodes, time and peak memory of two boxes of 0.8 united with round and chamfer blends at voxel 1/256.

Each case runs in a fresh process (its own peak resident memory): the two operand fields are built, then the union
(blended or not) and its surface; the peak is reported whole and above the process's resident size once the operands
are built (what the boolean and its surface add: the peak reset there, Linux's VmHWM). Prints a Markdown table.

    .venv/bin/python bench/blends.py [--voxel 256] [--blends 0.05 0.1 0.2]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.child import run_child  # noqa: E402

CASE = r"""
import json, resource, sys, time
sys.path.insert(0, sys.argv[1])
import engine
from tests.support import box_mesh, is_watertight, signed_volume
h, k, mode = 1.0 / float(sys.argv[2]), float(sys.argv[3]), sys.argv[4]
a = engine.build_field(*box_mesh(half=(0.4, 0.4, 0.4)), voxel_size=h)
b = engine.build_field(*box_mesh(half=(0.4, 0.4, 0.4), center=(0.4, 0.3, 0.2)), voxel_size=h)
def status(key):
    with open("/proc/self/status") as f:
        return next(int(line.split()[1]) for line in f if line.startswith(key)) / 1024
base = status("VmRSS")
with open("/proc/self/clear_refs", "w") as f:
    f.write("5")  # the peak (VmHWM) from here on
t = time.perf_counter()
r = engine.union(a, b, blend=k, blend_mode=mode)
verts, tris = r.to_mesh()
seconds = time.perf_counter() - t
peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
above = status("VmHWM") - base
print("RESULT " + json.dumps({"nodes": int(sum(r.level_counts)), "finest": int(r.level_counts[0]),
      "seconds": seconds, "peak": peak, "above": above, "volume": float(signed_volume(verts, tris)),
      "closed": bool(is_watertight(tris))}))
"""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--voxel", type=float, default=256.0, help="1 / voxel size")
    parser.add_argument("--blends", type=float, nargs="+", default=[0.05, 0.1, 0.2])
    args = parser.parse_args()
    run_child(CASE, args.voxel, 0.0, "round")  # compile first, outside the measurements
    hard = run_child(CASE, args.voxel, 0.0, "round")
    print("| blend | nodes (x hard) | finest | time s | peak MB (x hard) | above operands MB (x hard) | volume |")
    print("|---|---|---|---|---|---|---|")
    rows = [(0.0, "hard", hard)] + [
        (k, mode, run_child(CASE, args.voxel, k, mode)) for k in args.blends for mode in ("round", "chamfer")
    ]
    for k, mode, r in rows:
        closed = "" if r["closed"] else " (open)"
        print(
            f"| {k:g} {mode} | {r['nodes']:,} ({r['nodes'] / hard['nodes']:.2f}) | {r['finest']:,} | "
            f"{r['seconds']:.2f} | {r['peak']:.0f} ({r['peak'] / hard['peak']:.2f}) | "
            f"{r['above']:.0f} ({r['above'] / hard['above']:.2f}) | {r['volume']:.5f}{closed} |"
        )


if __name__ == "__main__":
    main()
