"""Kept faces on dense scans: a boolean whose operand has hundreds of thousands of triangles, kept against remeshed.

The open Stanford bunny (69 k triangles) split into four per triangle once (278 k) or twice (1.1 M), as a sculpt or
a fine scan is, united with a ball at diagonal / 256 in Blender (``aasdf.boolean``, the field cache cleared first:
the fields built, read to write). Kept faces keep every triangle of the scan away from the seam (hundreds of
thousands written); the remeshed result is the voxel surface (about 210 k). Each measurement is a fresh ``bpy``
process (warmed up once, then timed); kept and remeshed run in turns, ``--repeat`` rounds, the ratio the median of
the rounds' ratios (smallest and largest in brackets).

    .venv/bin/python bench/dense_scan.py [--repeat 3] [--splits 1 2]
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
import json, resource, sys
root, keep, splits = sys.argv[1], sys.argv[2] == "kept", int(sys.argv[3])
sys.path.insert(0, root)
import numpy as np
import bpy
from bench import baselines
from bench.addon import register
from bench.dense_scan import split_in_four
from bench.keep_faces import run_aasdf
from tests.support import load_mesh, normalised, uv_sphere

scan = normalised(load_mesh("stanford-bunny.obj"))
for _ in range(splits):
    scan = split_in_four(*scan)
ball = uv_sphere(0.25, center=(0.1, 0.1, 0.1), rings=32, segments=64)
h = baselines.diagonal(scan, ball) / 256
register()
run_aasdf(scan, ball, "UNION", h, keep)  # warm-up
out = run_aasdf(scan, ball, "UNION", h, keep)
rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
print("RESULT " + json.dumps({"seconds": out["seconds"], "faces": out["faces"], "closed": bool(out["closed"]),
                              "rss_mb": rss, "triangles": len(scan[1])}))
"""


def split_in_four(verts, tris):
    """Each triangle split into four at its edges' midpoints (shared midpoints once): the same surface, four times
    the triangles."""
    import numpy as np

    t = np.asarray(tris, dtype=np.int64)
    n = len(verts)
    edges = np.sort(np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]]), axis=1)
    keys, index = np.unique(edges[:, 0] * n + edges[:, 1], return_inverse=True)
    mids = (np.asarray(verts, np.float64)[keys // n] + np.asarray(verts, np.float64)[keys % n]) / 2.0
    ab, bc, ca = index.reshape(3, -1) + n
    a, b, c = t.T
    out = np.concatenate([np.stack(f, axis=1) for f in ((a, ab, ca), (ab, b, bc), (ca, bc, c), (ab, bc, ca))])
    return np.concatenate([verts, mids]).astype(np.float32), out.astype(np.int32)


def measure(method: str, splits: int) -> dict:
    return run_child(CHILD, method, splits)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--splits", nargs="+", type=int, default=[1, 2])
    args = parser.parse_args(argv)
    print(
        "| scan triangles | kept s (faces) | remeshed s (faces) | kept / remeshed | peak MB kept / remeshed | closed |"
    )
    print("|---|---|---|---|---|---|")
    for splits in args.splits:
        pair = paired(
            functools.partial(measure, "kept", splits),
            functools.partial(measure, "remeshed", splits),
            args.repeat,
            warm_up=False,
        )
        ours, theirs = pair["ours"], pair["theirs"]
        cells = [
            f"{ours['triangles']:,}",
            f"{ours['seconds']:.2f} ({ours['faces']:,})",
            f"{theirs['seconds']:.2f} ({theirs['faces']:,})",
            f"{pair['ratio']:.2f}x ({pair['low']:.2f}-{pair['high']:.2f})",
            f"{ours['rss_mb']:.0f} / {theirs['rss_mb']:.0f}",
            "yes" if ours["closed"] and theirs["closed"] else "no",
        ]
        print("| " + " | ".join(cells) + " |", flush=True)


if __name__ == "__main__":
    main()
