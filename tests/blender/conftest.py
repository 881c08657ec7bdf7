"""Blender tests run headless on the ``bpy`` module: the add-on is registered once per session, and every test starts
from an empty home file (``read_homefile`` keeps add-ons registered; ``read_factory_settings`` would not). They run
on every Blender the manifest names (``make test``: 5.0 in ``.venv``, 4.2 and 4.5 LTS in ``.venv-blender-4.x``)."""

import bpy
import pytest

import aasdf
from aasdf.aasdf_addon.preferences import ADDON_ID
from batch import shutdown

EXIT_STATUS = pytest.StashKey[int]()


def pytest_sessionfinish(session, exitstatus):
    session.config.stash[EXIT_STATUS] = int(exitstatus)


@pytest.hookimpl(trylast=True)
def pytest_unconfigure(config):
    """The bpy module of Blender 4.2 crashes when its process ends (``batch/shutdown.py``): end pytest's process here,
    with pytest's exit status. Test workers (pytest-xdist) end as their controller tells them."""
    if not hasattr(config, "workerinput") and EXIT_STATUS in config.stash:
        shutdown.end_process(config.stash[EXIT_STATUS])


@pytest.fixture(scope="session", autouse=True)
def addon():
    """The add-on package, registered, with an entry in the preferences (as enabling it in Blender gives)."""
    addons = bpy.context.preferences.addons
    added = ADDON_ID not in addons
    if added:  # as addon_utils.enable(default_set=True) does, before register()
        addons.new().module = ADDON_ID
    aasdf.register()
    yield aasdf
    if added and ADDON_ID in bpy.context.preferences.addons:
        bpy.context.preferences.addons.remove(bpy.context.preferences.addons[ADDON_ID])
    aasdf.unregister()


@pytest.fixture
def fresh_cache():
    """An empty field cache with its counters at zero, emptied again after the test."""
    from aasdf.aasdf_addon import cache

    cache.clear()
    cache.reset_stats()
    yield cache
    cache.clear()


@pytest.fixture(autouse=True)
def empty_scene(addon):
    """Start each test from an empty scene; fetch ``bpy.context`` references again after this."""
    bpy.ops.wm.read_homefile(use_empty=True)
    yield
