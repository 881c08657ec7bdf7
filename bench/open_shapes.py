"""Open shapes, copied so that they overlap: tubes, cones and bowls without caps, turned at random, one to three
copies each a random step apart (Blender's Array modifier on an open primitive), at diagonal / 64 … / 192. Past their
holes the copies' winding numbers add up, and the inside can bulge out of their bounding box. Printed per case:
whether the field's surface, an offset of -2 to 8 voxels and a boolean with a ball along its seams (kept faces) are
closed and 2-manifold (manifold3d); then how many failed.

    .venv/bin/python bench/open_shapes.py [--seed 1] [--count 40]
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
from tests.metrics import to_manifold  # noqa: E402
from tests.support import is_watertight, quaternion_turn, uv_sphere  # noqa: E402

OPS = (engine.union, engine.difference, engine.intersection)


def tube(radius: float, length: float, segments: int, top: float = 1.0) -> tuple:
    """A tube along z without caps (a cone where ``top`` < 1: its top ring that share of the radius)."""
    angle = np.linspace(0.0, 2.0 * np.pi, segments, endpoint=False)
    ring = np.c_[np.cos(angle), np.sin(angle)]
    verts = np.vstack(
        [
            np.c_[radius * ring, np.full(segments, -length / 2)],
            np.c_[top * radius * ring, np.full(segments, length / 2)],
        ]
    )
    i = np.arange(segments)
    j = (i + 1) % segments
    return verts, np.r_[np.c_[i, j, segments + j], np.c_[i, segments + j, segments + i]]


def shape(rng) -> tuple:
    """``(name, verts, tris)``: an open shape turned at random, in one to three copies a random step apart."""
    kind = int(rng.integers(3))
    if kind < 2:
        top = 1.0 if kind == 0 else rng.uniform(0.2, 0.9)
        verts, tris = tube(rng.uniform(0.1, 0.4), rng.uniform(0.5, 2.0), int(rng.integers(8, 48)), top)
    else:
        radius = rng.uniform(0.2, 0.6)
        verts, tris = uv_sphere(radius, rings=12, segments=int(rng.integers(12, 48)))
        tris = tris[verts[tris].mean(axis=1)[:, 2] < rng.uniform(-0.3, 0.5) * radius]  # a bowl
    q = rng.normal(size=4)
    verts = verts @ quaternion_turn(*(q / np.linalg.norm(q))).T
    copies, step = int(rng.integers(1, 4)), rng.uniform(-0.6, 0.6, 3) * (verts.max(0) - verts.min(0))
    all_verts = np.concatenate([verts + c * step for c in range(copies)]).astype(np.float32)
    all_tris = np.concatenate([tris + c * len(verts) for c in range(copies)]).astype(np.int32)
    return f"{('tube', 'cone', 'bowl')[kind]} x{copies}", all_verts, all_tris


def verdict(verts, tris) -> str:
    """ "ok" (closed and 2-manifold), "empty", or what fails."""
    if not len(tris):
        return "empty"
    try:
        manifold = to_manifold(verts, tris) is not None
    except Exception:  # noqa: BLE001 (manifold3d's refusal, whatever its type)
        manifold = False
    closed = is_watertight(tris)
    return "ok" if closed and manifold else f"closed {closed}, 2-manifold {manifold}"


def run_case(rng) -> tuple[str, list]:
    name, verts, tris = shape(rng)
    resolution = int(rng.choice([64, 96, 128, 192]))
    h = float(np.linalg.norm(verts.max(0) - verts.min(0))) / resolution
    (field,) = engine.build_fields([(verts, tris)], voxel_size=h)
    distance = float(rng.uniform(-2.0, 8.0)) * h
    centre = verts.mean(axis=0) + rng.uniform(-0.3, 0.3, 3)
    ball = uv_sphere(float(rng.uniform(0.1, 0.4)) * resolution * h, center=centre, rings=16, segments=32)
    op = OPS[int(rng.integers(3))]
    a, b = engine.build_fields([(verts, tris), ball], voxel_size=h, refine="auto")
    kept = op(a, b, seams=True).kept_surface()
    checks = [("field", verdict(*field.to_mesh()))]
    checks.append((f"offset {distance / h:.1f} voxels", verdict(*engine.offset(field, distance).to_mesh())))
    checks.append((f"{op.__name__} with a ball", verdict(kept["verts"], kept["tris"])))
    return f"{name} /{resolution}", checks


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--count", type=int, default=40)
    args = parser.parse_args(argv)
    rng = np.random.default_rng(args.seed)
    failed = 0
    for k in range(args.count):
        t0 = time.perf_counter()
        name, checks = run_case(rng)
        bad = [f"{what}: {result}" for what, result in checks if result not in ("ok", "empty")]
        failed += bool(bad)
        print(f"{k} {name} | {'; '.join(bad) or 'ok'} | {time.perf_counter() - t0:.1f}s", flush=True)
    print(f"{args.count} cases, {failed} with a result open or not 2-manifold")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
