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

# The engine's Warp modules with kernels, relative to the engine package (modules of Warp functions only are compiled
# into the modules whose kernels call them). Warp's own sparse marching cubes module is launched only on Warp versions
# other than the pinned one (extract.py's fallback), where prebuilt kernels cannot match anyway: not prebuilt.
ENGINE_MODULES = (
    "octree",
    "layout",
    "neighbours",
    "distance",
    "search",
    "fim",
    "winding",
    "signs",
    "holes",
    "build",
    "field",
    "meshsides",
    "ondemand",
    "closure",
    "sampling",
    "queries",
    "blendzone",
    "prune",
    "boolean",
    "marching",
    "extract",
    "sources",
    "facing",
    "dual",
    "flatness",
    "components",
    "blockedges",
    "edges",
    "sweeping",
    "redistancing",
    "fieldops",
    "keep",
    "leafreads",
    "coplanar",
    "judging",
    "samples",
    "ownside",
    "selfcross",
    "tiling",
    "uncross",
    "zipper",
    "slits",
    "coarsen",
    "collapses",
    "edgehash",
    "jumps",
    "normalsums",
    "quads",
    "coarse",
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


def warp_modules(engine_package: str, names=None) -> list:
    """The engine's Python modules with Warp kernels (``names``: only these of ``ENGINE_MODULES``)."""
    chosen = ENGINE_MODULES if names is None else [name for name in ENGINE_MODULES if name in names]
    return [importlib.import_module(f"{engine_package}.{name}") for name in chosen]


def modules_to_compile(engine_package: str, device) -> list:
    """The engine's Python modules (``warp_modules``) whose kernels Warp's kernel cache does not hold for ``device``
    yet: those the first launch would compile (seconds each) rather than load.

    Args:
        engine_package: The engine's package name (``engine``, or the add-on's ``<addon>.engine``).
        device: A Warp device or its alias.
    Returns:
        The modules, in ``ENGINE_MODULES`` order (empty when all are compiled).
    """
    import warp as wp

    device = wp.get_device(device)
    cache = Path(wp.config.kernel_cache_dir)
    # a CPU module is compiled with one thread per block: its hash (and folder) is that variant's
    block_dim, pattern = (1, "*.o") if device.is_cpu else (None, "*.sm*")
    return [
        module
        for module in warp_modules(engine_package)
        if not any((cache / wp.get_module(module.__name__).get_module_identifier(block_dim)).glob(pattern))
    ]


def compile_modules(modules, device, report=None, *, workers: int | None = None) -> None:
    """Compile (or load) ``modules`` on ``device``, ``workers`` at a time (default: one per core; Warp's compiler
    releases the GIL), so that a first run can show its progress: ``report(done, count, short name)`` is called in
    the caller's thread, with ``(0, count, "")`` first, then as each module is done.

    Raises:
        Whatever compiling a module raised.
    """
    from concurrent.futures import ThreadPoolExecutor, as_completed

    from . import parallel

    if report is not None:
        report(0, len(modules), "")
    with ThreadPoolExecutor(max(1, min(len(modules), workers or os.cpu_count() or 1))) as pool:
        running = {pool.submit(parallel.load_modules, [module], device): module for module in modules}
        for done, future in enumerate(as_completed(running), 1):
            future.result()
            if report is not None:
                report(done, len(modules), running[future].__name__.rpartition(".")[2])


def warm_up(engine_package: str, device) -> None:
    """Load every compiled module of the engine on ``device`` and build the extraction's lookup tables: what a
    process's first boolean would do on its way (the modules' hashes and loads about 0.3 s here when nothing checked
    them before, the tables 0.08 s). Kernels the cache lacks are compiled (seconds each): check first
    (:func:`modules_to_compile`) where that must not happen."""
    from . import dual, parallel

    parallel.load_modules(warp_modules(engine_package), device)
    dual.lookup_tables(device)


def configure_modules(engine_package: str) -> None:
    """Give every module the engine launches the portable CPU flags (before any of them loads)."""
    import warp as wp

    for module in warp_modules(engine_package) + [importlib.import_module(name) for name in WARP_MODULES]:
        wp.set_module_options({"cpu_compiler_flags": PORTABLE_CPU_FLAGS}, module)


def compile_prebuilt(out_dir, *, cuda: bool = True, modules=None, archs=CUDA_ARCHS, reuse=None) -> list[Path]:
    """Compile the engine's modules (imported as the top-level package ``engine``) into ``out_dir``.

    Args:
        out_dir: Folder for the compiled files (created).
        cuda: Also emit PTX for ``archs`` (works without a GPU, through NVRTC).
        modules: Names among ``ENGINE_MODULES`` to compile (default: all), so that several processes can share the
            work.
        archs: CUDA architectures to emit PTX for (default: ``CUDA_ARCHS``).
        reuse: A Warp kernel cache folder (versioned, as ``warp.config.kernel_cache_dir``) whose CPU objects of the
            same modules, with the same hash, are copied instead of compiled (a module's hash covers its source and
            options, so the copy is the object the compiler would write).
    Returns:
        The files written.
    """
    import warp as wp

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    modules = warp_modules(GENERIC_PACKAGE, modules)
    configure_modules(GENERIC_PACKAGE)
    written = []
    for module in modules:
        wp.set_module_options({"block_dim": 1}, module)
        cached = _cached_cpu_files(wp.get_module(module.__name__), reuse)
        if cached:
            for path in cached:
                shutil.copy2(path, out / path.name)
            written += [out / path.name for path in cached]
        else:
            written += wp.compile_aot_module(module, device="cpu", module_dir=out)
        if cuda and archs:
            wp.set_module_options({"block_dim": 256}, module)
            written += wp.compile_aot_module(module, arch=list(archs), module_dir=out, use_ptx=True)
    return [Path(p) for p in written]


def _cached_cpu_files(module, cache) -> list[Path]:
    """A module's CPU object and metadata in a kernel cache (empty when either is missing)."""
    if cache is None:
        return []
    folder = Path(cache) / module.get_module_identifier(block_dim=1)
    objects, metas = sorted(folder.glob("*.o")), sorted(folder.glob("*.meta"))
    return objects + metas if len(objects) == 1 and len(metas) == 1 else []


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
