"""The bake's estimated error: how far its vertex values are from the converged answer.

With ``settings.estimate_error`` the ``estimate`` stage runs the output stage twice more on the
same patch solution and measures how much the answer moves:

* **noise**: the final gather again with half the rays (another ray pattern). Two independent
  estimates with ``n`` and ``n / 2`` rays differ with ``3`` times the variance of the first,
  so the noise is their RMS difference over sqrt(3).
* **detail** (an output cut to a detail size ``h``): the output again at ``2 h``, interpolated to
  the vertices at ``h``. Where the light is smooth, linear interpolation converges as ``h^2``,
  so the error at ``h`` is a third of the change (Richardson, ``p = 2``). When the output is the
  user's own faces (finer than the detail size) there is no coarser output: noise only, and the
  report says so.

``error = hypot(noise, detail)``, a relative RMS like the bench's: luminance-weighted RMS over the
output vertices that do not emit and that the scene sees (not a floor under a block), over their
mean luminance. It is an estimate, not a bound:
``bench/speed_vs_error.py`` sets it beside the error measured against Cycles on each scene, and
where the coarser output goes wrong in a way the finer one does not (a lamp's back-lit ceiling
smeared across elements twice as wide), it overestimates.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, replace

import numpy as np

from ..light.emitters import vertex_frames
from ..util.colour import LUMA
from .interpolate import interpolate_located, locate
from .abrupt import abrupt_elements
from .sides import open_elements, seen_vertices
from .stage import vertex_stage
from ..rays import embree_available

__all__ = ["ErrorEstimate", "estimate_stage", "relative_rms"]


@dataclass(frozen=True)
class ErrorEstimate:
    """``error``: the estimated relative RMS error of the vertex values (0.02 = 2%), from its
    two parts: ``noise`` (the final gather's sampling noise) and ``detail`` (the output's
    discretisation; 0 when the output is the user's own faces: ``method`` 'rays', else
    'detail'); ``vertices``: how many output vertices it is measured over; ``seconds``: what
    the extra bakes cost."""

    error: float
    noise: float
    detail: float
    method: str
    vertices: int
    seconds: float

    def as_dict(self) -> dict:
        return {"error": self.error, "noise": self.noise, "detail": self.detail, "method": self.method,
                "vertices": self.vertices, "seconds": self.seconds}

    def describe(self) -> str:
        if self.method == "rays":
            return (f"estimated error {100 * self.error:.1f}% (sampling noise only: the output is "
                    "the meshes' own faces)")
        return (f"estimated error {100 * self.error:.1f}% (noise {100 * self.noise:.1f}%, detail "
                f"{100 * self.detail:.1f}%)")


def relative_rms(a, b, mask=None) -> float:
    """Luminance-weighted RMS of ``a - b`` (V, 3) over the mean luminance of ``b``, over ``mask``."""
    ya = np.asarray(a, dtype=np.float64) @ LUMA
    yb = np.asarray(b, dtype=np.float64) @ LUMA
    if mask is not None:
        ya, yb = ya[mask], yb[mask]
    if ya.size == 0:
        return 0.0
    mean = float(np.abs(yb).mean())
    return float(np.sqrt(np.mean((ya - yb) ** 2)) / mean) if mean > 0 else 0.0


def _lit_vertices(elements, opened=None) -> np.ndarray:
    """(V,) bool: vertices of at least one element that does not emit and that the scene sees
    (``opened`` (N,) > 0, :func:`.sides.open_elements`; None: every element): a floor under a
    block is nobody's error."""
    keep = np.zeros(len(elements.verts), bool)
    dark = elements.emission.max(axis=1) <= 0
    if opened is not None:
        dark &= np.asarray(opened) > 0
    p = elements.polys[dark]
    keep[p[p >= 0]] = True
    return keep


def _vertex_owner(elements) -> np.ndarray:
    owner = np.zeros(len(elements.verts), np.int64)
    for c in range(elements.polys.shape[1]):
        on = elements.polys[:, c] >= 0
        owner[elements.polys[on, c]] = elements.owner[on]
    return owner


def _again(ctx, **changes):
    """The vertex stage again on ``ctx``'s solution with ``changes`` to the settings: (elements,
    (V, 3) vertex values)."""
    other = replace(ctx, settings=replace(ctx.settings, **changes), elements=None, vertex_radiosity=None,
                    notes=[], progress=None)
    vertex_stage(other)
    return other.elements, other.vertex_radiosity


def estimate_stage(ctx) -> None:
    """Fill ``ctx.error_estimate`` (:class:`ErrorEstimate`) when ``settings.estimate_error``; a
    note says why when there is nothing to estimate with (no detail size)."""
    s = ctx.settings
    if not getattr(s, "estimate_error", False) or ctx.vertex_radiosity is None:
        return
    if not s.uses_elements():
        ctx.notes.append("no error estimate: it needs a detail size (output elements) to bake again "
                         "coarser")
        return
    t = time.perf_counter()
    fine, X = ctx.elements, ctx.vertex_radiosity
    mask = _lit_vertices(fine, open_elements(ctx, fine)) & seen_vertices(ctx, fine)
    ctx.say(0.0, "estimating the error: sampling noise")
    noise = detail = 0.0
    if s.gather_rays >= 2 and embree_available():
        # two independent gathers, of n and n / 2 rays: var(X_n - X_n/2) = 3 var(X_n) (the sky's
        # rays halved too: where the gather finds the world they are its rays, :mod:`.indirect`)
        _, Y = _again(ctx, gather_rays=s.gather_rays // 2, sky_rays=max(1, s.sky_rays // 2))
        noise = relative_rms(Y, X, mask) / np.sqrt(3.0)
    method = "rays"
    ctx.say(0.5, "estimating the error: the output at twice the detail size")
    coarse, Y = _again(ctx, element_size=2.0 * float(s.element_size))
    if coarse.geometry_key() != fine.geometry_key():      # else the meshes' own faces both times
        xv, nv, _ = vertex_frames(fine)
        idx, uv = locate(coarse, xv, _vertex_owner(fine), nv)
        smooth = ~abrupt_elements(coarse, Y)[idx]
        Y = interpolate_located(coarse, Y, idx, uv)
        # interpolation converges as h^2 where the light is smooth: the error at h is a third
        # of the change from 2 h (Richardson, p = 2). Not where it is not: inside a coarse
        # element whose corners' light differs 2x or more (a lamp's back-lit ring on a ceiling,
        # a shadow's edge) the change measures the coarse interpolation's own error, which the
        # output at h does not make (it reads such elements on a grid): 150% estimated against
        # 1.1% measured on the bench's Cornell box, 20% against 3% in its room
        detail = relative_rms(Y, X, mask & smooth) / 3.0
        method = "detail"
    ctx.error_estimate = ErrorEstimate(float(np.hypot(noise, detail)), float(noise), float(detail), method,
                                       int(mask.sum()), time.perf_counter() - t)
