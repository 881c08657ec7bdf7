"""The sidebar panels, the node editor's panel and Add menu, and the preferences, drawn headless with a real layout.

The ``bpy`` module has one window whose screen holds a 3D Viewport. ``window_manager.popmenu_begin__internal`` (the
first half of ``popup_menu``) gives a real ``UILayout`` there, so each ``draw`` runs on Blender's layout inside a
``temp_override`` of the viewport's (or a node editor's) sidebar region: the context is Blender's own. The popup is
never shown (``popmenu_end__internal`` needs a real screen and crashes headless; a few KB stay allocated).
``UILayout.introspect()`` lists what was drawn (texts, operators, properties), and Blender's complaints about unknown
properties (printed, not raised) are caught from the process output.
"""

import bpy
import numpy as np
import pytest

from aasdf.aasdf_addon import cache, nodes, pipeline, plan, preferences, runtime
from aasdf.ui import node_editor
from aasdf.ui import panel as sidebar
from tests.support import uv_sphere

SIDEBAR = (
    sidebar.AASDF_PT_main,
    sidebar.AASDF_PT_main_tree,
    sidebar.AASDF_PT_main_stats,
    sidebar.AASDF_PT_main_cache,
    sidebar.AASDF_PT_main_debug,
)
BLENDER_COMPLAINTS = ("not found", "unknown", "Traceback")  # e.g. "rna_uiItemR: property not found: ..."


def add_mesh_object(name, verts, tris, location=(0.0, 0.0, 0.0)):
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata(np.asarray(verts).tolist(), [], np.asarray(tris).tolist())
    obj = bpy.data.objects.new(name, mesh)
    bpy.context.scene.collection.objects.link(obj)
    obj.location = location
    bpy.context.view_layer.update()
    return obj


def select(*objects):
    for obj in bpy.context.view_layer.objects:
        obj.select_set(False)
    for obj in objects:
        obj.select_set(True)
    bpy.context.view_layer.objects.active = objects[0] if objects else None


def area_override(area_type="VIEW_3D"):
    """window / area / sidebar region of the headless window's area of ``area_type``."""
    window = bpy.context.window_manager.windows[0]
    area = next(area for area in window.screen.areas if area.type == area_type)
    region = next(region for region in area.regions if region.type == "UI")
    return {"window": window, "area": area, "region": region}


def flatten(items) -> list[dict]:
    found = []
    for item in items:
        if "items" in item:
            found += flatten(item["items"])
        else:
            found.append(item)
    return found


def drawn_layout(draw_func, area_type="VIEW_3D") -> dict:
    """Run ``draw_func(layout, context)`` on a real layout in ``area_type``'s sidebar; return what it drew.

    Returns:
        ``{"texts": [...], "operators": [...], "props": [...]}`` from ``UILayout.introspect()``.
    """
    wm = bpy.context.window_manager
    with bpy.context.temp_override(**area_override(area_type)):
        popup = wm.popmenu_begin__internal("Test", icon="NONE")
        draw_func(popup.layout, bpy.context)
        items = flatten(popup.layout.introspect())[2:]  # without the popup's title and separator
    return {
        "texts": [item["draw_string"] for item in items if item.get("draw_string")],
        "operators": [item["operator"] for item in items if "operator" in item],
        "props": [item["rna"] for item in items if "rna" in item],
    }


class Owner:
    """Stands in for a panel or menu instance: its ``layout``, and its class's attributes."""

    def __init__(self, cls, layout):
        self._cls, self.layout = cls, layout

    def __getattr__(self, name):
        return getattr(self._cls, name)


def draw_panel(panel_cls, area_type="VIEW_3D") -> dict:
    """A panel's or menu's ``draw`` on a real layout in ``area_type``'s sidebar, and its ``poll`` there.

    Returns:
        As ``drawn_layout``, plus ``"polled"``: the class's ``poll`` (True without one).
    """
    polled = []

    def draw(layout, context):
        polled.append(panel_cls.poll(context) if hasattr(panel_cls, "poll") else True)
        if polled[0]:  # as Blender: no draw() when poll() fails
            panel_cls.draw(Owner(panel_cls, layout), context)

    return {**drawn_layout(draw, area_type), "polled": polled[0]}


@pytest.fixture
def no_work(monkeypatch):
    """Fails the test if a draw() builds, combines or extracts anything."""

    def forbidden(*args, **kwargs):
        raise AssertionError("draw() must not compute")

    monkeypatch.setattr(runtime, "engine", forbidden)
    monkeypatch.setattr(pipeline, "operand_fields", forbidden)
    monkeypatch.setattr(plan, "evaluate", forbidden)
    monkeypatch.setattr(pipeline, "extract", forbidden)


@pytest.fixture
def no_complaints(capfd):
    """Blender prints (does not raise) when a layout names an unknown property or a draw function fails."""
    capfd.readouterr()
    yield
    out, err = capfd.readouterr()
    lines = [line for line in (out + err).splitlines() if "lib.icons" not in line]  # headless: no icons
    complaints = [line for line in lines if any(word in line for word in BLENDER_COMPLAINTS)]
    assert complaints == []


def draw_sidebar() -> dict:
    return {cls.__name__: draw_panel(cls) for cls in SIDEBAR}


@pytest.fixture(autouse=True)
def fresh_run(monkeypatch):
    monkeypatch.setattr(pipeline, "last_run", {})
    cache.clear()
    yield
    cache.clear()


# ---- the sidebar in each state ----


def test_sidebar_with_nothing_selected(no_work, no_complaints):
    bpy.context.scene.aasdf.resolution, bpy.context.scene.aasdf.levels = 96, 5  # not the operator's defaults
    drawn = draw_sidebar()
    main = drawn["AASDF_PT_main"]
    # The operation buttons are there, greyed by poll() (whose message is the tooltip), not hidden.
    booleans = [op for op in main["operators"] if op.startswith("bpy.ops.aasdf.boolean(")]
    assert [op.split("operation=")[1].split(",")[0] for op in booleans] == ["'UNION'", "'INTERSECT'", "'DIFFERENCE'"]
    assert all("resolution=96" in op and "levels=5" in op for op in booleans)  # the scene's settings
    assert [text for text in main["texts"] if text in ("Union", "Intersect", "Difference")] == [
        "Union",
        "Intersect",
        "Difference",
    ]
    assert not bpy.ops.aasdf.boolean.poll()
    props = {prop.split(".")[1].split("[")[0] for prop in main["props"]}
    assert props == {
        "voxel_size",
        "resolution",
        "levels",
        "padding",
        "blend",
        "blend_mode",
        "thickness",
        "sharp_edges",
        "keep_faces",
        "adaptivity",
        "hide_inputs",
    }
    assert "No boolean has run yet" in drawn["AASDF_PT_main_stats"]["texts"]
    assert "0 fields, 0.0 MB of 1,024 MB" in drawn["AASDF_PT_main_cache"]["texts"]
    assert any(op.startswith("bpy.ops.aasdf.clear_cache(") for op in drawn["AASDF_PT_main_cache"]["operators"])
    tree_panel = drawn["AASDF_PT_main_tree"]
    assert sum(op.startswith("bpy.ops.aasdf.tree_from_selection(") for op in tree_panel["operators"]) == 3
    assert not any("evaluate_tree" in op for op in tree_panel["operators"])  # no tree chosen
    assert not bpy.ops.aasdf.tree_from_selection.poll()
    assert "AASDF_PG_scene.debug_volume" in " ".join(drawn["AASDF_PT_main_debug"]["props"])
    assert all(entry["polled"] for entry in drawn.values())


def test_sidebar_with_one_mesh(no_work, no_complaints):
    select(add_mesh_object("Ball", *uv_sphere(1.0, rings=12, segments=24)))
    drawn = draw_sidebar()
    assert sum(op.startswith("bpy.ops.aasdf.boolean(") for op in drawn["AASDF_PT_main"]["operators"]) == 3
    assert not bpy.ops.aasdf.boolean.poll() and bpy.ops.aasdf.debug_volume.poll()
    assert any(op.startswith("bpy.ops.aasdf.debug_volume(") for op in drawn["AASDF_PT_main_debug"]["operators"])


def test_sidebar_shows_the_memory_kept_for_the_next_run(fresh_cache, no_complaints):
    a = add_mesh_object("A", *uv_sphere(1.0, rings=16, segments=32))
    b = add_mesh_object("B", *uv_sphere(1.0, rings=16, segments=32), location=(0.8, 0.0, 0.0))
    for x in (0.8, 0.81):  # the second run frees the first's result: arrays of megabytes
        b.location.x = x
        bpy.context.view_layer.update()
        select(a, b)
        bpy.ops.aasdf.boolean(operation="DIFFERENCE", resolution=256, hide_inputs=False)
    kept = runtime.pooled_bytes()
    assert kept > 0
    assert f"Kept for the next run: {kept / 2**20:.1f} MB" in draw_sidebar()["AASDF_PT_main_cache"]["texts"]
    assert bpy.ops.aasdf.clear_cache() == {"FINISHED"}
    assert runtime.pooled_bytes() == 0
    assert not any(text.startswith("Kept") for text in draw_sidebar()["AASDF_PT_main_cache"]["texts"])


def test_sidebar_with_a_result_and_its_statistics(monkeypatch, no_complaints):
    a = add_mesh_object("A", *uv_sphere(1.0, rings=16, segments=32))
    b = add_mesh_object("B", *uv_sphere(1.0, rings=16, segments=32), location=(0.8, 0.0, 0.0))
    select(a, b)
    bpy.ops.aasdf.boolean(operation="UNION", resolution=48, hide_inputs=False)
    select(a, b)
    bpy.ops.aasdf.tree_from_selection(operation="DIFFERENCE")
    run = dict(pipeline.last_run)
    assert run["object"] == "A.csg"

    def forbidden(*args, **kwargs):
        raise AssertionError("draw() must not compute")

    monkeypatch.setattr(runtime, "engine", forbidden)
    monkeypatch.setattr(pipeline, "operand_fields", forbidden)
    drawn = draw_sidebar()
    stats = drawn["AASDF_PT_main_stats"]["texts"]
    assert "A.csg (A CSG)" in stats
    assert f"Triangles: {run['triangles']:,}" in stats and f"Field nodes: {run['nodes']:,}" in stats
    assert [text for text in stats if text.strip().startswith("Level ")] == [
        f"  Level {level}: {count:,}" for level, count in enumerate(run["level_counts"])
    ]
    assert sum(text.strip().startswith(("Fields:", "Booleans:", "Surface:", "Write:")) for text in stats) == 4
    megabytes = cache.total_bytes() / 2**20
    assert f"2 fields, {megabytes:.1f} MB of 1,024 MB" in drawn["AASDF_PT_main_cache"]["texts"]
    tree_panel = drawn["AASDF_PT_main_tree"]
    assert 'bpy.ops.aasdf.evaluate_tree(tree="A CSG")' in tree_panel["operators"]
    assert any(prop.startswith("AASDF_NT_csg.auto_update") for prop in tree_panel["props"])

    # An invalid tree: its message is shown with the settings.
    tree = bpy.data.node_groups["A CSG"]
    tree.links.remove(tree.nodes["Output"].inputs[0].links[0])
    monkeypatch.undo()
    with pytest.raises(RuntimeError, match="Connect the 'Field' input"):
        bpy.ops.aasdf.evaluate_tree(tree=tree.name)
    assert tree.message in draw_panel(sidebar.AASDF_PT_main_tree)["texts"]


# ---- the node editor ----


def node_editor_with(tree):
    """Turn the headless window's Properties area into a node editor showing ``tree``."""
    window = bpy.context.window_manager.windows[0]
    area = next(area for area in window.screen.areas if area.type == "PROPERTIES")
    area.type = "NODE_EDITOR"
    space = area.spaces.active
    space.tree_type = nodes.TREE
    space.node_tree = tree
    return area


def test_node_editor_sidebar_and_add_menu(no_work, no_complaints):
    tree = bpy.data.node_groups.new("Tree", nodes.TREE)
    node_editor_with(tree)
    drawn = draw_panel(node_editor.AASDF_PT_csg_tree, area_type="NODE_EDITOR")
    assert drawn["polled"]
    assert 'bpy.ops.aasdf.evaluate_tree(tree="Tree")' in drawn["operators"]
    assert {"Auto Update", "Voxel Size", "Resolution", "Levels", "Padding"} <= set(drawn["texts"])
    assert not draw_panel(node_editor.AASDF_PT_csg_tree)["polled"]  # not in the 3D Viewport

    added = draw_panel(bpy.types.NODE_MT_add, area_type="NODE_EDITOR")["texts"]
    assert {"Input", "Boolean", "Output"} <= set(added)
    entries = []
    for menu in (node_editor.AASDF_MT_csg_add_input, node_editor.AASDF_MT_csg_add_boolean):
        entries += draw_panel(menu, area_type="NODE_EDITOR")["operators"]
    for node_type in (nodes.OBJECT, nodes.COLLECTION, nodes.UNION, nodes.INTERSECT, nodes.DIFFERENCE):
        assert any(f"type='{node_type}'" in op or f'type="{node_type}"' in op for op in entries), node_type
        assert bpy.types.Node.bl_rna_get_subclass(node_type) is not None


def test_nodes_draw_their_settings_and_messages(no_complaints):
    tree = bpy.data.node_groups.new("Tree", nodes.TREE)
    node_editor_with(tree)
    node = tree.nodes.new(nodes.DIFFERENCE)
    node.message = "Connect the 'Base' input"
    texts = drawn_layout(lambda layout, context: node.draw_buttons(context, layout), "NODE_EDITOR")["texts"]
    assert "Connect the 'Base' input" in texts and any(text.startswith("Blend") for text in texts)


# ---- preferences ----


def draw_preferences(prefs) -> list[str]:
    return drawn_layout(lambda layout, context: preferences.draw_preferences(layout, prefs))["texts"]


def test_preferences_round_trip(monkeypatch, no_complaints):
    prefs = preferences.get()
    try:
        prefs.device, prefs.cache_limit_mb = "CPU", 256
        prefs = preferences.get()
        assert (prefs.device, prefs.cache_limit_mb) == ("CPU", 256)
        assert cache.limit_bytes() == 256 * 2**20 and runtime.device() == "cpu"
        assert "Cache Memory Limit" in draw_preferences(prefs)

        # With a CUDA device reported by the driver, it is listed and can be chosen; Warp falls back to the CPU
        # when it has no such device (this machine).
        monkeypatch.setattr(preferences, "_cuda_devices", [(0, "Test GPU")])
        monkeypatch.setattr(preferences, "_device_items", None)
        prefs.device = "CUDA_0"
        assert preferences.get().device == "CUDA_0"
        assert "Test GPU (cuda:0)" in draw_preferences(prefs)
        import warp

        assert runtime.device() == ("cuda:0" if warp.get_cuda_device_count() > 0 else "cpu")
    finally:
        prefs.device, prefs.cache_limit_mb = "CPU", 1024
        monkeypatch.undo()
        preferences.reset_devices()
    assert (preferences.get().device, preferences.get().cache_limit_mb) == ("CPU", 1024)


def test_device_list_is_probed_once_and_lazily(monkeypatch):
    calls = []
    monkeypatch.setattr(preferences, "_probe_cuda_devices", lambda: calls.append(1) or [])
    preferences.reset_devices()
    try:
        assert calls == []  # nothing probed until the list is needed
        items = preferences.device_items(preferences.get(), bpy.context)
        assert [item[0] for item in items] == ["CPU"]
        preferences.device_items(preferences.get(), bpy.context)
        assert calls == [1]
    finally:
        monkeypatch.undo()
        preferences.reset_devices()
