"""Progress and cancellation hooks the caller passes into long core stages."""
from __future__ import annotations

import time

__all__ = ["Cancelled", "Ticker"]


class Cancelled(RuntimeError):
    """The caller's ``cancelled()`` returned True; the stage stopped and returned nothing."""


class Ticker:
    """Calls ``progress(fraction)`` at most every ``interval`` seconds and polls ``cancelled()``.

    ``tick(done, total)`` reports and raises :class:`Cancelled` when asked to stop.
    """

    def __init__(self, progress=None, cancelled=None, interval=0.2):
        self.progress = progress
        self.cancelled = cancelled
        self.interval = interval
        self._last = -1e30

    def tick(self, done, total, force=False):
        if self.cancelled is not None and self.cancelled():
            raise Cancelled("cancelled")
        if self.progress is None:
            return
        now = time.perf_counter()
        if force or now - self._last >= self.interval or done >= total:
            self._last = now
            self.progress(min(1.0, done / total) if total else 1.0)
