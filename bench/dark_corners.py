"""Corners that the Cycles reference never lights, and which of them the real-scene bench leaves out.

Cycles bakes some face corners of real files exactly 0: no light path in all its samples. Where the
geometry says why, the corner measures no surface a render would show lit, and
``real_scenes.compare`` leaves it out; every other never-lit corner is compared, so a point that
we light and Cycles does not still counts. A corner is explained when its bake point is

* **covered**: another face lies in its face's plane over the bake point (a duplicated face, or
  two faces back to back). Cycles' rays leave the point and meet that face at a distance of
  about 0 (it skips only the point's own triangle), so no light reaches it; a render of such a
  place shows the same dark flicker. ``godot_living_room``'s door strips, whose faces a second
  copy of the wall overlaps, are such corners: Cycles 0, the copy beside them 0.321;
* **sealed**: no ray from it leaves the scene, and all but :data:`LEAK` of :data:`RAYS` rays meet
  the back of a face or a face the reference never lights, or at least :data:`INSIDE` of them
  meet backs: the point lies inside a solid. Nothing outside can see it (``godot_zdm2``'s brushes
  buried in each other, whose faces cross the solids they pass through). Of the corners the
  reference lights, 0.6% of ``godot_zdm2``'s pass the second test, at a mean 3% of the scene's.

A never-lit corner that Cycles shades with a normal turned away from its face (custom normals:
its diffuse samples go below the surface and are dropped, in a render too) is compared: that is
what Cycles shows there.

The bake point is where Cycles shaded the corner (``point``: a POSITION bake; Cycles moves a
corner a fraction of a millimetre into its first triangle), or, in files without it, the corner
moved :data:`INWARD` of the way to its face's centroid; the sealed test's rays leave it lifted off
the face by :data:`LIFT` of the scene's diagonal.
Plain NumPy and Embree (``embreex``), on the arrays ``real_scenes.cycles_child`` writes: corner
positions ``pos`` (L, 3) in metres, grouped by face (``owner``, ``face``), in loop order.
"""
from __future__ import annotations

import numpy as np

from hemicube_radiosity.core.util.unique import run_positions

RAYS = 64          # rays per never-lit corner for the sealed test (cosine-weighted, one pattern)
LEAK = 1 / 16      # share of those rays that may meet a lit face's front through a solid's seams
INSIDE = 1 / 2     # share of those rays meeting backs that puts the point inside a solid
INWARD = 1e-3      # share of the way from a corner to its face's centroid: the bake point
LIFT = 1e-6        # of the scene's diagonal: off the face before the sealed test's rays
PLANE = 1e-7       # of the scene's diagonal: a face this close to the plane lies in it
CELLS = 128        # grid cells along the scene's longest side, to find the faces over a point
SPAN = 64          # a triangle whose box spans more cells is tested against every point
CHUNK = 16384      # never-lit points whose rays are cast at once


def fan_triangles(pos, owner, face):
    """The faces' triangles as fans from each face's first corner.

    pos (L, 3) float; owner, face (L,) int: corners grouped by face, in loop order.
    Returns tris (T, 3, 3) float64 and the face key of each triangle (T,) int64
    (``owner * 2**32 + face``, as :func:`face_keys`)."""
    key = face_keys(owner, face)
    start = np.flatnonzero(np.r_[True, key[1:] != key[:-1]])
    fan = np.maximum(np.diff(np.r_[start, len(key)]) - 2, 0)     # triangles per face
    first = np.repeat(start, fan)
    b = first + 1 + run_positions(fan)
    tris = np.stack([pos[first], pos[b], pos[b + 1]], 1).astype(np.float64)
    return tris, key[first]


def face_keys(owner, face):
    """(L,) int64: one key per (object, face)."""
    return np.asarray(owner, np.int64) * (1 << 32) + np.asarray(face, np.int64)


def bake_points(pos, centroid):
    """(L, 3): where Cycles bakes each corner, near enough: :data:`INWARD` toward the centroid."""
    return pos + INWARD * (centroid - pos)


def covered(points, keys, tris, tri_key, diag):
    """(N,) bool: a triangle of another face passes through ``points`` (N, 3), within
    :data:`PLANE` x ``diag`` (in the same plane, facing either way, or crossing it).
    ``keys`` (N,): each point's own face key; ``tris`` (T, 3, 3), ``tri_key`` (T,).
    Candidates come from a grid of :data:`CELLS` cells along the longest side: a point is tested
    against the triangles whose bounding box shares its cell (those spanning more than
    :data:`SPAN` cells against every point)."""
    N = len(points)
    out = np.zeros(N, bool)
    if N == 0 or len(tris) == 0:
        return out
    tol = PLANE * diag
    n = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    a = np.linalg.norm(n, axis=1)
    n = n / np.where(a > 0, a, 1.0)[:, None]
    lo, hi = tris.min(1) - tol, tris.max(1) + tol
    origin = lo.min(0)
    cell = max(float(np.max(hi.max(0) - origin)), 1e-30) / CELLS
    c0 = np.floor((lo - origin) / cell).astype(np.int64)
    span = np.floor((hi - origin) / cell).astype(np.int64) - c0 + 1
    size = span.prod(1)
    G = CELLS + 2
    pc = np.floor((points - origin) / cell).astype(np.int64)
    pid = (pc[:, 0] * G + pc[:, 1]) * G + pc[:, 2]
    # small triangles: one (cell, triangle) pair per cell of their box, sorted by cell
    small = np.flatnonzero((a > 0) & (size <= SPAN))
    rep = np.repeat(small, size[small])
    k = run_positions(size[small])
    sy, sz = span[rep, 1], span[rep, 2]
    cc = c0[rep] + np.stack([k // (sy * sz), (k // sz) % sy, k % sz], 1)
    cid = (cc[:, 0] * G + cc[:, 1]) * G + cc[:, 2]
    order = np.argsort(cid, kind="stable")
    cid, rep = cid[order], rep[order]
    first, last = np.searchsorted(cid, pid, "left"), np.searchsorted(cid, pid, "right")
    big = np.flatnonzero((a > 0) & (size > SPAN))
    step = max(1, min(N, (1 << 22) // max(len(big), 1)))      # points at a time: bounded memory
    for s in range(0, N, step):
        ps = np.arange(s, min(s + step, N))
        cnt = last[ps] - first[ps]
        pi = np.repeat(ps, cnt)
        ti = rep[np.repeat(first[ps], cnt) + run_positions(cnt)]
        if len(big):                          # the big triangles whose box holds the point
            inbox = np.all((points[ps, None] >= lo[big][None]) & (points[ps, None] <= hi[big][None]), axis=2)
            bp, bt = np.nonzero(inbox)
            pi, ti = np.r_[pi, ps[bp]], np.r_[ti, big[bt]]
        for u in range(0, len(pi), 1 << 20):
            p_, t_ = pi[u:u + (1 << 20)], ti[u:u + (1 << 20)]
            keep = tri_key[t_] != keys[p_]
            p_, t_ = p_[keep], t_[keep]
            d = np.einsum("ij,ij->i", points[p_] - tris[t_, 0], n[t_])
            near = np.abs(d) <= tol
            p_, t_, d = p_[near], t_[near], d[near]
            hit = inside_triangles(points[p_] - d[:, None] * n[t_], tris[t_])
            out[p_[hit]] = True
    return out


def inside_triangles(p, t, eps=1e-6):
    """(K,) bool: ``p`` (3,) or (K, 3) lies inside triangles ``t`` (K, 3, 3) (barycentric, ``eps``
    slack)."""
    v0, v1, v2 = t[:, 1] - t[:, 0], t[:, 2] - t[:, 0], p - t[:, 0]   # p: (3,) or (K, 3)
    d00, d01, d11 = (v0 * v0).sum(1), (v0 * v1).sum(1), (v1 * v1).sum(1)
    d20, d21 = (v2 * v0).sum(1), (v2 * v1).sum(1)
    den = d00 * d11 - d01 * d01
    with np.errstate(divide="ignore", invalid="ignore"):
        v = (d11 * d20 - d01 * d21) / den
        w = (d00 * d21 - d01 * d20) / den
        return (den > 0) & (v >= -eps) & (w >= -eps) & (v + w <= 1 + eps)


def sealed(points, normals, tris, tri_lit, diag, rays=RAYS, seed=0, scene=None):
    """(N,) bool: of ``rays`` cosine-weighted rays from ``points`` (N, 3), lifted :data:`LIFT` x
    ``diag`` along their unit ``normals``, none escapes the scene, and either at most :data:`LEAK`
    of them meet the front of a triangle whose face ``tri_lit`` (T,) bool says the reference
    lights, or at least :data:`INSIDE` of them meet backs (the point is inside a solid; faces of
    other solids buried in it, lit where they come out, take the rest). ``scene``: an Embree
    scene of ``tris`` already made."""
    from embreex import rtcore_scene as rtcs
    from embreex.mesh_construction import TriangleMesh

    N = len(points)
    if scene is None:
        scene = rtcs.EmbreeScene()
        TriangleMesh(scene, np.ascontiguousarray(tris, np.float32))
    if N > CHUNK:                                 # bounded memory: a chunk of points at a time
        return np.concatenate([sealed(points[s:s + CHUNK], normals[s:s + CHUNK], tris, tri_lit, diag,
                                      rays, seed, scene) for s in range(0, N, CHUNK)])
    if N == 0:
        return np.zeros(0, bool)
    tn = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    u = np.random.default_rng(seed).random((rays, 2))
    r, phi = np.sqrt(u[:, 0]), 2 * np.pi * u[:, 1]
    local = np.c_[r * np.cos(phi), r * np.sin(phi), np.sqrt(1 - u[:, 0])]
    a = np.where(np.abs(normals[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    t = np.cross(normals, a)
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    b = np.cross(normals, t)
    d = (local[None, :, :1] * t[:, None] + local[None, :, 1:2] * b[:, None]
         + local[None, :, 2:] * normals[:, None]).reshape(-1, 3)
    o = np.repeat(points + LIFT * diag * normals, rays, 0)
    prim = np.asarray(scene.run(o.astype(np.float32), d.astype(np.float32)))
    hit = prim >= 0
    front = np.zeros_like(hit)
    front[hit] = np.einsum("ij,ij->i", d[hit], tn[prim[hit]]) < 0
    escape = (~hit).reshape(N, rays).any(1)
    light = (front & tri_lit[np.maximum(prim, 0)]).reshape(N, rays).mean(1)
    back = (hit & ~front).reshape(N, rays).mean(1)
    return ~escape & ((light <= LEAK) | (back >= INSIDE))


def explained(z, never, lit):
    """The never-lit corners whose 0 the geometry explains, from ``real_scenes.cycles_child``'s
    arrays ``z`` (pos, centroid, normal, owner, face), ``never`` (L,) bool: the corners the
    reference never lights, and ``lit`` (L,) bool: those it lights (or that emit). Returns
    (covered (L,) bool, sealed (L,) bool), False outside ``never``; a corner both covered and
    sealed counts as covered."""
    pos, owner, face = np.asarray(z["pos"], float), z["owner"], z["face"]
    L = len(pos)
    cov, seal = np.zeros(L, bool), np.zeros(L, bool)
    idx = np.flatnonzero(never)
    if len(idx) == 0:
        return cov, seal
    diag = float(np.linalg.norm(np.ptp(pos, axis=0)))
    tris, tri_key = fan_triangles(pos, owner, face)
    keys = face_keys(owner, face)
    nrm = np.asarray(z["normal"], float)[idx]
    length = np.linalg.norm(nrm, axis=1)
    nrm = nrm / np.maximum(length, 1e-30)[:, None]
    if "point" in z:                   # Cycles' own bake points (a POSITION bake)
        p = np.asarray(z["point"], float)[idx]
    else:
        p = bake_points(pos[idx], np.asarray(z["centroid"], float)[idx])
    cov[idx] = covered(p, keys[idx], tris, tri_key, diag)
    rest = ~cov[idx] & (length > 0)              # not covered, with a normal to cast about
    seal[idx[rest]] = sealed(p[rest], nrm[rest], tris, np.isin(tri_key, np.unique(keys[lit])), diag)
    return cov, seal
