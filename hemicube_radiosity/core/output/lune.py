"""The light reflected more than once that a turned-around corner takes: what its lune sees.

Where Cycles turns a corner's triangle around (:mod:`.crease`: its shading normal N faces away
from its geometric normal Ng, and both are negated), its diffuse bounce keeps only the
directions between the two planes, the lune, and drops the rest (``bsdf_diffuse_sample``). The
lune lies behind the face: on a game level's brush, whose faces meet a partition or a fin along
an edge Cycles does not split (:mod:`..mesh.cycles_normals`), inside the solid, where nothing is
lit; under a fin's roof, in the wedge below it. The vertex's gather looked the other way (cosine
rays about the vertex's normal, in front of the face), so the share of it above the plane
(:mod:`.above`), or of an even hemisphere, (1 + N . Ng) / 2, says nothing of the lune: godot_zdm2's
2,545 such corners that Cycles never lights kept 0.37 of their vertex's light, 0.07 on the mean.

Here each such corner casts its own cosine rays about its turned shading normal (as many as the
gather, its pattern: :func:`.hemisphere.cosine_lattice`) from Cycles' bake point
(:func:`.lift.bake_points`), a hair behind the face, past the back an open surface gets
(:mod:`..mesh.backs`: the face's other side, which the lune sees from; started a ray offset
behind the face instead, past that back, the rays of a 2.5 cm chain link's corner in
godot_zdm2 passed the link's other faces and read 0.31 where Cycles has 0), and reads where they
land what the gather's rays read (the light leaving the element vertices, bilinear in the
element hit, front hits only). A ray below the triangle's turned plane, one
that meets a back and one that meets nothing read 0 (the world's light in the lune is the
corner's direct light). The corner keeps the luminance of that reading over its vertex's light
reflected more than once. The rays' hits are geometry only and cached: a relight casts none.
Radiance units; world space.
"""
from __future__ import annotations

import numpy as np

from ..hemisphere import cosine_lattice
from ..rays import embree_available, embree_scene
from ..runtime.cache import array_key, cache_key, cached, geometry_key
from ..util.colour import LUMA
from ..util.geometry import in_frames, tangent_frames
from .gather import patch_parameters, surface_weights

__all__ = ["lune_shares"]

#: Corners whose rays are cast at once.
CHUNK = 4096
#: Float32 steps of a point's largest coordinate its rays start behind its face: as near as
#: Cycles' start on it (:data:`.covered.LIFT_ULPS`); the lune's rays leave the plane.
LIFT_ULPS = 8
#: The least cosine between a face's normal and the back a ray meets for that back to be the
#: face's own (:func:`_lune_hits`).
PARALLEL = 0.9999


def lune_shares(ctx, elements, points, lift, shade, geo, v, read_v, arriving_v, rays) -> np.ndarray:
    """(K,) for K turned-around corners, the share of their vertex's light reflected more than
    once that they keep: the luminance of what their own ``rays`` cosine rays about ``shade``
    (K, 3) from their bake points ``points`` (K, 3) read in the lune (above the plane of unit
    normal ``geo`` (K, 3), both turned: behind the face) of ``read_v`` (V, 3), the light leaving
    the element vertices, over the luminance of ``arriving_v`` (V, 3), the light reflected more
    than once arriving at their vertices ``v`` (K,) (0 where that is 0). ``lift`` (K,): their
    object's ray offset, within half of which behind the face a back parallel to it is its
    own (:func:`_lune_hits`). NaN rows: not known (no Embree, no rays, nothing read): the
    caller's rule stands."""
    K = len(v)
    out = np.full(K, np.nan)
    if not K or rays <= 0 or read_v is None or arriving_v is None or not embree_available():
        return out
    key = cache_key(geometry_key(elements) + array_key(points) + array_key(lift) + array_key(shade)
                    + array_key(geo), ("lune-hits", int(rays), LIFT_ULPS))
    rows, ids, w = cached(getattr(ctx, "cache", None), key,
                          lambda: _lune_hits(elements, points, lift, shade, geo, int(rays)))
    y = np.asarray(read_v, dtype=np.float64) @ LUMA
    seen = np.bincount(rows, weights=np.einsum("hc,hc->h", w, y[ids]), minlength=K) / rays
    have = np.asarray(arriving_v, dtype=np.float64)[v] @ LUMA
    out[:] = np.where(have > 0, seen / np.where(have > 0, have, 1.0), 0.0)
    return out


def _lune_hits(elements, points, lift, shade, geo, rays):
    """(rows (h,) the corner of each ray that meets a front in the lune, ids (h, 4) the element
    vertices it reads and w (h, 4) float32 their bilinear weights), for :func:`lune_shares`.
    The rays start :data:`LIFT_ULPS` float32 steps behind the face; one that meets the back
    of a face parallel to it within half the ``lift`` (K,) behind it, its own back (an open
    surface's, :mod:`..mesh.backs`, a quarter of the lift behind it), goes on from past it."""
    scene = embree_scene(elements)
    params = patch_parameters(elements)
    local = cosine_lattice(rays, 0)
    R = len(local)
    tiny = LIFT_ULPS * 2.0 ** -23 * np.maximum(np.abs(points).max(axis=1), 1.0)
    rows, ids, w = [], [], []
    for a in range(0, len(points), CHUNK):
        x, n, g, h = points[a:a + CHUNK], shade[a:a + CHUNK], geo[a:a + CHUNK], lift[a:a + CHUNK]
        d = in_frames(local, tangent_frames(n)).reshape(-1, 3)
        k = np.repeat(np.arange(len(x)), R)
        into = np.einsum("ij,ij->i", d, g[k]) > 0               # in the lune: above the turned plane
        k, d = k[into], d[into]
        o = x[k] + tiny[a:a + CHUNK][k, None] * g[k]
        pid, t = scene.intersect(o, d)
        pid, t = np.asarray(pid), np.asarray(t, np.float64)
        y = o + np.where(pid >= 0, t, 0.0)[:, None] * d
        nh = elements.normals[np.maximum(pid, 0)]
        own = (pid >= 0) & (np.einsum("ij,ij->i", nh, g[k]) > PARALLEL) \
            & (np.einsum("ij,ij->i", y - x[k], g[k]) <= 0.5 * h[k])
        if own.any():                                       # past its own back, on along the ray
            o2 = y[own] + 0.25 * h[k[own], None] * g[k[own]]
            p2, t2 = scene.intersect(o2, d[own])
            pid[own], y[own] = np.asarray(p2), o2 + np.asarray(t2, np.float64)[:, None] * d[own]
        hit = np.flatnonzero(pid >= 0)
        front = hit[np.einsum("ij,ij->i", d[hit], elements.normals[pid[hit]]) < 0]
        i, x_w = surface_weights(params, elements.polys, pid[front], y[front])
        rows.append(a + k[front])
        ids.append(i.astype(np.int64))
        w.append(x_w.astype(np.float32))
    if not rows:
        return np.zeros(0, np.int64), np.zeros((0, 4), np.int64), np.zeros((0, 4), np.float32)
    return np.concatenate(rows), np.concatenate(ids), np.concatenate(w)
