"""*Keep Original Faces* in Blender: a quad box with UV maps, materials and a colour minus a cylinder. The faces the
cut leaves alone come back as the box's own quads, every attribute equal to the input's; the result is closed and
matches the exact boolean; switched off, the result is remeshed everywhere."""

import importlib

import bpy
import numpy as np
import pytest

from aasdf.aasdf_addon import pipeline
from tests.blender.scene import add_mesh_object, quad_box, select, world_arrays
from tests.metrics import exact_boolean, hausdorff, mesh_volume
from tests.support import is_watertight, uv_sphere

RESOLUTION = 128


def attribute(mesh, name, prop, width, dtype=np.float32):
    values = np.empty(len(mesh.attributes[name].data) * width, dtype=dtype)
    mesh.attributes[name].data.foreach_get(prop, values)
    return values.reshape(-1, width) if width > 1 else values


def faces_of(mesh):
    """Per face: its corners' vertex positions (as a sorted tuple key) and its loop range."""
    starts = attribute(mesh, ".corner_vert", "value", 1, np.int32)
    loop_start = np.empty(len(mesh.polygons), np.int32)
    mesh.polygons.foreach_get("loop_start", loop_start)
    totals = np.empty(len(mesh.polygons), np.int32)
    mesh.polygons.foreach_get("loop_total", totals)
    co = attribute(mesh, "position", "vector", 3)
    return starts, loop_start, totals, co


def scene():
    """A 2 x 2 x 2 box of six quads (materials per face, "UVMap", a second map, a corner colour), subdivided once so
    that its faces far from the cut are quads of their own, and a 12-sided cylinder through one corner of its top."""
    box = quad_box("Box")
    for k in range(2):
        box.data.materials.append(bpy.data.materials.new(f"Side{k}"))
    n = len(box.data.polygons)
    box.data.attributes.new("material_index", "INT", "FACE").data.foreach_set("value", np.arange(n, dtype=np.int32) % 2)
    uv = attribute(box.data, "UVMap", "vector", 2)
    box.data.attributes.new("Decal", "FLOAT2", "CORNER").data.foreach_set("vector", (0.3 * uv + 0.1).ravel())
    colour = box.data.color_attributes.new("Paint", "FLOAT_COLOR", "CORNER")
    colour.data.foreach_set(
        "color", np.random.default_rng(0).random((len(box.data.loops), 4)).astype(np.float32).ravel()
    )
    bpy.ops.mesh.primitive_cylinder_add(vertices=12, radius=0.3, depth=3.0, location=(0.55, 0.55, 0.0))
    cutter = bpy.context.active_object
    cutter.name = "Cutter"
    bpy.context.view_layer.update()
    return box, cutter


@pytest.fixture
def kept(fresh_cache):
    box, cutter = scene()
    select(box, cutter)
    assert bpy.ops.aasdf.boolean(operation="DIFFERENCE", resolution=RESOLUTION, hide_inputs=False) == {"FINISHED"}
    return box, cutter, bpy.context.active_object, dict(pipeline.last_run)


def test_the_cut_leaves_the_box_quads_as_they_were(kept):
    box, cutter, result, numbers = kept
    src, dst = box.data, result.data
    s_corner, s_start, s_total, s_co = faces_of(src)
    r_corner, r_start, r_total, r_co = faces_of(dst)
    # every quad of the result on the box's corners is one of the box's, corner by corner: positions, UVs, the second
    # map, the colour (the others are quads of the new surface along the seam)
    key = {tuple(np.round(s_co[s_corner[s : s + 4]], 6).ravel()): (s, k) for k, s in enumerate(s_start)}
    corner_set = {frozenset(map(tuple, np.round(s_co[s_corner[s : s + 4]], 6))) for s in s_start}
    box_quads = [
        r
        for r in np.flatnonzero(r_total == 4)
        if frozenset(map(tuple, np.round(r_co[r_corner[r_start[r] : r_start[r] + 4]], 6))) in corner_set
    ]
    assert len(box_quads) >= 60  # the box's 96 quads, less the few the bore comes near: measured 81
    s_uv, r_uv = attribute(src, "UVMap", "vector", 2), attribute(dst, "UVMap", "vector", 2)
    s_decal, r_decal = attribute(src, "Decal", "vector", 2), attribute(dst, "Decal", "vector", 2)
    s_paint, r_paint = attribute(src, "Paint", "color", 4), attribute(dst, "Paint", "color", 4)
    s_mat, r_mat = (
        attribute(src, "material_index", "value", 1, np.int32),
        attribute(dst, "material_index", "value", 1, np.int32),
    )
    for r in box_quads:
        loops = np.arange(r_start[r], r_start[r] + 4)
        found = key.get(tuple(np.round(r_co[r_corner[loops]], 6).ravel()))
        assert found is not None  # the same corners in the same order
        s, face = found
        source_loops = np.arange(s, s + 4)
        np.testing.assert_array_equal(r_co[r_corner[loops]], s_co[s_corner[source_loops]])
        np.testing.assert_array_equal(r_uv[loops], s_uv[source_loops])
        np.testing.assert_array_equal(r_decal[loops], s_decal[source_loops])
        np.testing.assert_array_equal(r_paint[loops], s_paint[source_loops])
        assert dst.materials[r_mat[r]] == src.materials[s_mat[face]]
    assert numbers["faces"] == len(dst.polygons) and numbers["faces"] < 3000


def test_the_kept_result_is_closed_and_exact(kept):
    box, cutter, result, _ = kept
    verts, tris = world_arrays(result)
    assert is_watertight(tris)
    exact = exact_boolean("DIFFERENCE", *world_arrays(box), *world_arrays(cutter))
    h = float(np.linalg.norm(np.ptp(np.r_[world_arrays(box)[0], world_arrays(cutter)[0]], axis=0))) / RESOLUTION
    d = hausdorff(verts, tris, *exact, n=50_000)
    assert d["max"] < 1.0 * h and d["p95"] < 0.05 * h, d  # measured: max 0.3 voxel
    assert mesh_volume(verts, tris) == pytest.approx(mesh_volume(*exact), rel=1e-3)


def test_keep_faces_off_remeshes(fresh_cache):
    box, cutter = scene()
    select(box, cutter)
    assert bpy.ops.aasdf.boolean(
        operation="DIFFERENCE", resolution=RESOLUTION, hide_inputs=False, keep_faces=False
    ) == {"FINISHED"}
    mesh = bpy.context.active_object.data
    totals = np.empty(len(mesh.polygons), np.int32)
    mesh.polygons.foreach_get("loop_total", totals)
    # remeshed: quads and triangles (measured 0.996 quads), as many triangles as before in all
    assert set(np.unique(totals)) == {3, 4} and np.mean(totals == 4) > 0.8
    assert np.sum(totals - 2) > 20_000
    assert bpy.context.scene.aasdf.keep_faces  # on by default


def test_a_copy_moved_by_a_voxel_is_reported_and_the_result_remeshed(fresh_cache):
    # its faces lie within the band of the original's nearly everywhere: nothing worth joining (engine/littlekept.py)
    from aasdf.operators import boolean as boolean_op

    verts, tris = uv_sphere(0.5, rings=24, segments=48)
    voxel = float(np.linalg.norm(np.ptp(verts, axis=0))) / RESOLUTION
    ball = add_mesh_object("Ball", verts, tris)
    copy = add_mesh_object("Copy", verts, tris, location=tuple(voxel * np.array([0.8, 0.56, -0.32])))
    select(ball, copy)
    assert bpy.ops.aasdf.boolean(operation="UNION", resolution=RESOLUTION, hide_inputs=False) == {"FINISHED"}
    (warning,) = boolean_op.last_run["warnings"]
    assert warning.startswith("Keep Original Faces: the inputs' faces lie within a few voxels")
    assert "remeshed" in warning
    result = bpy.context.active_object
    assert len(result.data.polygons) > 5 * len(tris) and is_watertight(world_arrays(result)[1])


def test_kept_faces_that_cannot_be_joined_are_reported_and_the_result_remeshed(fresh_cache, monkeypatch):
    # a join allowed no rounds cannot pair its loops: the user is told, and gets the closed remeshed surface
    from aasdf.aasdf_addon import runtime
    from aasdf.operators import boolean as boolean_op

    monkeypatch.setattr(importlib.import_module(runtime.engine().__name__ + ".hybrid"), "MAX_ROUNDS", 0)
    box, cutter = scene()
    select(box, cutter)
    assert bpy.ops.aasdf.boolean(operation="DIFFERENCE", resolution=RESOLUTION, hide_inputs=False) == {"FINISHED"}
    (warning,) = boolean_op.last_run["warnings"]
    assert warning.startswith("Keep Original Faces: the seams could not be joined") and "remeshed" in warning
    mesh = bpy.context.active_object.data
    assert len(mesh.polygons) > 3000 and is_watertight(world_arrays(bpy.context.active_object)[1])


def test_kept_edges_keep_their_seams_sharpness_and_creases(fresh_cache):
    """The box's UV seams, sharp edges and edge creases come back on the result's edges that are the box's own."""
    box, cutter = scene()
    mesh = box.data
    n = len(mesh.edges)
    rng = np.random.default_rng(1)
    seam, sharp, crease = rng.random(n) < 0.3, rng.random(n) < 0.3, rng.random(n).astype(np.float32)
    mesh.attributes.new("uv_seam", "BOOLEAN", "EDGE").data.foreach_set("value", seam)
    mesh.attributes.new("sharp_edge", "BOOLEAN", "EDGE").data.foreach_set("value", sharp)
    mesh.attributes.new("crease_edge", "FLOAT", "EDGE").data.foreach_set("value", crease)
    select(box, cutter)
    assert bpy.ops.aasdf.boolean(operation="DIFFERENCE", resolution=RESOLUTION, hide_inputs=False) == {"FINISHED"}
    result = bpy.context.active_object.data
    src_co, dst_co = attribute(mesh, "position", "vector", 3), attribute(result, "position", "vector", 3)
    src_edges = attribute(mesh, ".edge_verts", "value", 2, np.int32)
    dst_edges = attribute(result, ".edge_verts", "value", 2, np.int32)
    key = {tuple(sorted(map(tuple, src_co[e]))): k for k, e in enumerate(src_edges)}
    matched = [(k, key[pos]) for k, e in enumerate(dst_edges) if (pos := tuple(sorted(map(tuple, dst_co[e])))) in key]
    assert len(matched) > 100, len(matched)  # the box's edges away from the bore: measured 184 of its 192
    dst, src = np.array(matched).T
    np.testing.assert_array_equal(attribute(result, "uv_seam", "value", 1, bool)[dst], seam[src])
    np.testing.assert_array_equal(attribute(result, "crease_edge", "value", 1)[dst], crease[src])
    assert attribute(result, "sharp_edge", "value", 1, bool)[dst][sharp[src]].all()  # sharp stays sharp


def corner_normals(mesh):
    return attribute_of(mesh.corner_normals, "vector", 3)


def attribute_of(collection, prop, width):
    values = np.empty(len(collection) * width, dtype=np.float32)
    collection.foreach_get(prop, values)
    return values.reshape(-1, width)


@pytest.mark.parametrize("mirrored", [False, True])
def test_kept_faces_keep_their_custom_normals_turned_as_their_faces(mirrored, fresh_cache):
    box, cutter = scene()
    if mirrored:  # both mirrored about their own centres: the same shapes where they were (inverted before)
        box.scale.x = cutter.scale.x = -1.0
        bpy.context.view_layer.update()
    # the box shaded as a ball (each corner's normal along its position), the cylinder's sides radially
    corner_co = attribute(box.data, "position", "vector", 3)[attribute(box.data, ".corner_vert", "value", 1, np.int32)]
    box.data.normals_split_custom_set(corner_co / np.linalg.norm(corner_co, axis=1, keepdims=True))
    c_co = attribute(cutter.data, "position", "vector", 3)[attribute(cutter.data, ".corner_vert", "value", 1, np.int32)]
    radial = c_co * np.float32([1.0, 1.0, 0.0])
    cutter.data.normals_split_custom_set(radial / np.linalg.norm(radial, axis=1, keepdims=True))
    select(box, cutter)
    assert bpy.ops.aasdf.boolean(operation="DIFFERENCE", resolution=RESOLUTION, hide_inputs=False) == {"FINISHED"}
    result = bpy.context.active_object.data
    assert result.has_custom_normals
    r_corner, r_start, r_total, r_co = faces_of(result)
    normals = corner_normals(result)
    at = r_co[r_corner]
    # the box's quads given back whole (the quads on the box's own vertices: the others are new, along the seam): each
    # corner's normal is the box's there (the ball's shading)
    box_points = {tuple(p) for p in np.round(attribute(box.data, "position", "vector", 3), 6).tolist()}
    quads = np.flatnonzero(r_total == 4)
    on_box = np.array([tuple(p) in box_points for p in np.round(at, 6).tolist()])
    quads = quads[on_box[(r_start[quads, None] + np.arange(4))].all(axis=1)]
    quad_corners = (r_start[quads, None] + np.arange(4)).ravel()
    assert len(quads) >= 60  # measured 88
    expected = at[quad_corners] / np.linalg.norm(at[quad_corners], axis=1, keepdims=True)
    assert np.abs(normals[quad_corners] - expected).max() < 3e-4  # measured 9e-5: as Blender stores them
    # the bore's wall: the cylinder's kept faces, turned over, face its axis, their normals with them
    centre = np.float32([0.55, 0.55, 0.0])
    offset = (at - centre) * np.float32([1.0, 1.0, 0.0])
    wall = (np.abs(np.linalg.norm(offset, axis=1) - 0.3) < 1e-4) & (np.abs(at[:, 2]) < 0.9)
    assert wall.sum() >= 60  # measured 160 corners
    inward = -offset[wall] / np.linalg.norm(offset[wall], axis=1, keepdims=True)
    assert np.einsum("ij,ij->i", normals[wall], inward).min() > 0.999  # measured 1 - 1e-7


def test_an_adaptivity_merges_the_seams_new_faces_and_the_result_stays_exact(fresh_cache):
    """With Keep Original Faces, the Adaptivity merges the seam's new faces where flat (within each material's and UV
    island's faces: the box's materials alternate face by face, so little merges here): fewer faces, still closed and
    within the bounds of the exact boolean."""
    counts = []
    for adaptivity in (0.0, 1.0):
        box, cutter = scene()
        select(box, cutter)
        status = bpy.ops.aasdf.boolean(
            operation="DIFFERENCE", resolution=RESOLUTION, hide_inputs=False, adaptivity=adaptivity
        )
        assert status == {"FINISHED"}
        result = bpy.context.active_object
        counts.append(len(result.data.polygons))
        verts, tris = world_arrays(result)
        assert is_watertight(tris)
        d = hausdorff(verts, tris, *exact_boolean("DIFFERENCE", *world_arrays(box), *world_arrays(cutter)))
        voxel = pipeline.last_run["voxel_size"]
        assert d["max"] < 1.0 * voxel and d["p95"] < 0.05 * voxel, d
        for obj in (box, cutter, result):
            bpy.data.objects.remove(obj)
    # measured: 1,282 faces at 0, 855 at 1
    assert counts[1] < 0.9 * counts[0], counts


def test_kept_edges_are_sharp_where_their_source_edges_are_not_where_they_fold(fresh_cache):
    # every kept edge folding past 30 degrees was marked sharp: a smooth-shaded 8-sided cylinder came back flat
    bpy.ops.mesh.primitive_cylinder_add(vertices=8, radius=1.0, depth=2.0)  # 45 degrees between wall faces
    cylinder = bpy.context.active_object
    cylinder.data.shade_smooth()
    sharp_in = np.zeros(len(cylinder.data.edges), dtype=bool)
    ends = attribute(cylinder.data, ".edge_verts", "value", 2, np.int32)
    co = attribute(cylinder.data, "position", "vector", 3)
    vertical = np.abs(co[ends[:, 0], 2] - co[ends[:, 1], 2]) > 1.9
    sharp_in[np.flatnonzero(vertical)[0]] = True  # one wall edge marked sharp by the user
    cylinder.data.attributes.new("sharp_edge", "BOOLEAN", "EDGE").data.foreach_set("value", sharp_in)
    ball = add_mesh_object("Ball", *uv_sphere(0.3, rings=12, segments=24), location=(0.0, 0.0, 1.0))
    select(cylinder, ball)
    assert bpy.ops.aasdf.boolean(operation="DIFFERENCE", resolution=96, hide_inputs=False) == {"FINISHED"}
    result = bpy.context.active_object.data
    ends = attribute(result, ".edge_verts", "value", 2, np.int32)
    co = attribute(result, "position", "vector", 3)
    walls = np.abs(co[ends[:, 0], 2] - co[ends[:, 1], 2]) > 1.9  # the 8 wall edges, kept far from the dimple
    sharp = attribute(result, "sharp_edge", "value", 1, bool).ravel()
    assert walls.sum() == 8 and (sharp & walls).sum() == 1
    # the dimple's rim, where the surface folds into the new faces, is sharp
    rim = (np.abs(co[ends[:, 0], 2] - 1.0) < 1e-4) & (np.linalg.norm(co[ends[:, 0], :2], axis=1) < 0.35)
    assert (sharp & rim).sum() >= 8


@pytest.mark.parametrize("keep", [True, False], ids=["kept", "remeshed"])
def test_the_rendered_and_active_uv_map_and_colour_stay_as_they_were(keep, fresh_cache):
    # written in name order, the first made active and rendered: a material on the default map showed the lightmap
    box = quad_box("Box")
    mesh = box.data
    mesh.uv_layers[0].name = "Texture"
    mesh.uv_layers.new(name="Lightmap")
    for name in ("Wear", "Base"):
        mesh.color_attributes.new(name, "FLOAT_COLOR", "CORNER")
    mesh.color_attributes.active_color_name = "Wear"
    mesh.color_attributes.render_color_index = 0
    mesh.uv_layers.active = mesh.uv_layers["Lightmap"]  # edited, rendered another
    ball = add_mesh_object("Ball", *uv_sphere(0.5, rings=12, segments=24), location=(1.0, 1.0, 1.0))
    select(box, ball)
    assert bpy.ops.aasdf.boolean(operation="DIFFERENCE", resolution=48, hide_inputs=False, keep_faces=keep) == {
        "FINISHED"
    }
    result = bpy.context.active_object.data
    assert [layer.name for layer in result.uv_layers][:2] == ["Texture", "Lightmap"]
    assert next(layer.name for layer in result.uv_layers if layer.active_render) == "Texture"
    assert result.uv_layers.active.name == "Lightmap"
    colours = result.color_attributes
    assert colours.active_color_name == "Wear" and colours[colours.render_color_index].name == "Wear"


def _box_quads_kept(result, box):
    """How many of the result's quads are one of the box's (the same corner positions)."""
    s_corner, s_start, _, s_co = faces_of(box.data)
    r_corner, r_start, r_total, r_co = faces_of(result.data)
    corner_set = {frozenset(map(tuple, np.round(s_co[s_corner[s : s + 4]], 6))) for s in s_start}
    quads = np.flatnonzero(r_total == 4)
    return sum(
        frozenset(map(tuple, np.round(r_co[r_corner[r_start[r] : r_start[r] + 4]], 6))) in corner_set for r in quads
    )


def test_a_mirror_that_lays_every_face_on_another_keeps_the_faces_as_without_it(fresh_cache):
    # the box is symmetric about x: a Mirror modifier (Merge off) lays each face on another. As a defect everywhere it
    # kept none of them (the whole result remeshed, 6.2 s against 0.8 s remeshed at resolution 384)
    box, cutter = scene()
    select(box, cutter)
    assert bpy.ops.aasdf.boolean(operation="DIFFERENCE", resolution=RESOLUTION, hide_inputs=False) == {"FINISHED"}
    plain = bpy.context.active_object
    mirror = box.modifiers.new("Mirror", "MIRROR")
    mirror.use_mirror_merge = False
    bpy.context.view_layer.update()
    select(box, cutter)
    assert bpy.ops.aasdf.boolean(operation="DIFFERENCE", resolution=RESOLUTION, hide_inputs=False) == {"FINISHED"}
    mirrored = bpy.context.active_object
    assert _box_quads_kept(mirrored, box) == _box_quads_kept(plain, box) >= 60  # measured 81 each
    verts, tris = world_arrays(mirrored)
    assert is_watertight(tris)
    assert mesh_volume(verts, tris) == pytest.approx(mesh_volume(*world_arrays(plain)), rel=1e-4)


def test_repeated_faces_are_the_same_corners_in_the_same_turn():
    from aasdf.aasdf_addon.repeats import repeated_faces

    verts = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [1, 0, 0], [0, 0, 2]], dtype=np.float32)
    faces = [
        [0, 1, 2, 3],  # a quad
        [2, 3, 0, 4],  # the same corners (vertex 4 lies on vertex 1), starting elsewhere: repeated
        [3, 2, 1, 0],  # reversed: stays
        [0, 1, 5],  # a triangle
        [1, 2, 3, 0],  # the quad once more: repeated
        [0, 4, 2, 3, 5],  # other corners
    ]
    loop_start = np.cumsum([0] + [len(f) for f in faces[:-1]]).astype(np.int32)
    corner_vert = np.concatenate(faces).astype(np.int32)
    assert repeated_faces(verts, corner_vert, loop_start).tolist() == [False, True, False, False, True, False]


def test_the_last_boolean_reads_its_own_operands_about_its_seams_and_the_cutters_union_whole():
    from aasdf.aasdf_addon.plan import boolean_plan, read_whole

    assert read_whole(("field", 0)) == set()
    assert read_whole(boolean_plan("UNION", 2)) == set()
    assert read_whole(boolean_plan("DIFFERENCE", 2)) == set()
    assert read_whole(boolean_plan("DIFFERENCE", 4)) == {1, 2, 3}  # the first minus the cutters' union
    assert read_whole(boolean_plan("UNION", 3)) == {0, 1}  # (0 | 1) | 2: the odd one out goes up a level
    assert read_whole(boolean_plan("INTERSECT", 4)) == {0, 1, 2, 3}  # (0 & 1) & (2 & 3)
    nested = ("boolean", "UNION", 0.0, "ROUND", [("offset", 0.1, ("field", 0)), ("field", 1)])
    assert read_whole(nested) == {0}  # an offset reads its operand's whole surface
    assert read_whole(("shell", 0.1, "INSIDE", boolean_plan("UNION", 2))) == {0, 1}


def test_a_block_minus_three_cutters_builds_the_cutters_whole_and_the_block_on_demand(fresh_cache, monkeypatch):
    from aasdf.aasdf_addon import runtime

    asked = []
    engine = runtime.engine()
    build_fields = engine.build_fields
    monkeypatch.setattr(
        engine, "build_fields", lambda meshes, **k: asked.append(k["refine"]) or build_fields(meshes, **k)
    )
    box = quad_box("Block")
    cutters = []
    for k in range(3):  # three shapes: three fields (duplicates would share one)
        radius, x = 0.2 + 0.05 * k, 0.6 * k - 0.6
        bpy.ops.mesh.primitive_cylinder_add(vertices=12, radius=radius, depth=3.0, location=(x, 0.2, 0.0))
        cutters.append(bpy.context.active_object)
    select(box, *cutters)
    assert bpy.ops.aasdf.boolean(operation="DIFFERENCE", resolution=RESOLUTION, hide_inputs=False) == {"FINISHED"}
    assert asked == [["auto", "all", "all", "all"]]
    kept = bpy.context.active_object
    verts, tris = world_arrays(kept)
    exact = 8.0 - 2.0 * 3.0 * (0.2**2 + 0.25**2 + 0.3**2)  # 12-sided bores 2 deep: 3 r^2 each a unit of depth
    assert is_watertight(tris) and abs(mesh_volume(verts, tris) / exact - 1.0) < 1e-4  # measured 2.6e-5
    asked.clear()
    fresh_cache.clear()
    select(box, *cutters)
    assert bpy.ops.aasdf.boolean(operation="DIFFERENCE", resolution=RESOLUTION, hide_inputs=False, keep_faces=False)
    assert asked == [["all", "all", "all", "all"]]
