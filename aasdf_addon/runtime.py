"""Lazy gateway from the add-on to the engine.

``import warp`` costs about a second, so nothing imports the engine at registration. ``engine()`` imports it on
first use, after pointing Warp's kernel cache at a folder the extension owns, exactly once and before any kernel
is launched; a few seconds after Blender starts, :mod:`.warmup` does so in a thread of its own (``warm``), and a first
use meanwhile waits for it.
"""

import os
import tempfile
import threading
from contextlib import contextmanager
from pathlib import Path

import bpy

from . import preferences
from .preferences import ADDON_ID

_engine = None
_lock = threading.RLock()  # one import, one Warp start-up and one kernel check at a time, from any thread
# Shipped in the zip by ``make extension`` (absent in a source checkout: kernels then compile on first use).
PREBUILT_KERNELS = Path(__file__).resolve().parents[1] / "kernels"


def kernel_cache_dir() -> str:
    """Folder for Warp's compiled kernels.

    Returns:
        The extension's user folder ``.../extensions/.user/<repo>/aasdf/warp-cache`` when running as an installed
        extension; otherwise (the repository loaded as a plain package, as in the tests) ``$WARP_CACHE_PATH``, or
        ``<tempdir>/aasdf-warp-cache`` when that is unset.
    """
    try:
        path = bpy.utils.extension_path_user(ADDON_ID, path="warp-cache", create=True)
    except ValueError:  # "The package does not name an extension"
        path = ""
    return path or os.environ.get("WARP_CACHE_PATH") or os.path.join(tempfile.gettempdir(), "aasdf-warp-cache")


def verbose() -> bool:
    """Whether Warp may print its start-up banner and a line per module it loads: ``AASDF_VERBOSE=1`` (the batch
    script's ``--verbose``). Quiet by default."""
    return os.environ.get("AASDF_VERBOSE", "") not in ("", "0")


@contextmanager
def _native_stderr_silenced(active: bool):
    """Send what native code writes to stderr to the null device (Warp's library warns at start-up when a machine has
    no CUDA driver, which is no news on a CPU-only machine)."""
    try:
        fd = os.dup(2) if active else None
    except OSError:
        fd = None
    if fd is None:
        yield
        return
    null = os.open(os.devnull, os.O_WRONLY)
    os.dup2(null, 2)
    os.close(null)
    try:
        yield
    finally:
        os.dup2(fd, 2)
        os.close(fd)


def engine(cache_dir: str | None = None):
    """The engine package (``<addon>.engine``), imported on first call (from any thread: the others wait).

    Before the import, ``warp.config.kernel_cache_dir`` is set to ``cache_dir`` or ``kernel_cache_dir()`` (which asks
    Blender: a thread other than Blender's passes it) unless Warp was already configured or initialised by someone
    else in this Blender session (another add-on sharing the same Warp); Warp then keeps the folder it has. Unless
    ``verbose()``, Warp logs warnings only.
    """
    global _engine
    if _engine is not None:
        return _engine
    with _lock:
        if _engine is None:
            import warp

            if warp.config.kernel_cache_dir is None:  # None until warp.init() or a user sets it
                warp.config.kernel_cache_dir = cache_dir or kernel_cache_dir()
            quiet = not verbose()
            if quiet and warp.config.log_level == warp.LOG_INFO:  # Warp's default: nobody chose another
                warp.config.log_level = warp.LOG_WARNING
            from .. import engine as module

            # Kernels compiled when the zip was built, so that the first boolean loads them instead of compiling.
            with _native_stderr_silenced(quiet):
                warp.init()
            module.kernels.install_prebuilt(PREBUILT_KERNELS, warp.config.kernel_cache_dir, module.__name__)
            _engine = module
    return _engine


def loaded() -> bool:
    """Whether the engine was imported in this process (by a run or a warm-up)."""
    return _engine is not None


_kernels_ready: set = set()  # devices whose engine kernels were checked (and compiled if need be) in this process


def prepare_kernels(device: str, report=None, *, compile_missing: bool = True) -> int:
    """Compile the engine's kernels that Warp's kernel cache lacks for ``device`` (a first run in a checkout, or after
    an update; about two minutes for all of them on a CPU here), a module per core at a time, calling
    ``report(done, count, name)`` as each is done (``engine.kernels.compile_modules``); checked once per device and
    process, from any thread. Returns the modules compiled; with ``compile_missing`` False, -1 where some are missing
    (left to compile, the device not marked ready)."""
    if device in _kernels_ready:
        return 0
    module = engine()
    with _lock:
        if device in _kernels_ready:  # (checked by another thread meanwhile)
            return 0
        missing = module.kernels.modules_to_compile(module.__name__, device)
        if missing and not compile_missing:
            return -1
        if missing:
            module.kernels.compile_modules(missing, device, report)
        _kernels_ready.add(device)
    return len(missing)


def warm(choice: str, cache_dir: str) -> bool:
    """What a session's first boolean would wait for, done beforehand (from a thread other than Blender's): the engine
    imported (``cache_dir``: :func:`kernel_cache_dir`, asked of Blender by the caller), its kernels checked for the
    device ``choice`` names (the preferences' ``device``) and loaded, its tables built. Kernels still to compile are
    left to the first run, which shows their progress. Returns whether the kernels were ready."""
    module = engine(cache_dir)
    device = device_of(choice)
    if prepare_kernels(device, compile_missing=False) < 0:
        return False
    module.kernels.warm_up(module.__name__, device)
    return True


def release_memory(keep: int = 0) -> int:
    """Give the engine's pooled pages back to the system beyond ``keep`` bytes (``engine.release_memory``), if the
    engine is loaded; returns the bytes given back."""
    return _engine.release_memory(keep) if _engine is not None else 0


def pooled_bytes() -> int:
    """Bytes of pages the engine keeps for its next arrays (0 while the engine is not loaded): cheap, for panels."""
    return _engine.pooled_bytes() if _engine is not None else 0


def device_fallback(context=None) -> str | None:
    """What to tell when the preferred device is a GPU this machine cannot use (the run goes on the CPU), else None."""
    prefs = preferences.get(context)
    choice = prefs.device if prefs is not None else "CPU"
    if choice.startswith("CUDA") and device(context) == "cpu":
        return f"The preferred device {choice.replace('_', ' ')} cannot be used here: this ran on the CPU"
    return None


def device(context=None) -> str:
    """Warp device for the preferred device: ``"cuda:<n>"`` when ``CUDA_<n>`` is chosen and present, else ``"cpu"``."""
    prefs = preferences.get(context)
    return device_of(prefs.device if prefs is not None else "CPU")


def device_of(choice: str) -> str:
    """Warp device for a choice of the preferences' ``device`` (``"CPU"``, ``"CUDA_<n>"``); asks nothing of Blender."""
    if choice.startswith("CUDA"):
        ordinal = int(choice.partition("_")[2] or 0)
        engine()  # configures the kernel cache before Warp initialises
        import warp

        if warp.is_cuda_available() and ordinal < warp.get_cuda_device_count():
            return f"cuda:{ordinal}"
    return "cpu"
