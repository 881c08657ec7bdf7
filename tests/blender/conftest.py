"""Blender tests run headless on the ``bpy`` module: the add-on is registered once per session, and every test starts
from an empty home file (``read_homefile`` keeps add-ons registered; ``read_factory_settings`` would not)."""

import bpy
import pytest

import aasdf
from aasdf.aasdf_addon.preferences import ADDON_ID


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
