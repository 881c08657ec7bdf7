"""Every other attribute an operand holds comes back under its name, domain and type (aasdf_addon/generic_attributes):
bevel weights, a float weight linear in position, integer, boolean and colour face attributes, a vector per corner,
8-bit and 2D integers, rotations and matrices, sculpting's face sets and mask. Checked on a quad box holding them minus
a cylinder holding a face attribute of its own: kept faces, vertices and edges bit for bit, new faces from their source
faces, new vertices read off their source (rotations and matrices never blended: a source's value, or the identity
where the cutter has none)."""

import bpy
import numpy as np
import pytest

from tests.blender.scene import quad_box, select, world_arrays
from tests.metrics import closest_triangles, unsigned_distance

RESOLUTION = 128
GRADIENT = np.array([0.3, 0.2, -0.5])


HAS_INT16_2D = "INT16_2D" in bpy.types.Attribute.bl_rna.properties["data_type"].enum_items.keys()


def read(mesh, name, prop="value", width=1, dtype=np.float32):
    values = np.empty(len(mesh.attributes[name].data) * width, dtype=dtype)
    mesh.attributes[name].data.foreach_get(prop, values)
    return values.reshape(-1, width) if width > 1 else values


def put(mesh, name, kind, domain, values, prop="value"):
    mesh.attributes.new(name, kind, domain).data.foreach_set(prop, np.ascontiguousarray(values).ravel())


def weight(points) -> np.ndarray:
    """The box's "Weight": linear in position."""
    return (np.asarray(points, dtype=np.float64) @ GRADIENT + 1.0).astype(np.float32)


def unit_quaternions(rng, n) -> np.ndarray:
    q = rng.normal(size=(n, 4))
    return (q / np.linalg.norm(q, axis=1, keepdims=True)).astype(np.float32)


def rows_of(values, allowed) -> np.ndarray:
    """Whether each row of ``values`` is one of the rows of ``allowed``, bit for bit."""
    known = {row.tobytes() for row in np.ascontiguousarray(allowed)}
    return np.array([row.tobytes() in known for row in np.ascontiguousarray(values)], dtype=bool)


def scene():
    """The box (2 x 2 x 2, three cuts a side: 96 quads) holding an attribute of each kind, and a 12-sided cylinder
    through a corner of its top with a "Part" of its own (7 on every face)."""
    box = quad_box("Box")
    mesh, rng = box.data, np.random.default_rng(3)
    n_v, n_e, n_f, n_c = len(mesh.vertices), len(mesh.edges), len(mesh.polygons), len(mesh.loops)
    put(mesh, "bevel_weight_edge", "FLOAT", "EDGE", rng.random(n_e).astype(np.float32))
    put(mesh, "bevel_weight_vert", "FLOAT", "POINT", rng.random(n_v).astype(np.float32))
    put(mesh, "Weight", "FLOAT", "POINT", weight(read(mesh, "position", "vector", 3)))
    put(mesh, "Flag", "INT8", "POINT", rng.integers(-5, 5, n_v).astype(np.int8))
    put(mesh, "Part", "INT", "FACE", (np.arange(n_f) % 5 + 1).astype(np.int32))
    put(mesh, "Tag", "BOOLEAN", "FACE", rng.random(n_f) < 0.5)
    put(mesh, "Tone", "FLOAT_COLOR", "FACE", rng.random((n_f, 4)).astype(np.float32), "color")
    put(mesh, "Offset", "FLOAT_VECTOR", "CORNER", rng.random((n_c, 3)).astype(np.float32), "vector")
    put(mesh, "Pair", "INT32_2D", "EDGE", rng.integers(0, 9, (n_e, 2)).astype(np.int32))
    put(mesh, "Turn", "QUATERNION", "POINT", unit_quaternions(rng, n_v))
    put(mesh, "Spin", "QUATERNION", "EDGE", unit_quaternions(rng, n_e))
    put(mesh, "Frame", "FLOAT4X4", "FACE", rng.normal(size=(n_f, 16)).astype(np.float32))
    if HAS_INT16_2D:  # (dropped before; Blender 4.2 has no such type)
        put(mesh, "Short", "INT16_2D", "FACE", rng.integers(-300, 300, (n_f, 2)).astype(np.int16))
    put(mesh, ".sculpt_face_set", "INT", "FACE", (np.arange(n_f) % 3 + 1).astype(np.int32))  # sculpting's, hidden
    put(mesh, ".sculpt_mask", "FLOAT", "POINT", rng.random(n_v).astype(np.float32))
    bpy.ops.mesh.primitive_cylinder_add(vertices=12, radius=0.3, depth=3.0, location=(0.55, 0.55, 0.0))
    cutter = bpy.context.active_object
    cutter.name = "Cutter"
    put(cutter.data, "Part", "INT", "FACE", np.full(len(cutter.data.polygons), 7, np.int32))
    bpy.context.view_layer.update()
    return box, cutter


def faces_of(mesh):
    """Per face: its first corner and corner count; per corner its vertex; the vertex positions."""
    start, total = (np.empty(len(mesh.polygons), np.int32) for _ in range(2))
    mesh.polygons.foreach_get("loop_start", start)
    mesh.polygons.foreach_get("loop_total", total)
    return start, total, read(mesh, ".corner_vert", dtype=np.int32), read(mesh, "position", "vector", 3)


def difference(keep: bool):
    """The box minus the cutter, faces kept or not: box, cutter, result, ``keep``."""
    box, cutter = scene()
    select(box, cutter)
    done = bpy.ops.aasdf.boolean(operation="DIFFERENCE", resolution=RESOLUTION, hide_inputs=False, keep_faces=keep)
    assert done == {"FINISHED"}
    return box, cutter, bpy.context.active_object, keep


@pytest.fixture(params=[True, False], ids=["kept", "remeshed"])
def result(request, fresh_cache):
    return difference(request.param)


def test_attributes_come_back_under_their_name_domain_and_type(result):
    box, _, out, keep = result
    for name in (
        "bevel_weight_vert",
        "Weight",
        "Flag",
        "Part",
        *(("Short",) if HAS_INT16_2D else ()),
        "Tag",
        "Tone",
        "Offset",
        "Turn",
        "Frame",
        ".sculpt_face_set",
        ".sculpt_mask",
    ):
        src, dst = box.data.attributes[name], out.data.attributes.get(name)
        assert dst is not None, name
        assert (dst.domain, dst.data_type) == (src.domain, src.data_type), name
    for name in ("bevel_weight_edge", "Pair", "Spin"):  # an operand's own edges: only where faces are kept
        assert (name in out.data.attributes) == keep
    # new faces' values within what the sources hold (read past their source triangles, a weight in [0, 1] went to
    # -0.42 and 1.17; a random one per vertex here)
    source, carried = read(box.data, "bevel_weight_vert"), read(out.data, "bevel_weight_vert")
    assert carried.min() >= 0.0 and carried.max() <= source.max()  # (0: the cutter's, which has none)
    tone = read(out.data, "Tone", "color", 4)
    assert tone.min() >= 0.0 and tone.max() <= 1.0


def test_kept_faces_vertices_and_edges_keep_their_values_bit_for_bit(fresh_cache):
    box, _, out, _ = difference(keep=True)
    src, dst = box.data, out.data
    s_start, s_total, s_corner, s_co = faces_of(src)
    d_start, d_total, d_corner, d_co = faces_of(dst)
    key = {tuple(s_co[s_corner[s : s + t]].ravel()): k for k, (s, t) in enumerate(zip(s_start, s_total, strict=False))}
    pairs = [
        (f, key[k])
        for f, (s, t) in enumerate(zip(d_start, d_total, strict=False))
        if (k := tuple(d_co[d_corner[s : s + t]].ravel())) in key
    ]
    assert len(pairs) >= 60, len(pairs)  # the box's 96 quads less those the bore comes near: measured 81
    mine, theirs = np.array(pairs).T
    np.testing.assert_array_equal(read(dst, "Part", dtype=np.int32)[mine], read(src, "Part", dtype=np.int32)[theirs])
    np.testing.assert_array_equal(read(dst, "Tag", dtype=bool)[mine], read(src, "Tag", dtype=bool)[theirs])
    if HAS_INT16_2D:
        short = read(dst, "Short", "value", 2, np.int16)[mine]
        np.testing.assert_array_equal(short, read(src, "Short", "value", 2, np.int16)[theirs])
    sets = read(dst, ".sculpt_face_set", dtype=np.int32)
    np.testing.assert_array_equal(sets[mine], read(src, ".sculpt_face_set", dtype=np.int32)[theirs])
    np.testing.assert_array_equal(read(dst, "Tone", "color", 4)[mine], read(src, "Tone", "color", 4)[theirs])
    np.testing.assert_array_equal(read(dst, "Frame", width=16)[mine], read(src, "Frame", width=16)[theirs])
    d_loops = (d_start[mine][:, None] + np.arange(4)).ravel()
    s_loops = (s_start[theirs][:, None] + np.arange(4)).ravel()
    np.testing.assert_array_equal(read(dst, "Offset", "vector", 3)[d_loops], read(src, "Offset", "vector", 3)[s_loops])
    # the box's vertices in the result, by position
    at = {tuple(p): k for k, p in enumerate(s_co)}
    verts = np.array([(k, at[tuple(p)]) for k, p in enumerate(d_co) if tuple(p) in at])
    assert len(verts) > 80
    np.testing.assert_array_equal(read(dst, "Turn", width=4)[verts[:, 0]], read(src, "Turn", width=4)[verts[:, 1]])
    for name, dtype in (
        ("bevel_weight_vert", np.float32),
        ("Weight", np.float32),
        ("Flag", np.int8),
        (".sculpt_mask", np.float32),
    ):
        np.testing.assert_array_equal(
            read(dst, name, dtype=dtype)[verts[:, 0]], read(src, name, dtype=dtype)[verts[:, 1]]
        )
    # the box's edges in the result, by their ends' positions
    s_edges, d_edges = (
        read(src, ".edge_verts", width=2, dtype=np.int32),
        read(dst, ".edge_verts", width=2, dtype=np.int32),
    )
    edge_key = {tuple(sorted(map(tuple, s_co[e]))): k for k, e in enumerate(s_edges)}
    edges = np.array(
        [(k, edge_key[p]) for k, e in enumerate(d_edges) if (p := tuple(sorted(map(tuple, d_co[e])))) in edge_key]
    )
    assert len(edges) > 100  # measured 184 of the box's 192
    d_bevel, s_bevel = read(dst, "bevel_weight_edge"), read(src, "bevel_weight_edge")
    np.testing.assert_array_equal(d_bevel[edges[:, 0]], s_bevel[edges[:, 1]])
    np.testing.assert_array_equal(
        read(dst, "Pair", width=2, dtype=np.int32)[edges[:, 0]], read(src, "Pair", width=2, dtype=np.int32)[edges[:, 1]]
    )
    d_spin = read(dst, "Spin", width=4)
    np.testing.assert_array_equal(d_spin[edges[:, 0]], read(src, "Spin", width=4)[edges[:, 1]])
    new_edges = np.setdiff1d(np.arange(len(d_edges)), edges[:, 0])
    assert not d_bevel[new_edges].any()  # an edge that is no edge of the box has none
    assert (d_spin[new_edges] == [1.0, 0.0, 0.0, 0.0]).all()  # and Blender's default rotation, the identity


def test_new_faces_take_their_source_face_and_vertices_read_off_it(result):
    box, cutter, out, _ = result
    dst = out.data
    start, total, corner, co = faces_of(dst)
    centres = np.add.reduceat(co[corner], start, axis=0) / total[:, None]
    part = read(dst, "Part", dtype=np.int32)
    h = 2.0 * np.sqrt(3.0) / RESOLUTION
    # faces on the bore's wall (the cutter's, 7), faces on the box's sides (the part of the box face under them)
    b_verts, b_tris = world_arrays(box)
    to_box, to_wall = unsigned_distance(b_verts, b_tris, centres), unsigned_distance(*world_arrays(cutter), centres)
    wall = (to_wall < 1e-4) & (to_box > 2 * h)
    assert wall.sum() > 10 and (part[wall] == 7).all()
    near_box = (to_box < 1e-4) & (to_wall > 2 * h)
    tri, _ = closest_triangles(b_verts, b_tris, centres[near_box])
    polygon = np.empty(len(box.data.loop_triangles), np.int32)
    box.data.loop_triangles.foreach_get("polygon_index", polygon)
    expected = read(box.data, "Part", dtype=np.int32)[polygon[tri]]
    ok = part[near_box] == expected
    # every one (0.989 while faces along the box's edges took the triangle of their node, as near both sides)
    assert near_box.sum() > 50 and ok.all(), ok.mean()
    # a matrix per face: the box face's under it, the identity on the bore's wall (the cutter has none)
    frame = read(dst, "Frame", width=16)
    np.testing.assert_array_equal(frame[near_box], read(box.data, "Frame", width=16)[polygon[tri]])
    assert (frame[wall] == np.eye(4, dtype=np.float32).ravel()).all()
    # every vertex on the box in a face of the box reads the box's weight at its point of the face's source triangle:
    # linear, so what it is where the vertex is, or where the triangle ends nearest it (a corner of a face across two
    # of the box's triangles); a vertex on the bore's rim whose faces are all the cutter's reads the cutter's: none, 0
    of_box = np.zeros(len(co), dtype=bool)
    of_box[corner[np.repeat(part != 7, total)]] = True
    on_box = (unsigned_distance(b_verts, b_tris, co) < 1e-5) & of_box
    error = np.abs(read(dst, "Weight")[on_box] - weight(co[on_box]))
    exact = np.mean(error < 1e-5)
    assert on_box.sum() > 100 and exact > 0.99, exact  # measured 1.0 kept, 0.997 remeshed
    assert error.max() < np.linalg.norm(GRADIENT) * 2 * h, error.max()  # measured 0.58 h (in weight) remeshed
    # a rotation per point, never blended: a vertex of the box's faces takes one of the box's corners' rotations
    turn, identity = read(dst, "Turn", width=4), np.array([[1.0, 0.0, 0.0, 0.0]], np.float32)
    of_box_only = of_box.copy()
    of_box_only[corner[np.repeat(part == 7, total)]] = False
    assert of_box_only.sum() > 100 and rows_of(turn[of_box_only], read(box.data, "Turn", width=4)).all()
    assert rows_of(turn, np.concatenate([read(box.data, "Turn", width=4), identity])).all()
