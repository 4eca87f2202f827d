"""A value made elsewhere while the caller goes on with other work.

:class:`Background` makes it on a thread (collecting the results of a forked map that
:func:`.parallel.started_map` started); :class:`Ahead` makes it on one forked process (geometry-only
work that a later stage reads, run beside the stages before it). Either way the caller keeps
progress and cancellation on its own thread: ``result(cancelled)`` polls ``cancelled()`` while it
waits, and a cancelled or failed bake leaves no thread or process behind.
"""
from __future__ import annotations

import threading
from concurrent.futures import wait
from concurrent.futures.process import BrokenProcessPool

from .errors import RadiosityError
from .forked import (
    fork_pool, forget, processes_available, run_task, submit_forking, terminate
)
from .progress import Cancelled

__all__ = ["Background", "Ahead"]


class Background:
    """A result made on a thread while the caller goes on: ``collect(stop)`` runs on its own
    thread and returns the value; it should look at ``stop`` (a :class:`threading.Event`)
    between its steps and return early when it is set. Made for a forked map whose results
    are collected while the caller does other work: start it with
    :func:`.parallel.started_map` on the caller's thread (the workers are forked there, not
    beside the caller's running code), then hand the loop over its results to ``collect``.

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
    :func:`.elements.start_elements`) runs beside the stages before it, which leave a core idle
    (the patches, the refinement, the direct light: one core each). The process is forked on
    the calling thread when this is made and inherits ``fn`` and what it holds; only the value
    comes back (pickled). Use :meth:`start`, which returns None where no process can be forked
    (then the caller makes the value itself, where it reads it).

    :meth:`result` waits for the value (raising what ``fn`` raised), polling ``cancelled()``
    on the caller's thread; :meth:`close` terminates the process at once if it still runs (a
    cancelled or failed bake leaves nothing behind). Both can be called more than once."""

    def __init__(self, fn):
        self._pool, token = fork_pool(lambda _: fn(), 1)   # the process inherits fn
        try:
            self._future = submit_forking(self._pool, run_task, token, None)   # forks here
        except BaseException:
            self._pool.shutdown(wait=True, cancel_futures=True)
            raise
        finally:
            forget(token)

    @classmethod
    def start(cls, fn) -> "Ahead | None":
        """An :class:`Ahead` of ``fn``, or None where processes are not forked (not Linux,
        :data:`.forked.PROCESSES` off, inside a worker) or the fork fails (no memory or
        processes)."""
        if not processes_available():
            return None
        try:
            return cls(fn)
        except OSError:
            return None

    def result(self, cancelled=None, poll=0.05):
        """``fn()``'s value, once it is made; raises :class:`.progress.Cancelled` (after
        :meth:`close`) when ``cancelled()`` turns true while it waits."""
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
            terminate(self._pool)
        self._pool.shutdown(wait=True, cancel_futures=True)
        self._pool = None
