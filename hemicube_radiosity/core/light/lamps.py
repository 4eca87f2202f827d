"""Blender-style lamps and the direct light they give the patches (pure NumPy, rays by .rays).

What it computes
----------------
:func:`direct_irradiance` returns ``H_direct`` (N, 3): the irradiance in W/m^2 (per colour band)
that the lamps deliver to the front of every patch, evaluated at the patch centre and with
shadows. A diffuse patch turns it into radiance ``rho * H_direct / pi``, so the radiosity
source term, in the same radiance units as the patches' emission, is::

    S = emission + rho * H_direct / pi

(``core.light.stage.source_term`` does exactly this). The lamps themselves are not patches: they
are not seen by the form factors and receive no light.

Units: Cycles' conventions (checked in Blender's source)
---------------------------------------------------------
Blender hands Cycles ``strength = color * energy`` (``intern/cycles/blender/light.cpp``) and
Cycles turns it into radiance with ``eval_fac`` (``intern/cycles/scene/light.cpp``,
``kernel/light/{point,spot,distant,area}.h``):

* Point / spot, power P watts, radius r: ``eval_fac = 1 / (pi * area)`` with
  ``area = 4 pi r^2`` (4 when r = 0), i.e. radiant intensity ``P / (4 pi)`` W/sr, or radiance
  ``P / (4 pi^2 r^2)`` on the light's surface. Irradiance at distance d, incidence angle theta:
  ``P cos(theta) / (4 pi d^2)``. With a radius, Blender's default *soft falloff*
  (``use_soft_falloff``, Cycles ``is_sphere = false``) makes the light a disk of radius r facing
  the shading point, so near the light ``H = P / (4 pi (d^2 + r^2))`` for a facing receiver;
  with soft falloff off it is a sphere, which gives exactly the point-light value while the
  sphere is above the receiver's horizon. Both shapes are modelled (``soft_falloff``).
* Spot: the point light times ``smoothstep((cos(phi) - cos(spot_size/2)) /
  ((1 - cos(spot_size/2)) * spot_blend))``, phi the angle between the spot axis and the
  direction from the light to the receiver (``spot_light_attenuation``; a hard edge when the
  blend is 0). The cone is circular: non-uniform object scale (an elliptic cone in Cycles) is
  not modelled.
* Sun, strength S W/m^2, angle a (full angular diameter): a uniform disk of angular radius a/2
  with radiance ``S / (pi sin^2(a/2))`` (``eval_fac = 1 / area``, ``area = pi sin^2(a/2)``),
  so ``H = S cos(theta)`` while the disk is above the horizon.
* Area light, power P, one-sided, emitting along its local -Z: ``eval_fac = 1 / (pi * area)``
  (Cycles 4.x and later; 3.x used ``0.25 / area``), i.e. a Lambertian emitter of radiance
  ``L = P / (pi A)``, ``A = |X| size_x * |Y| size_y`` (times pi/4 for DISK/ELLIPSE), X and Y the
  first two columns of the object matrix. ``H = pi L F`` with F the exact point-to-polygon
  form factor (Lambert's contour integral, :func:`.polygon_ff.polygon_form_factor`) of the part of
  the light above the receiver's horizon. Disks and ellipses are regular 64-gons of the same
  area. The *spread* setting is ignored (taken as the default 180 degrees).
* The world's environment map: its variation about its mean, a light of its own colours
  (:mod:`.environment`); the mean is the constant world.

Shadows (soft shadows from radius / angle / size)
-------------------------------------------------
The unshadowed irradiance is computed in closed form (every light with a size is, as seen from
the receiver, a convex polygon of constant radiance: a disk, a sphere's silhouette disk, the sun
as a disk at unit distance, or the area light itself). Visibility is then sampled: ``samples``
stratified points per light per patch (jittered grid, seeded), each weighted by its share of
the unshadowed integrand, ``H = H_unshadowed * sum(v_s w_s a_s) / sum(w_s)`` (a_s: spot
attenuation). Points and a sun with zero size need a single shadow ray. Shadow rays go from the
patch centre (moved a hair along its normal) to the sample point; any patch (front or back)
blocks them. ``shadows``: 'embree' (needs embreex), 'numpy' (a NumPy BVH, slower, same
answers), 'none', or 'auto' (Embree when available): :func:`.rays.occluder`.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..util.geometry import DISK_SIDES, disk_polygons, equal_area_scale
from ..util.sampling import disk_samples, stratified_unit_square
from .environment import EnvironmentLight, environment_irradiance
from .polygon_ff import distant_form_factor, polygon_form_factor
from ..mesh.patches import PatchSet
from ..runtime.parallel import ordered_map, resolve_workers
from ..runtime.progress import Ticker
from ..rays import occluder, ray_offsets
from .transmit import first_visible, visibility

__all__ = ["PointLight", "SpotLight", "SunLight", "AreaLight", "EnvironmentLight", "UNBOUNDED", "direct_irradiance",
           "light_irradiance", "spot_attenuation", "AREA_SHAPES"]

AREA_SHAPES = ("SQUARE", "RECTANGLE", "DISK", "ELLIPSE")
RECEIVERS_PER_CHUNK = 4096
#: A sun's shadow rays a few first (:func:`sun_first`) from this many rows of its stratified
#: pattern on (16 samples: 4 first, the other 12 only where those part).
SUN_FIRST = 4


# --------------------------------------------------------------------------------------------
# Lights


def _vec3(v, name):
    a = np.asarray(v, dtype=np.float64).reshape(-1)
    if a.shape != (3,) or not np.all(np.isfinite(a)):
        raise ValueError(f"{name} must be 3 finite numbers, got {v!r}")
    return a


def _unit(v, name):
    a = _vec3(v, name)
    n = np.linalg.norm(a)
    if n == 0:
        raise ValueError(f"{name} must not be the zero vector")
    return a / n


def _nonneg(x, name):
    x = float(x)
    if not np.isfinite(x) or x < 0:
        raise ValueError(f"{name} must be a finite number >= 0, got {x!r}")
    return x


@dataclass
class PointLight:
    """Blender point light: ``power_w`` watts, colour (linear RGB), ``radius`` (shadow_soft_size).

    ``soft_falloff`` (Blender's default True): with a radius, a disk facing the receiver;
    False: a sphere.
    """

    position: tuple
    color: tuple = (1.0, 1.0, 1.0)
    power_w: float = 1000.0
    radius: float = 0.0
    soft_falloff: bool = True
    cast_shadows: bool = True

    def __post_init__(self):
        self.position = _vec3(self.position, "PointLight.position")
        self.color = _vec3(self.color, "PointLight.color")
        self.power_w = _nonneg(self.power_w, "PointLight.power_w")
        self.radius = _nonneg(self.radius, "PointLight.radius")


@dataclass
class SpotLight:
    """Blender spot light: a point light limited to a cone around ``direction`` (where it
    shines, the object's -Z). ``spot_size``: full cone angle in radians; ``spot_blend`` in [0, 1].
    """

    position: tuple
    direction: tuple
    color: tuple = (1.0, 1.0, 1.0)
    power_w: float = 1000.0
    radius: float = 0.0
    spot_size: float = np.pi / 4
    spot_blend: float = 0.15
    soft_falloff: bool = True
    cast_shadows: bool = True

    def __post_init__(self):
        self.position = _vec3(self.position, "SpotLight.position")
        self.direction = _unit(self.direction, "SpotLight.direction")
        self.color = _vec3(self.color, "SpotLight.color")
        self.power_w = _nonneg(self.power_w, "SpotLight.power_w")
        self.radius = _nonneg(self.radius, "SpotLight.radius")
        self.spot_size = float(self.spot_size)
        if not 0 < self.spot_size <= np.pi:
            raise ValueError(f"SpotLight.spot_size must be in (0, pi] radians, got {self.spot_size}")
        self.spot_blend = float(self.spot_blend)
        if not 0 <= self.spot_blend <= 1:
            raise ValueError(f"SpotLight.spot_blend must be in [0, 1], got {self.spot_blend}")


@dataclass
class SunLight:
    """Blender sun: ``direction`` from the light toward the scene (the object's -Z),
    ``strength`` W/m^2 of irradiance at normal incidence, ``angle`` its full angular diameter."""

    direction: tuple
    color: tuple = (1.0, 1.0, 1.0)
    strength: float = 1.0
    angle: float = 0.0
    cast_shadows: bool = True

    def __post_init__(self):
        self.direction = _unit(self.direction, "SunLight.direction")
        self.color = _vec3(self.color, "SunLight.color")
        self.strength = _nonneg(self.strength, "SunLight.strength")
        self.angle = float(self.angle)
        if not 0 <= self.angle < np.pi:
            raise ValueError(f"SunLight.angle must be in [0, pi) radians, got {self.angle}")


@dataclass
class AreaLight:
    """Blender area light: one-sided, centred at the matrix's translation, emitting along its
    local -Z; local X/Y carry ``size_x`` / ``size_y`` (object scale included, as in Cycles).
    SQUARE and DISK use ``size_x`` for both sides."""

    matrix_world: np.ndarray
    shape: str = "SQUARE"
    size_x: float = 1.0
    size_y: float = 1.0
    color: tuple = (1.0, 1.0, 1.0)
    power_w: float = 100.0
    cast_shadows: bool = True

    def __post_init__(self):
        m = np.asarray(self.matrix_world, dtype=np.float64)
        if m.shape != (4, 4) or not np.all(np.isfinite(m)):
            raise ValueError("AreaLight.matrix_world must be a finite 4x4 matrix")
        self.matrix_world = m
        if self.shape not in AREA_SHAPES:
            raise ValueError(f"AreaLight.shape must be one of {AREA_SHAPES}, got {self.shape!r}")
        self.size_x = _nonneg(self.size_x, "AreaLight.size_x")
        self.size_y = _nonneg(self.size_y, "AreaLight.size_y")
        self.color = _vec3(self.color, "AreaLight.color")
        self.power_w = _nonneg(self.power_w, "AreaLight.power_w")

    def frame(self):
        """(centre, axis_u, len_u, axis_v, len_v, emit_dir) as Cycles builds them."""
        m = self.matrix_world
        sy = self.size_x if self.shape in ("SQUARE", "DISK") else self.size_y
        eu, ev = m[:3, 0] * self.size_x, m[:3, 1] * sy
        lu, lv = float(np.linalg.norm(eu)), float(np.linalg.norm(ev))
        d = -m[:3, 2]
        dn = np.linalg.norm(d)
        return (m[:3, 3].copy(), eu / (lu or 1.0), lu, ev / (lv or 1.0), lv,
                d / (dn or 1.0))

    @property
    def ellipse(self) -> bool:
        return self.shape in ("DISK", "ELLIPSE")

    @property
    def area(self) -> float:
        _, _, lu, _, lv, _ = self.frame()
        return lu * lv * (np.pi / 4 if self.ellipse else 1.0)

    def polygon(self, sides=DISK_SIDES) -> np.ndarray:
        """(K, 3) corners: the rectangle, or a regular ``sides``-gon with the ellipse's area."""
        c, au, lu, av, lv, _ = self.frame()
        if not self.ellipse:
            s = np.array([(-1, -1), (1, -1), (1, 1), (-1, 1)], float) * 0.5
        else:
            phi = 2 * np.pi * np.arange(sides) / sides
            k = equal_area_scale(sides)                                     # same area as ellipse
            s = 0.5 * k * np.stack([np.cos(phi), np.sin(phi)], 1)
        return c + s[:, :1] * lu * au + s[:, 1:] * lv * av


# --------------------------------------------------------------------------------------------
# Spot cone


def spot_attenuation(cos_angle, spot_size, spot_blend):
    """Cycles' spot cone factor for the cosine of the angle between the spot axis and the
    direction from the light to the receiver."""
    ch = np.cos(0.5 * spot_size)
    c = np.asarray(cos_angle, dtype=np.float64)
    if spot_blend <= 0:
        return (c > ch).astype(np.float64)
    t = np.clip((c - ch) / ((1.0 - ch) * spot_blend), 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


# --------------------------------------------------------------------------------------------
# Per light


def _shade(x, n, E0, pts, w, atten, occ, eps, infinite=False, facing=None, first=None):
    """H = E0 * sum(v w a) / sum(w) over samples (N,S) toward points pts (N,S,3) (directions
    when ``infinite``). Rays only where E0 > 0 and w > 0; with ``facing`` (N, 3), only toward
    samples on its side (:func:`direct_irradiance`). ``first`` (k,) or None: these samples'
    rays first; a point whose k rays all pass (or all are blocked) takes that for the rest
    uncast (:func:`.transmit.first_visible`)."""
    N, S = w.shape
    # no attenuation (None): a factor of 1, left out (w * 1 is w, bit for bit)
    a = atten
    if facing is not None:
        up = np.einsum("nsc,nc->ns", pts if infinite else pts - x[:, None], facing) > 0
        a = (np.ones_like(w) if a is None else a) * up
    wsum = w.sum(axis=1)
    if occ is None:
        num = (w if a is None else w * a).sum(axis=1)
    else:
        need = (E0 > 0)[:, None] & (w > 0)
        if a is not None:
            need &= a > 0
        r, s = np.nonzero(need)
        v = np.zeros((N, S))
        if r.size:
            # each point's start once, then one row per ray (the same values as per ray)
            org = (x + eps[:, None] * n)[r]
            d, tf = (pts[r, s], None) if infinite else (pts[r, s] - org, np.full(r.size, 1.0 - 1e-4))
            v[r, s] = visibility(occ, org, d, tf) if first is None else \
                first_visible(occ, org, d, tf, r, np.isin(s, first), N, len(first))
        num = (v * w if a is None else v * w * a).sum(axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(wsum > 0, E0 * num / wsum, 0.0)


def sun_first(samples):
    """(c,) the samples of a sun's m x c stratified pattern (:func:`.sampling.stratified_unit_square`,
    m = floor(sqrt samples) >= :data:`SUN_FIRST`) cast first: its outer row, the disk's rim, one
    in each of c sectors; None with fewer samples. The sun's disk is half a degree: a point is
    lit or shadowed by all of it but in a thin penumbra, where an edge across the disk parts
    the rim's rays (an edge between two of them cuts off a sliver)."""
    m = int(np.floor(np.sqrt(samples)))
    if m < SUN_FIRST:
        return None
    c = samples // m
    return (m - 1) * c + np.arange(c)


def _area_weights(x, n, pts, light_n, v=None):
    """Unshadowed integrand per area sample: cos_receiver+ |cos_light| / t^2 (``v``: ``pts - x``
    when the caller has it)."""
    v = pts - x[:, None] if v is None else v
    t2 = np.einsum("nsc,nsc->ns", v, v)
    t = np.sqrt(t2)
    cr = np.maximum(np.einsum("nsc,nc->ns", v, n), 0.0) / t
    ln = light_n if light_n.ndim == 3 else light_n[:, None]
    cl = np.abs(np.einsum("nsc,nsc->ns", v, np.broadcast_to(ln, v.shape))) / t
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(t2 > 0, cr * cl / t2, 0.0)


def _point_like(light, x, n, rng, samples, occ, eps, facing=None):
    """Point and spot lights (irradiance per unit of color)."""
    P, r, c = light.power_w, light.radius, light.position
    spot = isinstance(light, SpotLight)
    v = c - x
    d2 = np.einsum("ij,ij->i", v, v)
    d = np.sqrt(d2)
    if r == 0:
        cos_r = np.maximum(np.einsum("ij,ij->i", v, n), 0.0) / d
        E0 = P * cos_r / (4 * np.pi * d2)
        a = None
        if spot:
            a = spot_attenuation(-(v @ light.direction) / d, light.spot_size, light.spot_blend)[:, None]
        return _shade(x, n, E0, c[None, None, :] + 0 * x[:, None], np.ones((len(x), 1)), a, occ, eps,
                      facing=facing)
    L = P / (4 * np.pi ** 2 * r * r)                    # radiance of the light's surface
    towards = -v / d[:, None]                            # unit, light -> receiver
    if light.soft_falloff:
        dc, dr = np.broadcast_to(c, x.shape), np.full(len(x), r)
    else:                                                # sphere: its silhouette disk
        dd = np.maximum(d, r * (1 + 1e-9))
        dc = c + (r * r / dd)[:, None] * towards
        dr = r * np.sqrt(1.0 - (r / dd) ** 2)
    E0 = L * np.pi * polygon_form_factor(x, n, disk_polygons(dc, towards, dr))
    pts = disk_samples(stratified_unit_square(rng, len(x), samples), dc, towards, dr)
    w = _area_weights(x, n, pts, towards)
    a = None
    if spot:
        dv = x[:, None] - pts
        cosang = np.einsum("nsc,c->ns", dv, light.direction) / np.linalg.norm(dv, axis=-1)
        a = spot_attenuation(cosang, light.spot_size, light.spot_blend)
    return _shade(x, n, E0, pts, w, a, occ, eps, facing=facing)


def _sun(light, x, n, rng, samples, occ, eps, facing=None):
    to_sun = -light.direction
    if light.angle == 0:
        E0 = light.strength * np.maximum(n @ to_sun, 0.0)
        return _shade(x, n, E0, np.broadcast_to(to_sun, (len(x), 1, 3)), np.ones((len(x), 1)),
                      None, occ, eps, infinite=True, facing=facing)
    h = 0.5 * light.angle
    L = light.strength / (np.pi * np.sin(h) ** 2)
    # the sun as a disk at unit distance from each receiver: same solid angle, same radiance
    dc = x + to_sun
    m = np.broadcast_to(-to_sun, x.shape)
    dr = np.full(len(x), np.tan(h))
    # the disk at the same offsets from every receiver: its form factor in closed form where it
    # is wholly above the horizon (0 wholly below), clipped to it only where it crosses it
    # (:func:`.distant_form_factor`)
    F, settled = distant_form_factor(n, disk_polygons(to_sun[None], -to_sun[None], np.full(1, np.tan(h)))[0])
    cut = np.flatnonzero(~settled)
    if cut.size:
        F[cut] = polygon_form_factor(x[cut], n[cut], disk_polygons(dc[cut], m[cut], dr[cut]))
    E0 = L * np.pi * F
    u = stratified_unit_square(rng, len(x), samples)     # every row's draws, lit or not: the same stream
    # the disk's samples only where it is above the horizon: a row with E0 = 0 casts no ray and
    # is 0 (exactly what _shade makes of it); half a scene's receivers face away from the sun
    lit = np.flatnonzero(E0 > 0)
    out = np.zeros(len(x))
    if lit.size:
        x, n, m = x[lit], n[lit], m[lit]
        # the disk's frame once: every receiver's disk faces the same way
        pts = disk_samples(u[lit], dc[lit], m[:1], dr[lit])
        v = pts - x[:, None]
        w = _area_weights(x, n, pts, m, v)
        dirs = v / np.linalg.norm(v, axis=-1, keepdims=True)
        out[lit] = _shade(x, n, E0[lit], dirs, w, None, occ, eps[lit], infinite=True,
                          facing=None if facing is None else facing[lit], first=sun_first(samples))
    return out


def _area(light, x, n, rng, samples, occ, eps, facing=None):
    A = light.area
    if A == 0 or light.power_w == 0:
        return np.zeros(len(x))
    c, au, lu, av, lv, emit = light.frame()
    L = light.power_w / (np.pi * A)
    front = (x - c) @ emit > 0                           # one-sided: only the emitting side
    E0 = np.zeros(len(x))
    if front.any():
        E0[front] = L * np.pi * polygon_form_factor(x[front], n[front], light.polygon())
    u = stratified_unit_square(rng, len(x), samples)
    if light.ellipse:
        r, phi = 0.5 * np.sqrt(u[..., 0]), 2 * np.pi * u[..., 1]
        su, sv = r * np.cos(phi), r * np.sin(phi)
    else:
        su, sv = u[..., 0] - 0.5, u[..., 1] - 0.5
    pts = c + (su * lu)[..., None] * au + (sv * lv)[..., None] * av
    w = _area_weights(x, n, pts, np.broadcast_to(emit, x.shape))
    return _shade(x, n, E0, pts, w, None, occ, eps, facing=facing)


# light type -> kernel(light, x (P,3), n (P,3), rng, samples, occluder|None, eps (P,), facing=None) -> (P,) W/m^2
# ((P, 3) for a light of its own colours: ``bands == 3``, the environment map)
KERNELS = {PointLight: _point_like, SpotLight: _point_like, SunLight: _sun, AreaLight: _area,
           EnvironmentLight: environment_irradiance}
# lights without a finite power: counted by what they deliver (the energy balance)
UNBOUNDED = (SunLight, EnvironmentLight)


def light_irradiance(patches: PatchSet, light, *, shadows="auto", samples=16, seed=0,
                     receivers=None, points=None, normals=None, eps=None, facing=None, workers=1, _occ=None,
                     _index=0):
    """Irradiance (P,) W/m^2 per unit of the light's colour (multiply by ``light.color``);
    (P, 3) for a light with its own colours (``light.bands == 3``: an environment map).

    At the patch centres by default, or at ``points`` (P, 3) with unit ``normals`` (P, 3) on the
    patches' surfaces (e.g. the patch vertices); ``receivers`` indexes into those points.
    ``eps`` (P,): the shadow rays' start offsets (default :func:`.rays.ray_offsets`);
    ``facing`` (P, 3) or None: as :func:`direct_irradiance`. ``workers`` (0 = every core): threads
    lighting chunks of :data:`RECEIVERS_PER_CHUNK` receivers at once (Embree lets go of the GIL
    while it casts, NumPy in its large steps); each chunk draws from its own random stream, so
    the result is the same, bit for bit, for any count.
    """
    occ = occluder(patches, shadows) if _occ is None else _occ
    x_all = patches.centers if points is None else np.asarray(points, np.float64)
    n_all = patches.normals if points is None else np.asarray(normals, np.float64)
    N = len(x_all)
    recv = np.arange(N) if receivers is None else np.asarray(receivers, np.int64)
    out = np.zeros((N, 3) if getattr(light, "bands", 1) == 3 else N)
    eps = ray_offsets(patches, points, normals) if eps is None else np.asarray(eps, np.float64)
    fn = KERNELS.get(type(light))
    if fn is None:
        raise TypeError(f"unknown light type {type(light).__name__}")
    samples = max(1, int(samples))
    starts = range(0, len(recv), RECEIVERS_PER_CHUNK)
    workers = resolve_workers(workers) if len(starts) > 1 else 1
    if workers > 1 and occ is not None and len(recv):
        occ.occluded(x_all[:1], n_all[:1])   # commit the scene before threads share it

    def chunk(s):
        ids = recv[s:s + RECEIVERS_PER_CHUNK]
        # one random stream per (seed, light, chunk start): reproducible for a given receiver set
        rng = np.random.default_rng([seed, _index, s])
        # a light with Blender's 'Shadow' switch off shines through everything
        kw = {} if facing is None else {"facing": np.asarray(facing, np.float64)[ids]}
        out[ids] = fn(light, x_all[ids], n_all[ids], rng, samples,
                      occ if light.cast_shadows else None, eps[ids], **kw)
    for _ in ordered_map(chunk, starts, workers):
        pass
    return out


def direct_irradiance(patches: PatchSet, lights, *, shadows="auto", samples=16, seed=0,
                      receivers=None, points=None, normals=None, eps=None, progress=None,
                      cancelled=None, facing=None, workers=1) -> np.ndarray:
    """Incident irradiance H_direct (N, 3) in W/m^2 from ``lights`` at every patch centre
    (or at ``points`` with ``normals``, see :func:`light_irradiance`).

    The radiosity source term is ``emission + rho * H_direct / pi`` (radiance units).
    ``shadows``: 'auto' | 'embree' | 'numpy' | 'none'. ``samples``: shadow samples per light per
    patch for lights with a size (radius, angle, area); zero-size lights use one ray.
    ``receivers``: patch ids to compute (others 0); ``eps`` (P,) the shadow rays' start offsets
    (default :func:`.rays.ray_offsets`). ``progress(f)``/``cancelled()`` as elsewhere.
    ``facing`` (P, 3) or None: light arrives only from directions d with d . facing > 0 (a
    point's own triangle's normal where its shading normal leans off it: Cycles blocks light
    from below the triangle's plane, :mod:`..output.crease`). ``workers``: as
    :func:`light_irradiance` (the same result for any count).
    """
    lights = list(lights)
    H = np.zeros((len(patches) if points is None else len(points), 3))
    if not lights:
        return H
    occ = occluder(patches, shadows)
    eps = ray_offsets(patches, points, normals) if eps is None else eps
    ticker = Ticker(progress, cancelled)
    for i, light in enumerate(lights):
        ticker.tick(i, len(lights), force=True)
        E = light_irradiance(patches, light, shadows=shadows, samples=samples, seed=seed,
                             receivers=receivers, points=points, normals=normals, eps=eps, facing=facing,
                             workers=workers, _occ=occ,
                             _index=i)
        H += (E if E.ndim == 2 else E[:, None]) * light.color[None, :]
    ticker.tick(len(lights), len(lights), force=True)
    return H
