"""The judge of the kept faces (``engine.keep.kept_triangles``): its fused path (two kernel launches a round,
``engine/judging.py``) against the sample-by-sample one, on the CAD pairs, the plate with four bores and bunny ∪ spot
at voxel = the pair's bounding-box diagonal / 256. Alternating rounds (``bench/paired.py``): median seconds of the
whole ``kept_triangles`` and of the judge's calls alone (wall, summed over the leaves' threads), process CPU seconds,
the median per-round ratio with its range, and whether both paths give the same arrays. Every run judges from scratch
(``verdicts.forget``): a first boolean, not a drag's step.

    .venv/bin/python bench/judge.py [--repeat 5] [--cases plate ...]
    AASDF_THREADS=1 .venv/bin/python bench/judge.py   # one thread: the CPU time is the judge's work alone
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import engine  # noqa: E402
from bench.paired import paired  # noqa: E402
from engine import keep, verdicts  # noqa: E402
from tests.support import cad_pairs, load_mesh, normalised, plate_and_bores  # noqa: E402

OPS = {"UNION": engine.union, "INTERSECT": engine.intersection, "DIFFERENCE": engine.difference}
KEYS = ("verts", "tris", "parent", "kept", "flip")


def cases() -> dict:
    spot = normalised(load_mesh("spot.obj"))
    bunny = normalised(load_mesh("stanford-bunny.obj"), center=(0.25, 0.0, 0.0), diagonal=0.8)
    return {"plate": ("DIFFERENCE", *plate_and_bores()), **cad_pairs(), "bunny | spot": ("UNION", bunny, spot)}


class JudgeClock:
    """Wall seconds spent in the judge's calls (``_Judge.judge``), summed over threads."""

    def __init__(self):
        self.seconds = 0.0
        judge = keep._Judge.judge

        def timed(judge_self, *args):
            start = time.perf_counter()
            try:
                return judge(judge_self, *args)
            finally:
                self.seconds += time.perf_counter() - start

        keep._Judge.judge = timed


def run(field, fused: bool, clock: JudgeClock) -> dict:
    """``kept_triangles`` from scratch (no first-round verdicts of an earlier run reused)."""
    verdicts.forget()
    clock.seconds = 0.0
    wall, cpu = time.perf_counter(), time.process_time()
    judged = keep.kept_triangles(field, fused=fused)
    return {
        "seconds": time.perf_counter() - wall,
        "cpu": time.process_time() - cpu,
        "judge": clock.seconds,
        "judged": judged,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--cases", nargs="*")
    args = parser.parse_args()
    clock = JudgeClock()
    print("| case | kept_triangles s (fused / general, ratio [range]) | judge s | CPU s | same arrays |")
    print("|---|---|---|---|---|")
    for name, (op, a, b) in cases().items():
        if args.cases and name not in args.cases:
            continue
        v = np.concatenate([a[0], b[0]])
        h = float(np.linalg.norm(v.max(0) - v.min(0))) / 256
        fa, fb = engine.build_fields([a, b], voxel_size=h)
        field = OPS[op](fa, fb)
        r = paired(lambda f=field: run(f, True, clock), lambda f=field: run(f, False, clock), args.repeat)
        ours, theirs = r["ours"], r["theirs"]
        pairs = zip(ours["judged"], theirs["judged"], strict=True)
        same = all(np.array_equal(x[key], y[key]) for x, y in pairs for key in KEYS)
        ratio = f"{r['ratio']:.2f} [{r['low']:.2f}-{r['high']:.2f}]"
        label = name.replace("|", "∪")
        print(
            f"| {label} | {ours['seconds']:.3f} / {theirs['seconds']:.3f}, {ratio} | {ours['judge']:.3f} / "
            f"{theirs['judge']:.3f} | {ours['cpu']:.3f} / {theirs['cpu']:.3f} | {same} |",
            flush=True,
        )


if __name__ == "__main__":
    main()
