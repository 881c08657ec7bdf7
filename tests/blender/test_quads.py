"""Remeshed results written as quads (``aasdf_addon/quad_faces.py``), headless: most faces of a remeshed boolean
are quads, the mesh is the engine's surface, and a quad whose halves read different materials, UVs or colours
stays two triangles (tests/blender/test_attributes.py checks the written quads' UVs and colours against the
sources)."""

import bpy
import numpy as np

from aasdf.aasdf_addon import quad_faces
from aasdf.operators import boolean as boolean_op
from tests.blender.scene import add_mesh_object, select, world_arrays
from tests.support import is_watertight, uv_sphere


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
