# SPDX-License-Identifier: GPL-3.0-or-later
"""Which triangle of a UV map each texel centre of an image lies in (:func:`rasterize`), for
:mod:`.lightmap`; and which triangles have no area in the world (:func:`flat_triangles`).

Image convention as :mod:`.lightmap`'s: (H, W) arrays, row 0 at v = 0, texel (r, c) centred at
uv ((c + 0.5) / W, (r + 0.5) / H).
"""
from __future__ import annotations

import numpy as np

from ..util.unique import run_positions

__all__ = ["rasterize", "edge_distances", "flat_triangles", "REACH"]

REACH = 0.75       # texels: a centre this close to a triangle (outside it) still takes its value
_CHUNK = 4_000_000  # candidate texels rasterized at once


def edge_distances(uvp, a, b, c):
    """(n, 3) signed distances of points ``uvp`` (n, 2) to the three edges of triangles a, b, c
    (n, 2) each, positive inside, in the units of the coordinates (texels); and (n, 3) the
    barycentric coordinates of the points (NaN for a degenerate triangle)."""
    def cross(p, q, r):
        return (q[:, 0] - p[:, 0]) * (r[:, 1] - p[:, 1]) - (q[:, 1] - p[:, 1]) * (r[:, 0] - p[:, 0])

    area = cross(a, b, c)
    sign = np.where(area < 0, -1.0, 1.0)
    w = np.stack([cross(b, c, uvp), cross(c, a, uvp), cross(a, b, uvp)], 1) * sign[:, None]
    lengths = np.stack([np.linalg.norm(c - b, axis=1), np.linalg.norm(a - c, axis=1),
                        np.linalg.norm(b - a, axis=1)], 1)
    with np.errstate(divide="ignore", invalid="ignore"):
        dist = w / lengths
        bary = w / np.abs(area)[:, None]
    return dist, bary


def rasterize(uv, width, height, reach=REACH, skip=None):
    """Which triangle each texel centre lies in.

    ``uv`` (T, 3, 2) the UV triangles (0..1 covers the image; outside it is left out, no
    wrapping). Returns ``tri`` (H, W) int64 (-1: no triangle within ``reach`` texels), ``bary``
    (H, W, 3) float64 barycentric coordinates of the texel centre in ``tri`` (clamped onto it when
    the centre lies outside: what the nearest point of the triangle reads), and ``inside``
    (H, W) bool (the centre lies inside ``tri``). Degenerate UV triangles (no area) are skipped,
    and so are the triangles ``skip`` (T,) bool marks (:func:`flat_triangles`)."""
    uv = np.asarray(uv, dtype=np.float64).reshape(-1, 3, 2)
    px = uv * np.array([width, height], float)            # texel units; centres at k + 0.5
    T = len(px)
    lo = np.ceil(px.min(axis=1) - reach - 0.5).astype(np.int64)    # first centre k + 0.5 >= min - reach
    hi = np.floor(px.max(axis=1) + reach - 0.5).astype(np.int64)   # last centre <= max + reach
    lo = np.maximum(lo, 0)
    hi = np.minimum(hi, [width - 1, height - 1])
    area2 = np.abs((px[:, 1, 0] - px[:, 0, 0]) * (px[:, 2, 1] - px[:, 0, 1])
                   - (px[:, 1, 1] - px[:, 0, 1]) * (px[:, 2, 0] - px[:, 0, 0]))
    nx = np.maximum(hi[:, 0] - lo[:, 0] + 1, 0)
    ny = np.maximum(hi[:, 1] - lo[:, 1] + 1, 0)
    count = np.where((area2 > 1e-12) & (True if skip is None else ~np.asarray(skip, bool)), nx * ny, 0)
    best = np.full(width * height, -np.inf)
    tri = np.full(width * height, -1, np.int64)
    bary = np.zeros((width * height, 3))
    start = 0
    while start < T:                                       # chunks of triangles, ~_CHUNK candidates each
        cum = np.cumsum(count[start:])
        stop = start + max(1, int(np.searchsorted(cum, _CHUNK, side="right")))
        ids = np.arange(start, min(stop, T))
        start = ids[-1] + 1
        n = count[ids]
        if n.sum() == 0:
            continue
        t = np.repeat(ids, n)
        k = run_positions(n)
        col = lo[t, 0] + k % nx[t]
        row = lo[t, 1] + k // nx[t]
        centre = np.stack([col + 0.5, row + 0.5], 1)
        dist, b = edge_distances(centre, px[t, 0], px[t, 1], px[t, 2])
        score = dist.min(axis=1)
        ok = score >= -reach
        t, col, row, score, b = t[ok], col[ok], row[ok], score[ok], b[ok]
        texel = row * width + col
        # the deepest triangle per texel (against the chunks before too)
        order = np.lexsort((score, texel))
        last = np.ones(order.size, bool)
        last[:-1] = texel[order][1:] != texel[order][:-1]
        pick = order[last]
        better = score[pick] > best[texel[pick]]
        pick = pick[better]
        best[texel[pick]] = score[pick]
        tri[texel[pick]] = t[pick]
        bary[texel[pick]] = b[pick]
    inside = best >= 0
    clamped = np.clip(bary, 0.0, None)
    clamped /= np.where(clamped.sum(1) > 0, clamped.sum(1), 1.0)[:, None]
    bary = np.where(inside[:, None], bary, clamped)
    return tri.reshape(height, width), bary.reshape(height, width, 3), inside.reshape(height, width)


def flat_triangles(world, dtype=np.float64) -> np.ndarray:
    """(T,) bool: the triangles ``world`` (T, 3, 3) without area, their edges parallel within
    float32 rounding (two corners at one place, three in a line: a bevel's collapsed corner).
    Their texels measure no point of the surface (Cycles shades them with a NaN normal: the sun
    alone through the corners' normals, no sky, no bounce); :func:`bake_lightmap` leaves them to
    the triangles beside them and the dilation, so no dark texel borders a lit one. ``dtype``:
    of the arithmetic (float32: Cycles' own, as the real-scene bench judges its bake points)."""
    w = np.asarray(world, dtype=dtype)
    e1, e2 = w[:, 1] - w[:, 0], w[:, 2] - w[:, 0]
    d11, d12, d22 = (e1 * e1).sum(1), (e1 * e2).sum(1), (e2 * e2).sum(1)
    return d11 * d22 - d12 * d12 <= 4 * np.finfo(np.float32).eps * d11 * d22
