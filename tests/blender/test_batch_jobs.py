"""``aasdf_batch.py --jobs``: job files run in one process, in worker processes and on a Dask ``LocalCluster``; every
fault (a malformed line, a missing file, an input that encloses nothing, an empty result, a job past its timeout, a
worker killed mid-job, the whole run killed) reported while the other jobs go on; outputs read back (watertight,
volume against the exact one), the report checked, no partial file left, and a rerun doing only what was left. The
tests of process management alone (timeouts, kills, reruns, Dask) run on the newest Blender only (``make test``)."""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import bpy
import numpy as np
import pytest

from tests.metrics import merge_vertices, mesh_volume
from tests.support import box_mesh, is_watertight, mesh_path

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "aasdf_batch.py"
# Two unit cubes, the second moved by (0.5, 0.3, 0.2): they share a 0.5 x 0.7 x 0.8 box.
SHARED = 0.5 * 0.7 * 0.8
EXACT = {"union": 2.0 - SHARED, "intersect": SHARED, "difference": 1.0 - SHARED}
RESOLUTION = "48"
# A job of seconds here (an offset of 8 voxels at /200, 3 s or more): what a timeout or a kill interrupts.
SLOW = {"inputs": [str(mesh_path("spot.obj"))], "offset": 0.1, "resolution": 200, "output": "slow.ply"}


def write_obj(path, verts, tris):
    lines = [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in verts] + [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in tris]
    path.write_text("\n".join(lines) + "\n", encoding="ascii")


@pytest.fixture(scope="module")
def meshes(tmp_path_factory):
    """A folder with the cubes ``a.obj``, ``b.obj``, ``far.obj`` touching neither and ``c.obj`` placed on ``far.obj``
    as ``b.obj`` is on ``a.obj``, and a square ``plane.obj``. Workers take a job sharing an input with their last one
    first: jobs meant to run after the slow one use ``far.obj`` and ``c.obj``."""
    folder = tmp_path_factory.mktemp("meshes")
    write_obj(folder / "a.obj", *box_mesh((0.5, 0.5, 0.5)))
    write_obj(folder / "b.obj", *box_mesh((0.5, 0.5, 0.5), center=(0.5, 0.3, 0.2)))
    write_obj(folder / "far.obj", *box_mesh((0.5, 0.5, 0.5), center=(5.0, 0.0, 0.0)))
    write_obj(folder / "c.obj", *box_mesh((0.5, 0.5, 0.5), center=(5.5, 0.3, 0.2)))  # far.obj's b.obj
    (folder / "garbage.stl").write_text("not an STL file", encoding="ascii")
    square = np.array([[-1, -1, 0.1], [1, -1, 0.1], [1, 1, 0.1], [-1, 1, 0.1]], dtype=np.float32)
    write_obj(folder / "plane.obj", square, np.array([[0, 1, 2], [0, 2, 3]]))
    return folder


def write_jobs(path, entries):
    """A JSON-lines job file; a string entry is written as it is (a malformed line)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    lines = [entry if isinstance(entry, str) else json.dumps(entry) for entry in entries]
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def pair(meshes, operation, output, first="a.obj", second="b.obj"):
    return {"inputs": [str(meshes / first), str(meshes / second)], "operation": operation, "output": output}


def run_batch(*args, timeout=300):
    return subprocess.run(
        [sys.executable, str(SCRIPT), *map(str, args)], capture_output=True, text=True, timeout=timeout, check=False
    )


def read_report(path) -> dict:
    """The report's jobs by their output's file name (or by ``where`` when it has none)."""
    jobs = json.loads(Path(path).read_text(encoding="utf-8"))["jobs"]
    return {Path(job["output"]).name if job["output"] else job["where"]: job for job in jobs}


def read_mesh(path):
    """The vertices and triangles of a written mesh file, imported with Blender's importer."""
    before = set(bpy.data.objects)
    getattr(bpy.ops.wm, f"{Path(path).suffix[1:]}_import")(filepath=str(path))
    (obj,) = [o for o in bpy.data.objects if o not in before]
    mesh = obj.data
    mesh.calc_loop_triangles()
    verts = np.empty(len(mesh.vertices) * 3, dtype=np.float32)
    mesh.vertices.foreach_get("co", verts)
    tris = np.empty(len(mesh.loop_triangles) * 3, dtype=np.int32)
    mesh.loop_triangles.foreach_get("vertices", tris)
    return merge_vertices(verts.reshape(-1, 3), tris.reshape(-1, 3))


def leftovers(folder) -> list:
    """Partial or temporary files a run left in ``folder``."""
    return sorted(p.name for p in Path(folder).rglob("*") if "partial" in p.name or p.name.endswith(".tmp"))


# ---- one process: the good jobs done, each fault reported alone ----


@pytest.fixture(scope="module")
def one_process(meshes, tmp_path_factory):
    """Eight jobs in one process (``--workers 0``), five of them faulty, the operation a command-line default."""
    folder = tmp_path_factory.mktemp("one")
    jobs = write_jobs(
        folder / "jobs.jsonl",
        [
            pair(meshes, None, "out/union.ply"),
            pair(meshes, "intersect", "out/intersect.obj"),
            '{"inputs": ["a.obj", "b.obj"], "output": "out/broken.ply"',
            pair(meshes, "difference", "out/difference.stl"),
            pair(meshes, "union", "out/missing.ply", second="nowhere.obj"),
            pair(meshes, "union", "out/plane.ply", second="plane.obj"),
            pair(meshes, "intersect", "out/empty.ply", second="far.obj"),
            pair(meshes, "union", "out/unreadable.ply", second="garbage.stl"),
        ],
    )
    done = run_batch(
        "--jobs", jobs, "--operation", "union", "--resolution", RESOLUTION, "--workers", 0,
        "--report", folder / "report.json",
    )  # fmt: skip
    return folder, done


def test_one_process_writes_every_good_job_watertight_with_the_exact_volume(one_process):
    folder, done = one_process
    assert done.returncode == 1, done.stderr[-3000:]  # some jobs failed
    assert "Traceback" not in done.stderr
    report = read_report(folder / "report.json")
    for name, operation in (("union.ply", "union"), ("intersect.obj", "intersect"), ("difference.stl", "difference")):
        entry = report[name]
        assert entry["status"] == "done", entry
        verts, tris = read_mesh(folder / "out" / name)
        assert is_watertight(tris)
        assert mesh_volume(verts, tris) == pytest.approx(EXACT[operation], rel=0.01)
        assert entry["volume"] == pytest.approx(mesh_volume(verts, tris), rel=1e-3)
        assert entry["triangles"] == len(tris) and entry["seconds"] > 0.0
    assert (folder / "out" / "intersect.mtl").exists()  # an .obj's material file moved into place with it
    assert leftovers(folder) == []


def test_one_process_builds_the_fields_of_shared_inputs_once(one_process):
    report = read_report(one_process[0] / "report.json")
    assert report["union.ply"]["fields_built"] == 2
    assert report["intersect.obj"]["fields_built"] == report["difference.stl"]["fields_built"] == 0


def test_report_lists_every_job_in_file_order(one_process):
    folder, done = one_process
    written = json.loads((folder / "report.json").read_text(encoding="utf-8"))
    assert [job["job"] for job in written["jobs"]] == list(range(1, 9))
    assert (written["summary"]["done"], written["summary"]["failed"], written["summary"]["jobs"]) == (3, 5, 8)
    assert "8 jobs: 3 done, 0 up to date, 5 failed" in done.stdout


@pytest.mark.parametrize(
    ("key", "message"),
    [
        ("jobs.jsonl:3", "not a JSON object"),
        ("missing.ply", "input file not found: "),
        ("plane.ply", "'plane' encloses no volume: give it a thickness or close it"),
        ("empty.ply", "the result is empty: nothing written"),
        ("unreadable.ply", "STL Import: Failed to read file"),
    ],
    ids=["malformed-line", "missing-file", "encloses-nothing", "empty-result", "unreadable-file"],
)
def test_a_failing_job_is_reported_with_its_reason_and_writes_nothing(one_process, key, message):
    folder, done = one_process
    entry = read_report(folder / "report.json")[key]
    assert entry["status"] == "failed" and message in entry["message"]
    assert f"aasdf_batch: failed: {entry['where']}: " in done.stderr
    assert not (folder / "out" / key).exists()


@pytest.mark.newest_blender  # process management: the tests above make its Blender calls on every version
def test_a_rerun_skips_what_is_up_to_date_and_force_redoes_it(one_process, meshes, tmp_path):
    folder, _ = one_process
    made = (folder / "out" / "union.ply").stat().st_mtime_ns
    again = run_batch(
        "--jobs", folder / "jobs.jsonl", "--operation", "union", "--resolution", RESOLUTION, "--workers", 0,
        "--report", tmp_path / "again.json",
    )  # fmt: skip
    report = read_report(tmp_path / "again.json")
    assert [report[name]["status"] for name in ("union.ply", "intersect.obj", "difference.stl")] == ["skipped"] * 3
    assert report["union.ply"]["volume"] == pytest.approx(EXACT["union"], rel=0.01)  # kept beside the output
    assert (folder / "out" / "union.ply").stat().st_mtime_ns == made and again.returncode == 1
    run_batch(
        "--jobs", folder / "jobs.jsonl", "--operation", "union", "--resolution", 40, "--workers", 0,
        "--report", tmp_path / "changed.json",
    )  # fmt: skip
    assert read_report(tmp_path / "changed.json")["union.ply"]["status"] == "done"  # other settings: redone
    forced = run_batch(
        "--jobs", folder / "jobs.jsonl", "--operation", "union", "--resolution", 40, "--workers", 0, "--force",
        "--report", tmp_path / "forced.json",
    )  # fmt: skip
    assert read_report(tmp_path / "forced.json")["union.ply"]["status"] == "done", forced.stderr[-2000:]


# ---- worker processes ----


def test_csv_shards_on_two_workers_cover_the_file_once(meshes, tmp_path):
    rows = [f"{meshes / 'a.obj'} {meshes / 'b.obj'},{op},{op}-{n}.ply" for n in range(2) for op in EXACT]
    jobs = tmp_path / "jobs.csv"
    jobs.write_text("inputs,operation,output\n" + "\n".join(rows) + "\n", encoding="utf-8")
    seen = {}
    for shard, workers in (("1/2", 2), ("2/2", 0)):
        done = run_batch(
            "--jobs", jobs, "--resolution", RESOLUTION, "--shard", shard, "--workers", workers,
            "--report", tmp_path / f"report-{shard[0]}.json",
        )  # fmt: skip
        assert done.returncode == 0, done.stderr[-3000:]
        report = read_report(tmp_path / f"report-{shard[0]}.json")
        assert all(entry["status"] == "done" for entry in report.values())
        assert not set(report) & set(seen)
        seen.update(report)
    assert sorted(seen) == sorted(f"{op}-{n}.ply" for n in range(2) for op in EXACT)
    for name, entry in seen.items():
        assert entry["volume"] == pytest.approx(EXACT[name.split("-")[0]], rel=0.01)


@pytest.mark.newest_blender  # process management: the tests above make its Blender calls on every version
def test_a_job_past_its_timeout_is_stopped_and_the_next_runs_on_a_new_worker(meshes, tmp_path):
    jobs = write_jobs(tmp_path / "jobs.jsonl", [SLOW, pair(meshes, "union", "after.ply")])
    done = run_batch(
        "--jobs", jobs, "--resolution", RESOLUTION, "--workers", 1, "--timeout", 1.5, "--report", tmp_path / "r.json"
    )  # fmt: skip
    assert done.returncode == 1, done.stderr[-3000:]
    report = read_report(tmp_path / "r.json")
    assert report["slow.ply"]["status"] == "failed"
    assert report["slow.ply"]["message"] == "stopped after the timeout of 1.5 s"
    assert report["after.ply"]["status"] == "done"
    assert not (tmp_path / "slow.ply").exists() and leftovers(tmp_path) == []
    verts, tris = read_mesh(tmp_path / "after.ply")
    assert is_watertight(tris) and mesh_volume(verts, tris) == pytest.approx(EXACT["union"], rel=0.01)


def children(pid: int) -> list:
    """The process ids of ``pid``'s worker processes (not multiprocessing's resource tracker)."""
    found = []
    for child in Path(f"/proc/{pid}/task/{pid}/children").read_text().split():
        cmdline = Path(f"/proc/{child}/cmdline").read_bytes()
        if b"spawn_main" in cmdline:
            found.append(int(child))
    return found


def wait_for(path, process, limit=120.0):
    end = time.monotonic() + limit
    while not Path(path).exists():
        assert process.poll() is None, process.communicate()
        assert time.monotonic() < end, f"{path} never appeared"
        time.sleep(0.05)


def start_batch(*args):
    return subprocess.Popen(
        [sys.executable, str(SCRIPT), *map(str, args)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )


@pytest.mark.newest_blender  # process management: the tests above make its Blender calls on every version
def test_a_worker_killed_mid_job_is_replaced_and_its_job_tried_again(meshes, tmp_path):
    jobs = write_jobs(
        tmp_path / "jobs.jsonl",
        [pair(meshes, "union", "first.ply"), SLOW, pair(meshes, "intersect", "last.ply", "far.obj", "c.obj")],
    )
    process = start_batch("--jobs", jobs, "--resolution", RESOLUTION, "--workers", 1, "--report", tmp_path / "r.json")
    wait_for(tmp_path / ".first.ply.aasdf.json", process)
    time.sleep(0.3)  # in the slow job now
    (worker,) = children(process.pid)
    os.kill(worker, signal.SIGKILL)
    out, err = process.communicate(timeout=240)
    assert process.returncode == 0, err[-3000:]
    report = read_report(tmp_path / "r.json")
    assert [report[name]["status"] for name in ("first.ply", "slow.ply", "last.ply")] == ["done"] * 3
    assert report["slow.ply"]["message"] == "tried again: its first worker died (killed by SIGKILL)"
    verts, tris = read_mesh(tmp_path / "slow.ply")
    assert is_watertight(tris) and len(tris) == report["slow.ply"]["triangles"]
    assert leftovers(tmp_path) == []


@pytest.mark.newest_blender  # process management: the tests above make its Blender calls on every version
def test_a_rerun_after_the_whole_run_was_killed_does_only_what_was_left(meshes, tmp_path):
    entries = [pair(meshes, op, f"{op}.ply") for op in EXACT] + [
        SLOW,
        pair(meshes, "union", "end.ply", "far.obj", "c.obj"),
    ]
    jobs = write_jobs(tmp_path / "jobs.jsonl", entries)
    process = start_batch("--jobs", jobs, "--resolution", RESOLUTION, "--workers", 1)
    wait_for(tmp_path / ".difference.ply.aasdf.json", process)
    time.sleep(0.3)
    os.killpg(process.pid, signal.SIGKILL)  # the run and its workers
    process.communicate(timeout=60)
    written = sorted(p.name for p in tmp_path.glob("*.ply"))
    assert written == ["difference.ply", "intersect.ply", "union.ply"]  # nothing half-written under a final name
    again = run_batch("--jobs", jobs, "--resolution", RESOLUTION, "--workers", 1, "--report", tmp_path / "r.json")
    assert again.returncode == 0, again.stderr[-3000:]
    report = read_report(tmp_path / "r.json")
    assert {name: entry["status"] for name, entry in report.items()} == {
        "union.ply": "skipped", "intersect.ply": "skipped", "difference.ply": "skipped",
        "slow.ply": "done", "end.ply": "done",
    }  # fmt: skip
    for name in ("slow.ply", "end.ply"):
        assert is_watertight(read_mesh(tmp_path / name)[1])
    assert leftovers(tmp_path) == []


# ---- a Dask cluster ----


@pytest.fixture(scope="module")
def local_cluster():
    """A Dask ``LocalCluster`` of two worker processes, one thread each, allowed to start job processes."""
    dask = pytest.importorskip("dask")
    distributed = pytest.importorskip("distributed")
    with dask.config.set({"distributed.worker.daemon": False}):
        cluster = distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None)
    client = distributed.Client(cluster)
    yield client
    client.close()
    cluster.close()


@pytest.mark.newest_blender  # process management: the tests above make its Blender calls on every version
def test_run_jobs_on_a_local_cluster(local_cluster, meshes, tmp_path):
    import aasdf_batch

    jobs = [pair(meshes, op, str(tmp_path / f"{op}-{n}.ply")) for n in range(2) for op in EXACT]
    jobs.append(pair(meshes, "intersect", str(tmp_path / "empty.ply"), second="far.obj"))
    entries = aasdf_batch.run_jobs(jobs, local_cluster, resolution=int(RESOLUTION))
    assert [entry["job"] for entry in entries] == list(range(1, 8))
    assert [entry["status"] for entry in entries] == ["done"] * 6 + ["failed"]
    assert entries[-1]["message"] == "the result is empty: nothing written"
    for entry in entries[:6]:
        verts, tris = read_mesh(entry["output"])
        operation = Path(entry["output"]).name.split("-")[0]
        assert is_watertight(tris) and mesh_volume(verts, tris) == pytest.approx(EXACT[operation], rel=0.01)
    # both Dask workers keep a job process of their own between jobs
    assert sorted(local_cluster.run(lambda: __import__("batch.cluster").cluster.job_process_id() > 0).values()) == [
        True,
        True,
    ]


@pytest.mark.newest_blender  # process management: the tests above make its Blender calls on every version
def test_scheduler_option_runs_a_job_file_on_the_cluster(local_cluster, meshes, tmp_path):
    jobs = write_jobs(tmp_path / "jobs.jsonl", [pair(meshes, op, f"{op}.ply") for op in EXACT])
    done = run_batch(
        "--jobs", jobs, "--resolution", RESOLUTION, "--scheduler", local_cluster.scheduler.address,
        "--report", tmp_path / "r.json",
    )  # fmt: skip
    assert done.returncode == 0, done.stderr[-3000:]
    report = read_report(tmp_path / "r.json")
    for name, entry in report.items():
        assert entry["status"] == "done" and entry["volume"] == pytest.approx(EXACT[name[:-4]], rel=0.01)
