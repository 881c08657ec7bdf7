"""The batch script's options: the parser of the command line (and of each line of a job file, whose keys are the
same long options without the dashes) and the checks run before Blender does anything. Imports neither ``bpy`` nor
the engine."""

import argparse
import math
import os
from pathlib import Path

IMPORTERS = {".obj": "obj_import", ".ply": "ply_import", ".stl": "stl_import"}
EXPORTERS = {".obj": "obj_export", ".ply": "ply_export", ".stl": "stl_export"}
OPERATIONS = {"union": "UNION", "intersect": "INTERSECT", "intersection": "INTERSECT", "difference": "DIFFERENCE"}

# Options naming files: a job file's relative paths are relative to its folder, the command line's to the working one.
PATH_OPTIONS = ("inputs", "output", "blend", "debug_volume")
# The add-on's Levels and Padding settings' ranges (a padding of 1,000 kept a kernel busy for minutes).
MAX_LEVELS, MAX_PADDING = 12, 32
# Options of the run as a whole, not of a job: a job file may not set them.
RUN_OPTIONS = ("jobs", "report", "workers", "timeout", "force", "shard", "scheduler", "verbose", "quiet")


class BatchError(Exception):
    """Bad arguments or input: printed without a traceback (exit status 2), or reported as the job's failure."""


class JobParser(argparse.ArgumentParser):
    """The parser of one job: raises ``BatchError`` instead of printing the usage and exiting."""

    def error(self, message):
        raise BatchError(message)


def add_job_options(parser):
    parser.add_argument("--operation", type=str.lower, choices=sorted(OPERATIONS), help="the boolean of the operands")
    parser.add_argument("--inputs", nargs="+", default=[], metavar="FILE", help="mesh files: .obj, .ply, .stl")
    parser.add_argument(
        "--objects", nargs="+", default=[], metavar="NAME", help="objects of the open .blend: mesh, text, curve, ..."
    )
    parser.add_argument("--output", metavar="FILE", help=".ply, .obj, .stl or .blend")
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
    parser.add_argument(
        "--adaptivity",
        type=float,
        default=0.0,
        help="0 to 1: merge the remeshed surface's cells (with kept faces, the seams' new faces) where it is flat, "
        "into fewer, larger polygons (default 0)",
    )
    parser.add_argument("--debug-volume", metavar="FILE", help="also write the result's field as a .vdb")
    parser.add_argument("--blend", metavar="FILE", help="open this .blend first (with the bpy module)")


def add_run_options(parser):
    parser.add_argument("--verbose", action="store_true", help="also print Warp's start-up and kernel-loading lines")
    parser.add_argument("--quiet", action="store_true", help="print only the summary, not each step")
    group = parser.add_argument_group("job files (the options above are then every job's defaults)")
    group.add_argument("--jobs", metavar="FILE", help="a job file: JSON lines or .csv, a job per line")
    group.add_argument("--report", metavar="FILE", help="write a JSON report: per job status, seconds, triangles...")
    group.add_argument("--workers", type=int, metavar="N", help="worker processes (default: the cores; 0: this one)")
    group.add_argument("--timeout", type=float, metavar="SECONDS", help="stop a job (and its worker) after this long")
    group.add_argument("--force", action="store_true", help="redo jobs whose output is up to date")
    group.add_argument("--shard", metavar="K/N", help="run only the K-th (1..N) of N disjoint slices of the jobs")
    group.add_argument("--scheduler", metavar="ADDRESS", help="run the jobs on this Dask scheduler's workers")


def command_line_parser(description: str) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="aasdf_batch.py", description=description)
    add_job_options(parser)
    add_run_options(parser)
    return parser


def job_parser(defaults: dict) -> JobParser:
    """The parser of a job file's lines, with ``defaults`` (the command line's job options) as its defaults."""
    parser = JobParser(prog="job", add_help=False)
    add_job_options(parser)
    parser.set_defaults(**defaults)
    return parser


def job_defaults(args) -> dict:
    """The command line's job options, its paths made absolute (relative to the working folder)."""
    defaults = {key: value for key, value in vars(args).items() if key not in RUN_OPTIONS}
    for key in PATH_OPTIONS:
        value = defaults.get(key)
        if isinstance(value, list):
            defaults[key] = [os.path.abspath(item) for item in value]
        elif value is not None:
            defaults[key] = os.path.abspath(value)
    return defaults


def check_args(args):
    """Refuse what cannot work before Blender does anything."""
    for path in args.inputs:
        if not os.path.isfile(path):
            raise BatchError(f"input file not found: {path}")
        if Path(path).suffix.lower() not in IMPORTERS:
            raise BatchError(f"cannot import {path}: use one of {', '.join(IMPORTERS)}")
    if args.blend is not None and not os.path.isfile(args.blend):
        raise BatchError(f".blend file not found: {args.blend}")
    if args.output is None:
        raise BatchError("give --output")
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
    if not 0.0 <= args.adaptivity <= 1.0:
        raise BatchError(f"--adaptivity must be from 0 to 1, not {args.adaptivity}")
    if args.resolution < 8 or args.voxel_size < 0.0:
        raise BatchError("--resolution must be at least 8 and --voxel-size not negative")
    if not (1 <= args.levels <= MAX_LEVELS and 1 <= args.padding <= MAX_PADDING):
        raise BatchError(
            f"--levels must be from 1 to {MAX_LEVELS} and --padding from 1 to {MAX_PADDING} (as in the add-on), not "
            f"{args.levels} and {args.padding}"
        )
    if args.blend_radius < 0.0:
        raise BatchError(f"--blend-radius must not be negative, not {args.blend_radius}")
    check_writable(args.output)
    read = [*args.inputs, *([args.blend] if args.blend is not None else [])]
    for written in (args.output, args.debug_volume):
        if written is not None and any(same_file(written, path) for path in read):
            raise BatchError(f"{written} is also an input: write the result to another file")


def same_file(a, b) -> bool:
    """Whether paths ``a`` and ``b`` name one file (the same path, or one file under two names)."""
    if os.path.normcase(os.path.abspath(a)) == os.path.normcase(os.path.abspath(b)):
        return True
    return os.path.exists(a) and os.path.exists(b) and os.path.samefile(a, b)


def check_writable(path) -> None:
    """Refuse an output (or report) path that is a folder, or whose nearest existing folder cannot be written to."""
    target = Path(os.path.abspath(path))
    if target.is_dir():
        raise BatchError(f"cannot write {path}: it is a folder")
    folder = target.parent
    while not folder.exists():
        folder = folder.parent
    if not folder.is_dir() or not os.access(folder, os.W_OK):
        raise BatchError(f"cannot write {path}: {folder} is not a folder this process may write in")
