"""Long-lived worker processes fed job by job: each imports ``bpy``, registers the add-on and loads the kernels once,
then runs the jobs it is sent (``execute.run_job``) until told to stop. A job past its timeout has its worker killed
and replaced, and is reported; a worker that dies mid-job (killed, out of memory) is replaced and its job tried once
more, then reported. Each worker works down a contiguous lane of the jobs (jobs sharing inputs stay on the worker
whose field cache holds them). Workers are started with the ``spawn`` method, so they need a Python with the ``bpy``
module."""

import multiprocessing
import os
import shutil
import signal
import sys
import time
from collections import deque
from multiprocessing.connection import wait

from . import shutdown
from .jobs import partial_dir
from .options import BatchError

ATTEMPTS = 2  # a job whose worker dies is tried once more
THREADS_VARIABLE = "AASDF_THREADS"  # the engine's threads per process (``engine.parallel.THREADS_VARIABLE``)
START_FAILURES = 3  # workers dying before their first job: give up, it will not get better


def serve(conn, quiet: bool, threads: int | None = None):
    """A worker's main loop: ``("started", number)`` when a job begins, ``("done", number, outcome)`` when it ends.
    ``threads``: the CPU threads its engine splits work over (its share of the cores), when given."""
    from . import report

    if threads:
        os.environ[THREADS_VARIABLE] = str(threads)  # read by the engine (``engine.parallel.cores``)
    scripts_last()
    if quiet:
        report.silence_stdout()
    from . import execute

    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the parent's to handle: it stops the workers
    execute.prepare()
    try:
        conn.send(("ready",))
        while (job := conn.recv()) is not None:
            conn.send(("started", job.number))
            conn.send(("done", job.number, execute.run_job(job)))
    except (EOFError, OSError):  # the parent is gone
        pass
    shutdown.end_process(0)  # Blender 4.2's and 4.5's bpy module cannot end the process itself


def scripts_last():
    """Move Blender's script folders (``.../bpy/<version>/scripts/...``, added to ``sys.path`` by a parent that had
    imported ``bpy`` and inherited through ``spawn``) behind the rest: the ``bpy`` module must be found before its
    own ``scripts/modules/bpy`` package."""
    marker = f"{os.sep}bpy{os.sep}"
    scripts = [path for path in sys.path if marker in path and f"{os.sep}scripts" in path]
    sys.path[:] = [path for path in sys.path if path not in scripts] + scripts


def death_of(process) -> str:
    code = process.exitcode
    if code is not None and code < 0:
        try:
            return f"killed by {signal.Signals(-code).name}"
        except ValueError:
            return f"killed by signal {-code}"
    return f"exit status {code}"


class Worker:
    """One worker process and its end of the pipe; ``job`` is the job it holds, ``started`` when it began it."""

    def __init__(self, quiet: bool = True, threads: int | None = None):
        context = multiprocessing.get_context("spawn")
        self.conn, child = context.Pipe()
        self.process = context.Process(target=serve, args=(child, quiet, threads), name="aasdf-worker")
        self.process.start()
        child.close()
        self.job, self.started, self.ready = None, None, False

    def give(self, job):
        """Send ``job``; a worker that has just died keeps it (its death is seen next, and the job tried again)."""
        self.job, self.started = job, None
        try:
            self.conn.send(job)
        except OSError:
            pass

    def stop(self, *, kill: bool = False):
        if kill:
            self.process.kill()
        else:
            try:
                self.conn.send(None)
            except OSError:
                pass
        self.process.join(5.0)
        if self.process.is_alive():
            self.process.kill()
            self.process.join()
        self.conn.close()

    def messages(self) -> list:
        """What the worker has sent so far (nothing more once it has died)."""
        found = []
        try:
            while self.conn.poll():
                found.append(self.conn.recv())
        except (EOFError, OSError):
            pass
        return found

    def run_one(self, job, timeout=None) -> dict | None:
        """Run one job and wait for it: its outcome, a timeout's, or None when the worker died."""
        self.give(job)
        while True:
            wait([self.conn, self.process.sentinel], timeout=0.2)
            for message in self.messages():
                if message[0] == "started":
                    self.started = time.monotonic()
                elif message[0] == "ready":
                    self.ready = True
                elif message[0] == "done":
                    self.job = None
                    return message[2]
            if not self.process.is_alive():
                return None
            if self.over_time(timeout):
                self.stop(kill=True)
                return stopped(job, f"stopped after the timeout of {timeout:g} s")

    def over_time(self, timeout) -> bool:
        return timeout is not None and self.started is not None and time.monotonic() - self.started > timeout


def stopped(job, how: str) -> dict:
    """The outcome of a job whose worker was stopped; what it was writing is removed."""
    if job.output:
        shutil.rmtree(partial_dir(job.output), ignore_errors=True)
    return {"status": "failed", "seconds": 0.0, "message": how}


class Pool:
    """``count`` workers running ``jobs``; ``on_outcome(job, outcome)`` is called as each ends.

    The jobs are dealt out in ``count`` contiguous lanes, one per worker, as job files list jobs sharing inputs near
    each other: each worker's field cache then holds what its next jobs need. A worker whose lane is empty takes the
    last job of the longest other lane (the one its owner would reach last)."""

    def __init__(self, count: int, *, timeout: float | None = None, quiet: bool = True):
        self.count, self.timeout, self.quiet = max(1, count), timeout, quiet
        self.workers, self.lanes, self.attempts, self.start_failures = [], [], {}, 0
        self.retried = {}  # job number -> how its first worker died
        self.threads = None

    def run(self, jobs, on_outcome):
        jobs = list(jobs)
        count = min(self.count, len(jobs))
        self.lanes = [deque(jobs[k * len(jobs) // count : (k + 1) * len(jobs) // count]) for k in range(count)]
        self.threads = max(1, default_count() // count)  # each worker's share of the cores
        self.workers = [Worker(self.quiet, self.threads) for _ in range(count)]
        try:
            while any(self.lanes) or self.busy():
                self.feed()
                self.step(on_outcome)
        finally:
            for worker in self.workers:
                if worker is not None:
                    worker.stop(kill=worker.job is not None)

    def busy(self) -> list:
        return [w for w in self.workers if w is not None and w.job is not None]

    def feed(self):
        for slot, worker in enumerate(self.workers):
            if worker is not None and worker.job is None and any(self.lanes):
                worker.give(self.take(slot))

    def take(self, slot: int):
        """The next job of lane ``slot``, else the last of the longest other lane."""
        if self.lanes[slot]:
            return self.lanes[slot].popleft()
        return max(self.lanes, key=len).pop()

    def step(self, on_outcome):
        """Wait for a message, a worker's death or a timeout, and act on it."""
        busy = self.busy()
        conns, sentinels = {id(w.conn): w for w in busy}, {w.process.sentinel: w for w in busy}
        for handle in wait([w.conn for w in busy] + list(sentinels), timeout=0.2):
            worker = sentinels[handle] if isinstance(handle, int) else conns[id(handle)]
            if worker.job is None or worker not in self.workers:
                continue
            for message in worker.messages():
                self.receive(worker, message, on_outcome)
            if worker.job is not None and not worker.process.is_alive():
                self.died(worker, on_outcome)
        for worker in self.busy():
            if worker.over_time(self.timeout):
                on_outcome(worker.job, stopped(worker.job, f"stopped after the timeout of {self.timeout:g} s"))
                self.replace(worker, kill=True)

    def receive(self, worker, message, on_outcome):
        if message[0] == "ready":
            worker.ready = True
        elif message[0] == "started":
            worker.started = time.monotonic()
        elif message[0] == "done":
            job, worker.job, worker.started = worker.job, None, None
            outcome = message[2]
            if job.number in self.retried and outcome["status"] == "done":
                outcome["message"] = f"tried again: its first worker died ({self.retried[job.number]})"
            on_outcome(job, outcome)

    def died(self, worker, on_outcome):
        job, how = worker.job, death_of(worker.process)
        if not worker.ready:
            self.start_failures += 1
            if self.start_failures >= START_FAILURES:
                raise BatchError(f"worker processes die as they start ({how}): is the bpy module importable?")
        self.attempts[job.number] = self.attempts.get(job.number, 0) + 1
        if self.attempts[job.number] < ATTEMPTS:
            self.lanes[self.workers.index(worker)].appendleft(job)  # tried again first, by a new worker
            self.retried[job.number] = how
            stopped(job, how)
        else:
            on_outcome(job, stopped(job, f"its worker died twice ({how})"))
        self.replace(worker, kill=False)

    def replace(self, worker, *, kill: bool):
        """Stop ``worker``; a new one takes its place while jobs are left."""
        worker.job = None
        worker.stop(kill=kill)
        self.workers[self.workers.index(worker)] = Worker(self.quiet, self.threads) if any(self.lanes) else None


def default_count() -> int:
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1
