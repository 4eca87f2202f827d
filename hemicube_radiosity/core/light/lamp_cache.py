"""Lamps' light at a set of points, kept for a relight.

A lamp's irradiance at fixed points scales with its strength (a sun's W/m^2, the watts of a
point, spot or area light) and with its colour; its shape (where the light falls, its
penumbrae, the shadow rays' verdicts) depends on the geometry and the lamp's place, size and
cone alone. :func:`lamp_irradiance` computes each lamp at unit strength in white
(:func:`.lamps.light_irradiance`, the same points, samples and random streams as
:func:`.lamps.direct_irradiance`), keeps that in the bake's cache under what it depends on, and
scales it. So a relight that changes a lamp's strength or colour, the world's or a material's
casts no shadow ray toward the lamps again, and the energy report's sun-only pass finds the
direct light's own rays. An environment map (a light of its own colours) is kept the same way:
its light is linear in its pixels and its directions follow their shape alone, so it is kept
for the map scaled to a mean luminance of 1 and scaled back (:func:`_unit_map`).
"""
from __future__ import annotations

from dataclasses import fields, replace

import numpy as np

from ..mesh.patches import PatchSet
from ..rays import ray_offsets
from ..runtime.cache import array_key, cache_key, cached, geometry_key
from ..runtime.progress import Ticker
from ..util.colour import LUMA
from .environment import EnvironmentLight
from .lamps import SUN_FIRST, UNBOUNDED, AreaLight, PointLight, SpotLight, SunLight, light_irradiance

__all__ = ["lamp_irradiance", "shadow_key", "SCALE"]

#: the field that scales each kind of lamp's light; every other field but ``color`` shapes it
SCALE = {PointLight: "power_w", SpotLight: "power_w", SunLight: "strength", AreaLight: "power_w"}


def shadow_key(patches: PatchSet) -> bytes:
    """What shadow rays through ``patches`` depend on: the geometry, and what light passes
    through its see-through faces where it has any (a relight of a new alpha casts again)."""
    st = patches.see_through
    return geometry_key(patches) + (b"" if st is None else st.key())


def _shape_key(light) -> str:
    """The lamp's kind and every field but its colour and strength, as text."""
    skip = ("color", SCALE[type(light)])
    vals = {f.name: getattr(light, f.name) for f in fields(light) if f.name not in skip}
    return type(light).__name__ + repr({k: np.asarray(v).tolist() if isinstance(v, np.ndarray) else v
                                        for k, v in vals.items()})


def _unit_map(light: EnvironmentLight) -> tuple:
    """(the map scaled to a mean luminance of 1, that scale, the key of its shape): a world
    made brighter or dimmer (its Strength) has the same unit map, to float32's precision, so
    a relight finds its light kept. (None, 0, b"") for a dark map. Kept on the light (the
    bake asks for it at every point set)."""
    memo = light.__dict__.setdefault("_memo", {})
    if "unit" not in memo:
        memo["unit"] = _make_unit_map(light)
    return memo["unit"]


def _make_unit_map(light: EnvironmentLight) -> tuple:
    scale = float(light.mean() @ LUMA)
    if not scale > 0:
        return None, 0.0, b""
    unit = replace(light, pixels=light.pixels / scale, color=(1.0, 1.0, 1.0))
    shape = array_key(unit.pixels.astype(np.float32)) + array_key(np.asarray(light.rotation, np.float32))
    return unit, scale, shape + repr((int(light.rays), bool(light.cast_shadows))).encode()


def lamp_irradiance(patches: PatchSet, lights, cache, *, shadows="auto", samples=16, seed=0, points=None,
                    normals=None, eps=None, facing=None, progress=None, cancelled=None, workers=1,
                    index=0, unbounded=None) -> np.ndarray:
    """Incident irradiance (P, 3) W/m^2 from ``lights``, as :func:`.lamps.direct_irradiance`
    with the same arguments gives it (at the patch centres, or at ``points`` (P, 3) with unit
    ``normals`` (P, 3); ``eps`` (P,) the rays' start offsets; ``facing`` (P, 3) or None;
    ``workers``: threads, the same result for any count), each lamp's unit transport (P,) kept
    in ``cache`` (None: nothing kept); ``index``: the first lamp's place among the bake's lamps
    (its random stream: one lamp of a list lit apart draws what it draws in the list). Equal to
    ``direct_irradiance`` up to rounding: each lamp's light is its unit light times its
    strength. ``unbounded`` (P, 3) or None: the suns' and environment maps' part of the result
    is added to it as well (what the energy balance counts as delivered by them)."""
    lights = list(lights)
    x = patches.centers if points is None else np.asarray(points, np.float64)
    n = patches.normals if points is None else np.asarray(normals, np.float64)
    H = np.zeros((len(x), 3))
    if not lights:
        return H
    if eps is None and points is not None:      # found by probe rays: kept as DirectLight.offsets keeps them
        eps = cached(cache, cache_key(geometry_key(patches) + array_key(patches.owner) + array_key(x) + array_key(n),
                                      ("ray-offsets",)), lambda: ray_offsets(patches, points, normals))
    eps = ray_offsets(patches, points, normals) if eps is None else np.asarray(eps, np.float64)
    base = shadow_key(patches) + array_key(x) + array_key(n) + array_key(eps)
    base += b"" if facing is None else array_key(np.asarray(facing, np.float64))
    kw = dict(shadows=shadows, samples=samples, seed=seed, points=points, normals=normals, eps=eps,
              facing=facing, workers=workers)
    ticker = Ticker(progress, cancelled)
    for i, light in enumerate(lights, start=index):
        ticker.tick(i - index, len(lights), force=True)
        scale = SCALE.get(type(light))
        if isinstance(light, EnvironmentLight):   # its own colours: kept for its unit map
            unit, s, shape = _unit_map(light)
            if unit is None:
                continue
            key = cache_key(base + shape, ("environment", i, int(samples), seed, shadows))
            E = cached(cache, key, lambda: light_irradiance(patches, unit, _index=i, **kw)) * s
        elif scale is None:
            raise TypeError(f"unknown light type {type(light).__name__}")
        elif getattr(light, scale) == 0:       # dark: no light, no ray
            continue
        else:
            unit = replace(light, **{scale: 1.0}, color=(1.0, 1.0, 1.0))
            first = ("first", SUN_FIRST) if isinstance(light, SunLight) else ()   # (:func:`.lamps.sun_first`)
            key = cache_key(base, ("lamp", _shape_key(light), i, int(samples), seed, shadows) + first)
            E = cached(cache, key, lambda: light_irradiance(patches, unit, _index=i, **kw)) * getattr(light, scale)
        E = (E if E.ndim == 2 else E[:, None]) * np.asarray(light.color, np.float64)[None, :]
        H += E
        if unbounded is not None and isinstance(light, UNBOUNDED):
            unbounded += E
    ticker.tick(len(lights), len(lights), force=True)
    return H
