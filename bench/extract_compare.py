"""Compare sparse mesh extraction strategies on a sphere band (a script, not a test).

Run from the repository root: ``.venv/bin/python bench/extract_compare.py [--resolutions 256 512] [--repeats 3]``.

For each effective resolution ``res`` the domain is the unit cube split into ``res^3`` cells; the samples are the cell
centres with ``|sdf| < 1.75 * spacing`` for a sphere of radius ``0.39`` (a band 3.5 cells thick), in shuffled order.
It times, per million samples:

* ``warp``: :func:`engine.extract.extract_surface` (galloping search kernel + ``sparse_marching_cubes_from_cells``);
* ``warp-private``: the same, but with the corner indices from the search handed to Warp's private
  ``_extract_from_dedup`` (skips Warp's re-sort of the 8 * M corner codes; informational, private API);
* ``skimage-blocks``: numpy ``searchsorted`` corner search, then scikit-image ``marching_cubes`` (Lewiner) on dense
  16^3-cube blocks (17^3 samples, one-sample overlap) masked to the complete crossing cubes, welded by lattice edge;
* the corner search alone: numpy ``searchsorted`` (7 sorted queries) against the Warp kernel of ``engine.extract``.

Each output is checked for watertightness, outward orientation and volume against ``4/3 pi r^3``.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import warp as wp  # noqa: E402
from skimage.measure import marching_cubes  # noqa: E402

from engine import extract  # noqa: E402
from tests.support import is_watertight, signed_volume  # noqa: E402

RADIUS = 0.39
HALF_BAND = 1.75  # cells: a crossing cube's corners lie within sqrt(3) cells of the surface
BLOCK = 16


# ---- inputs ----


def sphere_band(res: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray, float]:
    """Cell-centre samples of a sphere SDF within ``HALF_BAND`` cells of its surface, built slice by slice.

    Returns:
        coords (N, 3) int32 in shuffled order, values (N,) float32, spacing.
    """
    spacing = 1.0 / res
    centre = 0.5
    axis = (np.arange(res) + 0.5) * spacing - centre
    x, y = np.meshgrid(axis, axis, indexing="ij")
    rxy2 = x * x + y * y
    chunks_c, chunks_v = [], []
    for k in range(res):
        d = np.sqrt(rxy2 + axis[k] ** 2) - RADIUS
        i, j = np.nonzero(np.abs(d) < HALF_BAND * spacing)
        if len(i):
            chunks_c.append(np.stack([i, j, np.full_like(i, k)], axis=1))
            chunks_v.append(d[i, j])
    coords = np.concatenate(chunks_c).astype(np.int32)
    values = np.concatenate(chunks_v).astype(np.float32)
    order = np.random.default_rng(seed).permutation(len(coords))
    return coords[order], values[order], spacing


# ---- corner search ----


def sorted_keys(coords: np.ndarray) -> tuple[np.ndarray, np.ndarray, int, int, np.ndarray]:
    """Pack (N, 3) coordinates into sorted int64 keys; returns keys, order, stride_x, stride_y, lo."""
    coords = coords.astype(np.int64)
    lo = coords.min(axis=0)
    span = coords.max(axis=0) - lo + 2
    stride_y = int(span[2])
    stride_x = int(span[1]) * stride_y
    rel = coords - lo
    keys = rel[:, 0] * stride_x + rel[:, 1] * stride_y + rel[:, 2]
    order = np.argsort(keys)
    return keys[order], order, stride_x, stride_y, lo


def find_corners_numpy(keys: np.ndarray, stride_x: int, stride_y: int) -> tuple[np.ndarray, np.ndarray]:
    """Corner sample indices (N, 8) and completeness (N,) bool with numpy ``searchsorted`` on sorted queries."""
    n = len(keys)
    corners = np.empty((n, 8), dtype=np.int64)
    complete = np.ones(n, dtype=bool)
    for slot, (di, dj, dk) in enumerate(extract._CORNER_OFFSETS.tolist()):
        query = keys + (di * stride_x + dj * stride_y + dk)
        pos = np.minimum(np.searchsorted(keys, query), n - 1)
        complete &= keys[pos] == query
        corners[:, slot] = pos
    return corners, complete


def find_corners_warp(keys: np.ndarray, values: np.ndarray, stride_x: int, stride_y: int):
    """Corner sample indices (N, 8) int32 and active flags (N,) int32 with the Warp kernel of ``engine.extract``."""
    n = len(keys)
    corners = wp.empty((n, 8), dtype=wp.int32, device="cpu")
    active = wp.empty(n, dtype=wp.int32, device="cpu")
    wp.launch(
        extract._find_cube_corners_kernel,
        dim=n,
        inputs=[wp.array(keys, dtype=wp.int64), wp.array(values, dtype=wp.float32), stride_x, stride_y],
        outputs=[corners, active],
        device="cpu",
    )
    return corners.numpy(), active.numpy()


# ---- scikit-image on dense blocks ----


def extract_skimage_blocks(coords, values, *, origin, spacing, block: int = BLOCK, stats: dict | None = None):
    """Marching cubes on dense ``block^3``-cube blocks holding only the complete crossing cubes, welded by edge.

    Returns:
        verts (V, 3) float32, tris (F, 3) int32, outward for negative-inside values.
    """
    stats = {} if stats is None else stats
    t0 = time.perf_counter()
    keys, order, stride_x, stride_y, lo = sorted_keys(coords)
    rel = coords[order].astype(np.int64) - lo
    vals = extract._nudge_values(values[order].astype(np.float64), 0.0, extract._ISO_NUDGE * spacing)
    corners, complete = find_corners_numpy(keys, stride_x, stride_y)
    corner_vals = vals[corners]
    negative = np.count_nonzero(corner_vals < 0.0, axis=1)
    cubes = np.flatnonzero(complete & (negative > 0) & (negative < 8))
    cube_block = rel[cubes] // block
    t1 = time.perf_counter()

    # Group cubes by block; write each cube's 8 corners into its block's (block+1)^3 volume.
    side = block + 1
    block_key = (cube_block[:, 0] * (1 << 21) + cube_block[:, 1]) * (1 << 21) + cube_block[:, 2]
    by_block = np.argsort(block_key, kind="stable")
    cubes, cube_block, block_key = cubes[by_block], cube_block[by_block], block_key[by_block]
    starts = np.flatnonzero(np.r_[True, block_key[1:] != block_key[:-1]])
    ends = np.r_[starts[1:], len(cubes)]
    local_min = rel[cubes] - cube_block * block
    local_corner = local_min[:, None, :] + extract._CORNER_OFFSETS[None, :, :]
    flat_corner = (local_corner[..., 0] * side + local_corner[..., 1]) * side + local_corner[..., 2]
    # scikit-image's ``mask`` switches a cube on at its maximum corner (checked empirically with a one-cube mask).
    local_max = local_min + 1
    flat_max = (local_max[:, 0] * side + local_max[:, 1]) * side + local_max[:, 2]
    cval = vals[corners[cubes]]

    all_verts, all_tris, n_verts = [], [], 0
    volume = np.zeros(side**3, dtype=np.float32)
    mask = np.zeros(side**3, dtype=bool)
    for start, end in zip(starts, ends, strict=True):
        volume[:] = 0.0
        mask[:] = False
        volume[flat_corner[start:end].ravel()] = cval[start:end].ravel()
        mask[flat_max[start:end]] = True
        verts, tris, _, _ = marching_cubes(
            volume.reshape(side, side, side),
            level=0.0,
            mask=mask.reshape(side, side, side),
            gradient_direction="descent",  # outward for negative-inside values (checked by volume sign)
            method="lewiner",
        )
        all_verts.append(verts.astype(np.float64) + cube_block[start] * block)
        all_tris.append(tris + n_verts)
        n_verts += len(verts)
    t2 = time.perf_counter()

    # Weld: each vertex lies on one lattice edge (two integer coordinates); identify it by edge start + axis.
    verts = np.concatenate(all_verts)
    tris = np.concatenate(all_tris)
    frac = np.abs(verts - np.round(verts))
    axis = np.argmax(frac, axis=1)
    base = np.round(verts).astype(np.int64)
    base[np.arange(len(verts)), axis] = np.floor(verts[np.arange(len(verts)), axis]).astype(np.int64)
    edge_key = ((base[:, 0] * (1 << 20) + base[:, 1]) * (1 << 20) + base[:, 2]) * 3 + axis
    _, first, inverse = np.unique(edge_key, return_index=True, return_inverse=True)
    world = np.asarray(origin) + (verts[first] + lo + 0.5) * spacing
    tris = inverse.reshape(-1)[tris]
    t3 = time.perf_counter()
    stats.update(search=t1 - t0, mc=t2 - t1, weld=t3 - t2, blocks=len(starts))
    return world.astype(np.float32), tris.astype(np.int32)


# ---- Warp without its corner de-duplication (private API, for the numbers only) ----


def extract_warp_private(coords, values, *, origin, spacing):
    """Like ``extract_surface``, but feeding the known corner indices to ``warp._src``'s ``_extract_from_dedup``.

    Returns:
        verts (V, 3) float32, tris (F, 3) int32.
    """
    from warp._src.geometry.sparse_marching_cubes import _extract_from_dedup

    keys, order, stride_x, stride_y, lo = sorted_keys(coords)
    vals = extract._nudge_values(values[order].astype(np.float64), 0.0, extract._ISO_NUDGE * spacing)
    corners, active = find_corners_warp(keys, vals, stride_x, stride_y)
    cubes = np.flatnonzero(active)
    rel = np.stack([keys // stride_x, keys % stride_x // stride_y, keys % stride_y], axis=1)
    positions = (np.asarray(origin) + (rel + lo + 0.5) * spacing).astype(np.float32)
    verts, indices = _extract_from_dedup(
        wp.array(np.ascontiguousarray(corners[cubes]), dtype=wp.int32, device="cpu"),
        wp.array(positions, dtype=wp.vec3, device="cpu"),
        wp.array(vals, dtype=wp.float32, device="cpu"),
        0.0,
        wp.get_device("cpu"),
    )
    return verts.numpy(), indices.numpy().reshape(-1, 3)


# ---- driver ----


def best_of(fn, repeats: int) -> tuple[float, float, object]:
    """Best wall-clock and best process CPU time over ``repeats`` calls (everything here is single-threaded)."""
    best_wall, best_cpu, result = np.inf, np.inf, None
    for _ in range(repeats):
        wall, cpu = time.perf_counter(), time.process_time()
        result = fn()
        best_wall = min(best_wall, time.perf_counter() - wall)
        best_cpu = min(best_cpu, time.process_time() - cpu)
    return best_wall, best_cpu, result


def describe(name: str, wall: float, cpu: float, n: int, verts, tris, spacing: float) -> None:
    exact = 4.0 / 3.0 * np.pi * RADIUS**3
    vol_err = signed_volume(verts, tris) / exact - 1.0
    radial = np.abs(np.linalg.norm(verts.astype(np.float64) - 0.5, axis=1) - RADIUS).max() / spacing
    print(
        f"  {name:15s} wall {wall:6.3f} s  cpu {cpu:6.3f} s  = {cpu / n * 1e6:5.3f} cpu-s/Msample  "
        f"V={len(verts):8d} F={len(tris):8d}  watertight={is_watertight(tris)}  volume err={vol_err:+.1e}  "
        f"max |r-R|={radial:.4f} cells"
    )


def run_resolution(res: int, repeats: int) -> None:
    coords, values, spacing = sphere_band(res)
    n = len(coords)
    origin = (0.0, 0.0, 0.0)
    print(f"resolution {res}^3: N = {n} samples (shuffled), spacing = 1/{res}")

    wall, cpu, (verts, tris) = best_of(
        lambda: extract.extract_surface(coords, values, origin=origin, spacing=spacing, device="cpu"), repeats
    )
    describe("warp", wall, cpu, n, verts, tris, spacing)

    wall, cpu, (verts, tris) = best_of(
        lambda: extract_warp_private(coords, values, origin=origin, spacing=spacing), repeats
    )
    describe("warp-private", wall, cpu, n, verts, tris, spacing)

    stats: dict = {}
    wall, cpu, (verts, tris) = best_of(
        lambda: extract_skimage_blocks(coords, values, origin=origin, spacing=spacing, stats=stats), repeats
    )
    describe("skimage-blocks", wall, cpu, n, verts, tris, spacing)
    print(
        f"  {'':15s} last run (wall): corner search {stats['search']:.3f} s, marching_cubes on {stats['blocks']} "
        f"blocks {stats['mc']:.3f} s, weld {stats['weld']:.3f} s"
    )

    keys, order, stride_x, stride_y, _ = sorted_keys(coords)
    vals = values[order]
    _, t_sort, _ = best_of(lambda: sorted_keys(coords), repeats)
    _, t_np, (_, complete) = best_of(lambda: find_corners_numpy(keys, stride_x, stride_y), repeats)
    _, t_wp, (_, active) = best_of(lambda: find_corners_warp(keys, vals, stride_x, stride_y), repeats)
    print(
        f"  corner search (cpu): key packing + argsort {t_sort:.3f} s | numpy searchsorted {t_np:.3f} s "
        f"({t_np / n * 1e6:.3f} s/Msample, {complete.sum()} complete cubes) | Warp galloping kernel {t_wp:.3f} s "
        f"({t_wp / n * 1e6:.3f} s/Msample, {active.sum()} of them crossing)"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--resolutions", type=int, nargs="+", default=[256, 512])
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()

    wp.config.quiet = True
    wp.init()
    # Warm up: compile/load the kernels so that the timings below exclude code generation.
    warm_c, warm_v, warm_h = sphere_band(32)
    start = time.perf_counter()
    extract.extract_surface(warm_c, warm_v, origin=(0.0, 0.0, 0.0), spacing=warm_h, device="cpu")
    extract_warp_private(warm_c, warm_v, origin=(0.0, 0.0, 0.0), spacing=warm_h)
    print(f"warm-up (kernel load or compile): {time.perf_counter() - start:.2f} s")
    for res in args.resolutions:
        run_resolution(res, args.repeats)


if __name__ == "__main__":
    main()
