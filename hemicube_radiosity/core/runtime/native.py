"""The native libraries under NumPy, set for a bake: OpenBLAS's thread count and glibc's heap.

A bake's BLAS calls are tiny and its temporaries large and many: left as they are, OpenBLAS's
second thread spins beside the bake's own threads, and glibc maps and unmaps every large
temporary afresh (each page faulted in and zeroed again). :func:`one_blas_thread` and
:func:`kept_heap` hold the better settings around a bake (and put back what they found);
:func:`set_one_blas_thread` and :func:`keep_freed_memory` are what a forked worker process
(:mod:`.forked`) sets for itself. All best effort: nothing happens where the library is not
there (MKL or Accelerate instead of OpenBLAS, a C library other than glibc).
"""
from __future__ import annotations

import ctypes
import sys
import threading
from contextlib import contextmanager

__all__ = ["one_blas_thread", "kept_heap", "set_one_blas_thread", "keep_freed_memory", "openblas"]


#: glibc's ``mallopt`` parameters (malloc.h): M_TRIM_THRESHOLD, M_TOP_PAD.
_M_TRIM_THRESHOLD, _M_TOP_PAD = -1, -2


def keep_freed_memory():
    """glibc, in a forked worker (best effort; the process that bakes is left as it is): keep
    freed memory in the worker's heap for its next batch instead of handing it back to the
    system and faulting fresh zeroed pages in again, and grow the heap 64 MB at a time. A
    worker's batches make and drop the same large temporaries (a gather chunk's quarter million
    rays) again and again; kept, its page faults and system time drop to about a third
    (``docs/performance.md``). A worker lives for one map: what it keeps is freed when it
    exits."""
    try:
        libc = ctypes.CDLL(None)
        libc.mallopt(_M_TRIM_THRESHOLD, (1 << 31) - 1)
        libc.mallopt(_M_TOP_PAD, 1 << 26)
    except (OSError, AttributeError):
        pass


def set_one_blas_thread():
    """Ask the OpenBLAS that NumPy loaded for one thread, if it is there and has more (best
    effort). Its threads only spin beside the rasteriser's small products (3 x V): in the serial
    bake they burn a second core for nothing, and two workers with two BLAS threads each would
    fight over two cores.

    A count of one already (a worker forked by a bake, which holds :func:`one_blas_thread`) is
    left alone: OpenBLAS stops its threads at a fork, and ``openblas_set_num_threads`` in the
    child starts them again whatever the count, and a new thread spins (sched_yield) for about
    0.1 s, in every worker."""
    for set_threads, get_threads in openblas():
        if get_threads() != 1:
            set_threads(1)


def openblas() -> list:
    """(set, get) of the thread count of every OpenBLAS that NumPy loaded (none elsewhere: MKL,
    Accelerate), looked up once (NumPy loads its BLAS when it is imported, before any bake)."""
    global _BLAS
    if _BLAS is None:
        import numpy  # noqa: F401  (loads its BLAS, if it was not imported yet)
        found = []
        try:
            with open("/proc/self/maps") as f:
                paths = {line.split()[-1] for line in f if "openblas" in line.lower()}
        except OSError:
            paths = set()
        for path in sorted(paths):
            try:
                lib = ctypes.CDLL(path)
            except OSError:
                continue
            for prefix, suffix in (("openblas", "64_"), ("openblas", ""), ("scipy_openblas", "64_"),
                                   ("scipy_openblas", "")):
                set_threads = getattr(lib, f"{prefix}_set_num_threads{suffix}", None)
                get_threads = getattr(lib, f"{prefix}_get_num_threads{suffix}", None)
                if set_threads is not None and get_threads is not None:
                    set_threads.argtypes, set_threads.restype = [ctypes.c_int], None
                    get_threads.argtypes, get_threads.restype = [], ctypes.c_int
                    found.append((set_threads, get_threads))
                    break
        _BLAS = found
    return _BLAS


_BLAS = None                   # :func:`openblas`, once looked up
_BLAS_LOCK = threading.Lock()
_BLAS_HELD = []                # one entry per bake inside one_blas_thread() now
_BLAS_BEFORE = []              # (set, thread count) to put back when the last of them ends


@contextmanager
def one_blas_thread():
    """NumPy's OpenBLAS on one thread while the block runs (a bake), as before afterwards.

    A bake's BLAS calls are tiny: the luminance of a (V, 3) field (``values @ LUMA``), a few per
    relight. Above 9,216 products OpenBLAS hands half of such a call to its second thread,
    which then spins (sched_yield) for about 0.1 s waiting for more, beside the bake's own
    threads: relights ran measurably faster on one BLAS thread (``docs/performance.md``), with
    the same arrays bit for bit (each output of those products is summed by one thread either
    way). Bakes that overlap (the CLI's jobs) share the setting: the first sets it, the last
    puts back what the first found."""
    with _BLAS_LOCK:
        if not _BLAS_HELD:
            _BLAS_BEFORE[:] = [(set_threads, get_threads()) for set_threads, get_threads in openblas()]
            for set_threads, _ in _BLAS_BEFORE:
                set_threads(1)
        _BLAS_HELD.append(None)
    try:
        yield
    finally:
        with _BLAS_LOCK:
            _BLAS_HELD.pop()
            if not _BLAS_HELD:
                for set_threads, count in _BLAS_BEFORE:
                    set_threads(count)
                _BLAS_BEFORE.clear()


#: glibc's ``mallopt`` parameter M_MMAP_THRESHOLD (malloc.h), and the heap a bake keeps.
_M_MMAP_THRESHOLD = -3
_HEAP_MMAP, _HEAP_TRIM, _HEAP_TRIM_AFTER = 32 << 20, 256 << 20, 64 << 20
_HEAP_LOCK = threading.Lock()
_HEAP_HELD: list = []


@contextmanager
def kept_heap():
    """glibc, while the block runs (a bake; best effort, nothing elsewhere): arrays below 32 MB
    come from the heap, and up to 256 MB of freed heap is kept for the next ones, instead of each
    temporary being mapped fresh and unmapped (every page faulted in again, zeroed by the
    kernel). A bake makes and drops the same large temporaries thousands of times: kept, its
    page faults and system time drop to about a quarter, with the same peak memory
    (``docs/performance.md``). glibc moves to the same 32 MB on its own once a NumPy program
    frees an array that large; afterwards it keeps 64 MB of freed heap at its top (what it would
    keep then), and the next free hands the rest back to the system. Not trimmed at once
    (``malloc_trim``): a relight then faulted its pages in again every time. Bakes that overlap
    share the setting (the last one out puts it back). Workers forked meanwhile inherit it
    (:func:`keep_freed_memory` adds their own)."""
    libc = _glibc()
    with _HEAP_LOCK:
        if not _HEAP_HELD and libc is not None:
            libc.mallopt(_M_MMAP_THRESHOLD, _HEAP_MMAP)
            libc.mallopt(_M_TRIM_THRESHOLD, _HEAP_TRIM)
        _HEAP_HELD.append(None)
    try:
        yield
    finally:
        with _HEAP_LOCK:
            _HEAP_HELD.pop()
            if not _HEAP_HELD and libc is not None:
                libc.mallopt(_M_TRIM_THRESHOLD, _HEAP_TRIM_AFTER)


def _glibc():
    """glibc's ``mallopt`` (a ctypes CDLL), or None (not glibc)."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        libc = ctypes.CDLL(None)
        libc.mallopt                        # noqa: B018 (there, or None)
        return libc
    except (OSError, AttributeError, TypeError):
        return None
