"""Download the wheels the extension bundles into ``wheels/``, one set per Blender platform.

Blender ships numpy, so the only run-time dependency to bundle is ``warp-lang`` (``py3-none-<platform>`` wheels).
scikit-image stays a test and benchmark dependency: the engine extracts surfaces with Warp's own marching cubes.
The manifest's ``wheels`` list names the files; this script fetches them with ``pip download`` (skipping files
already present) and fails if a file the manifest names for a requested platform is still missing.

Usage: ``python tools/fetch_wheels.py [--platform linux-x64 ...]`` (default: every platform in the manifest).
Run it with the development venv's Python: it locates Blender's extension builder inside the ``bpy`` module.
"""

from __future__ import annotations

import argparse
import glob
import importlib.util
import os
import subprocess
import sys
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
MANIFEST = ROOT / "blender_manifest.toml"
WHEELS_DIR = ROOT / "wheels"

# Run-time requirements Blender does not ship (keep in step with the manifest's ``wheels``).
RUNTIME_REQUIREMENTS = ("warp-lang==1.19.0",)
PYTHON_VERSION = "3.11"  # Blender 4.2 to 5.0 embed Python 3.11
# Blender platform -> the pip ``--platform`` tag (pip also accepts older compatible tags, e.g. manylinux_2_17).
PIP_PLATFORMS = {
    "linux-x64": "manylinux_2_28_x86_64",
    "windows-x64": "win_amd64",
    "macos-arm64": "macosx_11_0_arm64",
}


def blender_ext():
    """Blender's extension builder ``blender_ext.py``, loaded as a module from the installed ``bpy`` (not imported)."""
    spec = importlib.util.find_spec("bpy")
    if spec is None or not spec.submodule_search_locations:
        raise SystemExit("The 'bpy' module is not installed: run this with .venv/bin/python (make venv).")
    pattern = os.path.join(spec.submodule_search_locations[0], "*", "scripts", "addons_core", "bl_pkg", "cli")
    found = sorted(glob.glob(os.path.join(pattern, "blender_ext.py")))
    if not found:
        raise SystemExit(f"Blender's extension builder was not found under {pattern}")
    module_spec = importlib.util.spec_from_file_location("blender_ext", found[-1])
    module = importlib.util.module_from_spec(module_spec)
    module_spec.loader.exec_module(module)
    return module


def read_manifest(path: Path = MANIFEST) -> dict:
    with open(path, "rb") as handle:
        return tomllib.load(handle)


def wheels_for(platform: str, manifest: dict | None = None) -> list[str]:
    """The manifest's wheel paths (``./wheels/...``) that Blender installs on ``platform``."""
    manifest = read_manifest() if manifest is None else manifest
    return blender_ext().paths_filter_wheels_by_platform(manifest.get("wheels", []), platform)


def fetch(platforms, *, dest: Path = WHEELS_DIR) -> dict[str, list[Path]]:
    """Download the run-time wheels for each platform into ``dest``.

    Args:
        platforms: Blender platform names, e.g. ``["linux-x64"]``.
        dest: Download folder.
    Returns:
        For each platform, the paths of the wheels the manifest names for it.
    Raises:
        SystemExit: If a platform is unknown, pip fails, or a wheel the manifest names is still missing.
    """
    manifest = read_manifest()
    result = {}
    for platform in platforms:
        if platform not in PIP_PLATFORMS or platform not in manifest["platforms"]:
            raise SystemExit(f"Unknown platform {platform!r}: expected one of {sorted(PIP_PLATFORMS)}")
        wanted = [dest / Path(rel).name for rel in wheels_for(platform, manifest)]
        if not all(path.is_file() for path in wanted):
            dest.mkdir(parents=True, exist_ok=True)
            cmd = [sys.executable, "-m", "pip", "download", "--only-binary=:all:", "--no-deps"]
            cmd += ["--platform", PIP_PLATFORMS[platform], "--python-version", PYTHON_VERSION, "--dest", str(dest)]
            print(f"fetch_wheels: {platform}: {' '.join(RUNTIME_REQUIREMENTS)}", flush=True)
            subprocess.run([*cmd, *RUNTIME_REQUIREMENTS], check=True)
        missing = [path.name for path in wanted if not path.is_file()]
        if missing:
            raise SystemExit(
                f"fetch_wheels: {platform}: the manifest names {missing}, which pip did not download: "
                f"update 'wheels' in {MANIFEST.name} to the files now in {dest}"
            )
        result[platform] = wanted
    return result


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--platform", action="append", help="Blender platform (repeatable); default: all")
    args = parser.parse_args(argv)
    for platform, paths in fetch(args.platform or read_manifest()["platforms"]).items():
        for path in paths:
            print(f"{platform}: {path.relative_to(ROOT) if path.is_relative_to(ROOT) else path}")


if __name__ == "__main__":
    main()
