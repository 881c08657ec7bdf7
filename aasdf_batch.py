"""Headless SDF booleans with AASDF: mesh files or objects of a .blend in, a mesh file or a .blend out.

Run it with Blender or with the ``bpy`` module::

    blender -b [scene.blend] -P aasdf_batch.py -- --operation union --inputs a.obj b.stl --resolution 256 \\
        --output out.ply [--debug-volume out.vdb] [--objects NAME ...] [--verbose | --quiet]
    python aasdf_batch.py --operation difference --inputs a.obj b.ply --output out.blend [--blend scene.blend]
    python aasdf_batch.py --jobs jobs.jsonl [--resolution 128 ...] [--workers N] [--report report.json]

Operands are the imported files (``.obj``, ``.ply``, ``.stl``; a file holding several meshes becomes one operand),
then the named objects, in the order given: the first is the active object, so DIFFERENCE is the first operand
minus all the others. ``--offset`` grows (or shrinks) the result and ``--shell`` hollows it (with one operand, that
operand alone); ``--thickness`` gives surfaces that enclose nothing a wall; ``--blend-mode``, ``--no-sharp-edges``
as the add-on's settings. The output is ``.ply``, ``.obj``, ``.stl`` or ``.blend``. Everything runs through the
add-on's pipeline, as ``bpy.ops.aasdf.boolean`` does; when AASDF is not already enabled, the repository this script
sits in is registered as the package ``aasdf``. Prints each step as it goes (``--quiet``: only the summary;
``--verbose``: Warp's own start-up and kernel-loading lines too) and a one-line summary; exits with 2 on bad arguments
or input and with 1 when the boolean fails or is empty, with the reason on stderr.

``--jobs FILE`` runs a job file (JSON lines or CSV, a job a line, keys = the long options without dashes; the
command line's options are every job's defaults) in long-lived processes (``--workers``, ``--scheduler`` for a Dask
cluster), skipping jobs whose output is up to date; it exits with 1 when any job failed. See docs/usage.md.
"""

import os
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent
if str(ROOT) not in sys.path:  # the batch package beside this script (worker processes find it the same way)
    sys.path.insert(0, str(ROOT))

from batch import options, report, runner, shutdown  # noqa: E402


def script_args(argv):
    """The script's own arguments: those after ``--`` when present (Blender's ``-P`` and ``python x.py --``)."""
    return argv[argv.index("--") + 1 :] if "--" in argv else argv[1:]


def run(args, out) -> int:
    """One boolean (exit status 0 or 1), or a job file with ``--jobs``."""
    if args.verbose:
        os.environ["AASDF_VERBOSE"] = "1"
    if args.jobs is not None:
        return runner.run_job_file(args, out, sys.stderr)
    options.check_args(args)
    from batch import single  # imports bpy

    return single.run(args, out, sys.stderr)


def run_jobs(jobs, client=None, *, workers=None, timeout=None, force=False, quiet=True, **defaults) -> list:
    """Run job dicts (keys as in a job file; relative paths relative to the working folder) from Python: on
    ``client``'s Dask cluster, else in ``workers`` local worker processes (default: the cores; 0: this process).
    ``defaults`` are every job's options where it gives none (``resolution=128``).

    Returns:
        A report line per job, in order: ``{"job", "where", "output", "status", "seconds", "triangles", "volume",
        "message"}``.
    """
    from batch import jobs as joblist

    base = options.job_defaults(options.command_line_parser("").parse_args([]))
    base.update(defaults)
    todo = joblist.jobs_from_dicts(jobs, base)
    count = 0 if client is not None else runner.worker_count(workers)
    _, entries = runner.run_jobs(todo, workers=count, timeout=timeout, force=force, client=client, quiet=quiet)
    return sorted(entries, key=lambda entry: entry["job"])


def main(argv=None) -> int:
    parser = options.command_line_parser(__doc__.split("\n\n")[0])
    args = parser.parse_args(script_args(sys.argv if argv is None else argv))
    if args.jobs is None and args.output is None:
        parser.error("the following arguments are required: --output")
    try:
        with report.blender_output_silenced(not args.verbose) as out:
            return run(args, out)
    except options.BatchError as err:
        print(f"aasdf_batch: error: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("aasdf_batch: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(shutdown.run_main(main))  # Blender 4.2 and 4.5 as a module cannot end it themselves
