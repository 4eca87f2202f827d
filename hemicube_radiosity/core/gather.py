"""Final gather: the light arriving at a point from a coarse patch solution, by cosine rays.

A coarse patch solution is accurate in the power each patch reflects but blurs where light
changes. The finer output elements gather it instead of interpolating it: from each element
vertex, stratified cosine-distributed rays find the surface they see, and read there the
bilinear interpolation of the patches' reflected radiance (``R = B - E``, at patch vertices).
Their mean is the radiance arriving at the point from reflected light (the emitters' own light
is added exactly by :mod:`.direct`). Rays that see no surface see the world's radiance; rays
that hit the back of a patch see nothing.
"""
from __future__ import annotations

import numpy as np

from .patches import PatchSet

__all__ = ["final_gather", "patch_parameters", "surface_values"]


def patch_parameters(patches: PatchSet):
    """Per patch: origin corner c0 (N,3), edge vectors e1, e2 (N,3) and the inverse Gram matrix
    (N,2,2) that turns a point's offset from c0 into (u, v) along e1, e2. Quads use e1 = c1 - c0,
    e2 = c3 - c0 (exact for parallelograms, what patch grids are made of), triangles
    e1 = c1 - c0, e2 = c2 - c0."""
    c = patches.corners()
    tri = patches.polys[:, 3] < 0
    e1 = c[:, 1] - c[:, 0]
    e2 = np.where(tri[:, None], c[:, 2] - c[:, 0], c[:, 3] - c[:, 0])
    a, b, d = (e1 * e1).sum(1), (e1 * e2).sum(1), (e2 * e2).sum(1)
    det = a * d - b * b
    inv = np.stack([np.stack([d, -b], 1), np.stack([-b, a], 1)], 1) / det[:, None, None]
    return c[:, 0], e1, e2, inv, tri


def surface_values(params, polys, vertex_values, pid, y):
    """Values at points ``y`` (H,3) on patches ``pid`` (H,): bilinear in a quad, linear in a
    triangle, from ``vertex_values`` (V,k) at the patch corners."""
    c0, e1, e2, inv, tri = params
    rel = y - c0[pid]
    g = np.stack([(rel * e1[pid]).sum(1), (rel * e2[pid]).sum(1)], 1)
    uv = np.clip(np.einsum("hij,hj->hi", inv[pid], g), 0.0, 1.0)
    u, v = uv[:, :1], uv[:, 1:]
    p = polys[pid]
    q = vertex_values[p[:, 0]], vertex_values[p[:, 1]], vertex_values[p[:, 2]], vertex_values[np.maximum(p[:, 3], 0)]
    quad = (1 - u) * (1 - v) * q[0] + u * (1 - v) * q[1] + u * v * q[2] + (1 - u) * v * q[3]
    lin = q[0] + u * (q[1] - q[0]) + v * (q[2] - q[0])
    return np.where(tri[pid][:, None], lin, quad)


def final_gather(patches: PatchSet, vertex_values, points, normals, scene, *, rays=256, seed=0,
                 world=None, chunk_rays=1 << 20, ticker=None) -> np.ndarray:
    """(P, k) mean radiance arriving at ``points`` (P, 3) with unit ``normals`` from surfaces whose
    outgoing radiance is ``vertex_values`` (V, k) at ``patches.verts`` (bilinear inside a patch).

    ``scene``: :func:`.embree_ff.embree_scene` of ``patches`` (needs ``intersect``). ``rays`` per
    point, stratified cosine directions turned by a random angle per point (seeded). ``world``
    (k,) radiance seen by rays that hit nothing (None: black).
    """
    from .embree_ff import cosine_directions
    from .hemicube import tangent_frames

    vals = np.asarray(vertex_values, dtype=np.float64)
    points = np.asarray(points, dtype=np.float64)
    normals = np.asarray(normals, dtype=np.float64)
    P, k = len(points), vals.shape[1]
    out = np.zeros((P, k))
    if P == 0:
        return out
    rng = np.random.default_rng(seed)
    g = int(np.ceil(np.sqrt(rays)))
    R = g * g
    i, j = np.meshgrid(np.arange(g), np.arange(g), indexing="ij")
    params = patch_parameters(patches)
    world = None if world is None else np.asarray(world, dtype=np.float64)
    eps = 1e-5 * scene.scale
    step = max(1, chunk_rays // R)
    for s in range(0, P, step):
        x, n = points[s:s + step], normals[s:s + step]
        m = len(x)
        u = np.stack([(i.ravel()[None] + rng.uniform(0, 1, (m, R))) / g,
                      (j.ravel()[None] + rng.uniform(0, 1, (m, R))) / g], axis=-1)   # (m, R, 2)
        local = cosine_directions(u.reshape(-1, 2)).reshape(m, R, 3)
        frames = tangent_frames(n, rng.uniform(0, 2 * np.pi, m))                 # (m, 3, 3) rows u, v, n
        d = np.einsum("mrj,mjc->mrc", local, frames)
        o = np.repeat(x + eps * n, R, axis=0)
        pid, tfar = scene.intersect(o, d.reshape(-1, 3))
        pid = np.asarray(pid)
        hit = pid >= 0
        front = np.zeros_like(hit)
        dd = d.reshape(-1, 3)
        front[hit] = np.einsum("ij,ij->i", dd[hit], patches.normals[pid[hit]]) < 0
        seen = np.zeros((m * R, k))
        if front.any():
            f = np.flatnonzero(front)
            y = o[f] + np.asarray(tfar, np.float64)[f, None] * dd[f]
            seen[f] = surface_values(params, patches.polys, vals, pid[f], y)
        if world is not None:
            seen[~hit] = world
        out[s:s + m] = seen.reshape(m, R, k).mean(axis=1)
        if ticker is not None:
            ticker.tick(s + m, P)
    return out
