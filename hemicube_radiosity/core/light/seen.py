"""The direct light a receiver sees on a grouped source whose pieces are lit unevenly.

The solve has one unknown per cluster of pieces (:mod:`..mesh.clusters`), and every receiver
reads a cluster's one value: its direct light is a mean over a few points of its pieces
(:func:`.points.stand_ins`, the pieces' centres). Where that light varies across the cluster
and a receiver sees only part of it, the mean is not what the receiver sees. A candle's top in
../shared/scenes' staircase hall is a disc modelled as a fan of 32 triangles, lit at its rim
and dark under the flame that stands on it: the flame's underside, 3 mm above the lit rim,
sees the rim; the wick's cap over the centre sees the dark middle. The centroids all lie at
two thirds of the radius, in the flame's shadow (reflected direct light 0.044); the flames'
undersides read 0.61 where Cycles has 0.84. Lit over the pieces' whole area instead (the disc's
mean), the caps over the dark centre read 0.51 where Cycles has 0.17, and the staircase's error
grew (22.8% -> 25.2% RMS): no one value of the cluster serves both receivers.

Here, for each receiver that sees much of such a cluster (a form factor of at least
:data:`F_MIN` to a grouped, non-emitting cluster whose reflected direct light, sampled at one
point spread over each of its stand-in pieces, varies by a coefficient of variation of at least
:data:`VARIES`), cosine rays from points spread over the receiver's pieces find the points of
the cluster it sees, and what they find of the direct light reflected there replaces the
cluster's mean in what the receiver gathers first: its source gains rho_r (sum over the hits of
w rho D - F_rc times the cluster's reflected direct light), a hit's weight w its point's share
of the receiver's area over its rays. The rays, leaving points over the whole receiver, also
stand for the form factor where one eye point (:mod:`..mesh.clusters`) sees the cluster
otherwise than the receiver's area does. The light reflected more than once still comes from
the cluster's one value. The gain is negative where a receiver sees the dark part of a cluster
(a trim pressed to a wall sees the wall in its own shadow): the solve takes such a source as
its two signed parts (:func:`..solve.stage._signed`). Radiance units; world space.
"""
from __future__ import annotations

import numpy as np

from ..rays import embree_available, embree_scene, ray_offsets
from ..runtime.cache import array_key, cache_key, cached, geometry_key
from ..util.geometry import tangent_frames
from ..util.sampling import cosine_directions
from ..util.colour import LUMA

__all__ = ["F_MIN", "VARIES", "seen_direct"]

#: The least form factor from a receiver to a cluster for which its view of the cluster is
#: found by rays: below it the cluster's part in what the receiver gathers is small.
F_MIN = 0.2
#: The least coefficient of variation of a cluster's reflected direct light over its spread
#: points (area-weighted) for which receivers see its parts rather than its mean: a cluster
#: lit over a share s of its area and dark elsewhere has sqrt((1 - s) / s), 1 at s = 0.5. At
#: 0.5 the generated terrain's sunlit slopes counted too (up to 0.92), for noise (its RMS
#: error 0.199% -> 0.201%); at 1.0 it bakes as before, bit for bit, and the staircase keeps
#: nine tenths of the gain (22.80% -> 21.12%, against 20.92% at 0.5).
VARIES = 1.0
#: Cosine rays per receiver, shared among its points (at least :data:`PER_POINT` each), which
#: are its stand-in pieces (:func:`.points.stand_ins`), each at a point spread over it, and at
#: least :data:`MIN_POINTS` of them (a receiver of few pieces: several points on each).
RAYS = 256
PER_POINT = 4
MIN_POINTS = 4
#: Shadow rays per point toward each emitter (the means are over many points).
SAMPLES = 2
#: The hits share the world's sky rays out (:meth:`.direct.DirectLight.at`'s ``split``): each
#: casts this share of them, the hits of one pair all of them between them. The sky's rays
#: were nine tenths of this stage's time in godot_zdm2 (5.1 of 5.6 s).
SKY_SPLIT = 16
#: The steps of the spread points' two parameters from one piece to the next (golden ratio's
#: and the plastic number's: irrational, so a run of pieces covers its whole square).
STEPS = (0.6180339887498949, 0.7548776662466927)


def spread_points(patches, rows, index=None) -> np.ndarray:
    """(M, 3) one point on each patch ``rows`` (M,) int: the ``index``-th (default the row's)
    point of a low-discrepancy sequence in the piece's parameter square (within 90% of it),
    mapped uniformly by area onto a triangle or bilinearly onto a quad. Congruent pieces (a
    fan's slivers) sample different places of their shape, as their centroids, all at one
    spot, do not."""
    i = np.asarray(rows if index is None else index, dtype=np.float64)
    u = 0.05 + 0.9 * np.mod(0.5 + i * STEPS[0], 1.0)
    v = 0.05 + 0.9 * np.mod(0.5 + i * STEPS[1], 1.0)
    q = patches.verts[patches.polys[rows]]                       # (M, 4, 3); a triangle's 4th: any
    tri = patches.polys[rows, 3] < 0
    s = np.sqrt(u)
    x_tri = (1 - s)[:, None] * q[:, 0] + (s * (1 - v))[:, None] * q[:, 1] + (s * v)[:, None] * q[:, 2]
    x_quad = (((1 - u) * (1 - v))[:, None] * q[:, 0] + (u * (1 - v))[:, None] * q[:, 1]
              + (u * v)[:, None] * q[:, 2] + ((1 - u) * v)[:, None] * q[:, 3])
    return np.where(tri[:, None], x_tri, x_quad)


def _stand_rows(clusters, stand, areas, which):
    """(rows (M,), cluster (M,), weight (M,)) of the stand-in pieces of the clusters ``which``
    (K,) bool, each weighted by the area of the pieces it stands for."""
    mine = which[clusters.of]
    w = np.bincount(stand[mine], weights=areas[mine], minlength=len(areas))
    rows = np.flatnonzero(w > 0)
    return rows, clusters.of[rows], w[rows]


def _varying(ctx, sources, stand):
    """(K,) bool: the clusters of ``sources`` whose reflected direct light, at one spread
    point on each stand-in piece, varies by at least :data:`VARIES` (coefficient of variation)."""
    p, c = ctx.patches, ctx.clusters
    K = len(c)
    which = np.zeros(K, bool)
    which[sources] = True
    rows, k, w = _stand_rows(c, stand, p.areas, which)
    x = spread_points(p, rows)
    eps = ray_offsets(p, owner=p.owner[rows])
    y = (p.rho[rows] * ctx.direct.at(x, p.normals[rows], "spread-points", samples=SAMPLES, eps=eps)) @ LUMA
    W = np.bincount(k, weights=w, minlength=K)
    mean = np.bincount(k, weights=w * y, minlength=K) / np.maximum(W, 1e-300)
    var = np.bincount(k, weights=w * (y - mean[k]) ** 2, minlength=K) / np.maximum(W, 1e-300)
    # rounded: a cluster of two equal pieces, one lit, sits on the threshold (exactly 1), where
    # rounding would decide, and a relight of the same light made brighter must pick the same
    cv = np.round(np.sqrt(var) / np.maximum(mean, 1e-300), 9)
    return which & (mean > 0) & (cv >= VARIES)


def seen_direct(ctx, stand) -> np.ndarray | None:
    """(K, 3) what each unknown's source gains (or loses) when the direct light it gathers
    first from a cluster lit unevenly is that of the part it sees (see the module docstring),
    or None where no receiver sees such a cluster. ``stand`` (N,) int (:func:`.points.stand_ins`)."""
    p, c, F = ctx.patches, ctx.clusters, ctx.form_factors
    if c is None or ctx.direct is None or not embree_available():
        return None
    K = len(c)
    rows = F.row_ids().astype(np.int64)
    cols = F.indices.astype(np.int64)
    grouped = (c.sizes > 1) & ~np.any(c.emission > 0, axis=1)
    pair = (F.data >= F_MIN) & grouped[cols] & (rows != cols)
    if not pair.any():
        return None
    pair[pair] = _varying(ctx, np.unique(cols[pair]), stand)[cols[pair]]
    if not pair.any():
        return None
    r_pair, c_pair, f_pair = rows[pair], cols[pair], F.data[pair].astype(np.float64)
    receivers = np.zeros(K, bool)
    receivers[r_pair] = True
    hx, hp, hr, hw = _cached_hits(ctx, *_receiver_points(c, stand, p.areas, receivers))
    key_pair = r_pair * K + c_pair
    key_hit = hr * K + c.of[hp]
    order = np.argsort(key_pair)
    at = np.searchsorted(key_pair[order], key_hit)
    at = np.minimum(at, len(order) - 1)
    on = key_pair[order][at] == key_hit                                # hits on a pair's cluster
    if not on.any():
        return None
    j = order[at[on]]                                                  # the pair each hit is on
    hx, hp, hw = hx[on], hp[on], hw[on]
    split = max(1, min(SKY_SPLIT, ctx.settings.sky_rays // 16))      # the world's rays shared out
    D = ctx.direct.at(hx, p.normals[hp], "seen-hits", samples=SAMPLES, eps=ray_offsets(p, owner=p.owner[hp]),
                      split=split, part=np.arange(len(hp)) % split)
    refl = p.rho[hp] * D
    seen = np.stack([np.bincount(j, weights=hw * refl[:, k], minlength=len(r_pair)) for k in range(3)], 1)
    # what the rays found of the cluster's direct light, for the form factor's share of its mean
    diff = seen - f_pair[:, None] * ctx.direct_source[c_pair]
    out = np.zeros((K, 3))
    for k in range(3):
        out[:, k] = np.bincount(r_pair, weights=diff[:, k], minlength=K)
    return c.rho * out


def _receiver_points(clusters, stand, areas, receivers):
    """(rows (M,) the piece of each point, index (M,) its place in the spread sequence,
    cluster (M,), weight (M,) its share of its cluster's area) of the points rays leave the
    clusters ``receivers`` (K,) bool from: one on each stand-in piece, repeated on a receiver
    of fewer than :data:`MIN_POINTS` of them (the sequence's next places)."""
    rows, k, w = _stand_rows(clusters, stand, areas, receivers)
    n = np.bincount(k, minlength=len(clusters))[k]
    m = -(-MIN_POINTS // n)                                            # points per piece
    rep = np.repeat(np.arange(len(rows)), m)
    j = np.arange(len(rep)) - np.repeat(np.cumsum(m) - m, m)          # 0 .. m-1 on each piece
    index = rows[rep] * MIN_POINTS + j
    w = w[rep] / m[rep]
    return rows[rep], index, k[rep], w / np.bincount(k[rep], weights=w, minlength=len(clusters))[k[rep]]


def _cached_hits(ctx, rows, index, k, w):
    """:func:`_hits`, kept in ``ctx.cache`` under the patches' geometry and the points: rays
    only (a relight's points are the same where the same clusters vary; 0.4 s of godot_zdm2's)."""
    key = cache_key(geometry_key(ctx.patches), ("seen-hits", RAYS, PER_POINT) +
                    tuple(array_key(a).hex() for a in (ctx.patches.owner, rows, index, k, w)))
    return tuple(cached(ctx.cache, key, lambda: _hits(ctx, rows, index, k, w)))


def _hits(ctx, rows, index, k, w):
    """(points (H, 3), piece (H,), receiver (H,), weight (H,)) where cosine rays from the
    receiver points (:func:`_receiver_points`) meet the front of a piece: each ray weighs its
    point's share over its count (:data:`RAYS` a receiver, :data:`PER_POINT` a point at least)."""
    p = ctx.patches
    n_pts = np.bincount(k, minlength=len(ctx.clusters))[k]
    R = np.maximum(PER_POINT, RAYS // n_pts)
    eps = ray_offsets(p, owner=p.owner[rows])
    x0 = spread_points(p, rows, index) + eps[:, None] * p.normals[rows]
    scene = embree_scene(p)
    hx, hp, hr, hw = [], [], [], []
    for count in np.unique(R):                                         # one lattice per count
        sel = np.flatnonzero(R == count)
        d = _directions(index[sel], int(count), tangent_frames(p.normals[rows[sel]]))
        o = np.repeat(x0[sel], count, axis=0)
        pid, t = scene.intersect(o, d)
        pid, t = np.asarray(pid), np.asarray(t, dtype=np.float64)
        hit = pid >= 0
        hit[hit] = np.einsum("ij,ij->i", d[hit], p.normals[pid[hit]]) < 0      # its front only
        hx.append(o[hit] + t[hit, None] * d[hit])
        hp.append(pid[hit])
        hr.append(np.repeat(k[sel], count)[hit])
        hw.append(np.repeat(w[sel] / count, count)[hit])
    return tuple(np.concatenate(a) for a in (hx, hp, hr, hw))


def _directions(index, count, frames) -> np.ndarray:
    """(M count, 3) ``count`` cosine-distributed world directions for each point (M,) of
    ``frames`` (M, 3, 3): a Fibonacci lattice of the unit square (as
    :func:`..hemisphere.cosine_lattice`) shifted by each point's own place ``index`` (M,) in
    a low-discrepancy sequence (a Cranley-Patterson rotation per point): few rays a point, and
    the points together still sample every elevation, which one lattice for all would not."""
    i = np.arange(count)
    a = np.mod(np.asarray(index, dtype=np.float64) * STEPS[0], 1.0)[:, None]
    b = np.mod(np.asarray(index, dtype=np.float64) * STEPS[1], 1.0)[:, None]
    u = np.mod((i + 0.5) / count + a / count, 1.0)
    v = np.mod(i * (np.sqrt(5.0) - 1.0) / 2.0 + b, 1.0)
    local = cosine_directions(np.stack([u, v], -1))                    # (M, count, 3)
    return np.einsum("mrj,mjc->mrc", local, frames).reshape(-1, 3)
