"""Batch jobs: 200 small booleans run by one ``aasdf_batch.py --jobs`` process against separate invocations, two
worker processes against one, and a Dask ``LocalCluster`` of two workers against ``--workers 2``.

The jobs (``--resolution 128``): the pairs of ten primitives (boxes, spheres, cylinders around the origin) under
union, intersection and difference (135), and five closed meshes of ``../shared/meshes`` with four cutters each
(a sphere, a box, a cylinder, a second sphere, placed on the mesh) under the three operations, plus a blended union
each (65): every primitive and every mesh is an input of several jobs. Separate invocations (today's command line,
one process per job) are timed on every tenth job (20) and scaled to 200. Every run writes into a fresh folder
(nothing skipped). Each Dask run gets a new cluster (2 worker processes, one thread each), started before the run is
timed; its workers' job processes start inside the timed run, as ``--workers``' do. Rounds alternate the order of
the runs; a ratio is the median of the rounds' ratios (range). Prints markdown.

    .venv/bin/python bench/batch.py [--rounds 2] [--sample 20]
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tests.support import box_mesh, cylinder_mesh, load_obj, uv_sphere  # noqa: E402

SCRIPT = ROOT / "aasdf_batch.py"
MESHES = ROOT.parent / "shared" / "meshes"
CLOSED = ("spot", "cow", "fandisk", "rocker-arm", "homer")
OPERATIONS = ("union", "intersect", "difference")
RESOLUTION = 128


def write_obj(path, verts, tris):
    lines = [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in verts] + [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in tris]
    path.write_text("\n".join(lines) + "\n", encoding="ascii")


def primitives(folder: Path) -> list:
    """Ten primitives that all contain a small ball around the origin (every pair overlaps)."""
    rng = np.random.default_rng(7)
    paths = []
    for k in range(10):
        center = rng.uniform(-0.2, 0.2, 3)
        size = rng.uniform(0.5, 0.9)
        shape = (
            box_mesh((size, size * 0.8, size * 0.6), center=center)
            if k % 3 == 0
            else uv_sphere(size, center=center, rings=24, segments=48)
            if k % 3 == 1
            else cylinder_mesh(size * 0.6, size * 2.0, segments=48, center=center)
        )
        paths.append(folder / f"primitive-{k}.obj")
        write_obj(paths[-1], *shape)
    return paths


def cutters(folder: Path, mesh: Path) -> list:
    """Four cutters placed on ``mesh`` (in its file's own coordinates, as the importer reads both alike)."""
    verts, _ = load_obj(mesh)
    lo, hi = verts.min(axis=0), verts.max(axis=0)
    center, diag = (lo + hi) / 2, float(np.linalg.norm(hi - lo))
    shapes = (
        uv_sphere(0.25 * diag, center=center + [0.25 * (hi - lo)[0], 0, 0], rings=24, segments=48),
        box_mesh((0.15 * diag,) * 3, center=hi - 0.1 * (hi - lo)),
        cylinder_mesh(0.08 * diag, 1.2 * diag, segments=48, center=center),
        uv_sphere(0.2 * diag, center=lo + 0.2 * (hi - lo), rings=24, segments=48),
    )
    paths = []
    for k, shape in enumerate(shapes):
        paths.append(folder / f"{mesh.stem}-cutter-{k}.obj")
        write_obj(paths[-1], *shape)
    return paths


def job_entries(folder: Path) -> list:
    prims = primitives(folder)
    entries = [
        {"inputs": [str(a), str(b)], "operation": op}
        for i, a in enumerate(prims)
        for b in prims[i + 1 :]
        for op in OPERATIONS
    ]
    for name in CLOSED:
        mesh = MESHES / f"{name}.obj"
        found = cutters(folder, mesh)
        entries += [{"inputs": [str(mesh), str(c)], "operation": op} for c in found for op in OPERATIONS]
        entries.append({"inputs": [str(mesh), str(found[0])], "operation": "union", "blend_radius": 0.02})
    return entries


def write_jobs(entries, path: Path, out: Path) -> Path:
    lines = [json.dumps({**entry, "output": str(out / f"job-{n:03d}.ply")}) for n, entry in enumerate(entries)]
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


CPU = {}  # run label -> CPU seconds (user + system) of its process tree, per round


def cpu_seconds() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def timed(args, label: str = "") -> tuple[float, dict]:
    start, cpu = time.perf_counter(), cpu_seconds()
    done = subprocess.run([sys.executable, str(SCRIPT), *map(str, args)], capture_output=True, text=True, check=False)
    seconds = time.perf_counter() - start
    CPU[label] = CPU.get(label, 0.0) + cpu_seconds() - cpu  # the script and its workers (reaped), not Dask's
    if done.returncode not in (0, 1):
        raise SystemExit(f"aasdf_batch failed: {done.stderr[-2000:]}")
    return seconds, done


def run_file(entries, work: Path, label: str, *extra) -> tuple[float, dict]:
    out = work / label
    jobs = write_jobs(entries, work / f"{label}.jsonl", out)
    seconds, _ = timed(["--jobs", jobs, "--resolution", RESOLUTION, "--report", work / f"{label}.json", *extra], label)
    report = json.loads((work / f"{label}.json").read_text(encoding="utf-8"))
    return seconds, report["summary"]


def separate(entries, work: Path, sample: int) -> float:
    """Seconds for every job run as its own invocation, from every ``len // sample``-th job, scaled."""
    step = max(1, len(entries) // sample)
    picked = entries[::step][:sample]
    total = 0.0
    for n, entry in enumerate(picked):
        args = ["--inputs", *entry["inputs"], "--operation", entry["operation"], "--resolution", RESOLUTION]
        if "blend_radius" in entry:
            args += ["--blend-radius", entry["blend_radius"]]
        seconds, _ = timed([*args, "--output", work / "separate" / f"job-{n:03d}.ply", "--quiet"], "separate")
        total += seconds
    return total * len(entries) / len(picked)


def on_new_cluster(run):
    """``run(["--scheduler", address])`` on a new LocalCluster of 2 worker processes (one thread each), started
    before and closed after: its job processes and their field caches start empty, as ``--workers``' do."""
    import dask
    import distributed

    # each worker's engine takes its share of the cores, as --workers gives it (docs/usage.md)
    saved = os.environ.get("AASDF_THREADS")
    os.environ["AASDF_THREADS"] = str(max(1, (os.cpu_count() or 1) // 2))
    try:
        with dask.config.set({"distributed.worker.daemon": False}):
            cluster = distributed.LocalCluster(n_workers=2, threads_per_worker=1, dashboard_address=None)
    finally:
        if saved is None:
            del os.environ["AASDF_THREADS"]
        else:
            os.environ["AASDF_THREADS"] = saved
    try:
        return run(["--scheduler", cluster.scheduler_address])
    finally:
        cluster.close()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--sample", type=int, default=20)
    parser.add_argument("--runs", default="separate,one,w1,w2,dask", help="which runs (some comparisons need two)")
    options = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="aasdf-bench-batch-") as tmp:
        work = Path(tmp)
        entries = job_entries(work)
        times = {name: [] for name in ("separate", "one", "w1", "w2", "dask")}
        loads = []
        summaries = {}
        for r in range(options.rounds):
            runs = [
                ("one", lambda r=r: run_file(entries, work, f"one-{r}", "--workers", 0)),
                ("w1", lambda r=r: run_file(entries, work, f"w1-{r}", "--workers", 1)),
                ("w2", lambda r=r: run_file(entries, work, f"w2-{r}", "--workers", 2)),
                ("dask", lambda r=r: on_new_cluster(lambda address: run_file(entries, work, f"dask-{r}", *address))),
                ("separate", lambda: (separate(entries, work, options.sample), {})),
            ]
            runs = [(name, run) for name, run in runs if name in options.runs.split(",")]
            for name, run in runs if r % 2 == 0 else runs[::-1]:
                load = os.getloadavg()[0]
                seconds, summary = run()
                times[name].append(seconds)
                summaries[name] = summary
                loads.append(load)
                print(f"<!-- round {r + 1} {name}: {seconds:.1f} s, load {load:.1f}, {summary} -->", file=sys.stderr)
    print(f"<!-- {json.dumps({'times': times, 'cpu': CPU, 'loads': loads})} -->", file=sys.stderr)
    ratio = {
        "one process vs separate invocations": ("separate", "one"),
        "--workers 2 vs --workers 1": ("w1", "w2"),
        "Dask LocalCluster (2 workers) vs --workers 2": ("w2", "dask"),
    }
    print(
        f"{len(entries)} jobs at /{RESOLUTION}, {next(iter(summaries.values()))['failed']} of them failing (empty "
        "differences); "
        f"{options.rounds} rounds; 1-minute load average at the start of the runs {min(loads):.1f}-{max(loads):.1f} "
        f"on {os.cpu_count()} cores (other work on the machine shares them)."
    )
    print("\n| run | seconds (per round) | CPU seconds of its processes (per round) |\n|---|---|---|")
    labels = {
        "separate": f"separate invocations (every {len(entries) // options.sample}th job timed, scaled)",
        "one": "one --jobs process (--workers 0)",
        "w1": "--workers 1",
        "w2": "--workers 2",
        "dask": "--scheduler (LocalCluster, 2 workers)",
    }
    for name, label in labels.items():
        if not times[name]:
            continue
        cpu = (
            ", ".join(f"{CPU[f'{name}-{r}']:.1f}" for r in range(options.rounds))
            if name in ("one", "w1", "w2")
            else "-"
        )
        print(f"| {label} | {', '.join(f'{s:.1f}' for s in times[name])} | {cpu} |")
    print("\n| comparison | speed-up (range) |\n|---|---|")
    for label, (slow, fast) in ratio.items():
        if not (times[slow] and times[fast]):
            continue
        values = [a / b for a, b in zip(times[slow], times[fast], strict=True)]
        print(f"| {label} | {statistics.median(values):.2f}x ({min(values):.2f}-{max(values):.2f}) |")


if __name__ == "__main__":
    main()
