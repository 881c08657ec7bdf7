"""Scaling and memory: time against resolution and triangle count, and peak memory against Blender's SDF pipeline.

Each measurement runs in a fresh process (so its peak resident memory is its own): a union of two overlapping copies
of a mesh, through AASDF's whole pipeline and through the geometry-nodes SDF pipeline at the same voxel size; each
process runs it once to warm up (kernels, node tree) and then once timed. The two methods' processes run in turns,
``--repeat`` rounds (default 3), AASDF first in even rounds and GN first in odd ones (``bench/paired.py``): the run
of median time gives the time and the peak, the ratio is the median of the rounds' ratios (smallest and largest in
brackets).

- vs resolution: spot ∪ spot(+0.3 x) at diagonal / 128, 256, 512, 1024;
- vs triangles at diagonal / 256: UV spheres of about 5 k, 80 k and 1 M triangles, and the Stanford bunny (69 k).

    .venv/bin/python bench/scaling.py [--repeat 3]
"""

from __future__ import annotations

import argparse
import functools
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench.child import run_child  # noqa: E402
from bench.paired import paired  # noqa: E402

CHILD = r"""
import json, resource, sys, time
sys.path.insert(0, sys.argv[1])
method, case, res = sys.argv[2], sys.argv[3], int(sys.argv[4])
import numpy as np
from tests.support import load_mesh, uv_sphere
if case == "spot":
    a = load_mesh("spot.obj")
elif case == "bunny":
    a = load_mesh("stanford-bunny.obj")
else:
    rings = int(case.split(":")[1])
    a = uv_sphere(1.0, rings=rings, segments=2 * rings)
b = (a[0] + np.float32([0.3 * float(np.linalg.norm(a[0].max(0) - a[0].min(0))), 0, 0]), a[1])
pts = np.vstack([a[0], b[0]])
h = float(np.linalg.norm(pts.max(0) - pts.min(0))) / res
if method == "aasdf":
    import warp as wp
    wp.config.quiet = True
    import engine

    def run():
        t0 = time.perf_counter()
        fa, fb = engine.build_fields([a, b], voxel_size=h)  # at the same time, as the add-on does
        verts, tris = engine.union(fa, fb).to_mesh()
        return time.perf_counter() - t0, tris, fa.node_count + fb.node_count
else:
    from bench import baselines

    def run():
        r = baselines.gn_sdf_boolean(a, b, "UNION", h)
        return r["seconds"], r["tris"], 0
run()  # warm-up: kernels loaded, node tree set up
seconds, tris, nodes = run()
print("RESULT " + json.dumps({"seconds": seconds, "triangles": int(len(tris)), "input_triangles": int(len(a[1])),
                               "rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, "nodes": nodes}))
"""


def measure(method: str, case: str, res: int) -> dict:
    return run_child(CHILD, method, case, res)


def row(label: str, case: str, res: int, repeat: int) -> None:
    pair = paired(
        functools.partial(measure, "aasdf", case, res),
        functools.partial(measure, "gn", case, res),
        repeat,
        warm_up=False,
    )
    ours, gn = pair["ours"], pair["theirs"]
    print(
        f"| {label} | {ours['input_triangles']:,} | /{res} | {ours['seconds']:.2f} | {gn['seconds']:.2f} "
        f"| {pair['ratio']:.2f}x ({pair['low']:.2f}-{pair['high']:.2f}) | {ours['nodes']:,} | {ours['rss_mb']:.0f} "
        f"| {gn['rss_mb']:.0f} |"
    )
    sys.stdout.flush()


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3)
    repeat = parser.parse_args(argv).repeat
    print(
        "# Scaling — union of a mesh and a shifted copy, fresh process per measurement (peak RSS is the process's), "
        f"AASDF and GN processes in {repeat} alternating rounds\n"
    )
    print(
        "| case | triangles (each) | res | AASDF s | GN SDF s | ratio | AASDF field nodes | AASDF peak MB "
        "| GN peak MB |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    for res in (128, 256, 512, 1024):
        row("spot ∪ spot", "spot", res, repeat)
    for rings in (48, 200, 700):
        row("sphere ∪ sphere", f"sphere:{rings}", 256, repeat)
    row("bunny ∪ bunny", "bunny", 256, repeat)


if __name__ == "__main__":
    main()
