"""The engine loaded in the background a few seconds after Blender starts, so that a session's first boolean does not
wait for it.

Importing Warp and the engine, checking Warp's kernel cache and loading the compiled kernels take over a second here (a
session's first boolean of the fandisk less a cylinder at /256: 1.6-2.1 s, the next ones 0.3-0.4 s; after the warm-up,
the first 0.3-0.4 s) and raise the process's memory by about 170 MB. With the preference *Load Engine at Start-Up* (on
by default), a one-shot timer START_DELAY seconds after registration, on Blender's thread, reads what only Blender can
tell (the preferred device, the kernel cache's folder), then starts a daemon thread that does the rest
(:func:`.runtime.warm`). A boolean started meanwhile waits for the thread's import or check (:mod:`.runtime` holds a
lock) rather than doing them again. Nothing is warmed in background mode (``blender -b``: a batch job imports the engine
when it needs it, a render never) nor when a run loaded the engine first; kernels still to compile (a first run in a
checkout) are left to the first run, which shows their progress.
"""

import threading

import bpy

from . import preferences, runtime

# Seconds after registration: Blender's own start-up (and other add-ons') first.
START_DELAY = 2.0

_thread = None


def wanted(prefs, background: bool, loaded: bool) -> bool:
    """Whether to warm the engine: Blender has a window (not ``background``), the preference is on, and nothing
    ``loaded`` it or started to."""
    return not background and prefs is not None and prefs.warm_up and not loaded


def start(choice: str, cache_dir: str) -> threading.Thread:
    """Warm the engine for the device ``choice`` (the preferences' ``device``) from a daemon thread; returns it. Errors
    are left to the first run, which meets them again and reports them."""
    global _thread

    def work():
        try:
            runtime.warm(choice, cache_dir)
        except Exception:  # noqa: BLE001 (the first boolean reports what went wrong, where the user sees it)
            pass

    _thread = threading.Thread(target=work, name="aasdf-warm-up", daemon=True)
    _thread.start()
    return _thread


def start_in_background():
    """The one-shot timer: reads the device and the cache folder on Blender's thread, then starts the warm-up."""
    prefs = preferences.get()
    if wanted(prefs, bpy.app.background, _loaded()):
        start(prefs.device, runtime.kernel_cache_dir())
    return None  # (once)


def _loaded() -> bool:
    return runtime.loaded() or _thread is not None


def register():
    if wanted(preferences.get(), bpy.app.background, _loaded()):
        bpy.app.timers.register(start_in_background, first_interval=START_DELAY, persistent=True)


def unregister():
    if bpy.app.timers.is_registered(start_in_background):
        bpy.app.timers.unregister(start_in_background)
