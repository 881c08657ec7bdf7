"""What result faces carry over from their operands: per-face materials, UV maps, colour attributes, shading and the
operand each face came from; checked on a cube with six materials, two UV maps and a colour gradient minus a
UV-mapped sphere with a material and a byte colour of its own, sharp and blended."""

import bpy
import numpy as np
import pytest

from aasdf.aasdf_addon import transfer
from tests.blender.scene import select, world_arrays
from tests.metrics import closest_triangles

RESOLUTION = 96
CENTRE, RADIUS = np.array([1.0, 1.0, 1.0]), 0.8


def attribute(mesh, name, prop, width, dtype=np.float32):
    values = np.empty(len(mesh.attributes[name].data) * width, dtype=dtype)
    mesh.attributes[name].data.foreach_get(prop, values)
    return values.reshape(-1, width) if width > 1 else values


def face_sizes(mesh) -> np.ndarray:
    """(F,) corners of each face (a remeshed result's quads and triangles)."""
    sizes = np.empty(len(mesh.polygons), np.int32)
    mesh.polygons.foreach_get("loop_total", sizes)
    return sizes


def face_centres(mesh, verts) -> np.ndarray:
    """(F, 3) mean of each face's corners."""
    sizes = face_sizes(mesh)
    corners = verts[attribute(mesh, ".corner_vert", "value", 1, np.int32)]
    return np.add.reduceat(corners, np.cumsum(sizes) - sizes, axis=0) / sizes[:, None]


def corner_table(obj):
    """(T, 3) loop indices and (T,) polygon of each loop triangle of an object's mesh."""
    mesh = obj.data
    mesh.calc_loop_triangles()
    loops = np.empty(3 * len(mesh.loop_triangles), np.int32)
    mesh.loop_triangles.foreach_get("loops", loops)
    polys = np.empty(len(mesh.loop_triangles), np.int32)
    mesh.loop_triangles.foreach_get("polygon_index", polys)
    return loops.reshape(-1, 3), polys


def scene():
    """The cube (2 x 2 x 2 at the origin, face k with material k, UV maps "UVMap" and "Decal", a float point colour
    "Tint" linear in position) and the sphere (material "Ball", "UVMap", a byte corner colour "Shade" linear in z)."""
    bpy.ops.mesh.primitive_cube_add(size=2.0)
    cube = bpy.context.active_object
    cube.name = "Cube"
    for k in range(6):
        cube.data.materials.append(bpy.data.materials.new(f"Side{k}"))
    cube.data.attributes.new("material_index", "INT", "FACE").data.foreach_set("value", np.arange(6, dtype=np.int32))
    uv = attribute(cube.data, "UVMap", "vector", 2)
    cube.data.attributes.new("Decal", "FLOAT2", "CORNER").data.foreach_set("vector", (0.5 * uv + 0.25).ravel())
    co = attribute(cube.data, "position", "vector", 3)
    tint = cube.data.color_attributes.new("Tint", "FLOAT_COLOR", "POINT")
    tint.data.foreach_set("color", np.c_[(co + 1.0) / 2.0, np.ones(len(co))].astype(np.float32).ravel())
    bpy.ops.mesh.primitive_uv_sphere_add(radius=RADIUS, location=tuple(CENTRE), segments=48, ring_count=24)
    sphere = bpy.context.active_object
    sphere.name = "Sphere"
    sphere.data.materials.append(bpy.data.materials.new("Ball"))
    sphere.data.shade_smooth()
    corner_vert = attribute(sphere.data, ".corner_vert", "value", 1, np.int32)
    z = attribute(sphere.data, "position", "vector", 3)[corner_vert, 2]
    shade = sphere.data.color_attributes.new("Shade", "BYTE_COLOR", "CORNER")
    level = (z + RADIUS) / (2.0 * RADIUS)
    shade.data.foreach_set("color", np.c_[level, level, level, np.ones(len(z))].astype(np.float32).ravel())
    bpy.context.view_layer.update()
    return cube, sphere


def source_values(obj, name, points, prop="vector", width=2):
    """A corner attribute of ``obj`` at the points of its surface closest to ``points``, interpolated on the
    triangle there (the reference a result corner is compared with), and how far away that surface is."""
    verts, tris = world_arrays(obj)
    tri, bary = closest_triangles(verts, tris, points)
    loops, _ = corner_table(obj)
    values = attribute(obj.data, name, prop, width)
    nearest = np.einsum("nk,nkd->nd", bary, verts[tris[tri]])
    return np.einsum("nk,nkd->nd", bary, values[loops[tri]]), np.linalg.norm(nearest - points, axis=1), tri


def seam_distance(obj, points) -> np.ndarray:
    """Distance from each point to the nearest UV seam of ``obj`` (an edge whose two faces' UVs differ)."""
    mesh = obj.data
    corner_vert = attribute(mesh, ".corner_vert", "value", 1, np.int32)
    uv = attribute(mesh, "UVMap", "vector", 2)
    starts = np.empty(len(mesh.polygons), np.int32)
    mesh.polygons.foreach_get("loop_start", starts)
    sizes = np.empty(len(mesh.polygons), np.int32)
    mesh.polygons.foreach_get("loop_total", sizes)
    loop = np.arange(len(corner_vert))
    poly = np.repeat(np.arange(len(starts)), sizes)
    nxt = np.where(loop + 1 < starts[poly] + sizes[poly], loop + 1, starts[poly])  # the next corner of its face
    a, b = corner_vert[loop], corner_vert[nxt]
    key = np.minimum(a, b) * len(mesh.vertices) + np.maximum(a, b)
    flip = a > b
    ends_uv = np.where(flip[:, None, None], np.stack([uv[nxt], uv[loop]], 1), np.stack([uv[loop], uv[nxt]], 1))
    order = np.argsort(key, kind="stable")
    key, ends_uv, a, b = key[order], ends_uv[order], a[order], b[order]
    first = np.r_[True, key[1:] != key[:-1]]
    group = np.cumsum(first) - 1
    differs = np.zeros(group.max() + 1, dtype=bool)
    np.logical_or.at(differs, group, np.abs(ends_uv - ends_uv[np.flatnonzero(first)][group]).max(axis=(1, 2)) > 1e-6)
    seam = np.flatnonzero(first & differs[group])
    co = world_arrays(obj)[0]
    p0, p1 = co[a[seam]], co[b[seam]]
    d = p1 - p0
    t = np.clip(np.einsum("nsk,sk->ns", points[:, None] - p0[None], d) / (d * d).sum(1)[None], 0.0, 1.0)
    return np.linalg.norm(points[:, None] - (p0[None] + t[..., None] * d[None]), axis=2).min(axis=1)


@pytest.fixture(params=[0.0, 2.0], ids=["sharp", "blended"])
def result(request, fresh_cache):
    cube, sphere = scene()
    select(cube, sphere)
    blend_voxels = request.param
    voxel = float(np.linalg.norm([2.0 + RADIUS, 2.0 + RADIUS, 2.0 + RADIUS])) / RESOLUTION
    assert bpy.ops.aasdf.boolean(
        operation="DIFFERENCE", resolution=RESOLUTION, blend=blend_voxels * voxel, hide_inputs=False, keep_faces=False
    ) == {"FINISHED"}
    obj = bpy.context.active_object
    verts, tris = world_arrays(obj)
    return {"cube": cube, "sphere": sphere, "obj": obj, "verts": verts, "tris": tris, "voxel": voxel}


def on_surfaces(r, points):
    """Distances from points to the cube and to the sphere."""
    cube_d = np.abs(np.abs(points).max(axis=1) - 1.0)
    sphere_d = np.abs(np.linalg.norm(points - CENTRE, axis=1) - RADIUS)
    return cube_d, sphere_d


def test_faces_take_the_material_of_their_source_face(result):
    r, mesh = result, result["obj"].data
    assert [slot.material.name for slot in r["obj"].material_slots] == [f"Side{k}" for k in range(6)] + ["Ball"]
    centres = face_centres(mesh, r["verts"])
    cube_d, sphere_d = on_surfaces(r, centres)
    h = r["voxel"]
    slots = attribute(mesh, "material_index", "value", 1, np.int32)
    operand = attribute(mesh, transfer.OPERAND_ATTRIBUTE, "value", 1, np.int32)
    # the face of the cube each centre lies on: its polygon's normal
    normals = np.empty(18, np.float32)
    r["cube"].data.polygons.foreach_get("normal", normals)
    axis = np.abs(centres).argmax(axis=1)
    side = np.sign(centres[np.arange(len(centres)), axis])
    facing = np.zeros_like(centres)
    facing[np.arange(len(centres)), axis] = side
    expected_side = np.argmax(facing @ normals.reshape(6, 3).T, axis=1)
    second = np.sort(np.abs(centres), axis=1)[:, 1]
    on_cube = (cube_d < 0.25 * h) & (sphere_d > h) & (second < 1.0 - h)  # away from edges and from the sphere
    on_sphere = (sphere_d < 0.25 * h) & (cube_d > h)
    assert on_cube.sum() > 1000 and on_sphere.sum() > 300
    assert np.mean(slots[on_cube] == expected_side[on_cube]) >= 0.995  # measured: 1.0, sharp and blended
    assert np.mean(slots[on_sphere] == 6) >= 0.995
    np.testing.assert_array_equal(operand[on_cube], 0)
    np.testing.assert_array_equal(operand[on_sphere], 1)
    # shading per face from its source face: the cube is flat, the sphere smooth
    sharp = attribute(mesh, "sharp_face", "value", 1, bool)
    assert sharp[on_cube].all() and not sharp[on_sphere].any()


def test_uvs_are_the_sources_uvs_at_the_closest_point_away_from_seams(result):
    r, mesh = result, result["obj"].data
    h = r["voxel"]
    loops = attribute(mesh, ".corner_vert", "value", 1, np.int32)
    corners = r["verts"][loops]
    got = attribute(mesh, "UVMap", "vector", 2)
    cube_d, sphere_d = on_surfaces(r, corners)
    errors = []
    for obj, near, far in ((r["cube"], cube_d, sphere_d), (r["sphere"], sphere_d, cube_d)):
        rows = np.flatnonzero((near < 0.25 * h) & (far > 2.0 * h))
        expected, _, _ = source_values(obj, "UVMap", corners[rows])
        rows_away = seam_distance(obj, corners[rows]) > h
        errors.append(np.abs(got[rows] - expected).max(axis=1)[rows_away])
    errors = np.concatenate(errors)
    assert len(errors) > 3000
    # measured p95: 6e-8 (float rounding), sharp and blended; the issue asks for 1e-3
    assert np.percentile(errors, 95) <= 1e-6, np.percentile(errors, 95)
    # "Decal" is the cube's alone: the sphere's faces read zeros
    decal = attribute(mesh, "Decal", "vector", 2)
    operand = np.repeat(attribute(mesh, transfer.OPERAND_ATTRIBUTE, "value", 1, np.int32), face_sizes(mesh))
    assert np.all(decal[operand == 1] == 0.0)
    on_cube = (operand == 0) & (cube_d < 0.25 * h) & (sphere_d > 2.0 * h)
    np.testing.assert_allclose(decal[on_cube], 0.5 * got[on_cube] + 0.25, atol=1e-5)


def test_colours_are_interpolated_into_the_corner_domain(result):
    r, mesh = result, result["obj"].data
    h = r["voxel"]
    tint = mesh.color_attributes["Tint"]
    shade = mesh.color_attributes["Shade"]
    assert (tint.domain, tint.data_type) == ("CORNER", "FLOAT_COLOR")
    assert (shade.domain, shade.data_type) == ("CORNER", "BYTE_COLOR")
    loops = attribute(mesh, ".corner_vert", "value", 1, np.int32)
    corners = r["verts"][loops]
    cube_d, sphere_d = on_surfaces(r, corners)
    tint_values = np.empty(4 * len(loops), np.float32)
    tint.data.foreach_get("color", tint_values)
    tint_values = tint_values.reshape(-1, 4)
    on_cube = (cube_d < 0.25 * h) & (sphere_d > 2.0 * h)
    error = np.abs(tint_values[on_cube, :3] - (corners[on_cube] + 1.0) / 2.0).max(axis=1)
    # the gradient, linear in position: measured p95 6e-8 (float rounding); the issue asks for 1/255
    assert np.percentile(error, 95) <= 1e-6, np.percentile(error, 95)
    shade_values = np.empty(4 * len(loops), np.float32)
    shade.data.foreach_get("color", shade_values)
    shade_values = shade_values.reshape(-1, 4)
    on_sphere = (sphere_d < 0.25 * h) & (cube_d > 2.0 * h)
    expected, _, _ = source_values(r["sphere"], "Shade", corners[on_sphere], prop="color", width=4)
    error = np.abs(shade_values[on_sphere, 0] - expected[:, 0])
    assert np.percentile(error, 95) <= 1.0 / 255.0, np.percentile(error, 95)  # measured 0.0016: bytes, twice
    assert np.all(shade_values[on_cube] == 0.0)  # the cube has no "Shade"
