"""Where Cycles bakes a smooth face's corner, and where its shadow rays below the plane start.

A corner whose shading normal N leans off its triangle's normal Ng sees a light direction L
with N . L > 0 > Ng . L. Cycles' shadow ray from there (``intern/cycles/kernel/light/sample.h``
``shadow_ray_offset``, with the shadow-terminator geometry offset of 0.1 that every object has by
default) does not skip its own triangle, and starts lifted off it toward the smooth surface
(``shadow_ray_smooth_surface_offset``: the height h of a parabola through the triangle's
corners and corner normals, bounded below by a linear envelope, along the interpolated normal).
The bake's point lies 1e-4 of its largest coordinate (at least 1e-4) in from the corner toward
the triangle's centre (``kernel/integrator/init_from_bake.h`` ``bake_offset_towards_center``).
From the lifted start the ray meets the triangle's plane again at a distance h (n . Ng) /
(-Ng . L): inside the triangle, or on a neighbour that carries the surface on, the sun is
blocked; past a convex edge it passes (a light a little below the plane, a start lifted much).
A face's corner is baked on the first of Blender's triangles of the face that holds it (a quad:
cut along its first diagonal; :func:`lifted_starts`), the rays cast by the caller. World units.
"""
from __future__ import annotations

import numpy as np

from ..util.geometry import barycentric

__all__ = ["BAKE_NUDGE", "face_corners", "bake_points",
           "corner_edges", "corner_normals", "lifted_starts", "lift", "ON_PLANE_ULPS"]

#: How far Cycles moves a corner's bake point toward its triangle's centre, per unit of its
#: largest coordinate (at least 1).
BAKE_NUDGE = 1e-4
#: Float32 steps of its largest coordinate a lifted start lies at least over its triangle's
#: plane (:func:`lifted_starts`). Raising every start by 4 (not only those nearer the plane) let
#: truck town's racetrack lip's rays pass a neighbour 4 mm on that Cycles' meet.
ON_PLANE_ULPS = 4


def _bake_frame(V, at):
    """(Ng (m, 3) unit, P (m, 3) the bake point, w (m, 3) its barycentrics) at corner ``at`` (m,)
    of triangles ``V`` (m, 3, 3)."""
    m = len(V)
    Ng = np.cross(V[:, 1] - V[:, 0], V[:, 2] - V[:, 0])
    Ng /= np.maximum(np.linalg.norm(Ng, axis=1, keepdims=True), 1e-300)
    corner = V[np.arange(m), at]
    to_centre = V.mean(axis=1) - corner
    dist = np.linalg.norm(to_centre, axis=1)
    step = np.minimum(dist, np.maximum(np.abs(corner).max(axis=1), 1.0) * BAKE_NUDGE)
    P = corner + to_centre * (step / np.maximum(dist, 1e-300))[:, None]
    return Ng, P, barycentric(V, P)


def _height(V, N, P, w, facing) -> np.ndarray:
    """(m,) Cycles' ``shadow_ray_smooth_surface_offset`` height at ``P`` (m, 3), barycentric
    ``w`` (m, 3); ``facing``: its interpolated normal on the triangle's side."""
    a = np.einsum("ij,ij->i", N[:, 2] - N[:, 0], V[:, 0] - V[:, 2])
    b = np.einsum("ij,ij->i", N[:, 2] - N[:, 1], V[:, 1] - V[:, 2])
    c = np.einsum("ij,ij->i", N[:, 1] - N[:, 0], V[:, 1] - V[:, 0])
    u, v = w[:, 0], w[:, 1]
    h = a * u * (u - 1) + (a + b + c) * u * v + b * v * (v - 1)
    up, down = [], []
    for i in range(3):
        j, k = (i + 1) % 3, (i + 2) % 3
        d_j = np.einsum("ij,ij->i", V[:, j] - V[:, i], N[:, i])
        d_k = np.einsum("ij,ij->i", V[:, k] - V[:, i], N[:, i])
        at = np.einsum("ij,ij->i", V[:, i] - P, N[:, i])
        up.append(np.maximum(at + np.maximum(np.maximum(d_j, d_k), 0.0), 0.0))
        down.append(np.maximum(-at + np.maximum(np.maximum(-d_j, -d_k), 0.0), 0.0))
    env_up = np.minimum(np.minimum(up[0], up[1]), up[2])
    env_down = np.minimum(np.minimum(down[0], down[1]), down[2])
    return np.where(facing, np.maximum(env_up, 0.5 * h), np.minimum(-env_down, 0.5 * h))


def face_corners(mesh, face, points, tol) -> np.ndarray:
    """(K,) int64: which corner (0.. in loop order) of face ``face`` (K,) of ``mesh`` lies at each
    of ``points`` (K, 3) within ``tol`` (world units), -1 for a point at none."""
    off = np.asarray(mesh.face_offsets, dtype=np.int64)
    idx = np.asarray(mesh.face_indices, dtype=np.int64)
    X = np.asarray(mesh.verts, dtype=np.float64)
    face = np.asarray(face, dtype=np.int64)
    size = off[face + 1] - off[face]
    out = np.full(len(face), -1, dtype=np.int64)
    for k in np.unique(size):
        rows = np.flatnonzero(size == k)
        d = np.linalg.norm(X[idx[off[face[rows]][:, None] + np.arange(k)[None, :]]] - points[rows][:, None], axis=2)
        j = np.argmin(d, axis=1)
        out[rows] = np.where(d[np.arange(len(rows)), j] <= tol, j, -1)
    return out


def source_corners(elements, meshes, p, x) -> np.ndarray:
    """(K,) int64: which corner (0.. in loop order) of its source face the element corner at
    ``x`` (K, 3) of element ``p`` (K,) is (:func:`face_corners`, within 1e-9 of the elements'
    size), -1 for one at none, and everywhere without ``meshes``."""
    out = np.full(len(p), -1, dtype=np.int64)
    if not meshes or not len(p):
        return out
    size = float(np.linalg.norm(np.ptp(elements.verts, axis=0))) if len(elements.verts) else 1.0
    owner = elements.owner[p]
    for oi, m in enumerate(meshes):
        rows = np.flatnonzero(owner == oi)
        if rows.size:
            out[rows] = face_corners(m, elements.source_face[p[rows]].astype(np.int64), x[rows], 1e-9 * size)
    return out


def corner_edges(elements, p, c):
    """(position (K, 3), edge to the next corner (K, 3), edge to the previous corner (K, 3)) of
    each corner ``c`` (K,) of element ``p`` (K,) (a triangle's corners cycle over 3, a quad's 4)."""
    polys = elements.polys
    k = np.where(polys[p, 3] >= 0, 4, 3)
    X = elements.verts
    here = X[polys[p, c]]
    return here, X[polys[p, (c + 1) % k]] - here, X[polys[p, (c - 1) % k]] - here


def corner_normals(elements, p, c) -> np.ndarray:
    """(K, 3) unit normal of the triangle each corner ``c`` (K,) of element ``p`` (K,) makes with
    its two neighbouring corners, turned to the element's side; the element's own normal where
    that triangle has no area."""
    _, nxt, prv = corner_edges(elements, p, c)
    n = np.cross(nxt, prv)
    length = np.linalg.norm(n, axis=1)
    own = elements.normals[p]
    scale = np.linalg.norm(nxt, axis=1) * np.linalg.norm(prv, axis=1)
    flat = ~(length > 1e-9 * scale)
    n = np.where(flat[:, None], own, n / np.where(flat, 1.0, length)[:, None])
    return np.where((np.einsum("ij,ij->i", n, own) < 0)[:, None], -n, n)


def bake_points(elements, meshes, p, c):
    """(K, 3) where Cycles bakes corner ``c`` (K,) of element ``p`` (K,). Blender gives a face
    corner one bake point, on the first of its loop triangles holding it (``object_bake_api.cc``
    ``bake_targets_populate_pixels_color_attributes``: "first triangle wins"), and Cycles moves it
    toward that triangle's centre by :data:`BAKE_NUDGE` of its largest coordinate (at least
    that of 1; at most the distance). An element corner at a corner of its source face is moved
    so (:func:`_first_triangles`); any other (a vertex cut inside a face, a corner of an n-gon
    Blender splits its own way) toward its element's centre, at most half way."""
    x = elements.verts[elements.polys[p, c]]
    big = np.maximum(np.abs(x).max(axis=1), 1.0)
    centre = np.array(elements.centers[p], dtype=np.float64)
    most = 0.5 * np.linalg.norm(centre - x, axis=1)
    found = _first_triangles(elements, meshes, p, x)
    if found is not None:
        k, tri_centre = found
        inside = _within(elements, p[k], c[k], tri_centre)
        k, tri_centre = k[inside], tri_centre[inside]
        centre[k] = tri_centre
        most[k] = np.linalg.norm(tri_centre - x[k], axis=1)
    to = centre - x
    dist = np.linalg.norm(to, axis=1)
    return x + to * (np.minimum(most, BAKE_NUDGE * big) / np.maximum(dist, 1e-300))[:, None]


def _within(elements, p, c, towards) -> np.ndarray:
    """(K,) bool: the direction from corner ``c`` (K,) of element ``p`` (K,) to ``towards``
    (K, 3) runs into the element or along one of its two edges at the corner (in its plane):
    not so for the elements of a face's other triangles at that corner (an n-gon's fan)."""
    x, nxt, prv = corner_edges(elements, p, c)
    d = towards - x
    n = elements.normals[p]
    size = np.linalg.norm(nxt, axis=1) * np.linalg.norm(d, axis=1)
    tol = 1e-9 * np.maximum(size, 1e-300)
    a = np.einsum("ij,ij->i", np.cross(nxt, d), n)
    b = np.einsum("ij,ij->i", np.cross(d, prv), n)
    return (a >= -tol) & (b >= -tol) & (np.linalg.norm(d, axis=1) > 0)


def _first_row_holding(ft, face, j) -> np.ndarray:
    """(K,) for each face ``face`` (K,) and its corner ``j`` (K,), the first row of the loop
    triangles ``ft`` (T, 4: face, three corners of it) of that face holding that corner; -1
    where none does."""
    rows = np.repeat(np.arange(len(ft)), 3)
    kf, kc = np.repeat(ft[:, 0], 3), ft[:, 1:].reshape(-1)
    order = np.lexsort((rows, kc, kf))                 # by face, corner, then row: first wins
    kf, kc, rows = kf[order], kc[order], rows[order]
    first = np.ones(len(kf), bool)
    first[1:] = (kf[1:] != kf[:-1]) | (kc[1:] != kc[:-1])
    span = int(max(kc.max(initial=0), np.max(j, initial=0))) + 2
    table = kf[first] * span + kc[first]
    rows = rows[first]
    query = face * span + j
    at = np.minimum(np.searchsorted(table, query), max(len(table) - 1, 0))
    hit = (j >= 0) & (len(table) > 0) & (table[at] == query) if len(table) else np.zeros(len(face), bool)
    return np.where(hit, rows[at] if len(table) else -1, -1)


def _first_triangles(elements, meshes, p, x):
    """(k (R,) rows of ``p``, centre (R, 3)): for the element corners at ``x`` (K, 3) that are
    corners of their source face, the centre of the first of Blender's loop triangles of the
    face holding it (:func:`_first_triangle_corners`); None when there are none."""
    found = _first_triangle_corners(elements, meshes, p, x)
    return None if found is None else (found[0], found[1].mean(axis=1))


def lifted_starts(elements, meshes, p, c):
    """(K, 3) where Cycles' shadow rays toward a light below its triangle's plane start at
    corner ``c`` (K,) of element ``p`` (K,) (module docstring: the bake point lifted by the
    whole shadow-terminator offset, which every light below the plane gets), NaN where the
    corner is no corner of its source face or its mesh has no corner normals."""
    x = elements.verts[elements.polys[p, c]]
    out = np.full((len(p), 3), np.nan)
    found = _first_triangle_corners(elements, meshes, p, x)
    if found is None:
        return out
    k, V, N, at = found
    ok = np.all(np.isfinite(N), axis=(1, 2))
    if ok.any():
        Ng, P, w = _bake_frame(V[ok], at[ok])
        out[k[ok]] = lift(V[ok], N[ok], Ng, P, w)
    return out


def lift(V, N, Ng, P, w) -> np.ndarray:
    """(m, 3) where Cycles' shadow rays toward a light below the plane start from points ``P``
    (m, 3), barycentric ``w`` (m, 3), of triangles ``V`` (m, 3, 3) with corner normals ``N``
    (m, 3, 3) and unit normal ``Ng`` (m, 3): lifted along the interpolated normal by the
    shadow-terminator offset (module docstring), at least :data:`ON_PLANE_ULPS` float32 steps
    over the plane."""
    n = np.einsum("mk,mkj->mj", w, N)
    h = _height(V, N, P, w, np.einsum("ij,ij->i", n, Ng) > 0)
    # at least ON_PLANE_ULPS float32 steps over the plane, so that a ray from a start on the
    # plane (a lift of 0) meets its triangle again as Cycles' does (or not, at random: ties)
    over = h * np.einsum("ij,ij->i", n, Ng)
    floor = ON_PLANE_ULPS * 2.0 ** -23 * np.maximum(np.abs(P).max(axis=1), 1.0)
    return P + h[:, None] * n + np.maximum(floor - over, 0.0)[:, None] * Ng


def _first_triangle_corners(elements, meshes, p, x):
    """(k (R,) rows of ``p``, V (R, 3, 3), N (R, 3, 3), at (R,)): for the element corners at
    ``x`` (K, 3) that are corners of their source face, the first of Blender's loop triangles
    of the face holding it: a triangle's own, a quad's (0, 1, 2) for corners 0-2 and (0, 2, 3)
    for corner 3, or the first row of the mesh's ``face_triangles`` holding it, where that
    triangle has an area; its corner normals (NaN without ``corner_normal``) and which of its
    corners the element corner is. None when there are none."""
    if not meshes:
        return None
    ks, Vs, Ns, ats = [], [], [], []
    corner = source_corners(elements, meshes, p, x)
    owner = elements.owner[p]
    for oi, m in enumerate(meshes):
        rows = np.flatnonzero(owner == oi)
        if not rows.size:
            continue
        face = elements.source_face[p[rows]].astype(np.int64)
        j = corner[rows]
        off = np.asarray(m.face_offsets, dtype=np.int64)
        n = off[face + 1] - off[face]
        tri = np.full((len(rows), 3), -1, dtype=np.int64)
        tri[(n == 3) & (j >= 0)] = (0, 1, 2)
        tri[(n == 4) & (j >= 0) & (j < 3)] = (0, 1, 2)
        tri[(n == 4) & (j == 3)] = (0, 2, 3)
        ft = getattr(m, "face_triangles", None)
        if ft is not None and len(ft):
            ft = np.asarray(ft, dtype=np.int64)
            listed = np.zeros(len(off) - 1, bool)
            listed[ft[:, 0]] = True
            tri[listed[face]] = -1
            row = _first_row_holding(ft, face, j)
            tri[row >= 0] = ft[row[row >= 0], 1:]
        ok = np.flatnonzero(tri[:, 0] >= 0)
        idx = np.asarray(m.face_indices, dtype=np.int64)
        loops = off[face[ok]][:, None] + tri[ok]
        V = np.asarray(m.verts, dtype=np.float64)[idx[loops]]
        cn = getattr(m, "corner_normal", None)
        N = np.full(V.shape, np.nan) if cn is None else np.asarray(cn, dtype=np.float64)[loops]
        # a triangle of no area (a quad with two corners at one point) has no centre to move to
        area2 = np.linalg.norm(np.cross(V[:, 1] - V[:, 0], V[:, 2] - V[:, 0]), axis=1)
        edge2 = np.max([np.sum((V[:, i] - V[:, (i + 1) % 3]) ** 2, axis=1) for i in range(3)], axis=0)
        flat = area2 <= 1e-9 * edge2
        ks.append(rows[ok[~flat]])
        Vs.append(V[~flat])
        Ns.append(N[~flat])
        ats.append(np.argmax(tri[ok][~flat] == j[ok][~flat, None], axis=1))
    if not ks:
        return None
    return np.concatenate(ks), np.concatenate(Vs), np.concatenate(Ns), np.concatenate(ats)
