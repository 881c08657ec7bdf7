"""A pool of resident pages for Warp's large CPU arrays: freed arrays' pages are moved into the next arrays.

Large arrays are mapped from the system and given back to it when freed (:data:`.plan.MMAP_THRESHOLD`, which keeps a
run's peak memory down), so every stage's arrays are fresh pages the system must find and zero on first touch: on this
project's 2-core machine a /512 build spends a fifth to a third of its wall time in the system doing that. This pool
maps large arrays itself and keeps their pages when they are freed; a new array takes pooled pages first, whatever
their sizes: a pooled block is split when it is larger than needed, and several are moved side by side into one
range when none is large enough (``mremap`` moves page table entries, it copies nothing). Only what the pool cannot
cover is fresh.

Resident memory in large arrays never exceeds what it would be without the pool: pooled pages are spent before any
fresh page is touched, so the pool holds at most what the process held at its last peak (smaller arrays come from the
C heap beside it; spot | spot at /512 peaked at 406-408 MB with the pool, 405-411 MB without). :func:`release_memory`
gives pooled pages back to the system.

Written by hand because Warp's CPU allocator has no pool (its memory pools are CUDA's) and the C allocator's own reuse
of freed blocks (a dynamic mmap threshold) fragments its heap: spot | spot at /512 peaked 15 % higher. Linux only
(``mremap``); elsewhere Warp's allocator stays as it is.
"""

from __future__ import annotations

import bisect
import ctypes
import os
import sys
import threading

# Arrays below this size are left to the C allocator (its heap reuses them already).
MIN_BYTES = 1 << 20

_PROT_READ_WRITE = 0x1 | 0x2
_MAP_PRIVATE_ANONYMOUS = 0x02 | 0x20
_MREMAP_MAYMOVE = 1
_MREMAP_FIXED = 2
_MAP_FAILED = ctypes.c_void_p(-1).value


class Pages:
    """mmap, mremap and munmap of the C library (OSError or AttributeError where it has none)."""

    def __init__(self):
        libc = ctypes.CDLL(None, use_errno=True)
        self.mmap = libc.mmap
        self.mmap.restype = ctypes.c_void_p
        self.mmap.argtypes = [ctypes.c_void_p, ctypes.c_size_t, ctypes.c_int, ctypes.c_int, ctypes.c_int, ctypes.c_long]
        self.mremap = libc.mremap
        self.mremap.restype = ctypes.c_void_p
        self.mremap.argtypes = [ctypes.c_void_p, ctypes.c_size_t, ctypes.c_size_t, ctypes.c_int, ctypes.c_void_p]
        self.munmap = libc.munmap
        self.munmap.restype = ctypes.c_int
        self.munmap.argtypes = [ctypes.c_void_p, ctypes.c_size_t]

    def map(self, size: int) -> int:
        ptr = self.mmap(None, size, _PROT_READ_WRITE, _MAP_PRIVATE_ANONYMOUS, -1, 0)
        if ptr is None or ptr == _MAP_FAILED:
            raise MemoryError(f"Could not map {size} bytes: {os.strerror(ctypes.get_errno())}")
        return ptr

    def move(self, src: int, size: int, dst: int) -> None:
        """Move the pages of [src, src + size) to dst (replacing what is mapped there)."""
        ptr = self.mremap(src, size, size, _MREMAP_MAYMOVE | _MREMAP_FIXED, dst)
        if ptr is None or ptr == _MAP_FAILED:
            raise MemoryError(f"Could not move {size} bytes: {os.strerror(ctypes.get_errno())}")

    def unmap(self, ptr: int, size: int) -> None:
        self.munmap(ptr, size)


class HostPool:
    """Warp's allocator protocol (``allocate``, ``deallocate``) for the CPU device: large arrays in pooled pages,
    smaller ones from ``base`` (the device's own allocator)."""

    deallocate_requires_context_guard = False
    resident_page_pool = True  # what another copy of the engine in the process looks for (``install``)

    def __init__(self, base, pages: Pages):
        self.base = base
        self.memory_kind = base.memory_kind
        self.pages = pages
        self.page = os.sysconf("SC_PAGE_SIZE")
        self._sizes: list[int] = []  # pooled blocks, sorted by size
        self._ptrs: list[int] = []
        self._live: dict[int, int] = {}  # pointer -> mapped size of the arrays handed out
        # Python's cycle collector may free arrays inside any change of the lists above (an allocation there runs
        # it): such a free, in the thread holding the (re-entrant) lock, is set aside until the change is done. A free
        # never waits for another thread's change either (set aside, done by the next change): finalisers run at the
        # interpreter's exit, after the daemon threads are stopped wherever they were, a change's lock held or not
        self._lock = threading.RLock()
        self._busy = False
        self._pending: list[tuple[int, int]] = []
        self._bisect_left = bisect.bisect_left  # kept: arrays may be freed while the interpreter shuts down
        self.pooled = 0  # bytes of pooled pages
        self.reused = 0  # bytes handed out from the pool so far
        self.fresh = 0  # bytes mapped afresh so far

    def _take(self, k: int) -> tuple[int, int]:
        self.pooled -= self._sizes[k]
        return self._sizes.pop(k), self._ptrs.pop(k)

    def _put(self, size: int, ptr: int) -> None:
        k = self._bisect_left(self._sizes, size)
        self._sizes.insert(k, size)
        self._ptrs.insert(k, ptr)
        self.pooled += size

    def _enter(self, wait: bool = True) -> bool:
        """Take the lock for a change of the lists; False (lock released) when this thread is inside one already, or
        without ``wait`` when another thread holds it."""
        if not self._lock.acquire(wait):
            return False
        if self._busy:
            self._lock.release()
            return False
        self._busy = True
        return True

    def _leave(self) -> None:
        """Free what was set aside during the change, then let go of the lock."""
        try:
            self._drain()
        finally:
            self._busy = False
            self._lock.release()

    def _drain(self) -> None:
        """Free what was set aside (inside a change of the lists)."""
        while self._pending:
            self._free(*self._pending.pop())

    def _free(self, ptr: int, size_in_bytes: int) -> None:
        size = self._live.pop(ptr, None)
        if size is not None:
            self._put(size, ptr)
        else:
            self.base.deallocate(ptr, size_in_bytes)

    def allocate(self, size_in_bytes: int) -> int:
        if size_in_bytes < MIN_BYTES:
            return self.base.allocate(size_in_bytes)
        size = -(-size_in_bytes // self.page) * self.page
        if not self._enter():  # an allocation inside a change of the lists (a finaliser): not from the pool
            return self.base.allocate(size_in_bytes)
        try:
            k = self._bisect_left(self._sizes, size)
            if k < len(self._sizes):  # the smallest pooled block that holds it, split
                block, ptr = self._take(k)
                if block > size:
                    self._put(block - size, ptr + size)
                self.reused += size
            else:  # every pooled block (largest first) moved side by side into a new range, the rest fresh
                ptr = self.pages.map(size)
                filled = 0
                while self._sizes and filled < size:
                    block, src = self._take(len(self._sizes) - 1)
                    used = min(block, size - filled)
                    try:
                        self.pages.move(src, used, ptr + filled)
                    except MemoryError:  # (the system's limit on mappings): the block stays pooled, the rest fresh
                        self._put(block, src)
                        break
                    if block > used:
                        self._put(block - used, src + used)
                    filled += used
                self.reused += filled
                self.fresh += size - filled
            self._live[ptr] = size
        finally:
            self._leave()
        return ptr

    def deallocate(self, ptr: int, size_in_bytes: int) -> None:
        if not self._enter(wait=False):
            self._pending.append((ptr, size_in_bytes))
            return
        try:
            self._free(ptr, size_in_bytes)
        finally:
            self._leave()

    def trim(self, keep: int = 0) -> int:
        """Give pooled pages back to the system (largest blocks first) until at most ``keep`` bytes stay pooled;
        returns the bytes given back."""
        released = []
        if not self._enter():
            return 0
        try:
            self._drain()  # (frees set aside by other threads' changes: pooled first, then given back)
            while self._sizes and self.pooled > keep:
                released.append(self._take(len(self._sizes) - 1))
        finally:
            self._leave()
        for size, ptr in released:
            self.pages.unmap(ptr, size)
        return sum(size for size, _ in released)


_pool: HostPool | None = None


_install_lock = threading.Lock()  # two builds at once load their modules from two threads


def install() -> HostPool | None:
    """Put a :class:`HostPool` in front of Warp's CPU allocator (once per process: a pool another copy of the engine
    installed is shared; Warp initialised); None off Linux, where Warp's CPU device has no replaceable allocator, or
    with ``AASDF_HOST_POOL=0``."""
    if _pool is not None or os.environ.get("AASDF_HOST_POOL", "1") == "0" or not sys.platform.startswith("linux"):
        return _pool
    with _install_lock:
        return _pool if _pool is not None else _install()


def _install() -> HostPool | None:
    global _pool
    import warp as wp

    cpu = wp.get_device("cpu")
    base = getattr(cpu, "default_allocator", None)
    if base is None or not hasattr(base, "allocate"):
        return None
    if getattr(base, "resident_page_pool", False):  # another copy of the engine installed one: share it
        _pool = base
        return _pool
    try:
        pages = Pages()
    except (OSError, AttributeError):
        return None
    _pool = HostPool(base, pages)
    cpu.default_allocator = _pool
    return _pool


def release_memory(keep: int = 0) -> int:
    """Give the pool's pages back to the system until at most ``keep`` bytes stay pooled (:meth:`HostPool.trim`;
    0 when no pool is installed). Returns the bytes given back."""
    return _pool.trim(max(int(keep), 0)) if _pool is not None else 0


def installed() -> HostPool | None:
    """The pool in front of Warp's CPU allocator, if one is."""
    return _pool


def pooled_bytes() -> int:
    """Bytes of resident pages the pool holds for the next arrays (0 when none is installed)."""
    return _pool.pooled if _pool is not None else 0
