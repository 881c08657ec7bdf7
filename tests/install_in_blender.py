"""Install the built extension zip in a bare ``bpy`` and report what Blender sees, as one JSON line.

Run by ``tests/test_install.py`` with the Python of an isolated venv that holds only ``bpy`` and what pip pulls in
for it (numpy, requests, zstandard, cython: what Blender itself ships), so a wheel missing from the zip cannot be
covered up by the development venv. ``BLENDER_USER_RESOURCES`` must name a throw-away folder.

Usage: ``python -I tests/install_in_blender.py <extension.zip>``
"""

import importlib
import importlib.util
import json
import os
import sys
from pathlib import Path

REPO = "user_default"
PKG_ID = "aasdf"
MODULE = f"bl_ext.{REPO}.{PKG_ID}"
REPORT_PREFIX = "AASDF-INSTALL-REPORT "
CLASSES = ("AASDF_PG_scene", "AASDF_PT_main", "AASDF_PT_main_debug", "AASDF_AddonPreferences")


def registered(bpy, name):
    """Whether a class called ``name`` is registered (PropertyGroups and preferences are not in ``bpy.types``)."""
    bases = (bpy.types.PropertyGroup, bpy.types.AddonPreferences, bpy.types.Panel, bpy.types.Operator)
    return any(base.bl_rna_get_subclass_py(name) is not None for base in bases)


def check_registered(bpy, report):
    """What registration put into Blender: classes, the scene pointer, preferences, operators."""
    report["registered"] = {name: registered(bpy, name) for name in CLASSES}
    report["scene_pointer"] = hasattr(bpy.types.Scene, "aasdf")
    report["scene_resolution"] = bpy.context.scene.aasdf.resolution if report["scene_pointer"] else None
    addon = bpy.context.preferences.addons.get(MODULE)
    report["preferences_device"] = addon.preferences.device if addon and addon.preferences else None
    operators = importlib.import_module(f"{MODULE}.operators")
    report["operators"] = sorted(cls.bl_idname for cls in operators.classes)
    report["operators_missing"] = [cls.bl_idname for cls in operators.classes if not cls.is_registered]


def check_engine(bpy, report):
    """The bundled Warp wheel is importable, and ``runtime.engine()`` puts the kernel cache in the user folder."""
    report["warp_imported_by_register"] = "warp" in sys.modules
    runtime = importlib.import_module(f"{MODULE}.aasdf_addon.runtime")
    engine = runtime.engine()
    import warp

    report["warp_file"] = warp.__file__
    report["engine_module"] = engine.__name__
    report["engine_exports"] = sorted(
        n for n in ("build_field", "union", "intersection", "difference") if hasattr(engine, n)
    )
    report["extension_cache_dir"] = bpy.utils.extension_path_user(MODULE, path="warp-cache")
    report["kernel_cache_dir_before_launch"] = warp.config.kernel_cache_dir

    @warp.kernel
    def double_kernel(values: warp.array(dtype=float)):
        i = warp.tid()
        values[i] = 2.0 * values[i]

    values = warp.array([1.0, 2.0, 3.0], dtype=float, device="cpu")
    warp.launch(double_kernel, dim=3, inputs=[values], device="cpu")
    report["kernel_result"] = values.numpy().tolist()
    report["kernel_cache_dir"] = warp.config.kernel_cache_dir
    report["kernel_cache_entries"] = len(os.listdir(warp.config.kernel_cache_dir))


def check_union_of_two_cubes(bpy, report):
    """The boolean operator in the installed extension: union of two overlapping 2x2x2 cubes (volume 12)."""
    bpy.ops.wm.read_homefile(use_empty=True)
    bpy.ops.mesh.primitive_cube_add(size=2.0, location=(0.0, 0.0, 0.0))
    first = bpy.context.active_object
    bpy.ops.mesh.primitive_cube_add(size=2.0, location=(1.0, 0.0, 0.0))
    second = bpy.context.active_object
    import contextlib
    import io

    import warp

    # Warp names every module it loads, and whether it came from the cache or had to be compiled (at its info level,
    # which the add-on turns down to warnings by default).
    warp.config.log_level = warp.LOG_INFO
    log = io.StringIO()
    with (
        contextlib.redirect_stdout(log),
        bpy.context.temp_override(active_object=first, selected_objects=[first, second]),
    ):
        report["boolean_result"] = sorted(bpy.ops.aasdf.boolean(operation="UNION"))
    warp.config.log_level = warp.LOG_WARNING
    loads = [line for line in log.getvalue().splitlines() if line.startswith("Module ")]
    report["modules_loaded"] = sorted(line.split()[1] for line in loads)
    report["modules_compiled"] = sorted(line.split()[1] for line in loads if "(compiled)" in line)
    result = bpy.data.objects.get(f"{first.name}.aasdf")
    if result is None:
        report["union_volume"] = None
        return
    import numpy as np

    mesh = result.data
    verts = np.empty(len(mesh.vertices) * 3, dtype=np.float32)
    mesh.vertices.foreach_get("co", verts)
    mesh.calc_loop_triangles()
    tris = np.empty(len(mesh.loop_triangles) * 3, dtype=np.int32)
    mesh.loop_triangles.foreach_get("vertices", tris)
    world = np.asarray(result.matrix_world, dtype=np.float64)
    v = verts.reshape(-1, 3).astype(np.float64) @ world[:3, :3].T + world[:3, 3]
    t = v[tris.reshape(-1, 3)]
    report["union_volume"] = float(np.einsum("ij,ij->i", t[:, 0], np.cross(t[:, 1], t[:, 2])).sum() / 6.0)


def check_warm_up(bpy, report):
    """What the warm-up after Blender's start does (``runtime.warm``, here from this thread) in the installed extension:
    the kernels found ready, every engine module loaded by the package's name, none compiled."""
    import contextlib
    import io

    import warp

    runtime = importlib.import_module(f"{MODULE}.aasdf_addon.runtime")
    warp.config.log_level = warp.LOG_INFO
    log = io.StringIO()
    with contextlib.redirect_stdout(log):
        report["warm_up_ready"] = runtime.warm("CPU", runtime.kernel_cache_dir())
    warp.config.log_level = warp.LOG_WARNING
    loads = [line for line in log.getvalue().splitlines() if line.startswith("Module ")]
    report["warm_up_loaded"] = sorted(line.split()[1] for line in loads)
    report["warm_up_compiled"] = sorted(line.split()[1] for line in loads if "(compiled)" in line)


def check_uninstalled(bpy, report, repo_dir):
    """After uninstalling: no add-on entry, classes, scene pointer, package folder or bundled Warp."""
    report["after_uninstall"] = {
        "addon_enabled": MODULE in bpy.context.preferences.addons,
        "classes_left": [name for name in CLASSES if registered(bpy, name)],
        "scene_pointer": hasattr(bpy.types.Scene, "aasdf"),
        "package_dir_exists": os.path.isdir(os.path.join(repo_dir, PKG_ID)),
        "bundled_warp_left": os.path.exists(report["warp_file"]),
    }


def main():
    zip_path = Path(sys.argv[-1]).resolve()
    report = {
        "visible_before_bpy": [
            m for m in ("warp", "scipy", "skimage", "manifold3d", "pytest") if importlib.util.find_spec(m)
        ]
    }
    import bpy

    report["bpy_version"] = bpy.app.version_string
    report["install"] = sorted(
        bpy.ops.extensions.package_install_files(filepath=str(zip_path), repo=REPO, enable_on_install=True)
    )
    report["addon_enabled"] = MODULE in bpy.context.preferences.addons
    repos = bpy.context.preferences.extensions.repos
    repo_index = next(i for i, repo in enumerate(repos) if repo.module == REPO)
    repo_dir = repos[repo_index].directory
    report["package_dir_exists"] = os.path.isdir(os.path.join(repo_dir, PKG_ID))

    check_registered(bpy, report)
    check_engine(bpy, report)
    check_union_of_two_cubes(bpy, report)
    check_warm_up(bpy, report)

    report["uninstall"] = sorted(bpy.ops.extensions.package_uninstall(repo_index=repo_index, pkg_id=PKG_ID))
    check_uninstalled(bpy, report, repo_dir)
    print(REPORT_PREFIX + json.dumps(report), flush=True)


if __name__ == "__main__":
    main()
