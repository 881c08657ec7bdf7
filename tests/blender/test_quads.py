"""Remeshed results written as quads (``aasdf_addon/quad_faces.py``), headless: most faces of a remeshed boolean
are quads, the mesh is the engine's surface, and a quad whose halves read different materials, UVs or colours
stays two triangles (tests/blender/test_attributes.py checks the written quads' UVs and colours against the
sources)."""

import bpy
import numpy as np

from aasdf.aasdf_addon import quad_faces
from aasdf.operators import boolean as boolean_op
from tests.blender.scene import add_mesh_object, select, world_arrays
from tests.support import box_mesh, is_watertight, uv_sphere


def polygon_sizes(mesh) -> np.ndarray:
    sizes = np.empty(len(mesh.polygons), np.int32)
    mesh.polygons.foreach_get("loop_total", sizes)
    return sizes


def test_a_remeshed_boolean_is_written_as_quads(fresh_cache):
    verts, tris = uv_sphere(1.0, rings=48, segments=96)
    a = add_mesh_object("Ball", verts, tris)
    b = add_mesh_object("Other", verts, tris, location=(0.8, 0.3, 0.1))
    select(a, b)
    assert bpy.ops.aasdf.boolean(operation="UNION", resolution=96, keep_faces=False) == {"FINISHED"}
    obj = bpy.context.active_object
    sizes = polygon_sizes(obj.data)
    # measured 0.986 quads (the rest triangles along the seam's crease), none larger
    assert np.mean(sizes == 4) >= 0.9 and sizes.max() == 4
    assert boolean_op.last_run["faces"] == len(sizes)
    # the same closed surface as the triangles the run counted
    _, loop_tris = world_arrays(obj)
    assert len(loop_tris) == boolean_op.last_run["triangles"]
    assert is_watertight(loop_tris)
    # the edges the engine found for the triangles, less the quads' diagonals: valid, each in two faces
    assert not obj.data.validate(verbose=False)
    assert 2 * len(obj.data.edges) == len(obj.data.loops)


def test_halves_with_different_attributes_are_not_merged():
    uv = np.tile(np.array([[0, 0], [1, 0], [1, 1], [0, 0], [1, 1], [0, 1]], np.float32), (4, 1))
    uv[6 * 1 + 3] += 0.5  # quad 1: its second half's UVs jump at the shared corner a (a UV seam)
    colour = np.ones((24, 4), np.float32)
    colour[6 * 2 + 4] = 0.0  # quad 2: a colour border at c
    attrs = {
        "material_index": np.array([0, 0, 0, 0, 0, 0, 0, 1], np.int32),  # quad 3: a material change
        "smooth": np.ones(8, bool),
        "operand": np.zeros(8, np.int32),
        "uv_maps": {"UVMap": uv},
        "colors": {"Col": ("FLOAT_COLOR", colour)},
    }
    assert quad_faces.mergeable(attrs, 4).tolist() == [True, False, False, False]
    tris = np.arange(24, dtype=np.int32).reshape(8, 3)
    out = quad_faces.quads_back({"tris": tris, "attributes": attrs, "edges": {}}, 4)
    sizes, corners = out["attributes"]["polygons"]
    assert sizes.tolist() == [4] and corners.tolist() == [0, 1, 2, 5]
    assert len(out["tris"]) == 6 and len(out["attributes"]["material_index"]) == 7
    assert len(out["attributes"]["uv_maps"]["UVMap"]) == 4 + 18


BORDER = 0.3  # a material border across the box's sides, off the lattice's blocks


def _box_minus_ball(adaptivity: float, border: str | None):
    """A box (its triangles above z = BORDER another value of the face attribute ``border``: "material_index", or a
    part id "Part"; None: one material) minus a ball, remeshed at ``adaptivity``: the result object."""
    verts, tris = box_mesh(subdivisions=20)
    slots = [bpy.data.materials.new("Low"), bpy.data.materials.new("High")]
    box = add_mesh_object("Box", verts, tris, materials=slots)
    index = (verts[tris].mean(axis=1)[:, 2] > BORDER).astype(np.int32) if border else np.zeros(len(tris), np.int32)
    box.data.attributes.new(border or "material_index", "INT", "FACE").data.foreach_set("value", index)
    ball = add_mesh_object("Ball", *uv_sphere(0.5, rings=32, segments=64), location=(0.0, 0.0, 1.0))
    select(box, ball)
    status = bpy.ops.aasdf.boolean(operation="DIFFERENCE", resolution=96, keep_faces=False, adaptivity=adaptivity)
    assert status == {"FINISHED"}
    return bpy.context.active_object


def _spanning(mesh, reach: float) -> int:
    """Faces with corners more than ``reach`` below and above z = BORDER."""
    sizes = polygon_sizes(mesh)
    co = np.empty(3 * len(mesh.vertices), np.float32)
    mesh.vertices.foreach_get("co", co)
    corner_vert = np.empty(len(mesh.loops), np.int32)
    mesh.loops.foreach_get("vertex_index", corner_vert)
    z = co.reshape(-1, 3)[corner_vert, 2] - BORDER
    start = np.cumsum(sizes) - sizes
    return int(np.count_nonzero((np.minimum.reduceat(z, start) < -reach) & (np.maximum.reduceat(z, start) > reach)))


def test_adaptivity_merges_flat_faces_but_not_across_a_material_border(fresh_cache):
    fine = _box_minus_ball(0.0, "material_index")
    fine_faces = len(fine.data.polygons)
    coarse = _box_minus_ball(1.0, "material_index")
    mesh = coarse.data
    # measured: 50,808 faces at 0 and 2,204 at 1
    assert len(mesh.polygons) < 0.1 * fine_faces
    assert boolean_op.last_run["faces"] == len(mesh.polygons)
    assert not mesh.validate(verbose=False) and 2 * len(mesh.edges) == len(mesh.loops)
    _, loop_tris = world_arrays(coarse)
    assert is_watertight(loop_tris)
    voxel = boolean_op.last_run["voxel_size"]
    # the material border at z = BORDER runs across the box's flat sides: no merged face spans it, where one material
    # lets them (measured 0 against 12)
    assert _spanning(mesh, 2.0 * voxel) == 0
    assert _spanning(_box_minus_ball(1.0, None).data, 2.0 * voxel) > 0


def test_adaptivity_does_not_merge_across_a_part_border(fresh_cache):
    """An integer face attribute (a part id) borders merged faces as a material does, and comes back on them."""
    mesh = _box_minus_ball(1.0, "Part").data
    voxel = boolean_op.last_run["voxel_size"]
    assert _spanning(mesh, 2.0 * voxel) == 0  # measured 0 (24 where part ids bordered nothing)
    part = np.empty(len(mesh.polygons), np.int32)
    mesh.attributes["Part"].data.foreach_get("value", part)
    assert set(np.unique(part)) == {0, 1}


def test_the_csg_output_node_has_an_adaptivity(fresh_cache):
    from aasdf.aasdf_addon import nodes

    box = add_mesh_object("Box", *box_mesh(subdivisions=2))
    ball = add_mesh_object("Ball", *uv_sphere(0.5, rings=32, segments=64), location=(0.0, 0.0, 1.0))
    tree = bpy.data.node_groups.new("Tree", nodes.TREE)
    tree.resolution = 64
    node_a, node_b = tree.nodes.new(nodes.OBJECT), tree.nodes.new(nodes.OBJECT)
    node_a.object, node_b.object = box, ball
    difference, output = tree.nodes.new(nodes.DIFFERENCE), tree.nodes.new(nodes.OUTPUT)
    tree.links.new(node_a.outputs[0], difference.inputs["Base"])
    tree.links.new(node_b.outputs[0], difference.inputs["Cutters"])
    tree.links.new(difference.outputs[0], output.inputs[0])
    output.keep_faces = False
    counts = []
    for adaptivity in (0.0, 1.0):
        output.adaptivity = adaptivity
        assert bpy.ops.aasdf.evaluate_tree(tree=tree.name) == {"FINISHED"}
        counts.append(len(bpy.data.objects[output.object_name].data.polygons))
    assert counts[1] < 0.2 * counts[0], counts


def test_source_regions_split_at_material_borders_part_borders_and_uv_seams():
    from types import SimpleNamespace

    from aasdf.aasdf_addon import regions

    # a strip of four triangles (two quads side by side, each split in two), corners numbered per triangle
    verts = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0], [0, 1, 0], [1, 1, 0], [2, 1, 0]], np.float32)
    tris = np.array([[0, 1, 4], [0, 4, 3], [1, 2, 5], [1, 5, 4]], np.int32)
    corners = np.arange(12, dtype=np.int32).reshape(4, 3)
    uv = verts[tris.ravel(), :2].copy()

    def operand(material, uv_map, generic=None):
        return SimpleNamespace(
            tris=tris,
            verts=verts,
            corners=corners,
            faces=np.arange(4),
            face_material=np.asarray(material),
            uv_maps={"UVMap": uv_map},
            generic=generic or {},
        )

    def groups(op):
        r = regions.source_regions([op])[0]
        return [int(np.flatnonzero(r == x)[0]) for x in r]  # each triangle's first triangle of its region

    assert groups(operand([0, 0, 0, 0], uv)) == [0, 0, 0, 0]
    assert groups(operand([0, 0, 1, 1], uv)) == [0, 0, 2, 2]  # a material border between the quads
    seam = uv.copy()
    seam[6:12, 0] += 5.0  # the second quad's UVs moved: a seam along the shared edge
    assert groups(operand([0, 0, 0, 0], seam)) == [0, 0, 2, 2]
    # a part id (an integer face attribute) borders a region as a material does; a float one (a weight) does not
    part = {"Part": ("FACE", "INT", np.array([3, 3, 4, 4], np.int32))}
    assert groups(operand([0, 0, 0, 0], uv, part)) == [0, 0, 2, 2]
    weight = {"Weight": ("FACE", "FLOAT", np.array([0.1, 0.1, 0.9, 0.9], np.float32))}
    assert groups(operand([0, 0, 0, 0], uv, weight)) == [0, 0, 0, 0]
