"""``aasdf_batch.py`` run as a subprocess with the ``bpy`` module: outputs written, bad input refused cleanly."""

import json
import re
import subprocess
import sys
from pathlib import Path

import bpy
import numpy as np
import pytest

from aasdf.aasdf_addon import bridge
from batch.jobs import read_jobs
from tests.blender.scene import NO_OPENVDB, SHIPS_OPENVDB
from tests.metrics import exact_boolean, hausdorff, merge_vertices, mesh_volume, unsigned_distance
from tests.support import is_watertight, load_mesh, mesh_path

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "aasdf_batch.py"


def run_batch(*args, timeout=240):
    return subprocess.run(
        [sys.executable, str(SCRIPT), *map(str, args)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=timeout,
        check=False,
    )


def write_binary_stl(path, verts, tris):
    """A binary STL of (V,3) vertices and (T,3) triangles."""
    v = np.asarray(verts, dtype=np.float32)[tris]
    normals = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]).astype(np.float32)
    record = np.zeros(len(tris), dtype=[("n", "<f4", 3), ("v", "<f4", (3, 3)), ("attr", "<u2")])
    record["n"], record["v"] = normals, v
    with open(path, "wb") as handle:
        handle.write(b"\0" * 80 + np.uint32(len(tris)).tobytes() + record.tobytes())


def imported_world(path):
    """World-space vertices and triangles of the one mesh in a file, imported into an empty scene by Blender's own
    importer (as the batch script imports its inputs), its vertices merged by position."""
    bpy.ops.wm.read_homefile(use_empty=True)
    importer = {".obj": "obj_import", ".ply": "ply_import", ".stl": "stl_import"}[Path(path).suffix]
    getattr(bpy.ops.wm, importer)(filepath=str(path))
    obj = bpy.context.selected_objects[0]
    return merge_vertices(*bridge.evaluated_mesh(obj, bpy.context.evaluated_depsgraph_get()))


def imported_arrays(path):
    """Vertices and triangles of the one mesh in a file, imported into the current (empty) scene."""
    bpy.ops.wm.ply_import(filepath=str(path))
    mesh = bpy.context.selected_objects[0].data
    mesh.calc_loop_triangles()
    verts = np.empty(len(mesh.vertices) * 3, dtype=np.float32)
    mesh.vertices.foreach_get("co", verts)
    tris = np.empty(len(mesh.loop_triangles) * 3, dtype=np.int32)
    mesh.loop_triangles.foreach_get("vertices", tris)
    return verts.reshape(-1, 3), tris.reshape(-1, 3)


@pytest.fixture(scope="module")
def scene_blend(tmp_path_factory):
    """A .blend with two overlapping spheres ``A``, ``B`` (meshes) and an ``Empty``."""
    from tests.support import uv_sphere

    bpy.ops.wm.read_homefile(use_empty=True)
    for name, x in (("A", 0.0), ("B", 0.7)):
        mesh = bpy.data.meshes.new(name)
        verts, tris = uv_sphere(1.0, center=(x, 0.0, 0.0), rings=16, segments=32)
        mesh.from_pydata(verts.tolist(), [], tris.tolist())
        bpy.context.scene.collection.objects.link(bpy.data.objects.new(name, mesh))
    bpy.context.scene.collection.objects.link(bpy.data.objects.new("Empty", None))
    path = tmp_path_factory.mktemp("scene") / "scene.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path), copy=True)
    return path


def test_mesh_files_in_ply_and_debug_volume_out(tmp_path):
    verts, tris = load_mesh("spot.obj")
    # The OBJ importer turns Y-up into Z-up; the STL importer keeps axes: shift along the imported X anyway.
    stl = tmp_path / "shifted.stl"
    write_binary_stl(stl, verts[:, [0, 2, 1]] * [1, -1, 1] + np.float32([0.3, 0.0, 0.1]), tris)
    out, vdb = tmp_path / "out" / "union.ply", tmp_path / "union.vdb"
    args = ("--operation", "union", "--inputs", mesh_path("spot.obj"), stl, "--resolution", 64, "--output", out)
    if not SHIPS_OPENVDB:  # Blender 4.2: the debug volume is refused before any work; the boolean runs without it
        refused = run_batch(*args, "--debug-volume", vdb)
        assert refused.returncode == 2 and refused.stdout == "", refused.stdout[-3000:]
        assert re.fullmatch(f"aasdf_batch: error: {NO_OPENVDB}.*; run it without --debug-volume\n", refused.stderr)
        assert not out.exists() and not vdb.exists()
    done = run_batch(*args, *(("--debug-volume", vdb) if SHIPS_OPENVDB else ()))
    assert done.returncode == 0, done.stderr[-3000:]
    summary = [line for line in done.stdout.splitlines() if line.startswith("aasdf_batch: union of 2 operands")]
    assert len(summary) == 1, done.stdout[-3000:]
    # quiet by default: its own lines only (each step, then the summary), none of Warp's or Blender's
    assert all(line.startswith("aasdf_batch: ") for line in done.stdout.splitlines()), done.stdout[-3000:]
    assert "building the fields of spot, shifted" in done.stdout and done.stderr == "", done.stderr[-3000:]
    result_verts, result_tris = imported_arrays(out)
    # the .ply carries spot's UVs, so vertices are split along UV seams: watertight once merged by position
    assert is_watertight(merge_vertices(result_verts, result_tris)[1])
    assert f"{len(result_tris):,} triangles" in summary[0]
    # the union of the inputs as Blender imports them, exactly
    exact = exact_boolean("UNION", *imported_world(mesh_path("spot.obj")), *imported_world(stl))
    voxel = float(summary[0].split("voxel size ")[1].split(",")[0])
    # measured: volume within 0.33 %, Hausdorff p95 0.074 voxel
    assert mesh_volume(result_verts, result_tris) == pytest.approx(mesh_volume(*exact), rel=0.01)
    assert hausdorff(result_verts, result_tris, *exact, n=50_000)["p95"] <= 0.22 * voxel
    if not SHIPS_OPENVDB:
        return
    assert vdb.stat().st_size > 0
    volume = bpy.data.volumes.new("Debug")
    volume.filepath = str(vdb)
    assert volume.grids.load() and "sdf" in volume.grids


def test_objects_of_a_blend_in_blend_out(scene_blend, tmp_path):
    out = tmp_path / "result.blend"
    done = run_batch(
        "--blend", scene_blend, "--objects", "A", "B", "--operation", "difference", "--resolution", 48,
        "--output", out, "--verbose",
    )  # fmt: skip
    assert done.returncode == 0, done.stderr[-3000:]
    assert "Module " in done.stdout and "load on device 'cpu'" in done.stdout  # --verbose: Warp's lines too
    bpy.ops.wm.open_mainfile(filepath=str(out))
    depsgraph = bpy.context.evaluated_depsgraph_get()
    result, a, b = (bridge.evaluated_mesh(bpy.data.objects[name], depsgraph) for name in ("A.aasdf", "A", "B"))
    assert bpy.data.objects["A"].hide_get() and bpy.data.objects["B"].hide_get()
    # A minus B, closed, as the exact difference of the two spheres saved in the .blend
    exact = exact_boolean("DIFFERENCE", *a, *b)
    assert is_watertight(result[1])
    assert mesh_volume(*result) == pytest.approx(mesh_volume(*exact), rel=0.0075)  # measured -0.25 %


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--inputs", "missing.obj", "{spot}"], "input file not found: missing.obj"),
        (["--inputs", "{spot}"], "give at least two operands"),
        (["--inputs", "{spot}", "{spot}", "--output", "out.fbx"], "cannot write out.fbx"),
        # (Blender's importer refusing a file, a file in the output's path, an unreadable .blend: tracebacks before)
        (["--inputs", "{spot}", "{garbage}"], "cannot read {garbage}: "),
        (["--inputs", "{spot}", "{spot}", "--output", "{file}/out.ply"], "cannot write {file}/out.ply: "),
        (["--blend", "{garbage_blend}", "--objects", "A", "B"], "cannot open {garbage_blend}: "),
        # the objects' checks read a .blend as test_objects_of_a_blend_in_blend_out does on every Blender, and refuse
        # as the operator does (tests/blender/test_boolean.py): on the newest Blender only
        pytest.param(
            ["--blend", "{blend}", "--objects", "A", "Nope"], "no object named 'Nope'", marks=pytest.mark.newest_blender
        ),
        pytest.param(
            ["--blend", "{blend}", "--objects", "A", "Empty"],
            "'Empty' is an empty and has no geometry",
            marks=pytest.mark.newest_blender,
        ),
    ],
    ids=[
        *("missing-file", "one-operand", "bad-output", "unreadable-input", "output-under-a-file", "unreadable-blend"),
        *("unknown-object", "no-geometry"),
    ],
)
def test_bad_input_exits_with_a_clear_message(args, message, scene_blend, tmp_path):
    names = {"garbage": tmp_path / "garbage.stl", "garbage_blend": tmp_path / "garbage.blend", "file": tmp_path / "f"}
    for key, path in names.items():  # (an empty .stl: Blender's importer fails to read it)
        path.write_bytes(b"" if key == "garbage" else b"not what it says it is\n" * 4)
    names = {key: str(path) for key, path in names.items()}
    args = [arg.format(spot=mesh_path("spot.obj"), blend=scene_blend, **names) for arg in args]
    message = message.format(**names)
    if "--output" not in args:
        args += ["--output", str(tmp_path / "out.ply")]
    done = run_batch("--operation", "union", *args)
    assert done.returncode == 2, done.stdout[-2000:] + done.stderr[-2000:]
    assert f"aasdf_batch: error: {message}" in done.stderr
    assert "Traceback" not in done.stderr
    assert not (tmp_path / "out.ply").exists()


def test_an_output_that_is_an_input_is_refused_and_the_input_kept(tmp_path):
    """Written over an input, a file was replaced by the result, and the jobs after it that read it gave wrong
    results (an intersection of 0.72 where 0.28 is exact): refused before any work, in a job file the job that would
    write over another's input."""
    cutter = tmp_path / "cutter.obj"
    cutter.write_bytes(Path(mesh_path("spot.obj")).read_bytes())
    before = cutter.read_bytes()
    done = run_batch("--operation", "difference", "--inputs", mesh_path("spot.obj"), cutter, "--output", cutter)
    assert done.returncode == 2 and f"aasdf_batch: error: {cutter} is also an input" in done.stderr, done.stderr
    assert cutter.read_bytes() == before
    jobs = tmp_path / "jobs.jsonl"
    entries = [
        {"inputs": [str(mesh_path("spot.obj")), "cutter.obj"], "operation": "difference", "output": "cutter.obj"},
        {"inputs": [str(mesh_path("spot.obj")), "cutter.obj"], "operation": "union", "output": "other.obj"},
        {"inputs": [str(mesh_path("spot.obj")), "cutter.obj"], "operation": "intersect", "output": "both.ply"},
    ]
    jobs.write_text("\n".join(json.dumps(entry) for entry in entries) + "\n", encoding="utf-8")
    read = read_jobs(jobs, {})
    assert read[0].error == f"{cutter} is also an input: write the result to another file"
    entries[0]["inputs"][1] = str(mesh_path("spot.obj"))  # another job's input, not its own
    jobs.write_text("\n".join(json.dumps(entry) for entry in entries) + "\n", encoding="utf-8")
    read = read_jobs(jobs, {})
    assert read[0].error == f"{cutter} is an input of jobs.jsonl:2: write the result to another file"
    assert not read[1].error and not read[2].error


def test_a_job_file_takes_remesh_as_the_command_line_does(tmp_path):
    """Job keys are the long options without dashes: "remesh" was refused as an unknown key."""
    spot = str(mesh_path("spot.obj"))
    jobs = tmp_path / "jobs.jsonl"
    entries = [{"inputs": [spot, spot], "operation": "union", "output": f"{k}.ply", "remesh": v} for k, v in
               enumerate([True, False, "yes"])]  # fmt: skip
    jobs.write_text("\n".join(json.dumps(entry) for entry in entries) + "\n", encoding="utf-8")
    assert [job.error or job.options["keep_faces"] for job in read_jobs(jobs, {})] == [False, True, False]


def test_unknown_operation_is_an_argument_error():
    done = run_batch("--operation", "xor", "--inputs", "a.obj", "b.obj", "--output", "out.ply")
    assert done.returncode == 2 and "invalid choice: 'xor'" in done.stderr


def test_engine_error_exits_1_and_writes_nothing(tmp_path):
    out = tmp_path / "out.ply"
    spot = mesh_path("spot.obj")
    done = run_batch("--operation", "union", "--inputs", spot, spot, "--voxel-size", 1e-6, "--output", out)
    assert done.returncode == 1, done.stdout[-2000:] + done.stderr[-2000:]
    assert "aasdf_batch: the boolean failed: spot: " in done.stderr
    assert "use a larger voxel size" in done.stderr and not out.exists()


def write_colored_ply(path, verts, tris, colors):
    """An ASCII PLY with per-vertex 8-bit colours."""
    header = [
        "ply",
        "format ascii 1.0",
        f"element vertex {len(verts)}",
        "property float x",
        "property float y",
        "property float z",
        "property uchar red",
        "property uchar green",
        "property uchar blue",
        f"element face {len(tris)}",
        "property list uchar int vertex_indices",
        "end_header",
    ]
    rows = [f"{x:.6f} {y:.6f} {z:.6f} {r} {g} {b}" for (x, y, z), (r, g, b) in zip(verts, colors, strict=True)]
    faces = [f"3 {a} {b} {c}" for a, b, c in tris]
    path.write_text("\n".join(header + rows + faces) + "\n", encoding="ascii")


def test_uvs_reach_an_obj_and_colours_a_ply(tmp_path):
    from tests.support import uv_sphere

    verts, tris = load_mesh("spot.obj")  # spot has UVs
    ball_v, ball_t = uv_sphere(0.4, center=(0.3, 0.2, 0.5), rings=16, segments=32)
    ball_c = np.c_[np.full(len(ball_v), 200), np.full(len(ball_v), 30), np.full(len(ball_v), 60)]
    ply = tmp_path / "ball.ply"
    write_colored_ply(ply, ball_v, ball_t, ball_c)
    for out in (tmp_path / "result.obj", tmp_path / "result.ply"):
        done = run_batch(
            "--operation", "union", "--inputs", mesh_path("spot.obj"), ply, "--resolution", 48, "--output", out
        )
        assert done.returncode == 0, done.stderr[-3000:]
    uvs = [line.split()[1:] for line in (tmp_path / "result.obj").read_text().splitlines() if line.startswith("vt ")]
    assert len(uvs) > 100 and np.ptp(np.asarray(uvs, dtype=float), axis=0).min() > 0.1  # spot's texture coordinates
    # the .obj is the union, closed
    spot = imported_world(mesh_path("spot.obj"))
    exact = exact_boolean("UNION", *spot, ball_v, ball_t)
    verts, tris = imported_world(tmp_path / "result.obj")
    assert is_watertight(tris)
    assert mesh_volume(verts, tris) == pytest.approx(mesh_volume(*exact), rel=0.02)  # measured +0.71 % (at /48)
    # the .ply's colours: the ball's on the faces it gave (its surface, away from spot), none elsewhere
    bpy.ops.wm.read_homefile(use_empty=True)
    bpy.ops.wm.ply_import(filepath=str(tmp_path / "result.ply"))
    mesh = bpy.context.selected_objects[0].data
    points = np.empty(3 * len(mesh.vertices), dtype=np.float32)
    mesh.vertices.foreach_get("co", points)
    points = points.reshape(-1, 3)
    colours = np.empty(4 * len(mesh.vertices), dtype=np.float32)
    assert mesh.color_attributes[0].domain == "POINT"
    mesh.color_attributes[0].data.foreach_get("color_srgb", colours)
    colours = np.rint(colours.reshape(-1, 4)[:, :3] * 255)
    on_ball = np.abs(np.linalg.norm(points - [0.3, 0.2, 0.5], axis=1) - 0.4) < 0.01
    away = unsigned_distance(*spot, points) > 0.1  # a seam's corners blend both sides' colours (measured to 0.06)
    assert (on_ball & away).sum() > 50  # measured 681 at 0.05
    assert np.abs(colours[on_ball & away] - [200, 30, 60]).max() <= 1
    far = np.linalg.norm(points - [0.3, 0.2, 0.5], axis=1) > 0.5  # spot's own faces
    assert np.all(np.abs(colours[far] - [200, 30, 60]).max(axis=1) > 20)


# the --keep-faces / --remesh switch over the add-on's pipeline: its Blender calls (.stl read, .ply written) run on
# every Blender in test_mesh_files_in_ply_and_debug_volume_out, kept faces in tests/blender/test_keep_faces.py
@pytest.mark.newest_blender
def test_faces_are_kept_by_default_and_remeshed_on_request(tmp_path):
    """A 12-triangle box minus a ball: by default the box's own faces stay (a few hundred faces), ``--remesh``
    remeshes everything; both closed, with the same volume."""
    from tests.support import box_mesh, uv_sphere

    box, ball = tmp_path / "box.stl", tmp_path / "ball.stl"
    write_binary_stl(box, *box_mesh())
    write_binary_stl(ball, *uv_sphere(0.6, center=(1.0, 1.0, 1.0), rings=16, segments=32))
    counts, volumes = {}, {}
    for flag in ("--keep-faces", "--remesh"):
        out = tmp_path / f"{flag[2:]}.ply"
        done = run_batch("--operation", "difference", "--inputs", box, ball, "--resolution", 64, "--output", out, flag)
        assert done.returncode == 0, done.stderr[-3000:]
        verts, tris = imported_world(out)
        assert is_watertight(tris)
        counts[flag], volumes[flag] = len(tris), mesh_volume(verts, tris)
    # measured: 1,202 triangles kept against 14,204 remeshed
    assert counts["--keep-faces"] < 0.25 * counts["--remesh"]
    assert volumes["--keep-faces"] == pytest.approx(volumes["--remesh"], rel=5e-3)
