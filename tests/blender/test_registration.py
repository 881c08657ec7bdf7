"""Registration: what ``aasdf.register()`` adds to Blender, and that unregistering removes all of it."""

import os
import sys
from pathlib import Path

import bpy
import pytest

import aasdf
from aasdf.aasdf_addon import preferences, properties, registration, runtime

PANELS = ("AASDF_PT_main", "AASDF_PT_main_debug")


def registered_state():
    """Everything registration is responsible for, as plain values."""
    return {
        "scene_group": bpy.types.PropertyGroup.bl_rna_get_subclass_py("AASDF_PG_scene") is not None,
        "preferences": bpy.types.AddonPreferences.bl_rna_get_subclass_py("AASDF_AddonPreferences") is not None,
        "scene_pointer": hasattr(bpy.types.Scene, "aasdf"),
        "panels": [name for name in PANELS if hasattr(bpy.types, name)],
        "classes": [cls.__name__ for cls in registration._classes() if cls.is_registered],
    }


ALL_REGISTERED = {
    "scene_group": True,
    "preferences": True,
    "scene_pointer": True,
    "panels": list(PANELS),
    "classes": [cls.__name__ for cls in registration._classes()],
}
NOTHING_REGISTERED = {"scene_group": False, "preferences": False, "scene_pointer": False, "panels": [], "classes": []}


def test_add_on_is_the_repository_loaded_as_a_package():
    assert Path(aasdf.__file__).resolve() == Path(__file__).resolve().parents[2] / "__init__.py"
    assert preferences.ADDON_ID == "aasdf"
    assert sys.modules["aasdf.aasdf_addon.registration"] is registration


def test_register_adds_classes_pointer_and_panels():
    assert registered_state() == ALL_REGISTERED
    assert {"AASDF_PG_scene", "AASDF_AddonPreferences", *PANELS} <= set(ALL_REGISTERED["classes"])


def test_scene_settings_have_their_defaults_and_accept_values():
    settings = bpy.context.scene.aasdf
    defaults = {name: getattr(settings, name) for name in ("resolution", "voxel_size", "levels", "padding", "blend")}
    assert defaults == {"resolution": 256, "voxel_size": 0.0, "levels": 4, "padding": 1, "blend": 0.0}
    assert (settings.hide_inputs, settings.debug_volume) == (True, False)
    settings.resolution = 3  # below the minimum: Blender clamps
    assert settings.resolution == 8
    settings.padding = 0  # (no finest cells about the surface: it would come out open)
    assert settings.padding == 1
    settings.blend = 0.25
    assert settings.blend == pytest.approx(0.25)


def test_operations_are_upper_case_enum_items():
    assert [item[0] for item in properties.OPERATIONS] == ["UNION", "INTERSECT", "DIFFERENCE"]
    assert all(len(item) == 3 and item[0].isupper() for item in properties.OPERATIONS)


def test_preferences_are_reachable_with_defaults():
    prefs = preferences.get()
    assert prefs is not None
    assert (prefs.device, prefs.cache_limit_mb) == ("CPU", 1024)
    # The device list is dynamic: the CPU, then one item per CUDA device the driver reports.
    items = preferences.device_items(prefs, bpy.context)
    assert items[0][0] == "CPU"
    assert [item[0] for item in items[1:]] == [f"CUDA_{n}" for n, _ in preferences.cuda_devices()]


def test_panel_lives_in_the_aasdf_sidebar_tab():
    panel = bpy.types.AASDF_PT_main
    assert (panel.bl_space_type, panel.bl_region_type, panel.bl_category) == ("VIEW_3D", "UI", "AASDF")
    assert bpy.types.AASDF_PT_main_debug.bl_parent_id == "AASDF_PT_main"


def test_unregister_register_round_trip_leaves_nothing_behind():
    bpy.context.scene.aasdf.levels = 7
    aasdf.unregister()
    try:
        assert registered_state() == NOTHING_REGISTERED
        aasdf.unregister()  # a second unregister is harmless
        assert registered_state() == NOTHING_REGISTERED
    finally:
        aasdf.register()
    assert registered_state() == ALL_REGISTERED
    # The pointer is back and usable; the stored value survived (it lives in the scene's ID properties).
    assert bpy.context.scene.aasdf.levels == 7
    bpy.context.scene.aasdf.levels = 3
    assert bpy.context.scene.aasdf.levels == 3


def test_failed_registration_rolls_back(monkeypatch):
    aasdf.unregister()

    class Broken:  # not a bpy type: register_class raises
        is_registered = False

    try:
        monkeypatch.setattr(registration.ui, "classes", (*registration.ui.classes, Broken))
        with pytest.raises(RuntimeError, match="missing bl_rna"):
            aasdf.register()
        assert registered_state() == NOTHING_REGISTERED
    finally:
        monkeypatch.undo()
        aasdf.register()
    assert registered_state() == ALL_REGISTERED


def test_kernel_cache_outside_an_extension_uses_warp_cache_path():
    assert runtime.kernel_cache_dir() == os.environ["WARP_CACHE_PATH"]


def test_engine_is_imported_lazily_once_with_the_cache_configured():
    engine = runtime.engine()
    assert engine is sys.modules["aasdf.engine"]
    assert runtime.engine() is engine
    assert callable(engine.build_field) and issubclass(engine.AasdfError, RuntimeError)
    import warp

    cache = Path(warp.config.kernel_cache_dir).resolve()
    assert cache.is_relative_to(Path(os.environ["WARP_CACHE_PATH"]).resolve())


def test_device_follows_preferences(monkeypatch):
    import warp

    prefs = preferences.get()
    assert runtime.device() == "cpu"
    monkeypatch.setattr(preferences, "_cuda_devices", [(0, "Test GPU")])  # as if the driver reported one
    monkeypatch.setattr(preferences, "_device_items", None)
    prefs.device = "CUDA_0"
    try:
        assert runtime.device() == ("cuda:0" if warp.is_cuda_available() else "cpu")
        # a GPU that cannot be used: the run goes on the CPU and says so (it did silently)
        fallback = runtime.device_fallback()
        assert (fallback is None) if warp.is_cuda_available() else fallback.startswith("The preferred device CUDA 0")
    finally:
        prefs.device = "CPU"
        monkeypatch.undo()
        preferences.reset_devices()


def test_each_setting_has_one_name_and_one_description_everywhere():
    # Scene settings, operators, the CSG tree and its nodes declare their settings through properties.py's factories:
    # a setting shown in two places is the same setting.
    seen = {}
    for cls in registration._classes():
        rna = cls.bl_rna
        if issubclass(cls, bpy.types.Operator):  # an operator's settings are on its properties' type
            rna = getattr(bpy.ops.aasdf, cls.bl_idname.split(".")[1]).get_rna_type()
        # Blender's own base class aside (its module is ``bpy_types`` up to 4.5, ``_bpy_types`` from 5.0)
        base = next(b for b in cls.__mro__[1:] if b.__module__ in ("bpy.types", "bpy_types", "_bpy_types"))
        inherited = {prop.identifier for prop in base.bl_rna.properties}
        for prop in rna.properties:
            if prop.identifier in inherited or prop.identifier == "rna_type":
                continue
            seen.setdefault(prop.identifier, set()).add((prop.name, prop.description, cls.__name__))
    shared = {ident: found for ident, found in seen.items() if len(found) > 1}
    assert {"voxel_size", "resolution", "levels", "padding", "blend", "hide_inputs", "operation"} <= set(shared)
    differing = {ident: found for ident, found in shared.items() if len({(n, d) for n, d, _ in found}) > 1}
    # one identifier, two settings: the sidebar's tree (a pointer) and the tree aasdf.evaluate_tree names (a string)
    assert differing.pop("tree", None) is not None
    assert differing == {}


def test_a_setting_factory_refuses_another_description():
    with pytest.raises(TypeError, match="declared once"):
        properties.blend_property(description="something else")
