"""The pool of resident pages behind Warp's large CPU arrays (engine/hostpool.py)."""

import ctypes
import sys

import numpy as np
import pytest
import warp as wp

import engine
from engine import hostpool
from tests.support import uv_sphere

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the pool is Linux's (mremap)")

MB = 2**20


def _view(ptr: int, size: int) -> np.ndarray:
    return np.ctypeslib.as_array((ctypes.c_uint8 * size).from_address(ptr))


def _resident_mb() -> float:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * 4096 / MB


class _Recorder:
    """A stand-in for Warp's own allocator: counts what reaches it."""

    memory_kind = None

    def __init__(self):
        self.allocated = self.freed = 0

    def allocate(self, n):
        self.allocated += 1
        return ctypes.cast(ctypes.create_string_buffer(n), ctypes.c_void_p).value

    def deallocate(self, ptr, n):
        self.freed += 1


def test_arrays_take_freed_pages_without_sharing_any():
    pool = hostpool.HostPool(_Recorder(), hostpool.Pages())
    live = {}
    rng = np.random.default_rng(3)
    for step in range(60):
        if live and rng.random() < 0.45:  # free one
            ptr = list(live)[rng.integers(len(live))]
            size, _ = live.pop(ptr)
            pool.deallocate(ptr, size)
        else:  # sizes around each other's, some larger than anything pooled (moved side by side), some split
            size = int(rng.integers(1, 24) * MB + rng.integers(0, 4096))
            ptr = pool.allocate(size)
            mark = step % 251 + 1
            _view(ptr, size)[:] = mark
            live[ptr] = (size, mark)
        for ptr, (size, mark) in live.items():  # every live array still holds what was written to it
            view = _view(ptr, size)
            assert view[0] == mark and view[-1] == mark and view[size // 2] == mark
    assert pool.reused > 0 and pool.base.allocated == 0  # large arrays only ever came from the pool's pages
    for ptr, (size, _) in live.items():
        pool.deallocate(ptr, size)
    pool.trim()
    assert pool.pooled == 0


def test_the_pool_holds_no_more_than_the_process_held_at_its_peak():
    pool = hostpool.HostPool(_Recorder(), hostpool.Pages())
    page = pool.page
    live, held, peak = {}, 0, 0
    rng = np.random.default_rng(5)
    for _ in range(200):
        if live and rng.random() < 0.5:
            ptr = list(live)[rng.integers(len(live))]
            size = live.pop(ptr)
            pool.deallocate(ptr, size)
            held -= -(-size // page) * page
        else:
            size = int(rng.integers(3, 40) * MB // 3)  # large arrays (smaller ones are the C heap's)
            live[pool.allocate(size)] = size
            held += -(-size // page) * page
        peak = max(peak, held)
        # what would be resident without the pool (the live arrays) plus what the pool keeps never passes the peak
        assert held + pool.pooled <= peak
    assert pool.fresh <= peak
    for ptr, size in live.items():
        pool.deallocate(ptr, size)
    pool.trim()


def test_released_pages_leave_the_process():
    pool = hostpool.HostPool(_Recorder(), hostpool.Pages())
    size = 96 * MB
    ptr = pool.allocate(size)
    _view(ptr, size)[:] = 1  # resident
    pool.deallocate(ptr, size)
    before = _resident_mb()
    assert pool.pooled == size
    assert pool.trim(keep=32 * MB) == size and pool.pooled == 0  # one block: all of it goes
    assert before - _resident_mb() > 80


def test_small_arrays_and_foreign_pointers_stay_with_warps_allocator():
    base = _Recorder()
    pool = hostpool.HostPool(base, hostpool.Pages())
    ptr = pool.allocate(hostpool.MIN_BYTES - 1)
    pool.deallocate(ptr, hostpool.MIN_BYTES - 1)
    pool.deallocate(12345, 8 * MB)  # an array made before the pool was installed
    assert (base.allocated, base.freed, pool.pooled) == (1, 2, 0)


def test_fields_from_reused_pages_equal_fields_from_fresh_ones(monkeypatch):
    """Kernels write every element of the arrays they make: pooled pages full of garbage change no value."""
    a, b = uv_sphere(1.0, rings=32, segments=64), uv_sphere(0.8, center=(0.9, 0.1, 0.0), rings=32, segments=64)
    h = 3.2 / 256

    def run():
        fa, fb = engine.build_fields([a, b], voxel_size=h)
        moved = np.eye(4)
        moved[:3, 3] = (0.37 * h, -0.21 * h, 0.05 * h)
        r = engine.difference(fa, fb.transformed(moved))
        verts, tris = r.to_mesh()
        return [fa.values.numpy().copy(), fb.values.numpy().copy(), r.values.numpy().copy(), verts, tris]

    fresh = run()
    pool = hostpool.installed()  # installed by the first launch (or shared with another copy of the engine)
    assert pool is not None and pool is wp.get_device("cpu").default_allocator and engine.pooled_bytes() > 0
    allocate = pool.allocate

    def poisoned(n):
        ptr = allocate(n)
        if n >= hostpool.MIN_BYTES:
            ctypes.memset(ptr, 0xFF, n)  # NaN floats, -1 integers
        return ptr

    monkeypatch.setattr(pool, "allocate", poisoned)
    reused = pool.reused
    again = run()
    assert pool.reused - reused > 8 * MB  # the second run's large arrays came from pooled pages
    for x, y in zip(fresh, again, strict=True):
        np.testing.assert_array_equal(x, y)
    assert engine.release_memory() > 0 and engine.pooled_bytes() == 0


def test_a_move_the_system_refuses_leaves_the_block_pooled_and_the_array_fresh():
    class Refusing(hostpool.Pages):
        def move(self, src, size, dst):
            raise MemoryError("Could not move: the system's limit on mappings")

    pool = hostpool.HostPool(_Recorder(), Refusing())
    first = pool.allocate(2 * MB)
    pool.deallocate(first, 2 * MB)
    ptr = pool.allocate(5 * MB)  # larger than the pooled block: would be gathered
    _view(ptr, 5 * MB)[:] = 7
    assert pool.pooled == 2 * MB and pool.fresh == 7 * MB and _view(ptr, 5 * MB)[-1] == 7
    pool.deallocate(ptr, 5 * MB)
    assert pool.trim() == 7 * MB


def test_an_array_freed_inside_a_change_of_the_pool_waits_for_it():
    """Python's cycle collector can free an array inside an allocation (in the same thread): no deadlock, no list
    changed under the change's feet; the array is pooled once the change is done."""

    class Collecting(hostpool.Pages):
        def move(self, src, size, dst):
            if garbage:
                pool.deallocate(*garbage.pop())  # as a finaliser run by a collection would
                assert pool.pooled == 0  # set aside: the block being moved is out of the lists, nothing else in
            super().move(src, size, dst)

    pool = hostpool.HostPool(_Recorder(), Collecting())
    first, kept, dropped = pool.allocate(2 * MB), pool.allocate(3 * MB), pool.allocate(1 * MB)
    pool.deallocate(first, 2 * MB)
    garbage = [(dropped, 1 * MB)]
    ptr = pool.allocate(4 * MB)  # no pooled block holds it: the 2 MB one is moved into it
    assert not garbage and pool.pooled == 1 * MB and pool.reused == 2 * MB
    for p, n in ((ptr, 4 * MB), (kept, 3 * MB)):
        _view(p, n)[:] = 5
        pool.deallocate(p, n)
    assert pool.trim() == 8 * MB


def test_a_free_never_waits_for_another_threads_change_of_the_pool():
    """A finaliser may free an array while another thread is inside a change of the pool, or after that thread was
    stopped there (a daemon thread, at the interpreter's exit): the free returns at once, set aside; the change takes
    it when it is done."""
    import threading

    inside, go_on = threading.Event(), threading.Event()

    class Stopping(hostpool.Pages):
        def move(self, src, size, dst):
            inside.set()
            go_on.wait(10)  # a thread stopped inside the change
            super().move(src, size, dst)

    pool = hostpool.HostPool(_Recorder(), Stopping())
    first, second = pool.allocate(2 * MB), pool.allocate(3 * MB)
    pool.deallocate(first, 2 * MB)
    got = []
    changing = threading.Thread(target=lambda: got.append(pool.allocate(4 * MB)), daemon=True)  # moves the 2 MB
    changing.start()
    inside.wait(10)
    freeing = threading.Thread(target=pool.deallocate, args=(second, 3 * MB), daemon=True)
    freeing.start()
    freeing.join(5)
    assert not freeing.is_alive()  # (before: it waited as long as the other thread was stopped)
    go_on.set()
    changing.join(10)
    assert pool.pooled == 3 * MB  # taken by the change when it was done
    pool._pending.append((got[0], 4 * MB))  # as a free set aside after that change: the release takes it too
    assert pool.trim() == 7 * MB and not pool._pending


EXIT_SCRIPT = """
import sys, threading, time
sys.path.insert(0, {root!r})
import engine, warp as wp
from engine import hostpool

pool = hostpool.install()
class Cycle: pass
held = Cycle(); held.me = held; held.array = wp.empty(3 << 20, dtype=wp.uint8, device="cpu")
del held  # (a cycle: freed by the collection at the interpreter's exit)
first = wp.empty(2 << 20, dtype=wp.uint8, device="cpu")
del first  # pooled
inside = threading.Event()
def move(src, size, dst):
    inside.set()
    time.sleep(3600)
pool.pages.move = move  # the next allocation moves the pooled block: a thread stopped there
threading.Thread(target=lambda: wp.empty(4 << 20, dtype=wp.uint8, device="cpu"), daemon=True).start()
inside.wait()
"""


def test_a_process_exits_while_a_daemon_thread_is_inside_a_change_of_the_pool():
    """As a script that leaves a boolean's judge running in its daemon thread: the interpreter stops the thread
    wherever it is, and the frees of its last collection do not wait for it (before: the process never exited)."""
    import subprocess
    from pathlib import Path

    root = str(Path(__file__).resolve().parents[2])
    done = subprocess.run([sys.executable, "-c", EXIT_SCRIPT.format(root=root)], timeout=30, capture_output=True)
    assert done.returncode == 0, done.stderr.decode()[-2000:]
