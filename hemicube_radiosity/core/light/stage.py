"""The direct-light stage: light that reaches a surface straight from an emitter or a lamp.

Two ways, chosen by ``settings.direct``:

* 'exact' (default): radiance arriving from the emissive patches in closed form times the visible
  fraction of shadow rays (:mod:`.emitters`), plus the lamps' irradiance / pi (:mod:`.lamps`), at
  the patch centres for the solve and again at every output vertex (:mod:`.output`). The solve
  then carries only reflected light.
* 'hemicube' (the paper's): emitted light goes through F like any other; lamps are evaluated at
  the patch centres only.

Units: radiance (W m^-2 sr^-1 per unit of colour); ``H`` is irradiance (W m^-2) = pi * radiance.
"""
from __future__ import annotations

from functools import partial

import numpy as np

from ..runtime.cache import array_key, cache_key, cached, geometry_key
from ..runtime.notes import warning
from ..form_factors.glossy import mirrored_source
from .lamps import UNBOUNDED
from .lamp_cache import lamp_irradiance
from .points import STAND_INS, centres_of, patch_average, stand_ins
from ..rays import embree_available, embree_scene
from ..hemisphere import open_fraction
from .direct import DirectLight, turns_emitters
from .seen import seen_direct

__all__ = ["direct_stage", "source_term"]


def source_term(patches, F, *, direct_irradiance=None, world=None) -> np.ndarray:
    """S = emission + rho * H_direct / pi + rho * sky * L_world  (radiance units, (N, 3)).

    ``patches``: anything with ``rho`` and ``emission`` (N, 3) (a PatchSet or Clusters);
    ``direct_irradiance`` (N,3) W/m^2 from lamps; ``world`` (3,) constant world radiance seen by
    the part of each hemisphere that sees no surface (``F.sky``).
    """
    S = np.array(patches.emission, dtype=np.float64)
    if direct_irradiance is not None:
        S += patches.rho * np.asarray(direct_irradiance, float) / np.pi
    if world is not None and np.any(np.asarray(world) > 0):
        if F.sky is None:
            raise ValueError("these form factors carry no sky fractions; the world cannot be lit")
        S += patches.rho * F.sky[:, None] * np.asarray(world, float)[None, :]
    return S


def _seen_weight(ctx):
    """``weight_at`` for :func:`patch_average`: a point counts fully when at least half of its
    hemisphere is open (:func:`.hemisphere.open_fraction`, reach a twentieth of the patch size), less as
    less of it is, nothing when it is enclosed (above a lamp's back, inside a block), so a
    patch's light is that of the part the scene sees. None without Embree."""
    p, s = ctx.patches, ctx.settings
    if not embree_available() or not s.patch_size:
        return None
    reach = 0.05 * float(s.patch_size)

    def weight_at(x, n):
        key = cache_key(geometry_key(p) + array_key(x), ("exposure", reach))
        e = cached(ctx.cache, key, lambda: open_fraction(p, x, n, embree_scene(p), reach, workers=s.workers))
        return np.minimum(1.0, e / 0.5)
    return weight_at


def _unknowns_direct(ctx, seen, rd, stand) -> np.ndarray:
    """(K, 3) direct light reflected by each unknown: its patch's ``rd`` (N, 3), or over a
    cluster's pieces the mean weighted by area and by ``seen`` at the piece centres (pieces the
    scene cannot see, a ceiling above a lamp, lend the cluster none of their light); a piece
    takes ``seen`` at its stand-in's centre (:func:`stand_ins`)."""
    p, c = ctx.patches, ctx.clusters
    if c is None or seen is None:
        return ctx.to_unknowns(rd)
    w = p.areas.copy()
    multi = c.sizes[c.of] > 1
    lit = np.zeros(len(p), bool)
    lit[stand[multi]] = True
    e = np.zeros(len(p))
    e[lit] = seen(*centres_of(p, lit))
    w[multi] *= e[stand[multi]]
    total = np.bincount(c.of, weights=w, minlength=len(c))
    mean = np.stack([np.bincount(c.of, weights=w * rd[:, k], minlength=len(c)) for k in range(3)], 1)
    out = mean / np.where(total > 0, total, 1.0)[:, None]
    unseen = ~(total > 0)                     # the plain area mean, made only when wanted
    return np.where(unseen[:, None], ctx.to_unknowns(rd), out) if unseen.any() else out


def _paper_source(ctx) -> None:
    """:func:`direct_stage` without an exact plan (the paper's 'hemicube' direct light, or nothing
    that emits): the lamps' light at the patch centres in ``ctx.irradiance``, and the solve's
    source ``ctx.source``: the emitters and the world through F, and the lamps' light reflected."""
    p, s, u = ctx.patches, ctx.settings, ctx.unknowns
    if turns_emitters(s) and s.direct == "hemicube" and p.emission.max(initial=0) > 0:
        ctx.notes.append("emitters light their front only with the paper's direct light "
                         "('hemicube'); 'exact' lights both sides as Cycles does")
    if ctx.lights:
        ctx.say(0.0, f"{len(ctx.lights)} lights")
        ctx.irradiance = lamp_irradiance(p, ctx.lights, ctx.cache, cancelled=ctx.cancelled,
                                         samples=s.light_samples, seed=s.light_seed, workers=s.workers)
    ctx.source = source_term(u, ctx.form_factors, world=ctx.world)
    mirrored = mirrored_source(ctx, np.zeros_like(u.emission), ctx.world)   # the world in a mirror
    if mirrored is not None:
        ctx.source += mirrored
    if ctx.irradiance is not None:
        ctx.source += ctx.to_unknowns(p.rho * ctx.irradiance) / np.pi
        np.maximum(ctx.source, 0.0, out=ctx.source)   # a map's signed variation: as in at()


def direct_stage(ctx) -> None:
    """Fill ``ctx.direct`` (the exact plan or None), ``ctx.direct_patch`` (radiance arriving at
    the patch centres, exact path), ``ctx.irradiance`` (N, 3) at the patch centres and the
    solve's source ``ctx.source`` (per unknown: a cluster takes its patches' area-weighted mean)."""
    p, s, u = ctx.patches, ctx.settings, ctx.unknowns
    world = 0.0 if ctx.world is None else float(np.max(np.asarray(ctx.world, dtype=np.float64), initial=0.0))
    if not ctx.lights and not world > 0 and not p.emitting().any():
        ctx.notes.append(warning("nothing lights the scene: no face emits, and no lamp or world "
                                 "light reaches it (a file with no light, or Lamps and World "
                                 "off): every vertex bakes black", topic="scene"))
    ctx.direct = DirectLight.plan(p, s, ctx.lights, ctx.cancelled, ctx.cache, ctx.clusters, ctx.world)
    if ctx.direct is None:
        _paper_source(ctx)
        return
    # direct light (emitters and lamps) arrives by the exact path; the solve carries only
    # reflected light R, and B = E + R (F would otherwise carry E a second time)
    ctx.say(0.0, f"exact direct light: {ctx.direct.emitters.size} emitting patches, "
                 f"{len(ctx.lights)} lamps")
    grouped = stand = None
    if ctx.clusters is not None:
        grouped = ctx.clusters.sizes[ctx.clusters.of] > 1
        stand = stand_ins(p, ctx.clusters, STAND_INS * s.patch_light_points ** 2)
    seen, memo = _seen_weight(ctx), {}
    far = any(isinstance(li, UNBOUNDED) for li in ctx.lights)

    def at(x, n, where, which=0, **share):   # the same points twice: light them once
        key = (where, array_key(x))
        if key not in memo:
            U = np.zeros((len(x), 3)) if far else None
            memo[key] = (ctx.direct.at(x, n, where, unbounded=U, **share), U)
        return memo[key][which]
    # the plain area mean is what lands on the patches (the energy report, the irradiance);
    # the solve takes the mean over the part of each patch the scene sees
    # (the points averaged share the sky's rays out: :data:`.points.SKY_SHARE`)
    average = partial(patch_average, p, s.patch_light_points, centre_only=grouped, stand=stand,
                      groups=None if ctx.clusters is None else ctx.clusters.of, share=True)
    ctx.direct_patch = average(at)
    ctx.irradiance = np.pi * ctx.direct_patch
    # the suns' and maps' share of it, from the same rays (the energy report counts it as emitted)
    ctx.unbounded_patch = average(lambda x, n, w, **k: at(x, n, w, 1, **k)) if far else None
    seen_patch = ctx.direct_patch if seen is None else average(at, weight_at=seen)
    ctx.direct_source = _unknowns_direct(ctx, seen, p.rho * seen_patch, stand)
    memo.clear()
    if ctx.direct.world is not None:          # the world's light, exact at the points above
        ctx.sky_patch = average(ctx.direct.world_at)
    # the world is in the direct light: the source does not take it again from F's sky
    ctx.source = source_term(u, ctx.form_factors) - u.emission + ctx.direct_source
    # what a receiver gathers first from a cluster lit unevenly: the part of it it sees
    gain = None if stand is None else seen_direct(ctx, stand)
    if gain is not None:
        ctx.source += gain
    # emitters and the world seen in a mirror: light reflected once already (not direct_source)
    mirrored = mirrored_source(ctx, u.emission, ctx.direct.world)
    if mirrored is not None:
        ctx.source += mirrored
    if not embree_available():
        ctx.notes.append("Embree is not available: shadow rays use the slower NumPy BVH")
