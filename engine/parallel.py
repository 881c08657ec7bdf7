"""Splitting Warp launches over the CPU cores.

A Warp launch on the CPU runs on one thread but releases the GIL, so launches of consecutive pieces of a range from
several Python threads use several cores. :func:`launch_split` does that for one kernel (pieces taken from a shared
counter by the caller and pooled helper threads), :func:`run_split` for any work on ranges, and :func:`run_tasks`
runs independent tasks side by side. On CUDA each is one ordinary launch (or the tasks one after the other).
"""

from __future__ import annotations

import os
import threading
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import warp as wp

from . import hostpool

# Below this many threads a launch is not worth splitting across CPU cores.
SPLIT_MIN_DIM = 20_000


EMIT_SPLIT_MIN_DIM = 1_000


# Pieces per core of a balanced split launch, taken by the cores in turn as they finish one (each piece is a launch
# of its own, ~60 us of Python: only for long launches whose items cost unevenly), of at least BALANCE_MIN_PIECE items.
BALANCE_PIECES_PER_CORE = 4


BALANCE_MIN_PIECE = 1024


# The CPU threads a process splits its work over: all the cores, or AASDF_THREADS when set (processes sharing a
# machine, such as the batch script's workers, each take their share instead of all competing for every core).
THREADS_VARIABLE = "AASDF_THREADS"


# The machine's cores, read once (``os.cpu_count`` reads a file each call, and every split launch asks).
_CPU_COUNT = os.cpu_count() or 1


def cores() -> int:
    """How many CPU threads work is split over: ``AASDF_THREADS`` when it is a positive integer, else the cores."""
    value = os.environ.get(THREADS_VARIABLE, "")
    if value.isdigit() and int(value) > 0:
        return int(value)
    return _CPU_COUNT


_helpers = None


_loaded = set()


_loaded_lock = threading.Lock()


_helpers_lock = threading.Lock()


def _helper_pool() -> ThreadPoolExecutor:
    """The threads that take pieces of split launches beside the caller's (starting a thread costs ~0.2 ms, more than
    many launches)."""
    global _helpers
    with _helpers_lock:
        if _helpers is None:
            # two builds may split launches at the same time (build_fields)
            _helpers = ThreadPoolExecutor(max_workers=2 * cores(), thread_name_prefix="aasdf-split")
        return _helpers


def run_split(
    work,
    dim: int,
    device,
    *,
    parts: int | None = None,
    min_dim: int = SPLIT_MIN_DIM,
    balance: bool = False,
    own_threads: bool = False,
    min_piece: int = BALANCE_MIN_PIECE,
) -> None:
    """Call ``work(start, count)`` on consecutive pieces of [0, dim) from the caller's and one more Python thread per
    further CPU core (Warp CPU launches release the GIL), or from ``parts`` threads, one piece each; one call on CUDA
    or for small ``dim``. ``balance``: the work per item is uneven (items near an open mesh's holes, or far from the
    surface): each core takes the next of ``BALANCE_PIECES_PER_CORE`` pieces per core as it finishes one, so none
    waits for the other (pieces of at least ``min_piece`` items). The helper threads come from a pool, and whichever
    thread is free takes the next piece (so a busy pool only slows a split down); ``work`` that splits work itself
    needs ``own_threads`` (a thread started for each piece). The first error is re-raised in the caller."""
    if dim <= 0:
        return
    device = wp.get_device(device)
    threads_n = parts or cores()
    if device.is_cuda or threads_n < 2 or dim < min_dim:
        work(0, dim)
        return
    pieces = threads_n
    if balance and parts is None:
        pieces = min(threads_n * BALANCE_PIECES_PER_CORE, max(threads_n, dim // max(1, min_piece)))
    bounds = np.linspace(0, dim, pieces + 1).astype(np.int64)
    errors = []
    taken = iter(range(pieces))
    lock = threading.Lock()

    def run():
        while not errors:
            with lock:
                k = next(taken, None)
            if k is None:
                return
            try:
                work(int(bounds[k]), int(bounds[k + 1] - bounds[k]))
            except Exception as err:  # re-raised below, in the caller's thread
                errors.append(err)

    if own_threads:
        threads = [threading.Thread(target=run) for _ in range(1, threads_n)]
        for t in threads:
            t.start()
        run()
        for t in threads:
            t.join()
    else:
        helpers = [_helper_pool().submit(run) for _ in range(1, threads_n)]
        run()
        for h in helpers:
            h.result()
    if errors:
        raise errors[0]


def run_tasks(tasks, device) -> None:
    """Call ``tasks`` (callables without arguments that launch independent work) from as many Python threads as the
    CPU has cores, each taking the next task as it finishes one; one after the other on CUDA. A thread per task made
    the judges of 37 operands (a plate minus 36 bores) take turns with Python's lock and the page pool's 37 ways:
    their kept surface 1.6-1.8 s. The first error is re-raised in the caller."""
    if wp.get_device(device).is_cuda or len(tasks) < 2 or cores() < 2:
        for task in tasks:
            task()
        return
    workers = min(len(tasks), cores())
    taken, lock = iter(range(len(tasks))), threading.Lock()

    def work(_k, _n):
        while True:
            with lock:
                k = next(taken, None)
            if k is None:
                return
            tasks[k]()

    run_split(work, workers, device, parts=workers, min_dim=0, own_threads=True)


def load_modules(modules, device) -> None:
    """Compile or load Warp modules (``wp.Module`` objects or Python modules with kernels) on ``device``, each once per
    process, from a thread of their own.

    Loading a module first hashes its kernels, and Warp's code generator catches an exception there whose traceback
    and the frame holding it form a cycle: every frame above it stays alive until Python's cycle collector runs. From
    a thread of its own those frames are the thread's; from the caller's they would keep its locals alive, such as
    the fields of a boolean or an extraction (hundreds of megabytes at /1024: measured, the first run's fields still
    resident through the second run's peak).
    Also puts the engine's pool of resident pages in front of Warp's CPU allocator, once (:mod:`.hostpool`)."""
    hostpool.install()
    device = wp.get_device(device)
    todo = [m for m in modules if (id(m), device.alias) not in _loaded]
    if not todo:
        return
    errors = []

    def load():
        try:
            for m in todo:
                wp.load_module(m, device=device)
        except Exception as err:  # noqa: BLE001 (re-raised in the caller's thread)
            errors.append(err)

    loader = threading.Thread(target=load)
    loader.start()
    loader.join()
    if errors:
        raise errors[0]
    with _loaded_lock:
        _loaded.update((id(m), device.alias) for m in todo)


def launch_split(
    kernel,
    dim: int,
    args,
    device,
    *,
    parts: int | None = None,
    min_dim: int = SPLIT_MIN_DIM,
    balance: bool = False,
    min_piece: int = BALANCE_MIN_PIECE,
) -> None:
    """Launch ``kernel`` over [0, dim) — on the CPU, as one launch per core from as many Python threads.

    A Warp CPU launch runs on one thread but releases the GIL, so launches from two threads use two cores. ``args``
    is called with (start, count) and returns the launch's ``inputs`` list (slices of per-thread arrays, or an
    offset the kernel adds to its thread id). On CUDA, or for small launches, this is one ordinary launch.
    ``balance``, ``min_piece``: see :func:`run_split`. Warp's CPU atomics are not atomic across two such launches (a
    sum into one slot loses one part's additions now and then): a kernel that adds into shared slots runs whole
    (``wp.launch``) or writes one value per thread, unless all it raises is a flag tested for nonzero.
    """
    if dim <= 0:
        return
    load_modules([kernel.module], device)  # compile (or load) once, before threads race for it
    run_split(
        lambda lo, n: wp.launch(kernel, dim=n, inputs=args(lo, n), device=device),
        dim,
        device,
        parts=parts,
        min_dim=min_dim,
        balance=balance,
        min_piece=min_piece,
    )


def host_view(array: np.ndarray, dtype, device) -> wp.array:
    """A Warp array of a C-contiguous numpy ``array`` on ``device``: on the CPU the numpy memory itself (the caller
    keeps ``array`` alive while kernels read it; copying 540 k faces' corner weights took 11 ms), elsewhere a copy."""
    device = wp.get_device(device)
    return wp.array(array, dtype=dtype, device=device, copy=not device.is_cpu)
