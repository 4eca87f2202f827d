"""How long a bake will take, said before its long work starts (the memory is
:func:`..mesh.stage.form_factor_gb`'s, said by the patch stage).

A bake's time goes to two kinds of work (``docs/performance.md``): the form factors, per
receiver (one hemi-cube each) and per piece drawn one by one in it (a curved cluster's faces;
a flat cluster is drawn as its outline, whatever it is cut into), and the output, per output
vertex (the final gather's rays, the exact direct light and what shines). The rates below were
measured on one worker (``bench/bench_dense.py`` prints the forecast beside the time it took;
``docs/performance.md``), from the Cornell box, the box tessellated ever finer and Suzanne
subdivided: the time taken came out between about 0.6 and 1.8 times the forecast, hence the
range :data:`SPREAD` (the Cornell box's lamp makes more of its output shine than the rate
assumes; a dense mesh's output is cheaper per vertex). A faster or slower machine scales all
of it. It is said once the patches are known and before the form factors, with the
output elements cut already (cached: the vertex stage finds them), and kept on the result
(``BakeResult.forecast``, the report's 'forecast'); a bake whose form factors come from the
cache (a relight) has nothing long to forecast.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .parallel import resolve_workers

__all__ = ["Forecast", "forecast", "SAID"]

#: How :meth:`Forecast.describe` begins (a headless run prints such a message at once).
SAID = "expected about"

#: Seconds per receiver's hemi-cube, and per curved piece drawn in it (one worker).
PER_RECEIVER = 6e-4
PER_CURVED_PIECE = 5e-8
#: Seconds per output vertex at 128 gather rays, the default (the exact direct light, the gather,
#: what shines).
PER_VERTEX = 2.2e-4
#: The other stages (patches, refinement, direct light at the patches, solve) as a share of these.
OTHER = 0.15
#: The time taken over the forecast, as measured (module docstring), the most for ``make demo``'s
#: bake of the Cornell box in a new process (its start-up counts too). Said as a range
#: beside the figure, with a margin above, so that a bake in the Cornell box's case (the most
#: over its forecast) is not a surprise.
SPREAD = (0.6, 2.0)
#: Speed-up of each worker after the first (``docs/performance.md``, 'Both cores').
PER_EXTRA_WORKER = 0.4


@dataclass
class Forecast:
    """Seconds expected for a bake: ``form_factors`` and ``output`` (the vertex stage) on
    ``workers`` workers, ``seconds`` in all; for ``receivers`` hemi-cubes with ``curved``
    pieces drawn one by one, and ``vertices`` output vertices."""

    seconds: float
    form_factors: float
    output: float
    receivers: int
    curved: int
    vertices: int
    workers: int

    def describe(self) -> str:
        lo, hi = (_seconds(self.seconds * k) for k in SPREAD)
        return (f"{SAID} {_seconds(self.seconds)} s ({lo}-{hi} s) on {self.workers} worker"
                f"{'s' if self.workers > 1 else ''} (form factors {self.form_factors:.1f} s for "
                f"{self.receivers} hemi-cubes, output {self.output:.1f} s for {self.vertices} vertices)")

    def as_dict(self) -> dict:
        return dict(self.__dict__)


def curved_pieces(patches, clusters) -> int:
    """Pieces in clusters whose pieces do not all share one normal: a hemi-cube draws them face
    by face (a flat cluster is drawn as its outline). None without clusters: each piece is a
    patch then, counted as a receiver."""
    if clusters is None:
        return 0
    of = np.asarray(clusters.of, dtype=np.int64)
    first = np.full(int(of.max(initial=-1)) + 1, -1, np.int64)
    first[of[::-1]] = np.arange(len(of))[::-1]
    bent = np.abs(patches.normals - patches.normals[first[of]]).max(axis=1) > 1e-6
    curved = np.zeros(len(first), bool)
    curved[of[bent]] = True
    return int(curved[of].sum())


def forecast(ctx, receivers: int, output_vertices: int) -> Forecast:
    """The :class:`Forecast` of the bake of ``ctx`` (after its patch stage) with ``receivers``
    hemi-cubes to draw and ``output_vertices`` to evaluate."""
    s = ctx.settings
    workers = resolve_workers(s.workers)
    speed = 1.0 + PER_EXTRA_WORKER * (workers - 1)
    curved = curved_pieces(ctx.patches, ctx.clusters)
    ff = receivers * (PER_RECEIVER + PER_CURVED_PIECE * curved) / speed
    rays = max(int(getattr(s, "gather_rays", 0) or 0), 32)
    out = output_vertices * PER_VERTEX * rays / 128 / speed
    return Forecast((1 + OTHER) * (ff + out), ff, out, int(receivers), curved, int(output_vertices), workers)


def _seconds(x: float) -> str:
    return f"{x:.1f}" if x < 10 else f"{x:.0f}"
