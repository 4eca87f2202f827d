"""The form-factor stage: F by the chosen method, reused from the cache when the geometry is.

Methods (``settings.method``): 'hemicube' (:mod:`.hemicube`, the NumPy rasteriser), 'embree'
(rays through the same hemi-cube pixels, :mod:`.embree_ff`), 'embree_stochastic' (cosine rays);
'auto' (the default) is one of the first two, whichever is faster here (:func:`chosen_method`).
Every method returns a :class:`.sparse.CSR` with ``sky`` filled and F_ii = 0.
"""
from __future__ import annotations

import time
from dataclasses import replace

import numpy as np

from . import embree as embree_ff
from ..runtime.cache import Memo, array_key, cache_key, geometry_key
from .glossy import specular_stage
from .hemicube import hemicube_form_factors
from ..mesh.elements import output_mesh_ahead
from ..mesh.patches import PatchSet
from ..output.shared import joined_ahead
from ..rays import embree_available
from ..util.sparse import CSR

__all__ = ["compute_form_factors", "receivers_needed", "chosen_method", "form_factor_stage"]


def receivers_needed(patches) -> np.ndarray:
    """Patches (or clusters) whose rows of F matter: a patch that reflects nothing (rho = 0 in every band,
    e.g. a pure emitter) has B = S whatever it sees, so its hemi-cube is never drawn."""
    return np.flatnonzero(patches.rho.max(axis=1) > 0)


def compute_form_factors(patches: PatchSet, settings, *, receivers=None, progress=None,
                         cancelled=None, clusters=None, probe=None) -> CSR:
    """F for ``patches`` (or their ``clusters``, every patch drawn) by ``settings.method`` (rows
    only for ``receivers``, default all), with ``settings.workers`` workers (the same F for any
    count): the hemi-cube on forked processes where there are any, Embree on threads
    (:mod:`.parallel`). ``probe``: called once before the long work with the seconds a
    hemi-cube took in a sample (the hemi-cube's, :func:`.hemicube.hemicube_form_factors`),
    or None (a method or a count of receivers that is not sampled)."""
    kw = dict(receivers=receivers, progress=progress, cancelled=cancelled, clusters=clusters,
              workers=getattr(settings, "workers", 1))
    if settings.method == "hemicube":
        return hemicube_form_factors(patches, settings.resolution, rotate_seed=settings.rotate_seed,
                                     probe=probe, **kw)
    if probe is not None:
        probe(None)
    if settings.method == "embree":
        return embree_ff.embree_hemicube_form_factors(patches, settings.resolution,
                                                      rotate_seed=settings.rotate_seed, **kw)
    return embree_ff.embree_stochastic_form_factors(patches, settings.rays_per_patch,
                                                    seed=settings.rotate_seed or 0, **kw)


#: :func:`.forecast.polygons_seen` by the digest of what it reads (geometry only): a relight
#: asks it again (20 ms of the bunny's relight)
_SEEN = Memo(8)


def chosen_method(ctx, receivers) -> str:
    """The method of ``ctx.settings``, 'auto' made 'hemicube' or 'embree': Embree's rays through
    the hemi-cube's pixels where a hemi-cube would draw so many polygons (:func:`.forecast.
    polygons_seen` from ``receivers``) that it would take longer than the rays (the same F
    but for what a pixel centre sees: zdm2's 63,000 pieces, about 10,600 drawn a hemi-cube,
    took 103 s drawn and 28 s cast, its vertices 1.1% apart, their mean 0.2%); the rasteriser
    for scenes with fewer (the Cornell box: as fast), and without Embree."""
    from ..runtime.forecast import hemicube_seconds, polygons_seen, ray_seconds
    s = ctx.settings
    if s.method != "auto":
        return s.method
    if not embree_available() or not len(receivers):
        return "hemicube"
    u = ctx.unknowns
    x, n = u.centers[receivers], u.normals[receivers]
    of = b"" if ctx.clusters is None else array_key(ctx.clusters.of)
    key = cache_key(geometry_key(ctx.patches) + of + array_key(x) + array_key(n), ("polygons-seen",))
    seen = _SEEN.get(key, lambda: polygons_seen(ctx.patches, ctx.clusters, x, n))
    return "embree" if hemicube_seconds(seen) > ray_seconds(s.resolution) else "hemicube"


def form_factor_stage(ctx) -> None:
    """Fill ``ctx.form_factors`` and ``ctx.form_factor_source`` ('computed' or 'cached'); an
    'auto' method is made the one used (:func:`chosen_method`) in ``ctx.settings``."""
    patches, cache = ctx.patches, ctx.cache
    recv = receivers_needed(ctx.unknowns)
    ctx.settings = replace(ctx.settings, method=chosen_method(ctx, recv))
    key = None
    if cache is not None:
        grouping = b"" if ctx.clusters is None else np.ascontiguousarray(ctx.clusters.of).tobytes()
        # the patches' key hashed once per geometry (a relight's patches share their cached arrays)
        st = getattr(patches, "see_through", None)             # what see-through patches pass
        key = cache_key(geometry_key(patches) + grouping + (b"" if st is None else st.key()),
                        ctx.settings.form_factor_key())
    F = cache.get(key) if cache is not None else None
    ctx.form_factor_source = "cached" if F is not None else "computed"
    if F is None:
        out_mesh = output_mesh_ahead(ctx)
        ahead = len(out_mesh.verts)
        started = time.perf_counter()

        def said(per_receiver):             # the forecast, with the sample's time when there is one
            from ..runtime.forecast import forecast
            nonlocal started
            ctx.forecast = forecast(ctx, recv, ahead, per_receiver, out_mesh, joined_ahead(out_mesh))
            ctx.say(0.0, ctx.forecast.describe())
            started = time.perf_counter()       # the ETA counts from here, not the sample

        def progress(fr):
            el = time.perf_counter() - started
            eta = el * (1 - fr) / fr if fr > 0 else float("nan")
            ctx.say(fr, f"{100 * fr:.0f}%  ETA {eta:.1f} s")

        F = compute_form_factors(patches, ctx.settings, receivers=recv, progress=progress,
                                 cancelled=ctx.cancelled, clusters=ctx.clusters, probe=said)
        F.meta.setdefault("receivers", int(recv.size))
        if cache is not None:
            cache.put(key, F)
    ctx.form_factors = F
    specular_stage(ctx)                      # light mirrored by glossy patches (F^s)
    ctx.say(1.0, f"{ctx.form_factor_source}: {F.nnz} nonzeros, {F.nbytes / 1e6:.1f} MB")
