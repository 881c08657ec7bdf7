"""Seconds of the adaptivity: ``to_mesh()`` (today: triangles, adaptivity 0) against ``to_mesh(quads=True,
adaptivity=a)`` with this checkout's ``engine/adaptive.py`` and with another checkout's, in one process, alternating
rounds (each round's order reversed from the last), on the bench pairs of ``bench/adaptivity.py`` at diagonal / 256.

The other checkout's ``adaptive.py`` is loaded beside this one (with those of the modules it imports relatively whose
source differs from this checkout's: their Warp kernels compile as modules of their own) and put in place of
``meshing.simplify`` for its runs; everything else (the fields, the extraction) is this checkout's. Ratios are the
medians of the rounds' ratios (``bench/paired.py``), with the smallest and largest.

    git worktree add /tmp/before <commit>
    .venv/bin/python bench/adaptivity_time.py --before /tmp/before [--repeat 7] [--cases cube ...]
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import re
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
os.environ.setdefault("WARP_CACHE_PATH", str(ROOT / ".warp-cache"))

import numpy as np  # noqa: E402

import engine  # noqa: E402
from bench.paired import round_ratios  # noqa: E402
from engine import meshing  # noqa: E402
from tests.support import cad_pairs, plate_and_bores  # noqa: E402

ADAPTIVITIES = (0.5, 0.75, 1.0)
OPS = {"UNION": engine.union, "INTERSECT": engine.intersection, "DIFFERENCE": engine.difference}


def cases() -> dict:
    cad = cad_pairs()
    return {
        "plate - 4 bores": ("DIFFERENCE", *plate_and_bores()),
        **{k: cad[k] for k in ("cube - bore", "fandisk - cylinder", "rocker-arm - cube", "hex prism & sphere")},
    }


def load_before(checkout: Path, name: str = "adaptive"):
    """The other checkout's engine module ``name``, loaded as ``engine.before_<name>`` (its relative imports of
    modules that differ from this checkout's loaded the same way)."""
    source = (checkout / "engine" / f"{name}.py").read_text()
    for dep in sorted(set(re.findall(r"^from \.(\w+) import", source, flags=re.M))):
        theirs = (checkout / "engine" / f"{dep}.py").read_text()
        if not (ROOT / "engine" / f"{dep}.py").exists() or (ROOT / "engine" / f"{dep}.py").read_text() != theirs:
            load_before(checkout, dep)
            source = re.sub(rf"^from \.{dep} import", f"from .before_{dep} import", source, flags=re.M)
    spec = importlib.util.spec_from_loader(f"engine.before_{name}", loader=None)
    module = importlib.util.module_from_spec(spec)
    module.__package__ = "engine"
    sys.modules[spec.name] = module
    exec(compile(source, str(checkout / "engine" / f"{name}.py"), "exec"), module.__dict__)
    return module


def timed(run) -> float:
    t0 = time.perf_counter()
    run()
    return time.perf_counter() - t0


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--before", type=Path, required=True, help="the other checkout")
    parser.add_argument("--repeat", type=int, default=7)
    parser.add_argument("--cases", nargs="*")
    args = parser.parse_args(argv)
    ours, theirs = meshing.simplify, load_before(args.before).simplify
    print("| pair | adaptivity | to_mesh() s | before s | / to_mesh() | after s | / to_mesh() | after / before |")
    print("|---|---|---|---|---|---|---|---|")
    for name, (op, a, b) in cases().items():
        if args.cases and not any(c in name for c in args.cases):
            continue
        verts = np.concatenate([a[0], b[0]])
        voxel = float(np.linalg.norm(verts.max(axis=0) - verts.min(axis=0))) / 256
        field = OPS[op](*engine.build_fields([a, b], voxel_size=voxel))

        def adaptive(simplify, adaptivity, field=field):
            meshing.simplify = simplify
            try:
                field.to_mesh(quads=True, adaptivity=adaptivity)
            finally:
                meshing.simplify = ours

        runs = {"today": field.to_mesh}
        for x in ADAPTIVITIES:
            runs[(0, x)] = lambda x=x: adaptive(theirs, x)
            runs[(1, x)] = lambda x=x: adaptive(ours, x)
        times = {k: [] for k in runs}
        for r in range(args.repeat + 1):  # the first round warms up
            for key in list(runs) if r % 2 else list(runs)[::-1]:
                seconds = timed(runs[key])
                if r:
                    times[key].append(seconds)
        for x in ADAPTIVITIES:
            before, after, today = times[(0, x)], times[(1, x)], times["today"]
            cells = [f"{statistics.median(today):.3f}"]
            for t in (before, after):
                cells += [f"{statistics.median(t):.3f}", ratio(t, today)]
            cells.append(ratio(after, before))
            print(f"| {name} | {x:g} | " + " | ".join(cells) + " |", flush=True)


def ratio(ours: list, theirs: list) -> str:
    """The median of the rounds' ratios, with the smallest and largest."""
    median, low, high = round_ratios(ours, theirs)
    return f"{median:.2f}x ({low:.2f}-{high:.2f})"


if __name__ == "__main__":
    main()
