"""The share of a vertex's gathered light that a corner of it takes: what arrives from above the
plane of the corner's own triangle.

An output vertex gathers the light reflected more than once with cosine rays about its shading
normal (:mod:`.gather`). Cycles bakes each face corner on its own triangle, and its diffuse
bounce drops every direction below that triangle's plane (``bsdf_diffuse_sample``): a corner
whose shading normal leans off its triangle (:mod:`.crease`) takes only the part of that light
arriving from above the plane. Taking the share of a cosine-weighted hemisphere above the plane,
(1 + N . Ng) / 2, assumed the light even over it; on a crest or a track's edge it comes mostly
from the ground below, which that plane cuts off. Here the gather's own hits say it: the light
they read from above the corner's plane over all they read (:func:`above_shares`). Radiance
units; world space.
"""
from __future__ import annotations

import numpy as np

from ..runtime.cache import array_key, cache_key, cached
from ..util.colour import LUMA
from .gather import patch_parameters, surface_weights

__all__ = ["above_shares"]

#: Vertices (or corners) whose hits are read at once.
CHUNK = 4096


def above_shares(ctx, elements, p, c, geo, xv, read_v) -> np.ndarray:
    """(K,) for corner ``c`` (K,) of element ``p`` (K,) with its triangle's unit normal ``geo``
    (K, 3), the share of its vertex's gathered light whose rays hit above that plane (through
    the vertex's point ``xv`` (V, 3)), read as ``read_v`` (V, 3) (the light leaving the element
    vertices, as the gather's rays read it); NaN where not known: no gather's hits
    (``ctx.gather_rays``, keyed by ``ctx.gather_key``), no hit, or nothing read. What the hits
    read (:func:`_reading`) is geometry only and cached: a relight reads no hit of the gather's."""
    out = np.full(len(p), np.nan)
    rays = getattr(ctx, "gather_rays", None)
    if rays is None or read_v is None or not len(p):
        return out
    gather = str(getattr(ctx, "gather_key", None) or "").encode()
    key = cache_key(gather + array_key(np.stack([p, c], 1)) + array_key(geo) + array_key(xv),
                    ("above-reading-by-vertex",))
    found = cached(getattr(ctx, "cache", None), key, lambda: _reading(rays, elements, p, c, geo, xv))
    if found is None:
        return out
    spans, ids, w, of, up = found
    val = np.einsum("hc,hc->h", w, (np.asarray(read_v, dtype=np.float64) @ LUMA)[ids])
    hit_of, row_up, at_up = cached(getattr(ctx, "cache", None), key + "-sums",
                                   lambda: _sums(spans, of, up, len(p)), disk=False)
    # each corner sums its vertex's hits, in order (a vertex's sum is each of its corners'), and
    # of those the ones above its plane (the others added nothing: the same sums, bit for bit)
    total = np.bincount(hit_of, weights=val, minlength=len(spans) - 1)[of]
    above = np.bincount(row_up, weights=val[at_up], minlength=len(p))
    ok = total > 0
    out[ok] = np.clip(above[ok] / total[ok], 0.0, 1.0)
    return out


def _sums(spans, of, up, K):
    """Geometry only, what :func:`above_shares` sums: (the vertex of each hit (h,), the corner
    (of K) and the hit of each corner's hit above its plane), kept so that a relight does not
    spread every vertex's hits over its corners again (truck town: 16 million)."""
    at, n = _spans(spans, of)                              # each corner reads its vertex's hits
    small = np.int32 if max(K, int(spans[-1])) < 2 ** 31 else np.int64
    rows = np.repeat(np.arange(K, dtype=small), n)
    return np.repeat(np.arange(len(spans) - 1, dtype=small), np.diff(spans)), rows[up], at[up].astype(small)


def _spans(start, v):
    """(at (h,) the rows of the hits of vertices ``v`` (k,), one vertex after another; n (k,)
    how many each has), the hits of vertex i being rows ``start[i]:start[i + 1]``."""
    n = start[v + 1] - start[v]
    return np.repeat(start[v] - (np.cumsum(n) - n), n) + np.arange(int(n.sum())), n


def _reading(rays, elements, p, c, geo, xv):
    """What the gather's hits of the corners' vertices read, each vertex's once (a vertex has
    several leaning corners; truck town's 32,825 read 3.5 million hits through 6,936
    vertices): (spans (U + 1,) vertex u's hits at rows ``spans[u]:spans[u + 1]`` of ids (h, 4)
    the element vertices they read and w (h, 4) their surface weights times the hit's own
    weight; of (K,) each corner's vertex u; up (k,) bool per corner, its vertex's hits in
    order, above the corner's triangle's plane); None without hits."""
    _, H = rays(hits=True)
    if H is None or not len(H):
        return None
    start = np.searchsorted(H[:, 0], np.arange(len(xv) + 1) - 0.5)   # the hits come in point order
    params = patch_parameters(elements)
    v = elements.polys[p, c]
    verts, of = np.unique(v, return_inverse=True)
    ids, w = [], []
    for a in range(0, len(verts), CHUNK):                  # temporaries: a chunk's hits at a time
        h = H[_spans(start, verts[a:a + CHUNK])[0]]
        i, x = surface_weights(params, elements.polys, h[:, 1].astype(np.int64), h[:, 2:5].astype(np.float64))
        if H.shape[1] > 5:                                   # hits carrying a weight of their own
            x = x * h[:, 5:6]
        ids.append(i.astype(np.int32))
        w.append(x.astype(np.float32))
    up = []
    for a in range(0, len(p), CHUNK):
        k = np.arange(a, min(a + CHUNK, len(p)))
        at, m = _spans(start, v[k])
        row = np.repeat(k, m)
        up.append(np.einsum("ij,ij->i", H[at, 2:5].astype(np.float64) - xv[v[row]], geo[row]) > 0)
    n = start[verts + 1] - start[verts]
    spans = np.concatenate([[0], np.cumsum(n)])
    return spans, np.concatenate(ids), np.concatenate(w), of, np.concatenate(up)
