"""The linux-x64 zip installs, runs and uninstalls in a Blender that has only what Blender ships.

Builds the zip with ``tools/build_extension.py`` (CPU kernels only; the warp-lang wheel is downloaded into ``wheels/``
once), then runs ``tests/install_in_blender.py`` with the Python of ``.venv-blender``: a venv holding only ``bpy`` and
what pip pulls in for it (numpy, requests, zstandard, cython), started with ``-I`` and a cleaned environment, so the
development venv's Warp, SciPy and scikit-image are invisible. Blender's user folder is a temporary directory.
"""

import json
import os
import shutil
import subprocess
import sys
import zipfile
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest

from engine.kernels import ENGINE_MODULES
from tests.packaging import package_files, unexpected_in_package

pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parents[1]
BLENDER_VENV = ROOT / ".venv-blender"
LINUX_WHEEL = "wheels/warp_lang-1.19.0-py3-none-manylinux_2_28_x86_64.whl"
MODULE = "bl_ext.user_default.aasdf"


def bpy_requirement() -> str:
    """The ``bpy==...`` pin of requirements-dev.txt, so both venvs run the same Blender."""
    pins = [line.strip() for line in (ROOT / "requirements-dev.txt").read_text(encoding="utf-8").splitlines()]
    (pin,) = [line for line in pins if line.startswith("bpy==")]
    return pin


def blender_python() -> Path:
    """Python of ``.venv-blender``, created (or re-created when the bpy pin changed) with only ``bpy`` in it."""
    python = BLENDER_VENV / "bin" / "python"
    stamp = BLENDER_VENV / "requirement.txt"
    requirement = bpy_requirement()
    if not (python.exists() and stamp.exists() and stamp.read_text(encoding="utf-8") == requirement):
        shutil.rmtree(BLENDER_VENV, ignore_errors=True)
        subprocess.run([sys.executable, "-m", "venv", str(BLENDER_VENV)], check=True)
        subprocess.run([str(python), "-m", "pip", "install", "--disable-pip-version-check", requirement], check=True)
        stamp.write_text(requirement, encoding="utf-8")
    return python


@pytest.fixture(scope="module")
def built_zip(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("dist")
    tool = ROOT / "tools" / "build_extension.py"
    # .venv-blender is made (mostly unpacking bpy) while the zip builds (mostly compiling kernels)
    venv = ThreadPoolExecutor(max_workers=1).submit(blender_python)
    # CPU kernels only, copied from the kernel cache the test run filled (tests/warm_kernels.py) when their hashes
    # match: the PTX a user's zip also holds takes NVRTC about a minute per module and architecture here, so it is
    # left to `make extension` (tests/engine/test_cuda_code.py checks every kernel translates to CUDA)
    cmd = [sys.executable, str(tool), "--platform", "linux-x64", "--output-dir", str(out), "--cuda-archs", ""]
    subprocess.run(cmd, check=True)
    venv.result()
    return out / "aasdf-0.1.0-linux_x64.zip"


@pytest.fixture(scope="module")
def report(built_zip, tmp_path_factory) -> dict:
    """What ``tests/install_in_blender.py`` saw while installing, using and uninstalling the zip."""
    python = blender_python()
    user = tmp_path_factory.mktemp("blender-user")
    env = {k: v for k, v in os.environ.items() if not k.startswith(("PYTHON", "WARP_", "BLENDER_", "VIRTUAL_ENV"))}
    env["BLENDER_USER_RESOURCES"] = str(user)
    script = ROOT / "tests" / "install_in_blender.py"
    done = subprocess.run(
        [str(python), "-I", str(script), str(built_zip)],
        cwd=user,
        env=env,
        capture_output=True,
        text=True,
        timeout=1800,
        check=False,
    )
    lines = [line for line in done.stdout.splitlines() if line.startswith("AASDF-INSTALL-REPORT ")]
    assert done.returncode == 0 and lines, f"exit {done.returncode}\n{done.stdout[-4000:]}\n{done.stderr[-4000:]}"
    result = json.loads(lines[-1].removeprefix("AASDF-INSTALL-REPORT "))
    result["user_dir"] = str(user)
    return result


def test_zip_holds_the_package_and_only_the_linux_wheel(built_zip):
    with zipfile.ZipFile(built_zip) as archive:
        names = set(archive.namelist())
        manifest = archive.read("blender_manifest.toml").decode("utf-8")
    assert package_files() <= names
    assert unexpected_in_package(names) == []
    assert [n for n in names if n.endswith(".whl")] == [LINUX_WHEEL]
    # prebuilt kernels: a CPU object and its metadata for every engine module with kernels, no sources
    for module in ENGINE_MODULES:
        kernels = [n for n in names if n.startswith(f"kernels/wp_engine.{module}_")]
        assert any(n.endswith(".o") for n in kernels) and any(n.endswith(".meta") for n in kernels), module
    assert not [n for n in names if n.startswith("kernels/") and n.endswith((".cpp", ".cu"))]
    assert 'platforms = ["linux-x64"]' in manifest


def test_isolated_python_sees_no_development_packages(report):
    assert report["visible_before_bpy"] == []
    assert report["bpy_version"] == bpy_requirement().split("==")[1]


def test_install_enables_the_add_on(report):
    assert report["install"] == ["FINISHED"]
    assert report["addon_enabled"] is True
    assert report["package_dir_exists"] is True


def test_enabled_add_on_registers_settings_panels_and_operators(report):
    assert report["registered"] == {
        "AASDF_PG_scene": True,
        "AASDF_PT_main": True,
        "AASDF_PT_main_debug": True,
        "AASDF_AddonPreferences": True,
    }
    assert report["scene_pointer"] is True
    assert report["scene_resolution"] == 256
    assert report["preferences_device"] == "CPU"
    assert report["operators_missing"] == []


def test_bundled_warp_is_used_and_caches_kernels_in_the_extension_folder(report):
    user = Path(report["user_dir"]).resolve()
    assert report["warp_imported_by_register"] is False
    assert Path(report["warp_file"]).resolve().is_relative_to(user / "extensions" / ".local")
    assert report["engine_module"] == f"{MODULE}.engine"
    assert report["engine_exports"] == ["build_field", "difference", "intersection", "union"]
    cache = Path(report["extension_cache_dir"])
    assert cache.resolve().is_relative_to(user / "extensions" / ".user" / "user_default" / "aasdf")
    # the engine import initialises Warp (to seed its cache with the prebuilt kernels), which adds its version
    assert Path(report["kernel_cache_dir_before_launch"]).parent == cache
    assert Path(report["kernel_cache_dir"]).parent == cache  # Warp adds its version: warp-cache/1.19.0
    assert report["kernel_result"] == [2.0, 4.0, 6.0]
    assert report["kernel_cache_entries"] >= 1


def test_union_of_two_cubes_in_the_installed_add_on(report):
    assert report["boolean_result"] == ["FINISHED"]
    assert report["union_volume"] == pytest.approx(12.0, rel=0.02)


def test_first_boolean_loads_prebuilt_kernels_instead_of_compiling(report):
    # a union of two closed cubes launches the build, the boolean and the extraction (not the hole caps, the winding
    # numbers of open meshes or the field operations), every one of them loaded from the zip's kernels
    launched = {"octree", "distance", "fim", "signs", "build", "prune", "boolean"}
    extraction = {"dual", "extract", "marching"}
    assert launched | extraction <= set(ENGINE_MODULES)
    loaded = {m.removeprefix(f"{MODULE}.engine.") for m in report["modules_loaded"]}
    assert launched <= loaded and loaded & extraction, sorted(loaded)
    assert report["modules_compiled"] == []


def test_the_warm_up_loads_every_other_engine_module_from_the_zips_kernels(report):
    assert report["warm_up_ready"] is True
    loaded = {m.removeprefix(f"{MODULE}.engine.") for m in report["modules_loaded"] + report["warm_up_loaded"]}
    assert loaded == set(ENGINE_MODULES), sorted(set(ENGINE_MODULES) ^ loaded)
    assert report["warm_up_compiled"] == []


def test_uninstall_removes_everything(report):
    assert report["uninstall"] == ["FINISHED"]
    assert report["after_uninstall"] == {
        "addon_enabled": False,
        "classes_left": [],
        "scene_pointer": False,
        "package_dir_exists": False,
        "bundled_warp_left": False,
    }
