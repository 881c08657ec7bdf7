"""A first run in a checkout says it compiles the engine's kernels and shows its progress over the modules: the steps
go to the pipeline's listeners (the batch script prints them) and the status bar."""

import bpy

from aasdf.aasdf_addon import pipeline, runtime
from tests.blender.scene import add_mesh_object, select
from tests.support import uv_sphere


def test_a_first_run_shows_the_kernels_it_compiles_module_by_module(monkeypatch, fresh_cache):
    engine = runtime.engine()
    modules = [engine.octree, engine.distance]  # already compiled here: loading them is quick
    monkeypatch.setattr(runtime, "_kernels_ready", set())
    monkeypatch.setattr(engine.kernels, "modules_to_compile", lambda package, device: list(modules))
    steps = []
    monkeypatch.setattr(pipeline, "progress_listeners", [steps.append])
    a = add_mesh_object("A", *uv_sphere(1.0, rings=16, segments=32))
    b = add_mesh_object("B", *uv_sphere(1.0, rings=16, segments=32), location=(0.5, 0.0, 0.0))
    select(a, b)
    assert bpy.ops.aasdf.boolean(operation="UNION", resolution=32, hide_inputs=False) == {"FINISHED"}
    first = "compiling the engine's kernels for this machine (first run only): "
    compiling = [step for step in steps if step.startswith(first)]
    assert compiling[0] == f"{first}0 of 2 done"
    assert sorted(compiling[1:]) in (
        [f"{first}1 of 2 done, distance", f"{first}2 of 2 done, octree"],
        [f"{first}1 of 2 done, octree", f"{first}2 of 2 done, distance"],
    )
    assert steps.index(compiling[-1]) < steps.index("building the fields of A")  # one geometry
    # checked once per process: the next run says nothing of kernels
    steps.clear()
    select(a, b)
    assert bpy.ops.aasdf.boolean(operation="UNION", resolution=40) == {"FINISHED"}
    assert steps and not any(step.startswith(first) for step in steps)
