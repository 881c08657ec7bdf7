"""Kept faces on random pairs: the shared meshes against boxes, balls and each other, placed and turned at random.

Each case takes one of the shared meshes (``tests.support.load_mesh``), and a ball, a box or another shared mesh
scaled to 0.3-0.8 of its size, all placed at random about its middle and turned at random about the second one's
centre (half the time as a turned mesh, half the time as its field placed by ``AdaptiveField.transformed``); union,
intersection or difference, at diagonal / 64, 128, 256 or 384, with the fields built on demand and the boolean made
along its seams as the add-on makes it. Printed per case: seconds, triangles, faces kept, the join's fallback if it
gave the kept faces up, whether the result is closed and consistently oriented, whether manifold3d takes it as a
2-manifold, how many pairs of its faces pass through each other (``tests.metrics.self_intersections``: faces touching
within float rounding count too), and of those how many the engine finds with a new face among them (its own
``selfcross.crossing_pairs``, as the tiling looks for them: the rest are a mesh's own faces, kept as they are); then
the sums. A flat mesh (the alligator) encloses nothing: its results are empty, as they should be.

    .venv/bin/python bench/stress.py [--seed 1] [--count 30]
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
os.environ.setdefault("WARP_CACHE_PATH", str(ROOT / ".warp-cache"))

import numpy as np  # noqa: E402

import engine  # noqa: E402
from engine.selfcross import crossing_pairs  # noqa: E402
from tests.metrics import self_intersections, to_manifold  # noqa: E402
from tests.support import box_mesh, is_watertight, load_mesh, quaternion_turn, uv_sphere  # noqa: E402

MESHES = ("stanford-bunny", "spot", "cow", "suzanne", "teapot", "homer", "alligator", "beetle", "fandisk", "rocker-arm")
OPS = {"union": engine.union, "intersection": engine.intersection, "difference": engine.difference}


def turn(rng) -> np.ndarray:
    """A random rotation (a unit quaternion's matrix)."""
    q = rng.normal(size=4)
    return quaternion_turn(*(q / np.linalg.norm(q)))


def pair(rng) -> tuple:
    """``(name, a, b, matrix or None)``: a shared mesh, the second operand about it, and its field's placement."""
    a_name = MESHES[rng.integers(len(MESHES))]
    a = load_mesh(a_name + ".obj")
    lo, hi = a[0].min(0), a[0].max(0)
    middle, size = (lo + hi) / 2, float(np.linalg.norm(hi - lo))
    kind = rng.integers(3)
    if kind == 0:
        b_name = "ball"
        radius, offset = size * rng.uniform(0.1, 0.35), rng.uniform(-0.3, 0.3, 3) * size
        b = uv_sphere(radius, center=middle + offset, rings=24, segments=48)
    elif kind == 1:
        b_name = "box"
        b = box_mesh(half=tuple(size * rng.uniform(0.08, 0.3, 3)), center=middle + rng.uniform(-0.3, 0.3, 3) * size)
    else:
        b_name = MESHES[rng.integers(len(MESHES))]
        verts, tris = load_mesh(b_name + ".obj")
        b_lo, b_hi = verts.min(0), verts.max(0)
        scale = size / float(np.linalg.norm(b_hi - b_lo)) * rng.uniform(0.3, 0.8)
        b = ((verts - (b_lo + b_hi) / 2) * scale + middle + rng.uniform(-0.25, 0.25, 3) * size, tris)
    verts = np.asarray(b[0], dtype=np.float64)
    centre, rotation = (verts.max(0) + verts.min(0)) / 2, turn(rng)
    matrix = np.eye(4)
    matrix[:3, :3], matrix[:3, 3] = rotation, centre - rotation @ centre
    placed = bool(rng.integers(2))
    if not placed:
        verts = (verts - centre) @ rotation.T + centre
    return f"{a_name} {{}} {b_name}", a, (verts.astype(np.float32), b[1]), matrix if placed else None


def run_case(a, b, matrix, op: str, resolution: int) -> dict:
    verts = np.concatenate([a[0], b[0]])
    voxel = float(np.linalg.norm(verts.max(0) - verts.min(0))) / resolution
    t0 = time.perf_counter()
    fa, fb = engine.build_fields([a, b], voxel_size=voxel, refine="auto")
    if matrix is not None:
        fb = fb.transformed(matrix)
    surface = OPS[op](fa, fb, seams=True).kept_surface()
    seconds = time.perf_counter() - t0
    v, t = surface["verts"], surface["tris"]
    try:
        manifold = bool(len(t)) and to_manifold(v, t) is not None
    except Exception:  # noqa: BLE001 (manifold3d's refusal: counted, not raised)
        manifold = False
    return {
        "seconds": seconds,
        "tris": len(t),
        "kept": int(np.count_nonzero(surface["kept"])),
        "fallback": surface["stats"].get("kept_fallback", "") if surface["stats"].get("join_failed") else "",
        "closed": bool(len(t)) and is_watertight(t),
        "manifold": manifold,
        "crossings": self_intersections(v, t) if len(t) else 0,
        "new crossings": len(crossing_pairs(v, t, "cpu", np.flatnonzero(~surface["kept"]))) if len(t) else 0,
    }


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--count", type=int, default=30)
    args = parser.parse_args(argv)
    rng = np.random.default_rng(args.seed)
    totals = {"cases": 0, "empty": 0, "fallbacks": 0, "not closed": 0, "not 2-manifold": 0, "crossings": 0}
    totals.update({"new crossings": 0, "kept": 0})
    print("| case | seconds | triangles | kept | join | closed | 2-manifold | crossing pairs | with a new face |")
    print("|---|---|---|---|---|---|---|---|---|")
    for k in range(args.count):
        name, a, b, matrix = pair(rng)
        op = tuple(OPS)[rng.integers(3)]
        resolution = (64, 128, 256, 384)[rng.integers(4)]
        out = run_case(a, b, matrix, op, resolution)
        label = f"{k} {name.format(op)} /{resolution}" + (" placed" if matrix is not None else "")
        join = out["fallback"] or "made"
        cells = [f"{out['seconds']:.2f}", f"{out['tris']:,}", f"{out['kept']:,}", join, out["closed"], out["manifold"]]
        crossings = f"{out['crossings']} | {out['new crossings']}"
        print(f"| {label} | " + " | ".join(map(str, cells)) + f" | {crossings} |", flush=True)
        totals["cases"] += 1
        totals["empty"] += not out["tris"]
        totals["fallbacks"] += bool(out["fallback"])
        totals["not closed"] += bool(out["tris"]) and not out["closed"]
        totals["not 2-manifold"] += bool(out["tris"]) and not out["manifold"]
        totals["crossings"] += out["crossings"]
        totals["new crossings"] += out["new crossings"]
        totals["kept"] += out["kept"]
    print("\n" + ", ".join(f"{key} {value:,}" for key, value in totals.items()))


if __name__ == "__main__":
    main()
