"""The Blender side of a batch job: the add-on registered once per process, mesh files imported as operands, the
scene emptied between jobs (the field cache kept), the result exported, and the numbers of a result mesh. Imported only
in a process that runs jobs (it imports ``bpy``)."""

import importlib.util
import os
import sys
from pathlib import Path

import bpy
import numpy as np

from .options import EXPORTERS, IMPORTERS, OPERATIONS, BatchError

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = "aasdf"
# Data a job leaves behind (imports, results, debug volumes), removed before the next job.
JOB_DATA = ("objects", "meshes", "materials", "images", "volumes", "textures", "node_groups")


def ensure_addon():
    """The add-on's package: the enabled add-on's, else the repository registered as ``aasdf``."""
    if not hasattr(bpy.types, "AASDF_OT_boolean"):
        package = sys.modules.get(PACKAGE)
        if package is None:
            spec = importlib.util.spec_from_file_location(
                PACKAGE, ROOT / "__init__.py", submodule_search_locations=[str(ROOT)]
            )
            package = importlib.util.module_from_spec(spec)
            sys.modules[PACKAGE] = package
            spec.loader.exec_module(package)
        if PACKAGE not in bpy.context.preferences.addons:  # as enabling the add-on does: preferences exist
            bpy.context.preferences.addons.new().module = PACKAGE
        package.register()
    return sys.modules[sys.modules[bpy.types.AASDF_OT_boolean.__module__].__name__.rpartition(".operators")[0]]


def import_operand(path):
    """Import one mesh file; several meshes in it are joined into one object."""
    before = set(bpy.data.objects)
    try:
        getattr(bpy.ops.wm, IMPORTERS[Path(path).suffix.lower()])(filepath=os.path.abspath(path))
    except RuntimeError as err:  # (Blender's importer refuses a file it cannot read)
        raise BatchError(f"cannot read {path}: {str(err).strip().splitlines()[-1]}") from None
    meshes = [obj for obj in bpy.data.objects if obj not in before and obj.type == "MESH"]
    if not meshes:
        raise BatchError(f"{path} holds no mesh")
    if len(meshes) > 1:
        with bpy.context.temp_override(
            active_object=meshes[0], selected_objects=meshes, selected_editable_objects=meshes
        ):
            bpy.ops.object.join()
    return meshes[0]


def open_blend(path) -> None:
    """Open the .blend file ``path`` (refused by name where Blender cannot read it)."""
    try:
        bpy.ops.wm.open_mainfile(filepath=os.path.abspath(path))
    except RuntimeError as err:
        raise BatchError(f"cannot open {path}: {str(err).strip().splitlines()[-1]}") from None


def scene_operand(name):
    """A named object of the scene with geometry (a mesh, text, curve, surface, metaball), else refused by name."""
    operands = ensure_addon().aasdf_addon.operands
    obj = bpy.data.objects.get(name)
    if obj is None or obj.name not in bpy.context.view_layer.objects:
        raise BatchError(f"no object named {name!r} in the scene")
    if not operands.is_operand(obj):
        raise BatchError(operands.refusal(obj))
    return obj


def select_only(objects, active):
    for obj in bpy.context.view_layer.objects:
        obj.select_set(obj in objects)
    bpy.context.view_layer.objects.active = active


def export_result(path):
    """Write the selected result object to ``path`` (``.ply``, ``.obj``, ``.stl``; ``.blend``: the whole file)."""
    path = os.path.abspath(path)
    suffix = Path(path).suffix.lower()
    # what each format can hold of what the result carries: UVs and materials in .obj, UVs and colours in .ply
    options = {
        ".obj": {"export_uv": True, "export_materials": True},
        ".ply": {"export_uv": True, "export_colors": "SRGB"},
    }
    try:
        os.makedirs(os.path.dirname(path), exist_ok=True)
        if suffix == ".blend":
            bpy.ops.wm.save_as_mainfile(filepath=path, copy=True)
        else:
            exporter = getattr(bpy.ops.wm, EXPORTERS[suffix])
            exporter(filepath=path, export_selected_objects=True, **options.get(suffix, {}))
    except (OSError, RuntimeError) as err:  # (checked before any work; the folder may have changed since)
        raise BatchError(f"cannot write {path}: {str(err).strip().splitlines()[-1]}") from None
    return path


def plan_of(args, count: int) -> tuple:
    """What the run computes: the boolean of the operands (or the one operand), then the offset, then the shell."""
    steps = ("field", 0)
    if count > 1:
        leaves = [("field", k) for k in range(count)]
        steps = ("boolean", OPERATIONS[args.operation], args.blend_radius, args.blend_mode, leaves)
    if args.offset is not None:
        steps = ("offset", args.offset, steps)
    if args.shell is not None:
        steps = ("shell", args.shell, args.shell_side, steps)
    return steps


def check_debug_volume(args, addon) -> None:
    """Refuse ``--debug-volume`` before any work where this Blender cannot write one (no OpenVDB module: 4.2).

    Raises:
        BatchError: Saying so, and that the boolean runs without it.
    """
    if args.debug_volume is None:
        return
    try:
        importlib.import_module(f"{addon.__name__}.aasdf_addon.debug").openvdb_module()
    except addon.aasdf_addon.runtime.engine().AasdfError as err:
        raise BatchError(f"{err}; run it without --debug-volume") from None


def gather_operands(args) -> list:
    """The job's operands, selected, the first active: its files imported, then its named objects (checked first:
    an unknown one fails before anything is imported)."""
    named = [scene_operand(name) for name in args.objects]
    operands = [import_operand(path) for path in args.inputs] + named
    if len(operands) > 1 and len({obj.name for obj in operands}) < 2:
        raise BatchError("give at least two different operands")
    select_only(operands, operands[0])
    return operands


def run_settings(pipeline, args, operands) -> tuple:
    """The job's field settings and its output (``pipeline``: the add-on's ``aasdf_addon.pipeline``)."""
    settings = pipeline.FieldSettings(args.voxel_size, args.resolution, args.levels, args.padding)
    output = pipeline.Output(
        f"{operands[0].name}.aasdf",
        hide_inputs=True,
        debug_volume=args.debug_volume is not None,
        sharp=args.sharp_edges,
        keep_faces=args.keep_faces,
        adaptivity=args.adaptivity,
    )
    return settings, output


def clear_scene():
    """Remove what the previous job left (objects, meshes, materials...) without reading a file: reading one would
    empty the add-on's field cache, which the next jobs share."""
    if bpy.context.mode != "OBJECT":
        bpy.ops.object.mode_set(mode="OBJECT")
    doomed = [block for name in JOB_DATA for block in getattr(bpy.data, name)]
    if doomed:
        bpy.data.batch_remove(doomed)


def mesh_volume(obj) -> float:
    """The volume a closed mesh object encloses in world space (divergence theorem over its triangles)."""
    mesh = obj.data
    mesh.calc_loop_triangles()
    verts = np.empty(len(mesh.vertices) * 3, dtype=np.float64)
    mesh.vertices.foreach_get("co", verts)
    tris = np.empty(len(mesh.loop_triangles) * 3, dtype=np.int64)
    mesh.loop_triangles.foreach_get("vertices", tris)
    matrix = np.asarray(obj.matrix_world, dtype=np.float64)
    world = verts.reshape(-1, 3) @ matrix[:3, :3].T + matrix[:3, 3]
    corners = world[tris.reshape(-1, 3)]
    return float(np.einsum("ij,ij->i", corners[:, 0], np.cross(corners[:, 1], corners[:, 2])).sum() / 6.0)
