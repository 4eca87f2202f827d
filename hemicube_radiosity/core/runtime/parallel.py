"""Batches of independent work on several cores, results in the order they were asked for.

:func:`ordered_map` is the one driver every stage uses: the caller keeps its loop over batches
and its :class:`.progress.Ticker` (progress and cancellation stay on the calling thread, polled
between batches), results arrive in batch order, so any result assembled from them is
bit-identical whatever the worker count, and at most ``2 * workers`` batches are in flight
(memory stays that of a few batches). With one worker nothing runs elsewhere: the batches run in
the caller's thread, one by one, as before.

Two ways to run the batches (issue 9, measured by ``bench/bench_parallel.py``):

* **Threads** (the default). Enough where the heavy calls release the GIL: Embree's form-factor
  rays run ~1.8-2x as fast on two threads, and processes measured no faster there.
* **Forked processes** (``processes=True``: the hemi-cube rasteriser, :mod:`.hemicube`). Its
  many small NumPy operations hold the GIL much of the time, so two threads drew only 1.1-1.3x
  as fast as one. On Linux the workers are ``fork()``-ed from the caller when the map starts, so
  they inherit ``fn`` and everything it holds (the patch geometry, the frames) without a copy or
  a pickle: only the items (receiver ids) go to them and only the results (sparse rows) come
  back. Nothing is imported or started anew: no Blender, no ``bpy`` (inside Blender
  ``sys.executable`` is the Blender binary, which the 'spawn' and 'forkserver' methods would
  run), no resource tracker; a worker runs only ``fn``, with one BLAS thread. Where 'fork' is
  not available or not safe (Windows, macOS), in a daemonic process, inside a worker, when the
  fork itself fails (no memory) or when :data:`PROCESSES` is False, the same call runs on
  threads.

When the consumer stops early (:class:`.progress.Cancelled` raised in its loop, or ``close()``)
the batches not yet started are dropped; threads finish the batch they are in, worker
processes are terminated at once. Either way nothing outlives the call.
"""
from __future__ import annotations

import ctypes
import itertools
import mmap
import multiprocessing
import os
import signal
import sys
import threading
import warnings
from collections import deque
from contextlib import contextmanager
from concurrent.futures import ProcessPoolExecutor, ThreadPoolExecutor
from concurrent.futures.process import BrokenProcessPool

import numpy as np

from .errors import RadiosityError

__all__ = ["resolve_workers", "ordered_map", "started_map", "shares", "one_blas_thread", "cpu_count",
           "processes_available", "Background", "Ahead", "PROCESSES", "shared_array"]

#: False: ``ordered_map(..., processes=True)`` runs on threads too (a switch for benchmarks and
#: for a host where forking misbehaves).
PROCESSES = True

_TASKS: dict = {}              # token -> fn of the process maps running now (inherited by fork)
_TOKENS = itertools.count()
_IN_WORKER = False             # True inside a forked worker: its own maps run serially
_PARENT_PID = None             # the process that forks the workers (set before every fork)


def cpu_count() -> int:
    """CPUs this process may run on (its affinity mask where the OS has one)."""
    if hasattr(os, "sched_getaffinity"):
        try:
            return max(1, len(os.sched_getaffinity(0)))
        except OSError:
            pass
    return max(1, os.cpu_count() or 1)


def resolve_workers(workers) -> int:
    """Workers for a ``workers`` setting: 0 or None = every CPU (:func:`cpu_count`),
    1 = serial, n = n. Negative values are an error."""
    if workers is None:
        return 1
    w = int(workers)
    if w < 0:
        raise ValueError(f"workers must be >= 0 (0: all cores), got {workers}")
    return cpu_count() if w == 0 else w


def processes_available() -> bool:
    """True where ``ordered_map(..., processes=True)`` forks worker processes: Linux with the
    'fork' start method, :data:`PROCESSES` on, not inside a daemonic process or a worker."""
    if not PROCESSES or _IN_WORKER or not sys.platform.startswith("linux"):
        return False
    if "fork" not in multiprocessing.get_all_start_methods():
        return False
    return not multiprocessing.current_process().daemon


def ordered_map(fn, items, workers=1, *, in_flight=None, processes=False):
    """Yield ``fn(item)`` for every item, in the order of ``items``.

    ``workers`` <= 1 (or inside a worker process): in the calling thread, lazily (exactly the
    serial loop). Otherwise on ``workers`` threads, or with ``processes=True`` on ``workers``
    forked processes where :func:`processes_available` (threads elsewhere), with at most
    ``in_flight`` (default ``2 * workers``) items submitted ahead of the one being yielded.
    Processes: ``fn`` is inherited, never pickled (a closure or bound method is fine); the items
    and results are pickled, so keep them small (ids in, rows out); ``fn`` must not touch
    ``bpy`` or anything that holds a lock of the parent's other threads. When the consumer stops
    early (an exception such as :class:`.progress.Cancelled` raised in its loop, or
    ``close()``), batches not yet started are dropped, running threads are waited for and
    worker processes terminated before the exception goes on. An exception in ``fn`` is raised
    at that item's turn.
    """
    workers = int(workers or 1)
    if workers <= 1 or _IN_WORKER:
        for item in items:
            yield fn(item)
        return
    if processes and processes_available():
        yield from _process_map(fn, items, workers, in_flight)
        return
    pool = ThreadPoolExecutor(max_workers=workers, thread_name_prefix="radiosity")
    try:
        yield from _ordered(pool, fn, items, workers, in_flight)
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


def shared_array(shape, dtype) -> np.ndarray:
    """A zero-filled array in memory shared with the processes forked after this call
    (anonymous ``MAP_SHARED``, no swap reserved: only the pages written take memory): a
    forked map's workers write their results into it, in place, and send back only where,
    instead of pickling the arrays through the pool's pipe. Freed when the last array that
    views it is. Linux (where maps fork) and other POSIX systems.

    Why: the final gather of the 54k-triangle box sends 117 MB of rows and hits back from its
    workers. Sent as pickles through the pipe, 118 MB in 14 chunks took 0.37-0.42 s of CPU
    (pickled, written, read and unpickled: four copies) against 0.03-0.05 s for the same map
    returning nothing."""
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
    start = -(-int(n) * a.itemsize // mmap.PAGESIZE) * mmap.PAGESIZE
    if start < len(mm):
        try:
            mm.madvise(remove, start, len(mm) - start)
        except OSError:
            pass


def shares(fn, n) -> list:
    """``[fn(0), ..., fn(n - 1)]`` for work cut into ``n`` shares that take about as long (a
    sparse product's rows): the calling thread runs ``fn(0)`` itself while ``n - 1`` threads
    run the others, and it returns when every share is done. Threads only; serial (in order)
    for ``n`` <= 1 or inside a worker process. An exception in a share is raised once the
    shares that had started have stopped (those not started are dropped).

    Why not :func:`ordered_map` with ``n`` threads: the caller would only wait, and each share
    would start on a thread started for it while the first share already runs and takes the
    GIL between its NumPy calls. The relight's two 3.7M-entry products (the dense Cornell room,
    bench_relight_dense.py) started their second share 0.3-4.5 ms late, and the same relights
    took a median 47.2 and 59.1 ms with the caller taking a share against 66.3 and 76.7 ms
    without (two paired runs of 80 relights, alternating in one process on this shared 2-core
    machine; the paired ratio 0.75-0.93 in six runs, 1.07 in one), with less spread."""
    n = int(n)
    if n <= 1 or _IN_WORKER:
        return [fn(i) for i in range(n)]
    pool = ThreadPoolExecutor(max_workers=n - 1, thread_name_prefix="radiosity")
    rest = []
    try:
        rest = [pool.submit(fn, i) for i in range(1, n)]
        first = fn(0)
        return [first] + [f.result() for f in rest]
    finally:
        for f in rest:
            f.cancel()
        pool.shutdown(wait=True)


def _ordered(pool, fn, items, workers, in_flight, *args, cancel=True):
    """Submit ``fn(*args, item)`` ahead on ``pool`` and yield the results in order; on an early
    stop, cancel what has not started (the caller shuts the pool down), unless ``cancel`` is
    False: a process pool about to be terminated marks its pending futures broken itself, and
    CPython 3.11's pool raised ``InvalidStateError`` on its manager thread when one of them had
    been cancelled meanwhile (a race: 3 of 25 runs of the cancel test on a loaded machine)."""
    ahead = max(workers, int(in_flight or 2 * workers))
    it = iter(items)
    pending = deque()
    try:
        for item in it:
            pending.append(pool.submit(fn, *args, item))
            if len(pending) >= ahead:
                break
        while pending:
            result = pending.popleft().result()
            for item in it:                  # keep the pool fed before handing the result over
                pending.append(pool.submit(fn, *args, item))
                break
            yield result
    finally:
        if cancel:
            for f in pending:
                f.cancel()


def started_map(fn, items, workers=1, *, in_flight=None, processes=False):
    """:func:`ordered_map`'s results, with its worker processes (if it forks) forked before this
    returns, on the calling thread: the results can then be collected on another thread
    (:class:`Background`) without waiting here for the first of them, and no fork happens
    beside the calling thread's own work."""
    workers = int(workers or 1)
    if processes and workers > 1 and not _IN_WORKER and processes_available():
        results = _process_map(fn, items, workers, in_flight, announce=True)
        next(results)                        # forks (or falls back to threads) and stops there
        return results
    return ordered_map(fn, items, workers, in_flight=in_flight, processes=processes)


def _process_map(fn, items, workers, in_flight, announce=False):
    """:func:`ordered_map` on ``workers`` forked processes (threads when the fork fails);
    ``announce``: first yield None once the workers are forked (:func:`started_map`)."""
    global _PARENT_PID
    token = next(_TOKENS)
    _TASKS[token] = fn                       # before the fork: the workers inherit it
    _PARENT_PID = os.getpid()
    pool = ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("fork"),
                               initializer=_worker_init)
    done = False
    try:
        try:
            with warnings.catch_warnings():  # Python >= 3.12 warns of fork() beside threads
                warnings.simplefilter("ignore", DeprecationWarning)
                pool.submit(_noop).result()  # the first submit forks every worker
        except OSError:                      # no memory or processes left to fork: threads
            if announce:
                yield None
            with ThreadPoolExecutor(max_workers=workers, thread_name_prefix="radiosity") as tp:
                yield from _ordered(tp, fn, items, workers, in_flight)
            done = True
            return
        if announce:
            yield None
        try:
            yield from _ordered(pool, _call, items, workers, in_flight, token, cancel=False)
        except BrokenProcessPool as exc:     # a worker was killed (out of memory, a signal)
            raise RadiosityError(f"a worker process stopped during the bake ({exc}); bake with "
                                 "fewer workers or less memory per worker (larger patches)") from exc
        done = True
    finally:
        _TASKS.pop(token, None)
        if not done:                         # stopped early: do not wait for running batches
            _terminate(pool)
        pool.shutdown(wait=True, cancel_futures=True)


def _terminate(pool) -> None:
    """Terminate ``pool``'s worker processes at once, so that its ``shutdown`` returns.

    A worker killed while it writes a result leaves half a message in the results pipe, and the
    pool's manager thread, reading it, would wait for the rest for ever: this process holds the
    pipe's writing end too (it made the pipe before forking), so the read never meets its end.
    Once the workers are gone, that end is closed here: the read ends, the pool counts itself
    broken, and its threads stop. (The test of a cancel during the background gather hung so,
    once.)"""
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
    _one_blas_thread()
    _keep_freed_memory()


#: glibc's ``mallopt`` parameters (malloc.h): M_TRIM_THRESHOLD, M_TOP_PAD.
_M_TRIM_THRESHOLD, _M_TOP_PAD = -1, -2


def _keep_freed_memory():
    """glibc, in a worker (best effort; the process that bakes is left as it is): keep freed
    memory in the worker's heap for its next batch instead of handing it back to the system
    and faulting fresh zeroed pages in again, and grow the heap 64 MB at a time. A worker's
    batches make and drop the same large temporaries (a gather chunk's quarter million rays)
    again and again: on the 54k-triangle box with two workers the workers took 405k page
    faults and 1.0 s of system time, 130k and 0.4 s with this (the whole bake's CPU time
    6.9-7.1 -> 5.9-6.0 s, alternating runs). A worker lives for one map: what it keeps is
    freed when it exits."""
    try:
        libc = ctypes.CDLL(None)
        libc.mallopt(_M_TRIM_THRESHOLD, (1 << 31) - 1)
        libc.mallopt(_M_TOP_PAD, 1 << 26)
    except (OSError, AttributeError):
        pass


def _die_with_parent():
    """Linux: the kernel kills this worker when the thread that forked it ends, so a baking
    process killed outright (a crash, SIGKILL, a batch timeout) leaves no worker waiting for
    batches forever (they hold its pipes open, so they would never see it go). That thread is
    in :func:`ordered_map` for the workers' whole life."""
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(1, signal.SIGKILL, 0, 0, 0)             # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        return
    if os.getppid() != _PARENT_PID:                        # the parent died before the call
        os._exit(1)


def _one_blas_thread():
    """Ask the OpenBLAS that NumPy loaded for one thread, if it is there and has more (best
    effort). Its threads only spin beside the rasteriser's small products (3 x V): in the serial
    bake they burn a second core for nothing, and two workers with two BLAS threads each would
    fight over two cores.

    A count of one already (a worker forked by a bake, which holds :func:`one_blas_thread`) is
    left alone: OpenBLAS stops its threads at a fork, and ``openblas_set_num_threads`` in the
    child starts them again whatever the count, and a new thread spins (sched_yield) for about
    0.1 s. The 54k-triangle box's two-worker bake forks 10 workers: perf counted 31,971
    sched_yield calls in OpenBLAS's ``blas_thread_server``, one such spin in every worker."""
    for set_threads, get_threads in _openblas():
        if get_threads() != 1:
            set_threads(1)


def _openblas() -> list:
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


_BLAS = None                   # :func:`_openblas`, once looked up
_BLAS_LOCK = threading.Lock()
_BLAS_HELD = []                # one entry per bake inside one_blas_thread() now
_BLAS_BEFORE = []              # (set, thread count) to put back when the last of them ends


@contextmanager
def one_blas_thread():
    """NumPy's OpenBLAS on one thread while the block runs (a bake), as before afterwards.

    A bake's BLAS calls are tiny: the luminance of a (V, 3) field (``values @ LUMA``), a few per
    relight. Above 9,216 products OpenBLAS hands half of such a call to its second thread,
    which then spins (sched_yield) for about 0.1 s waiting for more: through a whole relight of
    the dense Cornell room (41 ms), beside the two threads of its sparse products on this
    2-core machine (gdb: OpenBLAS's ``blas_thread_server`` in ``sched_yield``, 67% of a core
    over 30 relights). The same relights in processes started with OPENBLAS_NUM_THREADS=1:
    median 38.4 / 40.0 / 46.7 / 42.7 ms against 44.0 / 46.2 / 49.5 / 45.0 ms (alternating
    processes, 30 relights each), the same arrays bit for bit (each output of those products is
    summed by one thread either way). Bakes that overlap (the CLI's jobs) share the setting:
    the first sets it, the last puts back what the first found."""
    with _BLAS_LOCK:
        if not _BLAS_HELD:
            _BLAS_BEFORE[:] = [(set_threads, get_threads()) for set_threads, get_threads in _openblas()]
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
    kernel). A bake makes and drops the same large temporaries thousands of times: on one
    worker Suzanne at level 3 took 1.67M page faults and 3.7 s of system time in a 23.8 s bake,
    0.41M and 0.8 s in 19.3 s so; the 54k-triangle box 0.36M and 0.7 s, 0.11M and 0.2 s. Peak
    memory did not change (1,197 / 1,198 MB; 482 / 489 MB). glibc moves to the same 32 MB on its
    own once a NumPy program frees an array that large; afterwards it keeps 64 MB of freed heap
    at its top (what it would keep then), and the next free hands the rest back to the system.
    Not trimmed at once (``malloc_trim``): a relight (40 ms) then faulted its pages in again
    every time, 8-15% slower. Bakes that overlap share the setting (the last one out puts it
    back). Workers forked meanwhile inherit it (:func:`_keep_freed_memory` adds their own)."""
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


def _noop():
    return None


def _call(token, item):
    return _TASKS[token](item)


class Background:
    """A result made on a thread while the caller goes on: ``collect(stop)`` runs on its own
    thread and returns the value; it should look at ``stop`` (a :class:`threading.Event`)
    between its steps and return early when it is set. Made for a forked map whose results
    are collected while the caller does other work: start it with :func:`started_map` on the
    caller's thread (the workers are forked there, not beside the caller's running code), then
    hand the loop over its results to ``collect``.

    :meth:`result` waits for the value (or raises what ``collect`` raised) and polls
    ``cancelled()`` on the caller's thread while it waits (progress and cancellation stay on the
    calling thread, as everywhere else): on cancellation, or whenever the caller stops early,
    :meth:`close` sets ``stop`` and waits for the thread, whose map then terminates its workers.
    :meth:`ready` wraps a value made already (nothing runs)."""

    def __init__(self, collect=None):
        self._stop = threading.Event()
        self._done = threading.Event()
        self._value = self._error = None
        self._thread = None
        if collect is None:
            self._done.set()
            return
        self._thread = threading.Thread(target=self._run, args=(collect,), daemon=True,
                                        name="radiosity-background")
        self._thread.start()

    @classmethod
    def ready(cls, value) -> "Background":
        out = cls()
        out._value = value
        return out

    def _run(self, collect):
        try:
            self._value = collect(self._stop)
        except BaseException as exc:       # raised again on the caller's thread by result()
            self._error = exc
        finally:
            self._done.set()

    def result(self, cancelled=None, poll=0.05):
        """The value (once; the handle lets go of it), after waiting for the thread; raises
        :class:`.progress.Cancelled` (after :meth:`close`) when ``cancelled()`` turns true."""
        from .progress import Cancelled
        while not self._done.wait(poll):
            if cancelled is not None and cancelled():
                self.close()
                raise Cancelled("cancelled")
        self.close()
        if self._error is not None:
            error, self._error = self._error, None
            raise error
        value, self._value = self._value, None
        return value

    def close(self) -> None:
        """Ask the thread to stop and wait for it (nothing when it is done)."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join()


class Ahead:
    """``fn()`` made on one forked process while the caller goes on with other work: a bake's
    geometry-only work that a later stage reads (the output elements' cut along contacts,
    :func:`.output.start_elements`) runs beside the stages before it, which leave a core idle
    (the patches, the refinement, the direct light: one core each). The process is forked on
    the calling thread when this is made and inherits ``fn`` and what it holds; only the value
    comes back (pickled). Use :meth:`start`, which returns None where no process can be forked
    (then the caller makes the value itself, where it reads it, as before).

    :meth:`result` waits for the value (raising what ``fn`` raised), polling ``cancelled()``
    on the caller's thread; :meth:`close` terminates the process at once if it still runs (a
    cancelled or failed bake leaves nothing behind). Both can be called more than once."""

    def __init__(self, fn):
        global _PARENT_PID
        token = next(_TOKENS)
        _TASKS[token] = lambda _: fn()       # before the fork: the process inherits it
        _PARENT_PID = os.getpid()
        self._pool = ProcessPoolExecutor(max_workers=1, mp_context=multiprocessing.get_context("fork"),
                                         initializer=_worker_init)
        try:
            with warnings.catch_warnings():  # Python >= 3.12 warns of fork() beside threads
                warnings.simplefilter("ignore", DeprecationWarning)
                self._future = self._pool.submit(_call, token, None)    # forks, on this thread
        except BaseException:
            self._pool.shutdown(wait=True, cancel_futures=True)
            raise
        finally:
            _TASKS.pop(token, None)

    @classmethod
    def start(cls, fn) -> "Ahead | None":
        """An :class:`Ahead` of ``fn``, or None where processes are not forked (not Linux,
        :data:`PROCESSES` off, inside a worker) or the fork fails (no memory or processes)."""
        if not processes_available():
            return None
        try:
            return cls(fn)
        except OSError:
            return None

    def result(self, cancelled=None, poll=0.05):
        """``fn()``'s value, once it is made; raises :class:`.progress.Cancelled` (after
        :meth:`close`) when ``cancelled()`` turns true while it waits."""
        from concurrent.futures import wait
        from .progress import Cancelled
        while not wait([self._future], timeout=poll).done:
            if cancelled is not None and cancelled():
                self.close()
                raise Cancelled("cancelled")
        try:
            return self._future.result()
        except BrokenProcessPool as exc:     # the process was killed (out of memory, a signal)
            raise RadiosityError(f"a worker process stopped during the bake ({exc}); bake with "
                                 "fewer workers") from exc
        finally:
            self.close()

    def close(self) -> None:
        """Terminate the process if it still runs, and let go of it."""
        if self._pool is None:
            return
        if not self._future.done():
            _terminate(self._pool)
        self._pool.shutdown(wait=True, cancel_futures=True)
        self._pool = None
