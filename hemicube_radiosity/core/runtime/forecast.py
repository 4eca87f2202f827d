"""How long a bake will take, said before its long work starts (the memory is
:func:`..mesh.stage.form_factor_gb`'s, said by the patch stage).

A bake's time goes to two kinds of work (``docs/performance.md``): the form factors, per
receiver (one hemi-cube each), and the output, per output vertex (the final gather's rays, the
exact direct light and what shines; less where no emitting face lights the scene,
:data:`PER_VERTEX_LAMPS`, more for every lamp past the first, :data:`PER_EXTRA_LAMP`, and for
what shines where lamps other than suns light it, :data:`PER_VERTEX_SHINE`). The form factors' are measured: the hemi-cube draws a sample of its
receivers first, spread through the scene, and times them (up to 0.3 s or 2% of them:
:func:`..form_factors.hemicube._probe`); where there are too few to sample (or another method
makes them) they are counted, per receiver and per polygon drawn in its hemi-cube
(:func:`polygons_seen`). A hemi-cube's cost varies fourfold with the scene at the same count
of polygons seen (1.6 ms in the living room, 1.9 ms on the terrain, 3.3 ms in the truck town
and the bunny, 6.7 ms in zdm2), which the count alone put 0.6-2x off. The output's rates were
measured on one worker (``bench/bench_dense.py`` prints the forecast beside the time it took;
``docs/performance.md``), from the Cornell box, the box tessellated ever finer and Suzanne
subdivided, and fitted to the real scenes' sun and sky, per output vertex and per element the
detail size cuts beyond the pieces (:data:`PER_ELEMENT_CUT`): the output is the stage least
sure, from 0.7x (the living room) to 1.75x (zdm2, a shadow's edge across most of its rooms) of
its forecast, and :meth:`Forecast.describe` says so. Where Embree's rays make the form factors
(:func:`ray_seconds`) they are counted, not timed: within 0.6-1.1x on the real scenes. The
whole bake came out between about 0.6 and 1.8 times the forecast, hence the range :data:`SPREAD`. It is said once the patches are known and before the form factors, with the
output elements cut already (cached: the vertex stage finds them), and kept on the result
(``BakeResult.forecast``, the report's 'forecast'); a bake whose form factors come from the
cache (a relight) has nothing long to forecast.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..light.lamps import SunLight
from ..output.shine import BUDGET
from .parallel import resolve_workers

__all__ = ["Forecast", "forecast", "SAID"]

#: How :meth:`Forecast.describe` begins (a headless run prints such a message at once).
SAID = "expected about"

#: Seconds per receiver's hemi-cube, and per polygon it draws (one worker): in front of the
#: receiver and facing it (:func:`polygons_seen`). The per-polygon rate fitted to the real
#: scenes' idle times (``docs/performance.md``, 2 workers): a hemi-cube took 1.1 ms for the
#: living room's 1,460 polygons seen, 2.4 ms for the truck town's 7,500, 6.5 ms for zdm2's
#: 10,600 (an indoor level: every wall faces the receivers), 2.5 ms for the bunny's 4,100 (a
#: convex body turns most of itself away). This says 1.3, 2.0, 1.0 and 1.15 times those; one
#: rate per curved piece (every piece of a curved cluster, seen or not) said 0.7, 0.8, 0.4
#: (zdm2's form factors 2.4 times their forecast) and 1.6.
PER_RECEIVER = 6e-4
PER_SEEN = 5.5e-7
#: Seconds per receiver and per hemi-cube pixel of Embree's rays through them (method 'embree',
#: one worker), fitted to the Cornell box cut into 2,529 and 12,672 patches at resolutions 8, 32
#: and 64: 0.08-0.12, 1.2-1.4 and 4.7-5.0 ms a receiver, where the rasteriser took 0.6-1.1,
#: 1.4-4.3 and 2.3-6.3 ms (about 1,600 and 8,400 polygons seen; one process, the machine busy).
PER_RAY_RECEIVER = 5e-5
PER_PIXEL_RAY = 3.8e-7
#: Receivers :func:`polygons_seen` looks from (a fixed, even sample: the same forecast each time).
SEEN_SAMPLE = 64
#: Seconds per output vertex at 128 gather rays, the default (the exact direct light, the gather,
#: what shines), where emitting faces light the scene (their transport and what shines are
#: most of it: the Cornell box, ``bench_dense.py``) ...
PER_VERTEX = 2.2e-4
#: ... and where only lamps, suns and the world do (their rays on every core), plus
#: :data:`PER_ELEMENT_CUT`: fitted to the real scenes' sun and sky (``bench/real_scenes.py``, an
#: idle machine, 2 workers): the bunny and the terrain, whose output elements are their own faces
#: (0.063 and 0.078 ms a vertex), and the grey-white room, whose output is its patches (0.070).
PER_VERTEX_LAMPS = 9.5e-5
#: Seconds per output element the detail size cuts beyond the pieces (one worker, lamps only):
#: the elements' own work (what shines, abrupt grids, covered corners, the contact cut), which
#: a scanned bunny (its faces are its elements) does not have and indoor scenes of large
#: walls do: the living room, truck town and zdm2 (12,000, 13,000 and 68,000 such elements)
#: took 0.7, 1.2 and 1.75 times what this and :data:`PER_VERTEX_LAMPS` say (the vertex rate
#: alone said a fifth of zdm2's output stage).
PER_ELEMENT_CUT = 4.9e-4
#: What an output vertex that casts no gather rays of its own costs, as a share of
#: :data:`PER_VERTEX` or :data:`PER_VERTEX_LAMPS`: a flat-shaded mesh's corners at one place
#: cast one set between them (:mod:`..output.shared`, counted ahead by
#: :func:`..output.shared.joined_ahead`). The bunny's 201,570 vertices cast from 35,887 places:
#: its vertex stage took 0.55 of the CPU time it took when each cast its own (11.4 s and 20.5 s,
#: bench/real_scenes.py, 2 workers, a busy machine), which this says.
PER_JOINED = 0.46
#: Seconds per output vertex for each lamp past the first (one worker): its shadow rays at the
#: vertices, the abrupt elements' grids and cells, the elements' insides. The rates above were
#: fitted to one sun; sauer_pandora's six soft point lamps cast 42.8 s of rays in its 68 s output
#: stage on 2 workers for 108,794 vertices (cProfile, an idle machine).
PER_EXTRA_LAMP = 9e-5
#: Seconds per output vertex and group that shines (:mod:`..output.shine`: a contour and
#: shadow rays each), one worker, where lamps other than suns light the scene: their pools of
#: light shine, as many groups as :data:`..output.shine.BUDGET` allows (sauer_pandora's six
#: point lamps lit 681; the 64 that shone took 10.0 s on 2 workers for 108,794 vertices), while
#: a sun and a sky light no area that brightly (the living room and truck town shine none).
#: Emitting faces' are in :data:`PER_VERTEX`.
PER_VERTEX_SHINE = 2e-6
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
    pieces drawn one by one and about ``seen`` polygons drawn in each (:func:`polygons_seen`),
    and ``vertices`` output vertices; ``per_receiver``: the seconds a hemi-cube took in the
    sample drawn first (None: none drawn, the form factors counted)."""

    seconds: float
    form_factors: float
    output: float
    receivers: int
    curved: int
    vertices: int
    workers: int
    seen: float = 0.0
    per_receiver: float | None = None

    def describe(self) -> str:
        lo, hi = (_seconds(self.seconds * k) for k in SPREAD)
        return (f"{SAID} {_seconds(self.seconds)} s ({lo}-{hi} s) on {self.workers} worker"
                f"{'s' if self.workers > 1 else ''} (form factors {self.form_factors:.1f} s for "
                f"{self.receivers} hemi-cubes{', timed on a sample' if self.per_receiver else ''}, output {self.output:.1f} s for {self.vertices} vertices, "
                f"the least sure)")

    def as_dict(self) -> dict:
        return dict(self.__dict__)


def hemicube_seconds(seen: float) -> float:
    """Seconds a hemi-cube takes on one worker drawing about ``seen`` polygons."""
    return PER_RECEIVER + PER_SEEN * float(seen)


def ray_seconds(resolution: int) -> float:
    """Seconds Embree's rays through a hemi-cube of ``resolution`` take on one worker."""
    return PER_RAY_RECEIVER + PER_PIXEL_RAY * 3 * int(resolution) ** 2


def polygons_seen(patches, clusters, centers, normals, sample=SEEN_SAMPLE) -> float:
    """About how many polygons a hemi-cube draws: the mean over ``sample`` receivers, evenly
    spread through ``centers`` (R, 3) with unit ``normals`` (R, 3), of the pieces in front of the
    receiver and facing it, a piece of a flat cluster counted as 2 / its cluster's pieces (a
    flat cluster is drawn as its outline, :mod:`..form_factors.drawn`), any other as 1. Costs
    ``sample`` x pieces comparisons (zdm2's 63,000 pieces: a few milliseconds)."""
    c = np.asarray(patches.centers, dtype=np.float64)
    m = np.asarray(patches.normals, dtype=np.float64)
    if not len(c) or not len(centers):
        return 0.0
    w = np.ones(len(c))
    if clusters is not None:
        of = np.asarray(clusters.of, dtype=np.int64)
        bent = _bent(patches, of)
        size = np.bincount(of, minlength=len(bent))
        w = np.where(bent[of], 1.0, 2.0 / np.maximum(size[of], 1))
    pick = np.unique(np.linspace(0, len(centers) - 1, min(sample, len(centers))).astype(np.int64))
    x, n = np.asarray(centers, np.float64)[pick], np.asarray(normals, np.float64)[pick]
    cm = np.einsum("ij,ij->i", c, m)
    total = 0.0
    for s in range(0, len(x), 16):                       # (pieces, 16) at a time
        xs, ns = x[s:s + 16], n[s:s + 16]
        front = c @ ns.T > np.einsum("ij,ij->i", xs, ns)[None]
        facing = cm[:, None] < m @ xs.T
        total += float((w @ (front & facing)).sum())
    return total / len(x)


def _bent(patches, of) -> np.ndarray:
    """(K,) bool: clusters ``of`` (N,) whose pieces do not all share one normal."""
    first = np.full(int(of.max(initial=-1)) + 1, -1, np.int64)
    first[of[::-1]] = np.arange(len(of))[::-1]
    bent = np.abs(patches.normals - patches.normals[first[of]]).max(axis=1) > 1e-6
    curved = np.zeros(len(first), bool)
    curved[of[bent]] = True
    return curved


def curved_pieces(patches, clusters) -> int:
    """Pieces in clusters whose pieces do not all share one normal: a hemi-cube draws them face
    by face (a flat cluster is drawn as its outline). None without clusters: each piece is a
    patch then, counted as a receiver."""
    if clusters is None:
        return 0
    of = np.asarray(clusters.of, dtype=np.int64)
    return int(_bent(patches, of)[of].sum())


def forecast(ctx, receivers, output_vertices: int, per_receiver=None, elements_cut: int = 0,
             joined: int = 0) -> Forecast:
    """The :class:`Forecast` of the bake of ``ctx`` (after its patch stage) with ``receivers``
    hemi-cubes to draw (their ids among ``ctx.unknowns``, or how many: then looked at from all
    of them) and ``output_vertices`` to evaluate. ``per_receiver``: the seconds a hemi-cube
    took on one worker in a sample of this scene's (:func:`..form_factors.hemicube._probe`),
    which the form factors' forecast then is; None: the rates :data:`PER_RECEIVER` and
    :data:`PER_SEEN`. ``elements_cut``: output elements the detail size makes beyond the pieces
    (:func:`..mesh.elements.elements_cut_ahead`); ``joined``: output vertices that cast no
    gather rays of their own (:func:`..output.shared.joined_ahead`, :data:`PER_JOINED`)."""
    s = ctx.settings
    workers = resolve_workers(s.workers)
    speed = 1.0 + PER_EXTRA_WORKER * (workers - 1)
    u = ctx.unknowns if hasattr(ctx, "unknowns") else ctx.patches
    ids = np.arange(int(receivers)) if np.ndim(receivers) == 0 else np.asarray(receivers, np.int64)
    ids = ids[ids < len(u.centers)]
    seen = polygons_seen(ctx.patches, ctx.clusters, u.centers[ids], u.normals[ids])
    if per_receiver is None:
        per_receiver_said = ray_seconds(s.resolution) if s.method == "embree" else hemicube_seconds(seen)
    else:
        per_receiver_said = per_receiver
    ff = len(ids) * per_receiver_said / speed
    rays = max(int(getattr(s, "gather_rays", 0) or 0), 32)
    emitting = ctx.patches.emitting().any()
    lamps = list(getattr(ctx, "lights", ()))
    gathers = s.gather_rays > 0 and s.uses_elements()
    casting = output_vertices - (1 - PER_JOINED) * min(max(int(joined), 0), output_vertices) * gathers
    out = casting * (PER_VERTEX if emitting else PER_VERTEX_LAMPS) * rays / 128 \
        + output_vertices * PER_EXTRA_LAMP * max(len(lamps) - 1, 0)
    if not emitting:
        out += PER_ELEMENT_CUT * max(int(elements_cut), 0)
    if not emitting and s.gather_rays > 0 and s.uses_elements() \
            and any(not isinstance(lamp, SunLight) for lamp in lamps):
        out += output_vertices * BUDGET * PER_VERTEX_SHINE          # what shines, at most BUDGET groups
    out /= speed
    return Forecast((1 + OTHER) * (ff + out), ff, out, len(ids), curved_pieces(ctx.patches, ctx.clusters),
                    int(output_vertices), workers, float(seen), per_receiver)


def _seconds(x: float) -> str:
    return f"{x:.1f}" if x < 10 else f"{x:.0f}"
