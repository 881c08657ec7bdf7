"""Lazy gateway from the add-on to the engine.

``import warp`` costs about a second, so nothing imports the engine at registration. ``engine()`` imports it on
first use, after pointing Warp's kernel cache at a folder the extension owns, exactly once and before any kernel
is launched.
"""

import os
import tempfile

import bpy

from . import preferences
from .preferences import ADDON_ID

_engine = None


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


def engine():
    """The engine package (``<addon>.engine``), imported on first call.

    Before the import, ``warp.config.kernel_cache_dir`` is set to ``kernel_cache_dir()`` unless Warp was already
    configured or initialised by someone else in this Blender session (another add-on sharing the same Warp); Warp
    then keeps the folder it has.
    """
    global _engine
    if _engine is None:
        import warp

        if warp.config.kernel_cache_dir is None:  # None until warp.init() or a user sets it
            warp.config.kernel_cache_dir = kernel_cache_dir()
        from .. import engine as module

        _engine = module
    return _engine


def device(context=None) -> str:
    """Warp device for the preferred device: ``"cuda:0"`` when CUDA is chosen and present, otherwise ``"cpu"``."""
    prefs = preferences.get(context)
    if prefs is not None and prefs.device == "CUDA":
        engine()  # configures the kernel cache before Warp initialises
        import warp

        if warp.is_cuda_available():
            return "cuda:0"
    return "cpu"
