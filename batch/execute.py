"""One job in a long-lived process: the scene emptied (the add-on's field cache kept, so inputs several jobs share
are built once), the operands imported, the add-on's pipeline run, and the result written atomically: into a folder
beside the output, then moved into place (``os.replace``), so a killed job never leaves a half-written output.
Returns what the report says of the job; nothing raises past ``run_job``."""

import os
import shutil
import time
from argparse import Namespace

import bpy

from . import scene
from .jobs import Job, partial_dir, write_record
from .options import BatchError

_addon = None  # the add-on's package, registered once per process


def prepare():
    """Register the add-on, import the engine, load its kernels and build its tables, once for the process's jobs: a
    job's time (and its timeout) is then its own work."""
    global _addon
    if _addon is None:
        _addon = scene.ensure_addon()
        engine = _addon.aasdf_addon.runtime.engine()
        engine.kernels.warm_up(engine.__name__, _addon.aasdf_addon.runtime.device())
    return _addon


def result(status: str, started: float, message: str = "", **numbers) -> dict:
    return {"status": status, "seconds": round(time.perf_counter() - started, 4), "message": message, **numbers}


def run_job(job: Job) -> dict:
    """Run ``job``; returns ``{"status": "done" | "failed", "seconds", "triangles", "volume", "message"}``."""
    started = time.perf_counter()
    if job.error:
        return result("failed", started, job.error)
    addon = prepare()
    engine = addon.aasdf_addon.runtime.engine()
    try:
        numbers = boolean_to_file(addon, Namespace(**job.options))
    except (BatchError, engine.AasdfError) as err:
        return result("failed", started, str(err))
    except (OSError, RuntimeError) as err:  # an unreadable file (the importer's report), a full disk...
        return result("failed", started, " ".join(str(err).split()).removeprefix("Error: "))
    except Exception as err:  # noqa: BLE001 (a fault of ours in one job must not stop the thousands after it)
        return result("failed", started, f"unexpected {type(err).__name__}: {err}")
    finally:
        scene.clear_scene()
    write_record(job, numbers)
    return result("done", started, numbers.pop("warning", ""), **numbers)


def boolean_to_file(addon, args) -> dict:
    """Import, combine, write; the numbers of the result.

    Raises:
        BatchError, AasdfError: The input is refused or the result is empty; nothing is written.
    """
    scene.clear_scene()
    scene.check_debug_volume(args, addon)
    if args.blend is not None:  # reading a file empties the field cache: such jobs share nothing
        scene.open_blend(args.blend)
    pipeline, plan = addon.aasdf_addon.pipeline, addon.aasdf_addon.plan
    operands = scene.gather_operands(args)
    settings, output = scene.run_settings(pipeline, args, operands)
    inputs = [plan.Input(obj, args.thickness) for obj in operands]
    summary = pipeline.run(
        bpy.context, inputs, scene.plan_of(args, len(operands)), settings, output,
        source="aasdf_batch", operation=args.operation or "none",
    )  # fmt: skip
    if summary.get("empty"):
        raise BatchError("the result is empty: nothing written")
    obj = bpy.data.objects[summary["object"]]
    scene.select_only([obj], obj)
    write_atomically(args, obj)
    numbers = {
        "triangles": summary["triangles"],
        "volume": round(scene.mesh_volume(obj), 6),
        "fields_built": summary["fields_built"],
    }
    if summary["warnings"]:
        numbers["warning"] = "; ".join(summary["warnings"])
    return numbers


def write_atomically(args, obj) -> None:
    """Export into a folder beside the output, then move each file into place, the output last."""
    partial = partial_dir(os.path.abspath(args.output))
    shutil.rmtree(partial, ignore_errors=True)
    os.makedirs(partial)
    try:
        scene.export_result(os.path.join(partial, os.path.basename(args.output)))
        if args.debug_volume is not None:
            volume = bpy.data.objects[f"{obj.name}.sdf"].data
            os.makedirs(os.path.dirname(os.path.abspath(args.debug_volume)), exist_ok=True)
            staged = f"{args.debug_volume}.{os.getpid()}.partial"
            shutil.copyfile(bpy.path.abspath(volume.filepath), staged)
            os.replace(staged, args.debug_volume)
        main = os.path.basename(args.output)
        for name in sorted(os.listdir(partial), key=lambda item: item == main):  # e.g. an .obj's .mtl first
            os.replace(os.path.join(partial, name), os.path.join(os.path.dirname(partial), name))
    finally:
        shutil.rmtree(partial, ignore_errors=True)
