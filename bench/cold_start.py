"""Cold start: the first boolean in a fresh Blender process with an empty kernel cache, against the second one.

Each measurement runs in a new process (the ``bpy`` module with the add-on registered from the repository) whose
Warp kernel cache starts empty, once with the prebuilt kernels that ``make extension`` puts in the zip and once
without them. It prints the first and second ``bpy.ops.aasdf.boolean`` times (the field cache is cleared between
them, so both build both fields) and their difference.

    .venv/bin/python bench/cold_start.py [--resolution 128] [--repeat 3]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench.child import run_child  # noqa: E402

CHILD = r"""
import importlib.util, json, sys, time
root, kernels, resolution = sys.argv[1], sys.argv[2], int(sys.argv[3])
import bpy
spec = importlib.util.spec_from_file_location("aasdf", f"{root}/__init__.py", submodule_search_locations=[root])
pkg = importlib.util.module_from_spec(spec); sys.modules["aasdf"] = pkg; spec.loader.exec_module(pkg)
from aasdf.aasdf_addon import runtime
from pathlib import Path
runtime.PREBUILT_KERNELS = Path(kernels)
pkg.register()
bpy.ops.wm.read_homefile(use_empty=True)
bpy.ops.mesh.primitive_uv_sphere_add(radius=1.0, location=(0, 0, 0))
a = bpy.context.active_object
bpy.ops.mesh.primitive_uv_sphere_add(radius=1.0, location=(1.2, 0, 0))
b = bpy.context.active_object
times = []
for _ in range(2):
    bpy.ops.aasdf.clear_cache()
    t0 = time.perf_counter()
    with bpy.context.temp_override(active_object=a, selected_objects=[a, b]):
        bpy.ops.aasdf.boolean(operation="UNION", resolution=resolution, hide_inputs=False)
    times.append(time.perf_counter() - t0)
    bpy.data.objects.remove(bpy.data.objects[f"{a.name}.aasdf"])
print("RESULT " + json.dumps(times))
"""


def run_once(kernels: str, resolution: int) -> list[float]:
    with tempfile.TemporaryDirectory() as cache:
        return run_child(CHILD, kernels, resolution, cache=cache)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--resolution", type=int, default=128)
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args(argv)
    sys.path.insert(0, str(ROOT / "tools"))
    import build_extension

    with tempfile.TemporaryDirectory() as tmp:
        kernels = Path(tmp) / "kernels"
        build_extension.compile_kernels(kernels, archs=[])  # this CPU loads the CPU objects only
        print(f"# Cold start — two unit spheres, UNION at resolution {args.resolution}; medians of {args.repeat} fresh")
        print("# processes, each with an empty kernel cache\n")
        print("| kernels | first boolean s | second boolean s | first − second s |")
        print("|---|---|---|---|")
        for label, folder in (("prebuilt (shipped in the zip)", str(kernels)), ("none (compiled on first use)", "-")):
            runs = [run_once(folder, args.resolution) for _ in range(args.repeat)]
            first = statistics.median(r[0] for r in runs)
            second = statistics.median(r[1] for r in runs)
            print(f"| {label} | {first:.2f} | {second:.2f} | {first - second:+.2f} |")


if __name__ == "__main__":
    main()
