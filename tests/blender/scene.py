"""Scene helpers shared by the Blender tests: mesh objects from numpy arrays, a box of quads, selection, world-space
arrays."""

import bpy
import numpy as np

from aasdf.aasdf_addon import bridge

# Blender ships OpenVDB's Python module from 4.4 on; on 4.2 a debug volume is refused with this sentence.
SHIPS_OPENVDB = bpy.app.version >= (4, 4, 0)
NO_OPENVDB = "Debug Volume needs OpenVDB's Python module, which Blender .* does not provide"


def add_mesh_object(name, verts, tris, location=(0.0, 0.0, 0.0), materials=(), collection=None):
    """A mesh object from numpy arrays, linked to ``collection`` (default: the scene's collection)."""
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata(np.asarray(verts).tolist(), [], np.asarray(tris).tolist())
    for material in materials:
        mesh.materials.append(material)
    obj = bpy.data.objects.new(name, mesh)
    (collection or bpy.context.scene.collection).objects.link(obj)
    obj.location = location
    bpy.context.view_layer.update()  # matrix_world follows the location
    return obj


def quad_box(name: str, cuts: int = 3):
    """Blender's 2 x 2 x 2 cube at the origin, its faces subdivided ``cuts`` times (quads of their own), named."""
    bpy.ops.mesh.primitive_cube_add(size=2.0)
    box = bpy.context.active_object
    box.name = name
    bpy.ops.object.mode_set(mode="EDIT")
    bpy.ops.mesh.subdivide(number_cuts=cuts)
    bpy.ops.object.mode_set(mode="OBJECT")
    return box


def select(*objects, active=None):
    """Select exactly ``objects`` and make ``active`` (default: the first) the active object."""
    for obj in bpy.context.view_layer.objects:
        obj.select_set(False)
    for obj in objects:
        obj.select_set(True)
    bpy.context.view_layer.objects.active = active or objects[0]


def world_arrays(obj):
    """(V,3) world vertices and (T,3) triangles of an object's evaluated mesh."""
    return bridge.evaluated_mesh(obj, bpy.context.evaluated_depsgraph_get())
