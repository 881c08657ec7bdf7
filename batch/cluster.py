"""Jobs on a Dask distributed cluster: each task runs in the Dask worker's own long-lived job process (a worker of
``batch.workers``, started at the worker's first job and kept, with its engine, kernels and field cache, for the
next ones), so ``bpy`` never runs in Dask's threads. Jobs are placed on the workers in contiguous lanes (a
preference Dask may override to balance the load), so jobs sharing inputs find their fields cached. Dask is imported
only here, only in this mode.

Dask worker processes must be allowed children: start them with ``DASK_DISTRIBUTED__WORKER__DAEMON=False`` (or
``dask.config.set({"distributed.worker.daemon": False})`` before a ``LocalCluster``), one thread each."""

import multiprocessing
import threading
import uuid

from .options import BatchError
from .workers import ATTEMPTS, Worker, death_of, stopped

DAEMON_OFF = "DASK_DISTRIBUTED__WORKER__DAEMON=False"
_lock = threading.Lock()
_worker = None  # this Dask worker's job process


def run_on_worker(job, timeout=None) -> dict:
    """A Dask task: ``job`` run in this Dask worker's job process (started when missing or dead), tried once more
    in a new one when that dies mid-job."""
    global _worker
    if multiprocessing.current_process().daemon:
        return stopped(job, "the Dask worker cannot start processes: start it with " + DAEMON_OFF)
    with _lock:
        how = ""
        for _ in range(ATTEMPTS):
            if _worker is None or not _worker.process.is_alive():
                _worker = Worker(quiet=True)
            outcome = _worker.run_one(job, timeout)
            if outcome is not None:
                if outcome.get("message", "").startswith("stopped after the timeout"):
                    _worker = None  # killed: a new one for the next job
                return outcome
            how = death_of(_worker.process)
            _worker.stop(kill=True)
            _worker = None
        return stopped(job, f"its worker died twice ({how})")


def connect(address: str):
    """A Dask client of the scheduler at ``address``.

    Raises:
        BatchError: Dask is not installed or the scheduler cannot be reached.
    """
    try:
        from distributed import Client
    except ImportError:
        raise BatchError("--scheduler needs Dask: pip install 'dask[distributed]'") from None
    try:
        return Client(address, timeout=30)
    except OSError as err:
        raise BatchError(f"cannot reach the Dask scheduler at {address}: {err}") from err


def run(client, jobs, on_outcome, *, timeout=None):
    """Run ``jobs`` on ``client``'s cluster; ``on_outcome(job, outcome)`` as each ends (in any order)."""
    from distributed import as_completed

    run_id, addresses = uuid.uuid4().hex[:8], sorted(client.scheduler_info()["workers"])
    futures = {}
    for k, job in enumerate(jobs):  # contiguous lanes, as ``--workers`` deals them: a preference, not a rule
        lane = (
            {"workers": [addresses[k * len(addresses) // len(jobs)]], "allow_other_workers": True} if addresses else {}
        )
        futures[client.submit(run_on_worker, job, timeout, key=f"aasdf-{run_id}-{job.number}", pure=False, **lane)] = (
            job
        )
    for future in as_completed(futures):
        job = futures[future]
        try:
            outcome = future.result()
        except Exception as err:  # noqa: BLE001 (a task lost with its Dask worker: reported, the others go on)
            outcome = stopped(job, f"the Dask task failed: {type(err).__name__}: {err}")
        on_outcome(job, outcome)


def job_process_id() -> int:
    """The process id of this Dask worker's job process (0: none running)."""
    return _worker.process.pid if _worker is not None and _worker.process.is_alive() else 0
