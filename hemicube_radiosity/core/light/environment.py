"""The world's light by direction: an environment map (an HDRI) as a light.

A constant world is exact everywhere already: its radiance times the part of each point's
hemisphere where rays find no surface (:func:`..hemisphere.sky_fraction`), in the direct light, the
form factors' sky term and the gather. A map is a constant (its solid-angle median,
:meth:`EnvironmentLight.base`, which the reader hands on as the world) **plus its variation
about it**, and only the variation is this light: the sun spot of an HDRI, the sky's gradient,
the dark ground below. So the constant keeps every path it had, and the variation (which is
where the shadows come from) arrives directly at every patch point and output vertex like a
lamp's light, through shadow rays.

The variation's integral over a point's hemisphere, ``E(x) = int dL(w) V(x, w) max(0, n.w) dw``
(W/m^2, per band), is estimated with directions drawn in proportion to ``|dL| dw`` (the map's
pixels by their luminance's departure from the mean, times their solid angle): a sun spot gets
its share of the rays, however small it is. The directions are one fixed, stratified set for
every point (as the sky's lattice is), so neighbouring points see the same rays and the light is
smooth over a surface; the estimate is unbiased over the set's random shift.

That sameness is also what its error looks like: a point sees the sky through a window in only a
few of the set's directions, and every point of a surface through the same few, so a surface is
too bright or too dark all over by which directions its window happened to hold. Hence
:data:`RAYS_PER_SKY_RAY` directions per Sky Ray (most end on a wall a few metres off: cheap
shadow rays). Measured on the grey-and-white room of the real-scene bench (a furnished room lit
by an overcast HDRI through four windows), relative RMS against Cycles 256 spp (Cycles 64 spp:
37.7%): 256 directions with half of them on the peaks 39.7% (its cushions +19% and -14%, its
window alcoves +29% and +26%), the peaks at their share 38.3%, and 1,024 directions 35.1% (CPU
51 -> 111 s); under a sun, the sun's shadow is sharper for it too.

Map convention (Cycles' equirectangular, Blender's image rows bottom-up): ``u = 0.5 -
atan2(y, x) / 2 pi``, ``v = 0.5 + asin(z) / pi`` of the direction ``R d`` in the map's frame
(``rotation``: a Mapping node's, world -> map); +X is the image's centre column, +Z its top row.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..util.colour import LUMA
from .transmit import visibility

__all__ = ["EnvironmentLight", "equirect_uv", "environment_irradiance", "MAX_MAP_WIDTH", "RAYS_PER_SKY_RAY"]

PEAK = 20.0             # a pixel this many times the base's luminance is a peak (a sun)
MAX_MAP_WIDTH = 512      # maps are averaged down to at most this width (a 4k HDRI: 8 x 8 pixels each)
RAYS_PER_SKY_RAY = 4     # the set's directions per Sky Ray of the bake (module docstring)


def equirect_uv(d: np.ndarray) -> tuple:
    """(u, v) in [0, 1) x [0, 1] of unit directions ``d`` (..., 3) on an equirectangular map."""
    u = (0.5 - np.arctan2(d[..., 1], d[..., 0]) / (2 * np.pi)) % 1.0
    v = 0.5 + np.arcsin(np.clip(d[..., 2], -1.0, 1.0)) / np.pi
    return u, v


def _downsampled(px: np.ndarray, width: int) -> np.ndarray:
    """``px`` (H, W, 3) averaged down by a whole factor to at most ``width`` columns (energy and
    mean kept: each pixel of the result is the mean of its block)."""
    H, W, _ = px.shape
    k = max(1, int(np.ceil(W / width)))
    if k == 1:
        return px
    h, w = H // k, W // k
    if h == 0:
        return px.mean(axis=(0, 1), keepdims=True)
    return px[:h * k, :w * k].reshape(h, k, w, k, 3).mean(axis=(1, 3))


@dataclass
class EnvironmentLight:
    """An equirectangular environment map as a light: its variation about its mean (module
    docstring). ``pixels`` (H, W, 3) radiance, rows bottom-up as Blender stores them (strength
    included); ``rotation`` (3, 3) world -> map directions. ``color`` is white (the map has its
    own colours: :func:`environment_irradiance` gives (P, 3)); ``power_w`` 0 and
    ``cast_shadows`` as lamps have them."""

    pixels: np.ndarray
    rotation: np.ndarray = field(default_factory=lambda: np.eye(3))
    color: np.ndarray = field(default_factory=lambda: np.ones(3))
    power_w: float = 0.0
    cast_shadows: bool = True
    name: str = "world"
    rays: int = 256                    # directions per point (the bake: RAYS_PER_SKY_RAY x Sky Rays)
    bands: int = 3                     # light_irradiance gives (P, 3), not (P,) x color

    def __post_init__(self):
        px = np.asarray(self.pixels, dtype=np.float64)
        if px.ndim != 3 or px.shape[2] < 3 or px.shape[0] < 1 or px.shape[1] < 1:
            raise ValueError(f"environment pixels must be (H, W, 3), got {px.shape}")
        px = np.where(np.isfinite(px[..., :3]), np.maximum(px[..., :3], 0.0), 0.0)
        self.pixels = _downsampled(px, MAX_MAP_WIDTH)
        self.rotation = np.asarray(self.rotation, dtype=np.float64).reshape(3, 3)
        H, W, _ = self.pixels.shape
        lat = (np.arange(H) + 0.5) / H * np.pi - np.pi / 2                  # bottom row first
        # solid angle of each pixel: (2 pi / W) * (pi / H) * cos(latitude), summing to 4 pi
        self._omega = np.repeat((2 * np.pi / W) * (np.pi / H) * np.cos(lat)[:, None], W, axis=1)
        self._omega *= 4 * np.pi / self._omega.sum()

    def mean(self) -> np.ndarray:
        """(3,) the map's solid-angle mean radiance."""
        return (self.pixels * self._omega[..., None]).sum(axis=(0, 1)) / (4 * np.pi)

    def base(self) -> np.ndarray:
        """(3,) the constant world this light is the variation of: the map's solid-angle median,
        per band. Any constant would do (constant + variation is the map); the median leaves the
        least variation to sample, so a sun's rays are not spent on a sky that its own energy
        would otherwise lift the mean far above (under a Sky Texture's sun, the mean is 5x the
        sky's own radiance, and the sky in a shadow would be a small difference of large
        estimates)."""
        out = np.empty(3)
        w = self._omega.ravel()
        for k in range(3):
            v = self.pixels[..., k].ravel()
            o = np.argsort(v, kind="stable")
            c = np.cumsum(w[o])
            out[k] = v[o][min(np.searchsorted(c, 0.5 * c[-1]), v.size - 1)]
        return out

    def radiance(self, d: np.ndarray) -> np.ndarray:
        """(..., 3) the map's radiance towards world directions ``d`` (..., 3) (nearest pixel)."""
        H, W, _ = self.pixels.shape
        u, v = equirect_uv(np.asarray(d, float) @ self.rotation.T)
        i = np.clip((v * H).astype(np.int64), 0, H - 1)
        j = np.clip((u * W).astype(np.int64), 0, W - 1)
        return self.pixels[i, j]

    def directions(self, n: int, seed: int = 0) -> tuple:
        key = (int(n), int(seed))
        memo = self.__dict__.setdefault("_memo", {})
        if key not in memo:
            memo[key] = self._directions(*key)
        return memo[key]

    def _directions(self, n: int, seed: int = 0) -> tuple:
        """(dirs (n, 3) world, weight (n, 3)): ``n`` stratified directions drawn in proportion to
        ``|L - base| dw`` and each one's share of the variation's integral, so that
        ``sum_k weight_k f(d_k)`` estimates ``int (L - base)(w) f(w) dw`` for any ``f``."""
        base = self.base()
        dL = self.pixels - base
        mass = (np.abs(dL @ LUMA) * self._omega).ravel()
        if not mass.sum() > 0:
            return np.zeros((0, 3)), np.zeros((0, 3))
        H, W = self._omega.shape
        # two strata: the peaks (a sun: PEAK x the base's luminance and more) and the rest, half
        # the directions each, so a sun's energy does not leave the sky a handful of rays (under
        # a Sky Texture, the sky in the box's shadow was 10% off at 256 rays, 2% at 1,024)
        peak = (self.pixels @ LUMA).ravel() > PEAK * max(float(base @ LUMA), 1e-12)
        parts = [m for m in (np.where(peak, mass, 0.0), np.where(peak, 0.0, mass)) if m.sum() > 0]
        # ... but no more than their share of the variation either: bright clouds over an
        # overcast sky (1% of the sphere, 6% of the variation) took half the directions from the
        # sky that lit a room through its windows
        counts = [n]
        if len(parts) == 2:
            f = parts[0].sum() / mass.sum()
            first = n - n // 2 if f >= 0.5 else min(max(1, int(round(n * f))), n - 1)
            counts = [first, n - first]
        share = np.zeros(H * W)                    # the mixture's probability of each pixel
        rng = np.random.default_rng(seed)
        ks = []
        for q, m in enumerate(parts):
            cnt = counts[q]
            share += m / m.sum() * (cnt / n)
            cdf = np.cumsum(m) / m.sum()
            u = (np.arange(cnt) + rng.uniform()) / cnt                       # stratified in the cdf
            ks.append(np.minimum(np.searchsorted(cdf, u, side="right"), H * W - 1))
        k = np.concatenate(ks)
        i, j = np.divmod(k, W)
        jit = rng.uniform(size=(n, 2))
        lon = 2 * np.pi * (0.5 - (j + jit[:, 0]) / W)                        # the inverse of equirect_uv
        lat = np.pi * ((i + jit[:, 1]) / H - 0.5)
        local = np.stack([np.cos(lat) * np.cos(lon), np.cos(lat) * np.sin(lon), np.sin(lat)], -1)
        dirs = local @ self.rotation                                         # map -> world
        # estimator weight: dL / (n pdf), pdf = share_k / omega_k per steradian
        w = dL[i, j] * (self._omega[i, j] / (n * share[k]))[:, None]
        return dirs, w


def environment_irradiance(light: EnvironmentLight, x, n, rng, samples, occ, eps, facing=None) -> np.ndarray:
    """(P, 3) W/m^2: the map's variation about its base arriving at points ``x`` (P, 3) with unit
    normals ``n`` (P, 3), through shadow rays (``occ``: an occluder or None) starting ``eps``
    (P,) off the surface; ``facing`` (P, 3) or None: only from directions on its side (as
    :func:`.lamps.direct_irradiance`). ``light.rays``
    directions per point, one set for all (module docstring); ``rng`` and ``samples`` are the
    lamps' (unused: the set is fixed by the map, for smooth light)."""
    d, w = light.directions(light.rays, seed=0)
    out = np.zeros((len(x), 3))
    if not len(d):
        return out
    cos = n @ d.T                                                            # (P, R)
    r, s = np.nonzero((cos > 0) if facing is None else (cos > 0) & (facing @ d.T > 0))
    if not r.size:
        return out
    if occ is None:
        vis = np.ones(r.size, bool)
    else:
        vis = visibility(occ, x[r] + eps[r, None] * n[r], d[s], None)
    c = np.where(vis, cos[r, s], 0.0) if vis.dtype == bool else vis * cos[r, s]
    for k in range(3):
        out[:, k] = np.bincount(r, weights=c * w[s, k], minlength=len(x))
    return out
