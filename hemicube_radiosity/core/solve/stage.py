"""The ``solve`` stage: B = S + rho F B per band over the unknowns (clusters, or patches),
and the scene's energy balance in the report (emitters, lamps, suns and the world counted with
the power they send out).

Reads ``ctx.form_factors``, ``ctx.source`` and, on the exact direct path, ``ctx.direct``; fills
``ctx.solution`` (B = E + R: the solve carries reflected light only there) and ``ctx.reflected``.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..form_factors.stage import receivers_needed
from ..runtime.notes import warning
from ..light.lamp_cache import lamp_irradiance
from ..light.lamps import UNBOUNDED, SpotLight
from .residual import energy_balance
from .solvers import solve
from ..util.sparse import CSR
from ..form_factors.glossy import solve_matrix

#: At most this many solves more for coloured glossy patches: the solve takes F^s at the least
#: of the bands' albedos, each pass adds what the bands' own albedos add beside it (a defect
#: correction; its change shrinks by about rho (g - g_least) F each pass)
COLOUR_PASSES = 8


def solve_stage(ctx) -> None:
    """Fill ``ctx.solution``: B = S + rho F B per band (:func:`.solvers.solve`). On the exact
    direct path the solve carries reflected light only; the solution reports B = E + R."""
    s, p = ctx.settings, ctx.unknowns
    computed = np.zeros(len(p), bool)
    computed[receivers_needed(p)] = True
    ctx.say(0.0, s.solver)
    F, d, coloured = solve_matrix(ctx, ctx.form_factors)     # with the light glossy patches mirror
    rho, source, areas, solid = see_through_system(F, p.rho, ctx.source, p.areas)
    run = _signed(_solver(F, rho, d, s, areas, computed, ctx.cancelled), F, rho, areas, computed)
    sol = run(source, lambda fr: ctx.say(fr, ""))
    for _ in range(COLOUR_PASSES if coloured is not None else 0):   # a coloured metal's own bands
        B = sol.B if solid is None else sol.B * solid[:, None]
        last = sol.B
        sol = run(source + coloured(B))
        if np.max(np.abs(sol.B - last)) <= s.tolerance * max(np.max(np.abs(sol.B)), 1e-300):
            break
    if solid is not None:                             # each see-through patch's mean
        sol = replace(sol, B=sol.B * solid[:, None])
    bound = sol.error_bound
    ctx.say(1.0, f"{sol.iterations} iterations, residual {sol.residual:.2e}, error below {bound:.1e}"
            + ("" if sol.converged else " (NOT converged: raise max iterations)"))
    if not sol.converged:
        ctx.notes.append(warning(f"solver stopped after {sol.iterations} iterations with a "
                                 f"relative error up to {bound:.1e}, above the tolerance "
                                 f"{s.tolerance:g}: raise max iterations", topic="scene"))
    energy = scene_energy(ctx, sol.energy, computed) if sol.energy else sol.energy
    if ctx.direct is not None:
        ctx.reflected = sol.B
        sol = replace(sol, B=sol.B + p.emission, extra={**sol.extra, "reflected_only": True})
    ctx.solution = replace(sol, energy=energy)


def _signed(run, F, rho, areas, computed):
    """``run`` for a source that may be negative in places (:mod:`..light.seen` takes out of
    what a receiver gathers first the part of a cluster's mean direct light it does not see;
    the solution stays positive): by linearity the solution of the source's positive part
    minus that of its negative part, each solved as any source is (the solvers take sources
    of one sign). A source of one sign is solved once, as before."""
    def go(source, progress=None):
        neg = np.maximum(-np.asarray(source, dtype=np.float64), 0.0)
        if not neg.any():
            return run(source, progress)
        a, b = run(np.asarray(source, dtype=np.float64) + neg, progress), run(neg)
        B = a.B - b.B
        scale = max(float(np.abs(B).max()), 1e-300)
        bound = (a.error_bound * np.abs(a.B).max() + b.error_bound * np.abs(b.B).max()) / scale
        energy = energy_balance(F, rho, source, B, areas, computed=computed) if areas is not None else a.energy
        return replace(a, B=B, iterations=a.iterations + b.iterations, converged=bool(a.converged and b.converged),
                       error_bound=float(bound), energy=energy)
    return go


def _solver(F, rho, d, s, areas, computed, cancelled):
    """``run(source, progress=None) -> Solution``: :func:`.solvers.solve` of B = S + rho F B
    with settings ``s``; with ``d`` (K,) (glossy unknowns,
    :func:`..form_factors.glossy.solve_matrix`) for B / d, F's columns times d, rho and S over
    d (0 where d is 0), made once for every source it is run with, and B and its energy
    balance made again in the unscaled unknowns."""
    kw = dict(areas=areas, cancelled=cancelled, computed=computed)
    if d is None:
        return lambda source, progress=None: solve(F, rho, source, s.solver, s.tolerance, s.max_iterations,
                                                   progress=progress, **kw)
    keep = d[F.indices] > 0
    Fd = CSR.from_coo(F.row_ids()[keep], F.indices[keep], F.data[keep] * d[F.indices[keep]], F.shape, F.meta)
    over = np.where(d > 0, 1.0 / np.where(d > 0, d, 1.0), 0.0)[:, None]
    rho_d = np.minimum(np.asarray(rho) * over, RHO_CAP)

    def run(source, progress=None):
        sol = solve(Fd, rho_d, np.asarray(source) * over, s.solver, s.tolerance, s.max_iterations,
                    progress=progress, **kw)
        B = sol.B * d[:, None]
        energy = energy_balance(F, rho, source, B, areas, computed=computed) if areas is not None else sol.energy
        return replace(sol, B=B, energy=energy)
    return run


def see_through_system(F, rho, source, areas):
    """(rho, source, areas, solid) to solve with F: where F's ``meta['passes']`` (n,) holds
    see-through patches' transmittances t (:mod:`..form_factors.hemicube`), F reads their light
    over their solid part, 1 - t of them (``solid``): the solve then solves for it, their
    reflectance and source over ``solid`` (their colour), their areas times it (the energy
    balance counts what they absorb on it); B is the solution times ``solid``. Else the inputs
    as they are and ``solid`` None."""
    t = F.meta.get("passes") if F.meta else None
    if t is None:
        return rho, source, areas, None
    solid = 1.0 - np.asarray(t, dtype=np.float64)
    over = np.where(solid > 0, 1.0 / np.where(solid > 0, solid, 1.0), 0.0)[:, None]
    rho = np.asarray(rho, dtype=np.float64)
    rho = np.where(solid[:, None] < 1, np.minimum(rho * over, RHO_CAP), rho)
    areas = np.asarray(areas, dtype=np.float64) * np.maximum(solid, 1e-6)
    return rho, np.asarray(source, dtype=np.float64) * over, areas, solid


#: The most a see-through patch's colour reflects in the solve (its reflectance over its opacity
#: stays below the input's own bound, rounding aside)
RHO_CAP = 0.999


def lamp_power(light) -> np.ndarray:
    """(3,) what a lamp sends out, in the balance's units (radiance x area: watts / pi), or
    None for a sun (unbounded: it is counted as what reaches the patches). Point: P; spot: P
    times its cone's share of the sphere, ``(1 - cos(size/2)) (1 - blend/2) / 2`` (Cycles'
    smoothstep integrates to half the blend band); area: P (one-sided). A point or spot with a
    radius and soft falloff is counted by its far field (the disk model gives a little less
    near it)."""
    if isinstance(light, UNBOUNDED):
        return None
    share = 1.0
    if isinstance(light, SpotLight):
        share = 0.5 * (1 - np.cos(0.5 * light.spot_size)) * (1 - 0.5 * light.spot_blend)
    return light.power_w * share * np.asarray(light.color, float) / np.pi


def _suns_at(ctx):
    """(N, 3) radiance arriving from the suns (and environment maps) alone at the patches, or
    None without one: on the exact path the direct light's own share of them
    (``ctx.unbounded_patch``, from the same rays); on the 'hemicube' path sampled exactly as
    the direct light was (same seed and ray streams: the other lamps are kept in the list, dark
    and without shadow rays)."""
    s, p = ctx.settings, ctx.patches
    if not any(isinstance(li, UNBOUNDED) for li in ctx.lights):
        return None
    if ctx.direct is not None:
        return ctx.unbounded_patch
    only = [li if isinstance(li, UNBOUNDED) else replace(li, power_w=0.0, cast_shadows=False)
            for li in ctx.lights]
    return lamp_irradiance(p, only, ctx.cache, samples=s.light_samples, seed=s.light_seed,
                           cancelled=ctx.cancelled, workers=s.workers) / np.pi


def _world_and_direct(ctx, a, D, computed):
    """(what the world delivers, what the direct light delivers, what of it is absorbed) per band,
    radiance x area: on the exact path the world is in ``D`` (``ctx.sky_patch`` its part);
    otherwise it comes through F's sky fractions and is reflected by the solve."""
    p, u = ctx.patches, ctx.unknowns
    if ctx.sky_patch is not None:
        return (a * ctx.sky_patch).sum(axis=0), (a * D).sum(axis=0), (a * (1 - p.rho) * D).sum(axis=0)
    world = world_reflected = np.zeros(3)
    if ctx.world is not None and np.any(np.asarray(ctx.world) > 0) and ctx.form_factors.sky is not None:
        sky = np.where(computed, ctx.form_factors.sky, 0.0)
        world = (u.areas * sky).sum() * np.asarray(ctx.world, float)
        world_reflected = (u.areas[:, None] * u.rho * sky[:, None] * np.asarray(ctx.world, float)).sum(axis=0)
    recv = (a * D).sum(axis=0) + world
    return world, recv, (a * (1 - p.rho) * D).sum(axis=0) + world - world_reflected


def scene_energy(ctx, solved: dict, computed) -> dict:
    """The whole scene's power balance per band, radiance x area (x pi for watts):
    ``emitted = absorbed + escaped``, where the solve's own balance (``solved``, kept under
    'solve') counts only what goes through F.

    What is counted: emitted is the emissive faces' light (both sides when two-sided, on the
    exact path; what the solve emits on the 'hemicube' path), the lamps' power
    (:func:`lamp_power`) and, for the unbounded sources (suns, the world), the light they deliver
    to the patches. Light arriving directly (``ctx.direct_patch``, or the lamps' irradiance on
    the 'hemicube' path) is absorbed at (1 - rho) and reflected into the solve (less what the
    parts of patches the scene cannot see reflect: absorbed where it lands); what the direct
    light does not deliver to any patch's front escapes (through openings into the world, or
    onto back faces), as does what the solve's rows do not see. 'direct' holds the direct
    light's own emitted / received / absorbed / escaped; ``imbalance`` is relative, as in
    :func:`.residual.energy_balance` (the direct part balances by construction: its escape is
    measured as what did not arrive, checked against closed forms in tests/core/test_hard_cases.py)."""
    p, u = ctx.patches, ctx.unknowns
    # the areas over three bands: the same products as p.areas[:, None]'s, without broadcasting
    # a (N, 1) factor along the short axis (5x as long)
    a = np.repeat(np.asarray(p.areas, dtype=np.float64)[:, None], 3, axis=1)
    zero = np.zeros(3)
    if ctx.direct is not None:
        D = ctx.direct_patch
        e = p.emitting()
        sides = 2.0 if ctx.direct.two_sided else 1.0
        surf = sides * (a[e] * p.emission[e]).sum(axis=0)
    else:
        D = zero[None] if ctx.irradiance is None else ctx.irradiance / np.pi
        surf = zero
    lamps = [lamp_power(li) for li in ctx.lights]
    lamps = sum((w for w in lamps if w is not None), zero)
    sun = _suns_at(ctx)
    sun = zero if sun is None else (a * sun).sum(axis=0)
    world, recv, absorbed = _world_and_direct(ctx, a, D, computed)
    if getattr(ctx, "specular", None) is not None:
        # glossy patches hand their share of the direct light on (F^s, the lamps' spread)
        absorbed = absorbed - (a * ctx.glossy * D).sum(axis=0)
    if ctx.direct_source is not None:
        # what the parts of patches the scene cannot see reflect (a ceiling above a lamp's back)
        # lands on what encloses them, not in the solve (light/stage.py, _seen_weight)
        absorbed = absorbed + (u.areas[:, None] * (ctx.to_unknowns(p.rho * D) - ctx.direct_source)).sum(axis=0)
    emitted = surf + lamps + sun + world
    direct = {"emitted": emitted, "received": recv, "absorbed": absorbed, "escaped": emitted - recv}
    # the 'hemicube' path's emitters are the solve's own source
    own = zero if ctx.direct is not None else (u.areas[:, None] * u.emission).sum(axis=0)
    total = {"emitted": emitted + own,
             "absorbed": absorbed + np.asarray(solved["absorbed"]),
             "escaped": direct["escaped"] + np.asarray(solved["escaped"])}
    miss = np.abs(total["emitted"] - total["absorbed"] - total["escaped"])
    with np.errstate(invalid="ignore", divide="ignore"):
        imb = np.where(total["emitted"] > 0, miss / total["emitted"], 0.0)
    return {**{k: v.tolist() for k, v in total.items()}, "imbalance": float(np.max(imb)),
            "direct": {k: v.tolist() for k, v in direct.items()}, "solve": solved}
