"""Prebuilt kernels: compile the engine's Warp modules ahead of time, and seed a kernel cache with them.

A fresh process compiles every Warp module on first launch (seconds each). ``make extension`` compiles the engine's
modules — and the Warp modules the engine uses (sparse marching cubes) — once, for the CPU of the build machine
and as PTX for common CUDA architectures, into a ``kernels/`` folder shipped in the zip. At run time
:func:`install_prebuilt` copies them into the kernel cache under the module names the engine has there (Blender
loads it as ``bl_ext.<repo>.aasdf.engine``), so the first boolean loads kernels instead of compiling them. A kernel
whose source changed has another hash and simply compiles as before.
"""

from __future__ import annotations

import importlib
import os
import re
import shutil
from pathlib import Path

# The engine's Warp modules, relative to the engine package, and Warp's own modules the engine launches.
ENGINE_MODULES = (
    "octree",
    "distance",
    "fim",
    "signs",
    "holes",
    "build",
    "sampling",
    "boolean",
    "marching",
    "extract",
    "sweeping",
    "redistancing",
    "fieldops",
)
WARP_MODULES = ("warp._src.geometry.sparse_marching_cubes",)
# Prebuilt files name engine modules with this placeholder package.
GENERIC_PACKAGE = "engine"
CUDA_ARCHS = (75, 86, 89, 90)
# Warp's default CPU flags without -march=native: objects built here load on any x86-64 (or arm64) CPU of the same
# platform. The flags are part of each module's hash, so build and run time must agree.
PORTABLE_CPU_FLAGS = (
    "-mllvm=-inline-threshold=9000 -mllvm=-inline-cold-callsite-threshold=3000 -mllvm=-slp-recursion-max-depth=4"
)
# wp_<module>_<7-hex hash><.suffixes>; the folder Warp keeps a module in is the part before the suffixes.
_MODULE_FILE = re.compile(r"^(wp_.+_[0-9a-f]{7})(\..*)?$")


def warp_modules(engine_package: str) -> list:
    """The Python modules whose Warp kernels the engine launches."""
    names = [f"{engine_package}.{name}" for name in ENGINE_MODULES] + list(WARP_MODULES)
    return [importlib.import_module(name) for name in names]


def configure_modules(engine_package: str) -> None:
    """Give every module the engine launches the portable CPU flags (before any of them loads)."""
    import warp as wp

    for module in warp_modules(engine_package):
        wp.set_module_options({"cpu_compiler_flags": PORTABLE_CPU_FLAGS}, module)


def compile_prebuilt(out_dir, *, cuda: bool = True) -> list[Path]:
    """Compile the engine's modules (imported as the top-level package ``engine``) into ``out_dir``.

    Args:
        out_dir: Folder for the compiled files (created).
        cuda: Also emit PTX for ``CUDA_ARCHS`` (works without a GPU, through NVRTC).
    Returns:
        The files written.
    """
    import warp as wp

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    modules = warp_modules(GENERIC_PACKAGE)
    configure_modules(GENERIC_PACKAGE)
    written = []
    for module in modules:
        wp.set_module_options({"block_dim": 1}, module)
        written += wp.compile_aot_module(module, device="cpu", module_dir=out)
        if cuda:
            wp.set_module_options({"block_dim": 256}, module)
            written += wp.compile_aot_module(module, arch=list(CUDA_ARCHS), module_dir=out, use_ptx=True)
    return [Path(p) for p in written]


def install_prebuilt(source_dir, cache_dir, engine_package: str) -> int:
    """Copy prebuilt kernels into a Warp kernel cache, renamed for the engine's package name.

    Args:
        source_dir: Folder written by :func:`compile_prebuilt` (missing: nothing to do).
        cache_dir: Warp's effective kernel cache folder (``warp.config.kernel_cache_dir`` after ``warp.init()``).
        engine_package: The engine's package name in this process, e.g. ``bl_ext.user_default.aasdf.engine``.
    Returns:
        How many files were copied (0 when the cache already has them).
    """
    source, cache = Path(source_dir), Path(cache_dir)
    if not source.is_dir():
        return 0
    copied = 0
    generic = f"wp_{GENERIC_PACKAGE}."
    for path in sorted(source.iterdir()):
        name = path.name
        if path.is_dir() or not name.startswith("wp_"):
            continue
        if name.startswith(generic):
            name = f"wp_{engine_package}." + name[len(generic) :]
        match = _MODULE_FILE.match(name)
        if match is None:
            continue
        target = cache / match.group(1) / name  # Warp's layout: <cache>/wp_<module>_<hash>/<file>
        if target.exists():
            continue
        target.parent.mkdir(parents=True, exist_ok=True)
        tmp = target.with_name(f"{target.name}.tmp{os.getpid()}")
        shutil.copy2(path, tmp)
        os.replace(tmp, target)
        copied += 1
    return copied
