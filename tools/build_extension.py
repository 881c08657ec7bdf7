"""Build the extension zips with Blender's own builder, one per platform: ``dist/aasdf-<version>-<platform>.zip``.

Steps: fetch the platform wheels (``tools/fetch_wheels.py``); copy the files the manifest's
``[build] paths_exclude_pattern`` lets through into a staging folder (``build/extension/``), with the manifest's
``platforms`` and ``wheels`` narrowed to the requested platforms and the wheels hard-linked in; validate it; then run
``blender_ext.py build --split-platforms``. Staging lets one platform be built without the other platforms' wheels.

Usage: ``python tools/build_extension.py [--platform linux-x64 ...] [--output-dir dist]``.
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import subprocess
import sys
import tempfile
import zipfile
from importlib.metadata import version
from pathlib import Path

import fetch_wheels
from fetch_wheels import MANIFEST, ROOT

STAGE_DIR = ROOT / "build" / "extension"
TAGS = "scripts/modules/_bpy_internal/extensions/tags.py"


def _toml_list(key: str, values) -> str:
    body = "".join(f'  "{value}",\n' for value in values)
    return f"{key} = [\n{body}]"


def narrowed_manifest(text: str, platforms, wheels) -> str:
    """The manifest ``text`` with its top-level ``platforms`` and ``wheels`` lists replaced."""
    for key, values in (("platforms", platforms), ("wheels", wheels)):
        text, count = re.subn(rf"(?ms)^{key}\s*=\s*\[.*?\]", _toml_list(key, values), text, count=1)
        if count != 1:
            raise SystemExit(f"build_extension: no top-level '{key} = [...]' in {MANIFEST.name}")
    return text


def stage(platforms, wheel_paths, stage_dir: Path = STAGE_DIR, *, kernels: bool = True, archs=None) -> Path:
    """Copy the package files into ``stage_dir`` as the builder would select them, and (``kernels``) compile the
    prebuilt kernels into it (PTX for ``archs``, default all of ``CUDA_ARCHS``); return ``stage_dir``."""
    builder = blender_ext()
    manifest = fetch_wheels.read_manifest()
    excluded = builder.PathPatternMatch(manifest.get("build", {}).get("paths_exclude_pattern", []))
    if stage_dir.exists():
        shutil.rmtree(stage_dir)
    stage_dir.mkdir(parents=True)
    for folder, dirs, files in os.walk(ROOT):
        rel = Path(folder).relative_to(ROOT)
        dirs[:] = [d for d in dirs if not excluded.test_path(f"{(rel / d).as_posix()}/")]
        for name in files:
            rel_file = (rel / name).as_posix()
            if rel_file == MANIFEST.name or excluded.test_path(rel_file) or os.path.islink(Path(folder) / name):
                continue
            (stage_dir / rel).mkdir(parents=True, exist_ok=True)
            shutil.copy2(Path(folder) / name, stage_dir / rel_file)
    rel_wheels = []
    (stage_dir / "wheels").mkdir()
    for path in wheel_paths:
        target = stage_dir / "wheels" / path.name
        try:
            os.link(path, target)
        except OSError:
            shutil.copy2(path, target)
        rel_wheels.append(f"./wheels/{path.name}")
    text = narrowed_manifest(MANIFEST.read_text(encoding="utf-8"), platforms, rel_wheels)
    (stage_dir / MANIFEST.name).write_text(text, encoding="utf-8")
    if kernels:
        compile_kernels(stage_dir / "kernels", archs)
    return stage_dir


def compile_kernels(out_dir: Path, archs=None) -> list[Path]:
    """Prebuilt Warp kernels for the zip (CPU objects for this platform, PTX for ``archs``, default the common CUDA
    architectures), compiled in fresh processes with empty kernel caches, one per CPU core, each taking every n-th
    module; sources are left out. CPU objects the development kernel cache already holds for the same module hashes
    (``$WARP_CACHE_PATH``, default ``.warp-cache``, as the tests fill it) are copied. See ``engine/kernels.py``."""
    sys.path.insert(0, str(ROOT))
    try:
        from engine.kernels import CUDA_ARCHS, ENGINE_MODULES
    finally:
        sys.path.remove(str(ROOT))
    archs = CUDA_ARCHS if archs is None else archs
    reuse = Path(os.environ.get("WARP_CACHE_PATH", ROOT / ".warp-cache")) / version("warp-lang")
    code = (
        "import sys; sys.path.insert(0, sys.argv[1]); import warp; warp.config.log_level = warp.LOG_WARNING; "
        "from engine import kernels; "
        "kernels.compile_prebuilt(sys.argv[2], modules=sys.argv[3].split(','), "
        "archs=[int(a) for a in sys.argv[4].split(',') if a], reuse=sys.argv[5])"
    )
    workers = max(1, min(os.cpu_count() or 1, len(ENGINE_MODULES)))
    shares = [",".join(ENGINE_MODULES[k::workers]) for k in range(workers)]
    with tempfile.TemporaryDirectory() as caches:
        running = []
        for k, share in enumerate(shares):
            env = {**os.environ, "WARP_CACHE_PATH": os.path.join(caches, str(k))}
            cmd = [sys.executable, "-c", code, str(ROOT), str(out_dir), share, ",".join(map(str, archs)), str(reuse)]
            running.append(subprocess.Popen(cmd, env=env))
        failed = [proc.args for proc in running if proc.wait() != 0]
        if failed:
            raise subprocess.CalledProcessError(1, failed[0])
    for path in out_dir.iterdir():
        if path.suffix in (".cpp", ".cu"):
            path.unlink()
    return sorted(out_dir.iterdir())


def blender_ext():
    return fetch_wheels.blender_ext()


def build(platforms, output_dir: Path, archs=None) -> list[Path]:
    """Fetch wheels, stage and build; return the zips written to ``output_dir``, one per platform (PTX kernels for
    ``archs``, default all of ``CUDA_ARCHS``)."""
    wheels = fetch_wheels.fetch(platforms)
    source = stage(platforms, [path for plat in platforms for path in wheels[plat]], archs=archs)
    script = blender_ext().__file__
    tags = Path(script).parents[4] / TAGS
    output_dir.mkdir(parents=True, exist_ok=True)
    subprocess.run([sys.executable, script, "validate", "--valid-tags", str(tags), str(source)], check=True)
    cmd = [sys.executable, script, "build", "--source-dir", str(source), "--output-dir", str(output_dir)]
    subprocess.run([*cmd, "--valid-tags", str(tags), "--split-platforms"], check=True)
    version = fetch_wheels.read_manifest()["version"]
    zips = [output_dir / f"aasdf-{version}-{platform.replace('-', '_')}.zip" for platform in platforms]
    missing = [str(path) for path in zips if not path.is_file()]
    if missing:
        raise SystemExit(f"build_extension: the builder did not write {missing}")
    return zips


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--platform", action="append", help="Blender platform (repeatable); default: all")
    parser.add_argument("--output-dir", type=Path, default=ROOT / "dist")
    parser.add_argument("--list", action="store_true", help="also list each zip's files")
    parser.add_argument(
        "--cuda-archs", help="comma-separated CUDA architectures to emit PTX for (default: engine.kernels.CUDA_ARCHS)"
    )
    args = parser.parse_args(argv)
    platforms = args.platform or fetch_wheels.read_manifest()["platforms"]
    archs = None if args.cuda_archs is None else [int(a) for a in args.cuda_archs.split(",") if a]
    for path in build(platforms, args.output_dir.resolve(), archs):
        shown = path.relative_to(ROOT) if path.is_relative_to(ROOT) else path
        print(f"built {shown} ({path.stat().st_size / 2**20:.1f} MiB)")
        if args.list:
            with zipfile.ZipFile(path) as archive:
                for info in archive.infolist():
                    print(f"  {info.file_size:>12,d}  {info.filename}")


if __name__ == "__main__":
    main()
