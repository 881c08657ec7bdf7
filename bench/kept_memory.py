"""Kept faces at fine voxels: time and peak memory in Blender, beside the geometry-nodes SDF pipeline.

Each measurement is a fresh ``bpy`` process (its peak resident memory its own): AASDF's ``aasdf.boolean`` union with
*Keep Original Faces* (the add-on registered, the field cache cleared before each run: the fields built, read to
write), or the SDF nodes' union at the same voxel size; each process runs once to warm up (kernels, node tree) and
then once timed. The two methods' processes run in turns, ``--repeat`` rounds; the ratio is the median of the rounds'
ratios (smallest and largest in brackets). Their fields are built on demand where their bands are large for their
triangles (their finest level only along the seams and about an open mesh's holes, ``engine/ondemand.py``):

- ``spot``: spot ∪ spot moved by 0.3 of its diagonal (5.8 k triangles each);
- ``ball``: a 100 k-triangle ball ∪ spot;
- ``bunny``: the open Stanford bunny (69 k triangles) ∪ spot, as ``bench/keep_faces.py`` places them.

    .venv/bin/python bench/kept_memory.py [--repeat 3] [--resolutions 512 1024] [--cases spot ball]
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
import json, os, resource, sys, time
root, method, res, case = sys.argv[1], sys.argv[2], int(sys.argv[3]), sys.argv[4]
sys.path.insert(0, root)
import numpy as np
import bpy
from bench import baselines
from tests.support import load_mesh, normalised, uv_sphere
if case == "spot":
    a = load_mesh("spot.obj")
    b = (a[0] + np.float32([0.3 * float(np.linalg.norm(a[0].max(0) - a[0].min(0))), 0, 0]), a[1])
elif case == "bunny":
    a = normalised(load_mesh("stanford-bunny.obj"), center=(0.25, 0.0, 0.0), diagonal=0.8)
    b = normalised(load_mesh("spot.obj"))
else:
    a = normalised(uv_sphere(1.0, rings=224, segments=224))
    b = normalised(load_mesh("spot.obj"), center=(0.3, 0.1, 0.0), diagonal=0.8)
h = baselines.diagonal(a, b) / res
if method == "gn":
    def once():
        r = baselines.gn_sdf_boolean(a, b, "UNION", h)
        return r["seconds"], len(r["tris"])
else:
    from bench.addon import register
    from bench.keep_faces import run_aasdf

    register()

    def once():
        out = run_aasdf(a, b, "UNION", h, True)
        return out["seconds"], out["faces"]
once()  # warm-up
seconds, faces = once()
rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
print("RESULT " + json.dumps({"seconds": seconds, "faces": faces, "rss_mb": rss}))
"""


def measure(method: str, case: str, res: int) -> dict:
    return run_child(CHILD, method, res, case)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--resolutions", nargs="+", type=int, default=[512, 1024])
    parser.add_argument("--cases", nargs="+", default=["spot", "ball"])
    args = parser.parse_args(argv)
    print("| pair | voxel | AASDF kept faces s (faces) | SDF nodes s (faces) | AASDF / nodes | peak MB AASDF / nodes |")
    print("|---|---|---|---|---|---|")
    for case in args.cases:
        for res in args.resolutions:
            pair = paired(
                functools.partial(measure, "aasdf", case, res),
                functools.partial(measure, "gn", case, res),
                args.repeat,
                warm_up=False,
            )
            ours, gn = pair["ours"], pair["theirs"]
            cells = [
                f"{ours['seconds']:.2f} ({ours['faces']:,})",
                f"{gn['seconds']:.2f} ({gn['faces']:,})",
                f"{pair['ratio']:.2f}x ({pair['low']:.2f}-{pair['high']:.2f})",
                f"{ours['rss_mb']:.0f} / {gn['rss_mb']:.0f}",
            ]
            print(f"| {case} | /{res} | " + " | ".join(cells) + " |", flush=True)


if __name__ == "__main__":
    main()
