"""Batches of independent work on several cores, results in the order they were asked for.

Threads, not processes (measured by ``bench/bench_parallel.py``, issue 9):
NumPy releases the GIL inside its array loops, so the rasteriser's batches of receivers
(:mod:`.hemicube`) and the closed-form parts of the direct light run on both cores from one
``ThreadPoolExecutor``. A thread needs nothing Blender does not already allow (the modal operator
runs the bake in a worker thread), whereas a process inside Blender would be a fork of Blender
or a spawn of its bundled Python (``sys.executable`` there), which has no ``embreex`` unless
installed into it and must rebuild the scene and the Embree BVH.

:func:`ordered_map` is the one driver every stage uses: the caller keeps its loop over batches
and its :class:`.progress.Ticker` (progress and cancellation stay on the calling thread, polled
between batches), results arrive in batch order, so any result assembled from them is
bit-identical whatever the worker count, and at most ``2 * workers`` batches are in flight
(memory stays that of a few batches). With one worker nothing is threaded: the batches run in the
caller's thread, one by one, as before.
"""
from __future__ import annotations

import os
from collections import deque
from concurrent.futures import ThreadPoolExecutor

__all__ = ["resolve_workers", "ordered_map", "cpu_count"]


def cpu_count() -> int:
    """CPUs this process may run on (its affinity mask where the OS has one)."""
    if hasattr(os, "sched_getaffinity"):
        try:
            return max(1, len(os.sched_getaffinity(0)))
        except OSError:
            pass
    return max(1, os.cpu_count() or 1)


def resolve_workers(workers) -> int:
    """Worker threads for a ``workers`` setting: 0 or None = every CPU (:func:`cpu_count`),
    1 = serial, n = n. Negative values are an error."""
    if workers is None:
        return 1
    w = int(workers)
    if w < 0:
        raise ValueError(f"workers must be >= 0 (0: all cores), got {workers}")
    return cpu_count() if w == 0 else w


def ordered_map(fn, items, workers=1, *, in_flight=None):
    """Yield ``fn(item)`` for every item, in the order of ``items``.

    ``workers`` <= 1: in the calling thread, lazily (exactly the serial loop). Otherwise on a
    pool of ``workers`` threads with at most ``in_flight`` (default ``2 * workers``) items
    submitted ahead of the one being yielded. When the consumer stops early (an exception such
    as :class:`.progress.Cancelled` raised in its loop, or ``close()``), batches not yet started
    are dropped and the running ones are waited for before the exception goes on, so no thread
    outlives the call. An exception in ``fn`` is raised at that item's turn.
    """
    workers = int(workers or 1)
    if workers <= 1:
        for item in items:
            yield fn(item)
        return
    ahead = max(workers, int(in_flight or 2 * workers))
    it = iter(items)
    pool = ThreadPoolExecutor(max_workers=workers, thread_name_prefix="radiosity")
    pending = deque()
    try:
        for item in it:
            pending.append(pool.submit(fn, item))
            if len(pending) >= ahead:
                break
        while pending:
            result = pending.popleft().result()
            for item in it:                  # keep the pool fed before handing the result over
                pending.append(pool.submit(fn, item))
                break
            yield result
    finally:
        for f in pending:
            f.cancel()
        pool.shutdown(wait=True, cancel_futures=True)
