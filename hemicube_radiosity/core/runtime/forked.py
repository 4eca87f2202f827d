"""Worker processes forked from the bake: what they inherit, how they start and stop.

Where the heavy work holds the GIL (the hemi-cube rasteriser's many small NumPy operations), two
threads run little faster than one; forked processes do. On Linux the workers are ``fork()``-ed
from the caller when a map starts, so they inherit the function and everything it holds (the
patch geometry, the frames) without a copy or a pickle: only the items (receiver ids) go to them
and only the results (sparse rows) come back, or the results are written in place into a
:func:`shared_array`. Nothing is imported or started anew: no Blender, no ``bpy`` (inside
Blender ``sys.executable`` is the Blender binary, which the 'spawn' and 'forkserver' methods
would run), no resource tracker; a worker runs only its function, with one BLAS thread.

The pieces here: :data:`PROCESSES` and :func:`processes_available` (whether to fork at all),
:func:`fork_pool` (a pool whose workers inherit a function, run as :func:`run_task`),
:func:`submit_forking` (the first submit, which forks), :func:`terminate` (stop the workers at
once), :func:`shared_array` and :func:`release_tail`. :mod:`.parallel` maps over such pools,
:class:`.background.Ahead` runs one value on one.
"""
from __future__ import annotations

import ctypes
import itertools
import mmap
import multiprocessing
import os
import signal
import sys
import warnings
from concurrent.futures import ProcessPoolExecutor

import numpy as np

from .native import keep_freed_memory, set_one_blas_thread

__all__ = ["PROCESSES", "processes_available", "in_worker", "fork_pool", "submit_forking", "run_task",
           "forget", "terminate", "shared_array", "release_tail"]

#: False: ``ordered_map(..., processes=True)`` runs on threads too (a switch for benchmarks and
#: for a host where forking misbehaves).
PROCESSES = True

_TASKS: dict = {}              # token -> fn of the process maps running now (inherited by fork)
_TOKENS = itertools.count()
_IN_WORKER = False             # True inside a forked worker: its own maps run serially
_PARENT_PID = None             # the process that forks the workers (set before every fork)


def processes_available() -> bool:
    """True where ``ordered_map(..., processes=True)`` forks worker processes: Linux with the
    'fork' start method, :data:`PROCESSES` on, not inside a daemonic process or a worker."""
    if not PROCESSES or _IN_WORKER or not sys.platform.startswith("linux"):
        return False
    if "fork" not in multiprocessing.get_all_start_methods():
        return False
    return not multiprocessing.current_process().daemon


def in_worker() -> bool:
    """True inside a forked worker (its own maps run serially)."""
    return _IN_WORKER


def fork_pool(fn, workers: int):
    """(pool, token): a process pool of ``workers`` that fork from this process at the first
    submit (:func:`submit_forking`), with ``fn`` registered under ``token`` before they do, so they
    inherit it: ``pool.submit(run_task, token, item)`` runs ``fn(item)`` in a worker, ``fn``
    never pickled. :func:`forget` the token once the workers are forked or gone."""
    global _PARENT_PID
    token = next(_TOKENS)
    _TASKS[token] = fn                       # before the fork: the workers inherit it
    _PARENT_PID = os.getpid()
    pool = ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("fork"),
                               initializer=_worker_init)
    return pool, token


def submit_forking(pool, fn=None, *args):
    """``pool.submit(fn, *args)`` (``fn`` None: nothing), the future: the first submit to a
    :func:`fork_pool` forks every worker, on the calling thread. Raises OSError when the fork
    fails (no memory or processes left)."""
    with warnings.catch_warnings():          # Python >= 3.12 warns of fork() beside threads
        warnings.simplefilter("ignore", DeprecationWarning)
        return pool.submit(_noop if fn is None else fn, *args)


def run_task(token, item):
    """In a worker: the registered function of ``token`` (:func:`fork_pool`) on ``item``."""
    return _TASKS[token](item)


def forget(token) -> None:
    """Let go of the function registered under ``token`` (:func:`fork_pool`)."""
    _TASKS.pop(token, None)


def terminate(pool) -> None:
    """Terminate ``pool``'s worker processes at once, so that its ``shutdown`` returns.

    A worker killed while it writes a result leaves half a message in the results pipe, and the
    pool's manager thread, reading it, would wait for the rest for ever: this process holds the
    pipe's writing end too (it made the pipe before forking), so the read never meets its end.
    Once the workers are gone, that end is closed here: the read ends, the pool counts itself
    broken, and its threads stop."""
    procs = list((getattr(pool, "_processes", None) or {}).values())
    for p in procs:
        try:
            p.terminate()
        except (OSError, AttributeError):
            pass
    for p in procs:
        try:
            p.join(5.0)
        except (OSError, AttributeError, AssertionError):
            pass
    if all(getattr(p, "exitcode", None) is not None for p in procs):
        writer = getattr(getattr(pool, "_result_queue", None), "_writer", None)
        try:
            if writer is not None:
                writer.close()
        except OSError:
            pass


def _worker_init():
    """In a forked worker: Ctrl-C is the parent's to handle (it terminates the workers), maps
    inside ``fn`` run serially, and BLAS uses one thread (each worker is one of the cores)."""
    global _IN_WORKER
    _IN_WORKER = True
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    _die_with_parent()
    set_one_blas_thread()
    keep_freed_memory()


def _die_with_parent():
    """Linux: the kernel kills this worker when the thread that forked it ends, so a baking
    process killed outright (a crash, SIGKILL, a batch timeout) leaves no worker waiting for
    batches forever (they hold its pipes open, so they would never see it go). That thread is
    in the map for the workers' whole life."""
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(1, signal.SIGKILL, 0, 0, 0)             # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        return
    if os.getppid() != _PARENT_PID:                        # the parent died before the call
        os._exit(1)


def _noop():
    return None


def shared_array(shape, dtype) -> np.ndarray:
    """A zero-filled array in memory shared with the processes forked after this call
    (anonymous ``MAP_SHARED``, no swap reserved: only the pages written take memory): a
    forked map's workers write their results into it, in place, and send back only where,
    instead of pickling the arrays through the pool's pipe. Freed when the last array that
    views it is. Linux (where maps fork) and other POSIX systems.

    Why: a large bake's final gather sends a hundred MB of rows and hits back from its workers;
    pickled through the pipe, each is copied four times (pickled, written, read, unpickled),
    which cost many times the CPU of the same map returning nothing."""
    shape = tuple(int(x) for x in np.atleast_1d(shape))
    dtype = np.dtype(dtype)
    size = max(1, int(np.prod(shape, dtype=np.int64)) * dtype.itemsize)
    flags = getattr(mmap, "MAP_SHARED", 1) | getattr(mmap, "MAP_ANONYMOUS", 0x20)
    if sys.platform.startswith("linux"):
        flags |= 0x4000                                    # MAP_NORESERVE
    mm = mmap.mmap(-1, size, flags=flags)
    return np.frombuffer(mm, dtype=dtype, count=int(np.prod(shape, dtype=np.int64))).reshape(shape)


def release_tail(a: np.ndarray, n: int) -> None:
    """Hand back to the system the pages of a 1-D :func:`shared_array` ``a`` past its first ``n``
    items (best effort: where ``madvise(MADV_REMOVE)`` is there; the pages read as zeros after).
    The array keeps its size: what is past ``n`` must not be read."""
    mm = a
    while mm is not None and not isinstance(mm, mmap.mmap):
        mm = getattr(mm, "base", None) if not isinstance(mm, memoryview) else mm.obj
    remove = getattr(mmap, "MADV_REMOVE", None)
    if mm is None or remove is None:
        return
    first = -(-int(n) * a.itemsize // mmap.PAGESIZE) * mmap.PAGESIZE
    if first < len(mm):
        try:
            mm.madvise(remove, first, len(mm) - first)
        except OSError:
            pass
