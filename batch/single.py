"""One boolean from the command line (``aasdf_batch.py`` without ``--jobs``): the operands imported or taken from the
open .blend, the add-on's pipeline run, the result exported, each step and a summary printed to ``out``."""

import os
import shutil
import time

import bpy

from . import scene
from .options import check_args


def progress_printer(start: float, out):
    """A pipeline listener printing each step of the run with the seconds since ``start``."""

    def show(text):
        print(f"aasdf_batch: {time.perf_counter() - start:6.2f} s  {text}", file=out, flush=True)

    return show


def describe(args, summary, count: int) -> str:
    return " then ".join(
        part
        for part in (
            f"{args.operation} of {summary['operands']} operands" if count > 1 else None,
            f"offset {args.offset:+g}" if args.offset is not None else None,
            f"shell {args.shell:g}" if args.shell is not None else None,
        )
        if part
    )


def run(args, out, err) -> int:
    """Run the boolean ``args`` describe; returns the exit status (1: the boolean failed or is empty).

    Raises:
        BatchError: Bad arguments or input (exit status 2).
    """
    check_args(args)
    if args.blend is not None:
        scene.open_blend(args.blend)
    package = scene.ensure_addon()
    scene.check_debug_volume(args, package)
    pipeline, plan = package.aasdf_addon.pipeline, package.aasdf_addon.plan
    if bpy.context.mode != "OBJECT":
        bpy.ops.object.mode_set(mode="OBJECT")
    operands = scene.gather_operands(args)  # (bad objects refused before the engine and Warp load: 1.3 s)
    engine = package.aasdf_addon.runtime.engine()
    start = time.perf_counter()
    listener = progress_printer(start, out)
    if not args.quiet:
        pipeline.progress_listeners.append(listener)
    settings, output = scene.run_settings(pipeline, args, operands)
    try:
        summary = pipeline.run(
            bpy.context,
            [plan.Input(obj, args.thickness) for obj in operands],
            scene.plan_of(args, len(operands)),
            settings,
            output,
            source="aasdf_batch",
            operation=args.operation or "none",
        )
    except engine.AasdfError as error:
        print(f"aasdf_batch: the boolean failed: {error}", file=err)
        return 1
    finally:
        if listener in pipeline.progress_listeners:
            pipeline.progress_listeners.remove(listener)
    if summary.get("empty"):
        print("aasdf_batch: the result is empty: nothing written", file=err)
        return 1
    for warning in summary["warnings"]:
        print(f"aasdf_batch: warning: {warning}", file=err)
    result = bpy.data.objects[summary["object"]]
    if args.debug_volume is not None:
        volume = bpy.data.objects[f"{result.name}.sdf"].data
        os.makedirs(os.path.dirname(os.path.abspath(args.debug_volume)), exist_ok=True)
        shutil.copyfile(bpy.path.abspath(volume.filepath), args.debug_volume)
    scene.select_only([result], result)
    path = scene.export_result(args.output)
    print(
        f"aasdf_batch: {describe(args, summary, len(operands))} -> {path}: "
        f"{summary['triangles']:,} triangles, {summary['nodes']:,} field nodes, "
        f"voxel size {summary['voxel_size']:.5g}, boolean {summary['seconds']:.2f} s, "
        f"total {time.perf_counter() - start:.2f} s"
        + (f"; debug volume {args.debug_volume}" if args.debug_volume else ""),
        file=out,
    )
    return 0
