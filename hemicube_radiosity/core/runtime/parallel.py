"""Batches of independent work on several cores, results in the order they were asked for.

:func:`ordered_map` is the one driver every stage uses: the caller keeps its loop over batches
and its :class:`.progress.Ticker` (progress and cancellation stay on the calling thread, polled
between batches), results arrive in batch order, so any result assembled from them is
bit-identical whatever the worker count, and at most ``2 * workers`` batches are in flight
(memory stays that of a few batches). With one worker nothing runs elsewhere: the batches run in
the caller's thread, one by one.

Two ways to run the batches (measured by ``bench/bench_parallel.py``):

* **Threads** (the default). Enough where the heavy calls release the GIL: Embree's form-factor
  rays scale on threads, and processes gain nothing there.
* **Forked processes** (``processes=True``: the hemi-cube rasteriser, :mod:`.hemicube`), whose
  many small NumPy operations hold the GIL much of the time. The workers are forked from the
  caller when the map starts and inherit ``fn`` (:mod:`.forked`). Where 'fork' is not available
  or not safe (Windows, macOS), in a daemonic process, inside a worker, when the fork itself
  fails (no memory) or when :data:`.forked.PROCESSES` is False, the same call runs on threads.

When the consumer stops early (:class:`.progress.Cancelled` raised in its loop, or ``close()``)
the batches not yet started are dropped; threads finish the batch they are in, worker
processes are terminated at once. Either way nothing outlives the call. :func:`started_map`
forks before it returns, so that another thread (:class:`.background.Background`) can collect
the results; :func:`shares` splits one piece of work over threads, the caller taking a share.
"""
from __future__ import annotations

import os
from collections import deque
from concurrent.futures import ThreadPoolExecutor
from concurrent.futures.process import BrokenProcessPool

from .errors import RadiosityError
from .forked import (
    fork_pool, forget, in_worker, processes_available, run_task, submit_forking, terminate
)

__all__ = ["resolve_workers", "ordered_map", "started_map", "shares", "cpu_count"]


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


def ordered_map(fn, items, workers=1, *, in_flight=None, processes=False):
    """Yield ``fn(item)`` for every item, in the order of ``items``.

    ``workers`` <= 1 (or inside a worker process): in the calling thread, lazily (exactly the
    serial loop). Otherwise on ``workers`` threads, or with ``processes=True`` on ``workers``
    forked processes where :func:`.forked.processes_available` (threads elsewhere), with at most
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
    if workers <= 1 or in_worker():
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


def shares(fn, n) -> list:
    """``[fn(0), ..., fn(n - 1)]`` for work cut into ``n`` shares that take about as long (a
    sparse product's rows): the calling thread runs ``fn(0)`` itself while ``n - 1`` threads
    run the others, and it returns when every share is done. Threads only; serial (in order)
    for ``n`` <= 1 or inside a worker process. An exception in a share is raised once the
    shares that had started have stopped (those not started are dropped).

    Why not :func:`ordered_map` with ``n`` threads: the caller would only wait, and each share
    would start on a thread started for it while the first share already runs and takes the
    GIL between its NumPy calls: the second share started late, and relights ran slower and
    with more spread (``bench/bench_relight_dense.py``, ``docs/performance.md``)."""
    n = int(n)
    if n <= 1 or in_worker():
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
    been cancelled meanwhile (a race)."""
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
    (:class:`.background.Background`) without waiting here for the first of them, and no fork happens
    beside the calling thread's own work."""
    workers = int(workers or 1)
    if processes and workers > 1 and not in_worker() and processes_available():
        results = _process_map(fn, items, workers, in_flight, announce=True)
        next(results)                        # forks (or falls back to threads) and stops there
        return results
    return ordered_map(fn, items, workers, in_flight=in_flight, processes=processes)


def _process_map(fn, items, workers, in_flight, announce=False):
    """:func:`ordered_map` on ``workers`` forked processes (threads when the fork fails);
    ``announce``: first yield None once the workers are forked (:func:`started_map`)."""
    pool, token = fork_pool(fn, workers)     # the workers inherit fn
    done = False
    try:
        try:
            submit_forking(pool).result()    # the first submit forks every worker
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
            yield from _ordered(pool, run_task, items, workers, in_flight, token, cancel=False)
        except BrokenProcessPool as exc:     # a worker was killed (out of memory, a signal)
            raise RadiosityError(f"a worker process stopped during the bake ({exc}); bake with "
                                 "fewer workers or less memory per worker (larger patches)") from exc
        done = True
    finally:
        forget(token)
        if not done:                         # stopped early: do not wait for running batches
            terminate(pool)
        pool.shutdown(wait=True, cancel_futures=True)
