"""Job files without Blender: lines parsed into jobs (the command line's options as defaults, relative paths from the
job file's folder), bad lines turned into failed jobs with their reason, shards, the up-to-date check, the progress
lines and the report."""

import io
import json
import os
import sys
import time

import pytest

from batch import jobs, options, report


def defaults(**changes) -> dict:
    args = options.command_line_parser("").parse_args([])
    for key, value in changes.items():
        setattr(args, key, value)
    return options.job_defaults(args)


@pytest.fixture
def folder(tmp_path):
    """A job folder with two mesh files (their content is not read here)."""
    for name in ("a.obj", "b.stl"):
        (tmp_path / name).write_text("", encoding="ascii")
    return tmp_path


def test_json_lines_take_defaults_and_resolve_paths_from_the_file(folder, monkeypatch):
    monkeypatch.chdir("/")
    (folder / "jobs.jsonl").write_text(
        '{"inputs": ["a.obj", "b.stl"], "operation": "difference", "output": "out/ab.ply", "resolution": 64}\n'
        "\n# a comment\n"
        '{"inputs": ["a.obj", "b.stl"], "output": "out/u.obj", "sharp_edges": false, "blend-radius": 0.1}\n',
        encoding="utf-8",
    )
    found = jobs.read_jobs(folder / "jobs.jsonl", defaults(operation="union", resolution=128))
    assert [job.error for job in found] == ["", ""]
    first, second = (job.options for job in found)
    assert first["inputs"] == [str(folder / "a.obj"), str(folder / "b.stl")]
    assert first["output"] == str(folder / "out" / "ab.ply")
    assert (first["operation"], first["resolution"]) == ("difference", 64)
    assert (second["operation"], second["resolution"], second["sharp_edges"]) == ("union", 128, False)
    assert second["blend_radius"] == 0.1
    assert [job.where for job in found] == ["jobs.jsonl:1", "jobs.jsonl:4"]


def test_csv_splits_operands_and_leaves_empty_cells_to_the_defaults(folder):
    (folder / "jobs.csv").write_text(
        "inputs,operation,output,resolution,sharp_edges\n"
        "a.obj b.stl,intersect,one.stl,,no\n"
        '"a.obj" "b.stl",,two.ply,200,\n',
        encoding="utf-8",
    )
    found = jobs.read_jobs(folder / "jobs.csv", defaults(operation="union", resolution=48))
    assert [job.error for job in found] == ["", ""]
    one, two = (job.options for job in found)
    assert one["inputs"] == two["inputs"] == [str(folder / "a.obj"), str(folder / "b.stl")]
    assert (one["operation"], one["resolution"], one["sharp_edges"]) == ("intersect", 48, False)
    assert (two["operation"], two["resolution"], two["sharp_edges"]) == ("union", 200, True)


@pytest.mark.parametrize(
    ("line", "message"),
    [
        ('{"inputs": ["a.obj" "b.stl"]}', "not a JSON object: Expecting ',' delimiter"),
        ('["a.obj", "b.stl"]', "a job is an object of options, not list"),
        ('{"inputs": ["a.obj", "b.stl"], "output": "x.ply", "colour": "red"}', "unknown key 'colour'"),
        ('{"inputs": ["a.obj", "b.stl"], "output": "x.ply", "workers": 4}', "unknown key 'workers'"),
        ('{"inputs": ["a.obj", "b.stl"], "output": "x.ply", "resolution": "high"}', "invalid int value: 'high'"),
        ('{"inputs": ["a.obj", "b.stl"], "output": "x.ply", "operation": "xor"}', "invalid choice: 'xor'"),
        ('{"inputs": ["a.obj", "b.stl"], "output": "x.ply", "resolution": [1, 2]}', "'resolution' takes one value"),
        ('{"inputs": ["a.obj", "b.stl"], "output": "x.ply", "sharp_edges": "maybe"}', "must be true or false"),
        ('{"inputs": ["a.obj", "gone.obj"], "output": "x.ply"}', "input file not found: "),
        ('{"inputs": ["a.obj", "b.stl"]}', "give --output"),
        ('{"inputs": ["a.obj", "b.stl"], "output": "x.fbx"}', "cannot write "),
        ('{"inputs": ["a.obj"], "output": "x.ply"}', "give at least two operands"),
    ],
    ids=[
        "malformed-json", "not-an-object", "unknown-key", "run-option", "bad-number", "bad-choice", "list-for-one",
        "bad-flag", "missing-file", "no-output", "bad-output", "one-operand",
    ],
)  # fmt: skip
def test_a_bad_line_fails_alone_with_its_reason(folder, line, message):
    good = '{"inputs": ["a.obj", "b.stl"], "output": "good.ply"}'
    (folder / "jobs.jsonl").write_text(f"{good}\n{line}\n{good.replace('good', 'fine')}\n", encoding="utf-8")
    found = jobs.read_jobs(folder / "jobs.jsonl", defaults(operation="union"))
    assert [job.number for job in found] == [1, 2, 3]
    assert found[0].error == found[2].error == ""
    assert message in found[1].error


def test_csv_row_with_too_many_cells_and_a_shared_output_fail(folder):
    (folder / "jobs.csv").write_text(
        "inputs,output\na.obj b.stl,x.ply\na.obj b.stl,y.ply,extra\na.obj b.stl,x.ply\n'a.obj b.stl,z.ply\n",
        encoding="utf-8",
    )
    found = jobs.read_jobs(folder / "jobs.csv", defaults(operation="union"))
    assert found[0].error == ""
    assert "more cells than the header has columns" in found[1].error
    assert found[2].error.startswith("the same output as jobs.csv:2")
    assert found[3].error == "'inputs': No closing quotation"  # (the whole run stopped with a traceback)


def test_an_unreadable_job_file_is_a_batch_error(tmp_path):
    with pytest.raises(options.BatchError, match="cannot read the job file"):
        jobs.read_jobs(tmp_path / "none.jsonl", defaults())


def test_shards_are_disjoint_and_cover_every_job():
    everything = list(range(10))
    shards = [jobs.shard(everything, f"{k}/3") for k in (1, 2, 3)]
    assert sorted(sum(shards, [])) == everything
    assert shards[0] == [0, 3, 6, 9]
    assert jobs.shard(everything, None) == everything
    for spec in ("0/3", "4/3", "two", "1/2/3"):
        with pytest.raises(options.BatchError, match="--shard"):
            jobs.shard(everything, spec)


def test_an_output_is_up_to_date_only_if_newer_than_its_inputs_and_made_under_the_same_settings(folder):
    (folder / "jobs.jsonl").write_text('{"inputs": ["a.obj", "b.stl"], "output": "o.ply"}\n', encoding="utf-8")
    (job,) = jobs.read_jobs(folder / "jobs.jsonl", defaults(operation="union"))
    assert jobs.done_before(job) is None  # no output yet
    (folder / "o.ply").write_text("ply", encoding="ascii")
    assert jobs.done_before(job) is None  # no record of its settings
    jobs.write_record(job, {"triangles": 12, "volume": 1.0})
    assert jobs.done_before(job)["triangles"] == 12
    other = jobs.Job(1, "x", {**job.options, "resolution": 999})
    assert jobs.done_before(other) is None  # other settings
    moved = jobs.Job(1, "x", {**job.options, "output": str(folder / "o.ply")})
    assert jobs.settings_hash(moved.options) == jobs.settings_hash(job.options)
    later = time.time() + 10
    os.utime(folder / "b.stl", (later, later))
    assert jobs.done_before(job) is None  # an input changed after the output


class FakeTerminal(io.StringIO):
    def isatty(self):
        return True


def test_progress_prints_plain_lines_to_a_file_and_a_bar_on_a_terminal():
    job = jobs.Job(1, "j:1", {"output": "o.ply"})
    out, err = io.StringIO(), io.StringIO()
    progress = report.Progress(2, out, err)
    progress.add(job, {"status": "done", "seconds": 0.5, "triangles": 1200, "volume": 1.0})
    progress.add(jobs.Job(2, "j:2"), {"status": "failed", "message": "input file not found: x.obj"})
    summary = progress.close()
    assert "[1/2] done o.ply 1,200 triangles, 0.50 s" in out.getvalue()
    assert "aasdf_batch: failed: j:2: input file not found: x.obj" in err.getvalue()
    assert (summary["done"], summary["failed"], summary["jobs"]) == (1, 1, 2)
    terminal = FakeTerminal()
    progress = report.Progress(1, io.StringIO(), terminal)
    assert progress.bar is not None  # tqdm is installed for the tests
    progress.add(job, {"status": "done", "seconds": 0.5, "triangles": 1200, "volume": 1.0})
    progress.close()
    assert "1/1" in terminal.getvalue() and "job/s" in terminal.getvalue()


def test_report_is_written_whole_in_job_order(tmp_path):
    lines = [report.entry(jobs.Job(n, f"j:{n}", {"output": f"{n}.ply"}), {"status": "done"}) for n in (2, 1)]
    report.write_report(tmp_path / "r" / "report.json", {"jobs": 2}, lines)
    written = json.loads((tmp_path / "r" / "report.json").read_text(encoding="utf-8"))
    assert [line["job"] for line in written["jobs"]] == [1, 2]
    assert set(written["jobs"][0]) >= {"status", "seconds", "triangles", "volume", "message"}
    assert os.listdir(tmp_path / "r") == ["report.json"]


def test_workers_take_contiguous_lanes_then_the_end_of_the_longest_other():
    from batch import workers

    pool = workers.Pool(2)
    pool.lanes = [workers.deque([0, 1, 2]), workers.deque([3, 4, 5, 6])]
    assert [pool.take(0), pool.take(0), pool.take(1)] == [0, 1, 3]
    assert [pool.take(0), pool.take(0), pool.take(0)] == [2, 6, 5]  # its own, then the far end of the other lane
    assert list(pool.lanes[1]) == [4]


def test_worker_counts_and_a_timeout_without_workers_are_checked():
    from batch import runner

    assert runner.worker_count(None) >= 1 and runner.worker_count(0) == 0
    with pytest.raises(options.BatchError, match="--workers must be 0 or more"):
        runner.worker_count(-1)
    args = options.command_line_parser("").parse_args(["--jobs", "j.jsonl", "--workers", "0", "--timeout", "5"])
    with pytest.raises(options.BatchError, match="--timeout needs worker processes"):
        runner.run_job_file(args, io.StringIO(), io.StringIO())
    for timeout in ("0", "-1"):  # (every job was "stopped after the timeout of -1 s")
        args = options.command_line_parser("").parse_args(["--jobs", "j.jsonl", "--timeout", timeout])
        with pytest.raises(options.BatchError, match="--timeout must be a number of seconds above 0"):
            runner.run_job_file(args, io.StringIO(), io.StringIO())


def test_progress_falls_back_to_plain_lines_without_tqdm(monkeypatch):
    monkeypatch.setitem(sys.modules, "tqdm", None)  # as in Blender's own Python: the import fails
    out, terminal = io.StringIO(), FakeTerminal()
    progress = report.Progress(1, out, terminal)
    assert progress.bar is None
    progress.add(jobs.Job(1, "j:1", {"output": "o.ply"}), {"status": "done", "seconds": 0.5, "triangles": 10})
    progress.close()
    assert "[1/1] done o.ply 10 triangles" in out.getvalue()


def test_the_report_is_rewritten_as_jobs_end(tmp_path):
    path = tmp_path / "report.json"
    progress = report.Progress(3, io.StringIO(), io.StringIO(), report=path, every=0.0)
    progress.add(jobs.Job(1, "j:1", {"output": "1.ply"}), {"status": "done", "seconds": 0.1, "triangles": 8})
    written = json.loads(path.read_text(encoding="utf-8"))  # a run killed now keeps this
    assert (written["summary"]["jobs"], written["summary"]["total"]) == (1, 3)
    progress.add(jobs.Job(2, "j:2"), {"status": "failed", "message": "gone"})
    progress.close()
    written = json.loads(path.read_text(encoding="utf-8"))
    assert [line["status"] for line in written["jobs"]] == ["done", "failed"]


def test_inside_blenders_executable_jobs_run_in_its_one_process(monkeypatch):
    from types import SimpleNamespace

    from batch import runner

    monkeypatch.setitem(sys.modules, "bpy", SimpleNamespace(app=SimpleNamespace(module=False)))
    assert runner.inside_blender() and runner.worker_count(None) == 0
    with pytest.raises(options.BatchError, match="worker processes need a Python with the bpy module"):
        runner.worker_count(2)
    monkeypatch.setitem(sys.modules, "bpy", SimpleNamespace(app=SimpleNamespace(module=True)))
    assert not runner.inside_blender() and runner.worker_count(None) >= 1
    # Blender 4.2 has no bpy.app.module: its executable has a binary path, its module an empty one
    monkeypatch.setitem(sys.modules, "bpy", SimpleNamespace(app=SimpleNamespace(binary_path="/opt/blender/blender")))
    assert runner.inside_blender() and runner.worker_count(None) == 0
    monkeypatch.setitem(sys.modules, "bpy", SimpleNamespace(app=SimpleNamespace(binary_path="")))
    assert not runner.inside_blender() and runner.worker_count(None) >= 1


def test_adaptivity_is_a_job_option_checked_from_0_to_1(tmp_path):
    box, ball, out = tmp_path / "a.stl", tmp_path / "b.stl", tmp_path / "o.ply"
    box.write_bytes(b""), ball.write_bytes(b"")
    parser = options.command_line_parser("")
    base = ["--operation", "union", "--inputs", str(box), str(ball), "--output", str(out)]
    assert parser.parse_args(base).adaptivity == 0.0
    options.check_args(parser.parse_args([*base, "--adaptivity", "0.5"]))
    for bad in ("1.5", "-0.1", "nan"):
        with pytest.raises(options.BatchError, match="--adaptivity must be from 0 to 1"):
            options.check_args(parser.parse_args([*base, "--adaptivity", bad]))


def test_levels_and_padding_under_1_are_refused_before_blender_starts(tmp_path):
    # a padding of 0 leaves the surface's cubes without their nodes: the result would come out open
    box, ball, out = tmp_path / "a.stl", tmp_path / "b.stl", tmp_path / "o.ply"
    box.write_bytes(b""), ball.write_bytes(b"")
    parser = options.command_line_parser("")
    base = ["--operation", "union", "--inputs", str(box), str(ball), "--output", str(out)]
    options.check_args(parser.parse_args([*base, "--padding", "1", "--levels", "1"]))
    options.check_args(parser.parse_args([*base, "--padding", "32", "--levels", "12"]))
    # (a padding of 1,000 kept a kernel busy for minutes: the add-on's ranges)
    for bad in (["--padding", "0"], ["--levels", "0"], ["--padding", "-2"], ["--padding", "33"], ["--levels", "13"]):
        with pytest.raises(options.BatchError, match="--levels must be from 1 to 12 and --padding from 1 to 32"):
            options.check_args(parser.parse_args([*base, *bad]))
    with pytest.raises(options.BatchError, match="--blend-radius must not be negative, not -1.0"):  # (a traceback)
        options.check_args(parser.parse_args([*base, "--blend-radius", "-1"]))
    # an output under a file, or a folder, refused before any work (a traceback after the boolean before)
    (tmp_path / "f").write_bytes(b"")
    (tmp_path / "o.ply").mkdir()
    cases = {tmp_path / "f" / "out.ply": "f is not a folder this process may write in", tmp_path / "o.ply": "a folder"}
    for output, why in cases.items():
        with pytest.raises(options.BatchError, match=f"cannot write {output}: .*{why}"):
            options.check_args(parser.parse_args([*base[:-1], str(output)]))
