"""Headless SDF booleans with AASDF: mesh files or objects of a .blend in, a mesh file or a .blend out.

Run it with Blender or with the ``bpy`` module::

    blender -b [scene.blend] -P aasdf_batch.py -- --operation union --inputs a.obj b.stl --resolution 256 \\
        --output out.ply [--debug-volume out.vdb] [--objects NAME ...] [--verbose | --quiet]
    python aasdf_batch.py --operation difference --inputs a.obj b.ply --output out.blend [--blend scene.blend]

Operands are the imported files (``.obj``, ``.ply``, ``.stl``; a file holding several meshes becomes one operand),
then the named objects, in the order given: the first is the active object, so DIFFERENCE is the first operand
minus all the others. ``--offset`` grows (or shrinks) the result and ``--shell`` hollows it (with one operand, that
operand alone); ``--thickness`` gives surfaces that enclose nothing a wall; ``--blend-mode``, ``--no-sharp-edges``
as the add-on's settings. The output is ``.ply``, ``.obj``, ``.stl`` or ``.blend``. Everything runs through the
add-on's pipeline, as ``bpy.ops.aasdf.boolean`` does; when AASDF is not already enabled, the repository this script
sits in is registered as the package ``aasdf``. Prints each step as it goes (``--quiet``: only the summary;
``--verbose``: Warp's own start-up and kernel-loading lines too) and a one-line summary; exits with 2 on bad arguments
or input and with 1 when the boolean fails or is empty, with the reason on stderr.
"""

import argparse
import importlib.util
import math
import os
import shutil
import sys
import time
from contextlib import contextmanager
from pathlib import Path

ROOT = Path(__file__).resolve().parent
PACKAGE = "aasdf"
IMPORTERS = {".obj": "obj_import", ".ply": "ply_import", ".stl": "stl_import"}
EXPORTERS = {".obj": "obj_export", ".ply": "ply_export", ".stl": "stl_export"}
OPERATIONS = {"union": "UNION", "intersect": "INTERSECT", "intersection": "INTERSECT", "difference": "DIFFERENCE"}


class BatchError(Exception):
    """Bad arguments or input: printed without a traceback, exit status 2."""


def script_args(argv):
    """The script's own arguments: those after ``--`` when present (Blender's ``-P`` and ``python x.py --``)."""
    return argv[argv.index("--") + 1 :] if "--" in argv else argv[1:]


def parse_args(args):
    parser = argparse.ArgumentParser(prog="aasdf_batch.py", description=__doc__.split("\n\n")[0])
    parser.add_argument("--operation", type=str.lower, choices=sorted(OPERATIONS), help="the boolean of the operands")
    parser.add_argument("--inputs", nargs="+", default=[], metavar="FILE", help="mesh files: .obj, .ply, .stl")
    parser.add_argument(
        "--objects", nargs="+", default=[], metavar="NAME", help="objects of the open .blend: mesh, text, curve, ..."
    )
    parser.add_argument("--output", required=True, metavar="FILE", help=".ply, .obj, .stl or .blend")
    parser.add_argument("--resolution", type=int, default=256, help="voxels along the inputs' bounding-box diagonal")
    parser.add_argument("--voxel-size", type=float, default=0.0, help="finest voxel size (overrides --resolution)")
    parser.add_argument("--levels", type=int, default=4)
    parser.add_argument("--padding", type=int, default=1)
    parser.add_argument("--blend-radius", type=float, default=0.0, help="smooth blend radius (0: sharp)")
    parser.add_argument("--blend-mode", type=str.upper, choices=["ROUND", "CHAMFER"], default="ROUND")
    parser.add_argument(
        "--thickness", type=float, default=0.0, help="a wall this thick for surfaces that enclose nothing (0: none)"
    )
    parser.add_argument("--offset", type=float, metavar="DISTANCE", help="then grow (> 0) or shrink (< 0) the result")
    parser.add_argument("--shell", type=float, metavar="WALL", help="then hollow the result, walls this thick")
    parser.add_argument("--shell-side", type=str.upper, choices=["INSIDE", "OUTSIDE", "CENTER"], default="INSIDE")
    parser.add_argument(
        "--sharp-edges",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="keep creases sharp (default) or round them (--no-sharp-edges: marching cubes)",
    )
    parser.add_argument(
        "--keep-faces",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="keep the inputs' own faces away from the seams (default) or remesh the whole result (--no-keep-faces)",
    )
    parser.add_argument("--remesh", dest="keep_faces", action="store_false", help="the same as --no-keep-faces")
    parser.add_argument("--debug-volume", metavar="FILE", help="also write the result's field as a .vdb")
    parser.add_argument("--blend", metavar="FILE", help="open this .blend first (with the bpy module)")
    parser.add_argument("--verbose", action="store_true", help="also print Warp's start-up and kernel-loading lines")
    parser.add_argument("--quiet", action="store_true", help="print only the summary, not each step")
    return parser.parse_args(args)


def check_args(args):
    """Refuse what cannot work before Blender does anything."""
    for path in args.inputs:
        if not os.path.isfile(path):
            raise BatchError(f"input file not found: {path}")
        if Path(path).suffix.lower() not in IMPORTERS:
            raise BatchError(f"cannot import {path}: use one of {', '.join(IMPORTERS)}")
    if args.blend is not None and not os.path.isfile(args.blend):
        raise BatchError(f".blend file not found: {args.blend}")
    suffix = Path(args.output).suffix.lower()
    if suffix not in EXPORTERS and suffix != ".blend":
        raise BatchError(f"cannot write {args.output}: use one of {', '.join([*EXPORTERS, '.blend'])}")
    if args.debug_volume is not None and Path(args.debug_volume).suffix.lower() != ".vdb":
        raise BatchError(f"the debug volume must be a .vdb file, not {args.debug_volume}")
    count = len(args.inputs) + len(args.objects)
    if args.offset is None and args.shell is None and count < 2:
        raise BatchError("give at least two operands (--inputs and --objects together), or --offset or --shell")
    if count == 0:
        raise BatchError("give an operand (--inputs or --objects)")
    if count > 1 and args.operation is None:
        raise BatchError("give --operation to combine several operands")
    for name in ("voxel_size", "blend_radius", "thickness", "offset", "shell"):
        value = getattr(args, name)
        if value is not None and not math.isfinite(value):
            raise BatchError(f"--{name.replace('_', '-')} must be a finite number, not {value}")
    if args.thickness < 0.0 or (args.shell is not None and args.shell <= 0.0):
        raise BatchError("--thickness must not be negative and --shell must be positive")
    if args.resolution < 8 or args.voxel_size < 0.0:
        raise BatchError("--resolution must be at least 8 and --voxel-size not negative")


def ensure_addon():
    """The add-on's package: the enabled add-on's, else the repository registered as ``aasdf``."""
    import bpy

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
    import bpy

    before = set(bpy.data.objects)
    getattr(bpy.ops.wm, IMPORTERS[Path(path).suffix.lower()])(filepath=os.path.abspath(path))
    meshes = [obj for obj in bpy.data.objects if obj not in before and obj.type == "MESH"]
    if not meshes:
        raise BatchError(f"{path} holds no mesh")
    if len(meshes) > 1:
        with bpy.context.temp_override(
            active_object=meshes[0], selected_objects=meshes, selected_editable_objects=meshes
        ):
            bpy.ops.object.join()
    return meshes[0]


def scene_operand(name, operands):
    """A named object of the scene with geometry (``operands``: the add-on's ``aasdf_addon.operands``)."""
    import bpy

    obj = bpy.data.objects.get(name)
    if obj is None or obj.name not in bpy.context.view_layer.objects:
        raise BatchError(f"no object named {name!r} in the scene")
    if not operands.is_operand(obj):
        raise BatchError(operands.refusal(obj))
    return obj


def export_result(args):
    import bpy

    path = os.path.abspath(args.output)
    os.makedirs(os.path.dirname(path), exist_ok=True)
    suffix = Path(path).suffix.lower()
    if suffix == ".blend":
        bpy.ops.wm.save_as_mainfile(filepath=path, copy=True)
    else:
        # what each format can hold of what the result carries: UVs and materials in .obj, UVs and colours in .ply
        options = {".obj": {"export_uv": True, "export_materials": True}, ".ply": {"export_uv": True}}
        if suffix == ".ply":
            options[".ply"]["export_colors"] = "SRGB"
        getattr(bpy.ops.wm, EXPORTERS[suffix])(filepath=path, export_selected_objects=True, **options.get(suffix, {}))
    return path


# Where this script prints its own lines (the terminal, even while Blender's output is silenced).
out = sys.stdout


@contextmanager
def blender_output_silenced(active: bool):
    """Send what Blender prints to stdout (importers' timings, operator reports) to the null device, while this
    script's own lines (``out``) still reach the terminal."""
    global out
    if not active:
        yield
        return
    sys.stdout.flush()
    saved = os.dup(1)
    null = os.open(os.devnull, os.O_WRONLY)
    os.dup2(null, 1)
    os.close(null)
    stdout = sys.stdout
    out = os.fdopen(saved, "w", buffering=1)
    sys.stdout = open(os.devnull, "w")  # noqa: SIM115 (closed below)
    try:
        yield
    finally:
        sys.stdout.close()
        sys.stdout = stdout
        out.flush()
        os.dup2(saved, 1)
        out.close()
        out = stdout


def progress_printer(start: float):
    """A pipeline listener printing each step of the run with the seconds since ``start``."""

    def show(text):
        print(f"aasdf_batch: {time.perf_counter() - start:6.2f} s  {text}", file=out, flush=True)

    return show


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


def run(args) -> int:
    check_args(args)
    if args.verbose:
        os.environ["AASDF_VERBOSE"] = "1"
    import bpy

    if args.blend is not None:
        bpy.ops.wm.open_mainfile(filepath=os.path.abspath(args.blend))
    package = ensure_addon()
    pipeline, plan = package.aasdf_addon.pipeline, package.aasdf_addon.plan
    engine = package.aasdf_addon.runtime.engine()
    if bpy.context.mode != "OBJECT":
        bpy.ops.object.mode_set(mode="OBJECT")
    # Names first: an unknown object fails before anything is imported.
    named = [scene_operand(name, package.aasdf_addon.operands) for name in args.objects]
    operands = [import_operand(path) for path in args.inputs] + named
    if len(operands) > 1 and len({obj.name for obj in operands}) < 2:
        raise BatchError("give at least two different operands")
    for obj in bpy.context.view_layer.objects:
        obj.select_set(obj in operands)
    bpy.context.view_layer.objects.active = operands[0]
    start = time.perf_counter()
    listener = progress_printer(start)
    if not args.quiet:
        pipeline.progress_listeners.append(listener)
    settings = pipeline.FieldSettings(args.voxel_size, args.resolution, args.levels, args.padding)
    output = pipeline.Output(
        f"{operands[0].name}.aasdf",
        hide_inputs=True,
        debug_volume=args.debug_volume is not None,
        sharp=args.sharp_edges,
        keep_faces=args.keep_faces,
    )
    try:
        summary = pipeline.run(
            bpy.context,
            [plan.Input(obj, args.thickness) for obj in operands],
            plan_of(args, len(operands)),
            settings,
            output,
            source="aasdf_batch",
            operation=args.operation or "none",
        )
    except engine.AasdfError as err:
        print(f"aasdf_batch: the boolean failed: {err}", file=sys.stderr)
        return 1
    finally:
        if listener in pipeline.progress_listeners:
            pipeline.progress_listeners.remove(listener)
    if summary.get("empty"):
        print("aasdf_batch: the result is empty: nothing written", file=sys.stderr)
        return 1
    for warning in summary["warnings"]:
        print(f"aasdf_batch: warning: {warning}", file=sys.stderr)
    result = bpy.data.objects[summary["object"]]
    if args.debug_volume is not None:
        volume = bpy.data.objects[f"{result.name}.sdf"].data
        os.makedirs(os.path.dirname(os.path.abspath(args.debug_volume)), exist_ok=True)
        shutil.copyfile(bpy.path.abspath(volume.filepath), args.debug_volume)
    for obj in bpy.context.view_layer.objects:
        obj.select_set(obj == result)
    bpy.context.view_layer.objects.active = result
    path = export_result(args)
    what = " then ".join(
        part
        for part in (
            f"{args.operation} of {summary['operands']} operands" if len(operands) > 1 else None,
            f"offset {args.offset:+g}" if args.offset is not None else None,
            f"shell {args.shell:g}" if args.shell is not None else None,
        )
        if part
    )
    print(
        f"aasdf_batch: {what} -> {path}: "
        f"{summary['triangles']:,} triangles, {summary['nodes']:,} field nodes, "
        f"voxel size {summary['voxel_size']:.5g}, boolean {summary['seconds']:.2f} s, "
        f"total {time.perf_counter() - start:.2f} s"
        + (f"; debug volume {args.debug_volume}" if args.debug_volume else ""),
        file=out,
    )
    return 0


def main(argv=None) -> int:
    args = parse_args(script_args(sys.argv if argv is None else argv))
    try:
        with blender_output_silenced(not args.verbose):
            return run(args)
    except BatchError as err:
        print(f"aasdf_batch: error: {err}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
