"""A batch of jobs from start to end: read the job file, take the shard asked for, set aside the jobs that cannot run
and those already done, run the rest (in this process, in worker processes or on a Dask cluster), show the progress
and write the report."""

import sys

from . import jobs as joblist
from . import report, shutdown
from . import workers as workers_module
from .options import BatchError, check_writable, job_defaults


def inside_blender() -> bool:
    """Whether this is Blender's own executable (``blender -b -P``): its Python cannot start ``bpy`` workers."""
    return "bpy" in sys.modules and shutdown.bpy_module() is None


def worker_count(asked) -> int:
    """Worker processes to start (0: run the jobs in this process).

    Raises:
        BatchError: Workers asked for inside Blender's executable, or a negative count.
    """
    if asked is None:
        return 0 if inside_blender() else workers_module.default_count()
    if asked < 0:
        raise BatchError(f"--workers must be 0 or more, not {asked}")
    if asked > 0 and inside_blender():
        raise BatchError("worker processes need a Python with the bpy module: use --workers 0 inside Blender")
    return asked


def run_job_file(args, out, err) -> int:
    """``--jobs FILE``: every job of the file (or of its shard); exit status 1 when any failed."""
    count = worker_count(args.workers)
    if args.timeout is not None and not args.timeout > 0.0:
        raise BatchError(f"--timeout must be a number of seconds above 0, not {args.timeout}")
    if args.report is not None:  # (written as the jobs end: refused before the first, not after the last)
        check_writable(args.report)
    if args.timeout is not None and count == 0 and args.scheduler is None:
        raise BatchError("--timeout needs worker processes (--workers 1 or more): this process cannot stop a job")
    client = None
    if args.scheduler is not None:
        from . import cluster

        client = cluster.connect(args.scheduler)
    jobs = joblist.shard(joblist.read_jobs(args.jobs, job_defaults(args)), args.shard)
    summary, _ = run_jobs(
        jobs, workers=count, timeout=args.timeout, force=args.force, client=client,
        out=out, err=err, quiet=args.quiet, report_path=args.report,
    )  # fmt: skip
    return 1 if summary["failed"] else 0


def run_jobs(
    jobs, *, workers=0, timeout=None, force=False, client=None, out=None, err=None, quiet=False, report_path=None
):
    """Run ``jobs`` (``jobs.Job``): those with an error are failed, those up to date skipped (unless ``force``),
    the others run; ``report_path``: the JSON report, kept up to date as they end.

    Returns:
        ``(summary, entries)``: the counts, and a report line per job.
    """
    progress = report.Progress(len(jobs), out or sys.stdout, err or sys.stderr, quiet=quiet, report=report_path)
    todo = set_aside(jobs, progress, force=force)
    if todo and client is not None:
        from . import cluster

        cluster.run(client, todo, progress.add, timeout=timeout)
    elif todo and workers == 0:
        run_here(todo, progress.add)
    elif todo:
        workers_module.Pool(workers, timeout=timeout).run(todo, progress.add)
    return progress.close(), progress.entries


def set_aside(jobs, progress, *, force: bool) -> list:
    """The jobs to run; reports the others (cannot run, or up to date)."""
    todo = []
    for job in jobs:
        record = None if job.error or force else joblist.done_before(job)
        if job.error:
            progress.add(job, {"status": "failed", "seconds": 0.0, "message": job.error})
        elif record is not None:
            numbers = {"triangles": record.get("triangles"), "volume": record.get("volume")}
            progress.add(job, {"status": "skipped", "seconds": 0.0, "message": "up to date", **numbers})
        else:
            todo.append(job)
    return todo


def run_here(jobs, on_outcome):
    """Every job in this process, one after the other (the engine, kernels and field cache shared)."""
    from . import execute

    for job in jobs:
        on_outcome(job, execute.run_job(job))
