"""The manifest and the build tools, without downloading anything: the manifest validates with Blender's own
builder, its wheels match the pinned run-time requirement, and staging keeps exactly the package files."""

import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tools"))

import build_extension  # noqa: E402  (tools/ is not a package)
import fetch_wheels  # noqa: E402
from tests.packaging import package_files, unexpected_in_package  # noqa: E402


def test_manifest_validates_with_blenders_builder():
    builder = fetch_wheels.blender_ext().__file__
    tags = Path(builder).parents[4] / build_extension.TAGS
    done = subprocess.run(
        [sys.executable, builder, "validate", "--valid-tags", str(tags), str(ROOT)],
        capture_output=True,
        text=True,
        check=False,
    )
    assert done.returncode == 0, done.stdout + done.stderr


def test_manifest_fields():
    manifest = fetch_wheels.read_manifest()
    assert (manifest["id"], manifest["version"], manifest["type"]) == ("aasdf", "0.1.0", "add-on")
    assert manifest["blender_version_min"] == "4.2.0"
    assert manifest["license"] == ["SPDX:GPL-3.0-or-later"]
    assert set(manifest["platforms"]) == set(fetch_wheels.PIP_PLATFORMS)
    assert set(manifest["permissions"]) == {"files"}


@pytest.mark.parametrize("platform", sorted(fetch_wheels.PIP_PLATFORMS))
def test_each_platform_gets_exactly_one_warp_wheel_of_the_pinned_version(platform):
    (requirement,) = fetch_wheels.RUNTIME_REQUIREMENTS
    name, version = requirement.split("==")
    wheels = [Path(w).name for w in fetch_wheels.wheels_for(platform)]
    assert len(wheels) == 1
    assert wheels[0].startswith(f"{name.replace('-', '_')}-{version}-py3-none-")
    assert fetch_wheels.PIP_PLATFORMS[platform] in wheels[0]


def test_dev_requirements_pin_the_bundled_warp():
    pins = (ROOT / "requirements-dev.txt").read_text(encoding="utf-8").split()
    assert set(fetch_wheels.RUNTIME_REQUIREMENTS) <= set(pins)


OLDER_BLENDERS = sorted(p.stem.removeprefix("requirements-blender-") for p in ROOT.glob("requirements-blender-*.txt"))


@pytest.mark.parametrize("version", OLDER_BLENDERS)
def test_older_blender_requirements_pin_their_bpy_and_the_bundled_warp(version):
    # the same warp-lang as .venv: the kernels compiled for one serve all (tests/warm_kernels.py)
    pins = (ROOT / f"requirements-blender-{version}.txt").read_text(encoding="utf-8").split()
    assert set(fetch_wheels.RUNTIME_REQUIREMENTS) <= set(pins)
    (bpy,) = [pin for pin in pins if pin.startswith("bpy==")]
    assert bpy.removeprefix("bpy==").startswith(f"{version}.")


def test_the_oldest_blender_tested_is_the_manifest_minimum():
    manifest = tomllib.loads((ROOT / "blender_manifest.toml").read_text(encoding="utf-8"))
    oldest = min(OLDER_BLENDERS, key=lambda v: tuple(map(int, v.split("."))))
    assert manifest["blender_version_min"] == f"{oldest}.0"
    assert {"4.2", "4.5"} <= set(OLDER_BLENDERS)


def test_narrowed_manifest_replaces_only_platforms_and_wheels():
    text = (ROOT / "blender_manifest.toml").read_text(encoding="utf-8")
    wheel = "./wheels/warp_lang-1.19.0-py3-none-manylinux_2_28_x86_64.whl"
    narrowed = tomllib.loads(build_extension.narrowed_manifest(text, ["linux-x64"], [wheel]))
    original = tomllib.loads(text)
    assert (narrowed["platforms"], narrowed["wheels"]) == (["linux-x64"], [wheel])
    assert {k: v for k, v in narrowed.items() if k not in ("platforms", "wheels")} == {
        k: v for k, v in original.items() if k not in ("platforms", "wheels")
    }


def test_stage_copies_the_package_files_and_nothing_else(tmp_path):
    wheel = tmp_path / "warp_lang-1.19.0-py3-none-manylinux_2_28_x86_64.whl"
    wheel.write_bytes(b"not a real wheel")
    # the kernels it compiles into the stage are the install test's business (it builds and installs the real zip)
    stage = build_extension.stage(["linux-x64"], [wheel], stage_dir=tmp_path / "stage", kernels=False)
    staged = {p.relative_to(stage).as_posix() for p in stage.rglob("*") if p.is_file()}
    assert package_files() <= staged
    assert unexpected_in_package(staged) == []
    assert [f for f in staged if f.startswith("wheels/")] == [f"wheels/{wheel.name}"]
    manifest = tomllib.loads((stage / "blender_manifest.toml").read_text(encoding="utf-8"))
    assert manifest["platforms"] == ["linux-x64"]
    assert manifest["wheels"] == [f"./wheels/{wheel.name}"]


def test_unexpected_files_are_caught():
    files = {"__init__.py", "engine/field.py", "tests/conftest.py", "tools/x.py", ".ci/run", "engine/__pycache__/a.pyc"}
    assert unexpected_in_package(files) == [".ci/run", "engine/__pycache__/a.pyc", "tests/conftest.py", "tools/x.py"]
