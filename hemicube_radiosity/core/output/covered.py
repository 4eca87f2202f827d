"""Light per element corner where another surface lies between the corner and its vertex's rays.

An output vertex is lit once (:mod:`.stage`), its rays starting a ray offset off a point a hair
inside its elements (:func:`.rays.ray_offsets`: 1e-5 of the object's diagonal, 2 cm on a 2 km
ground ring). Cycles bakes each face corner at the corner itself, nudged toward its triangle's
centre (:data:`.lift.BAKE_NUDGE`), and its rays start there, skipping only their own triangle
(``kernel/integrator/init_from_bake.h``; self-intersection is avoided by primitive, not by
distance). Where another surface passes closer over the corner than our rays start (a bevel
strip tucked under the slab it meets, a wall's top under a coincident lid, grass lying a few
millimetres under a road, the ground ring under the town's grass), Cycles' rays meet it and
the corner is dark, and the light around it is what a render shows there; ours started above
it and read the open room or the sun.

Here every element corner is baked where Cycles bakes it (:func:`bake_points`: a corner of
its source face on the first of Blender's triangles holding it, moved toward that triangle's
centre; any other toward its element's), and a bake point is *covered* where another face lies
over it, along its triangle's normal, within its object's ray offset, or between it and where
its vertex's rays start (:func:`covered_corners`; two rays per point). A covered point is lit
on its own (:func:`covered_light`) from :data:`LIFT_ULPS` float32 steps off it (at most half
way to the face over it): its direct light found again there (cosine to its shading normal,
nothing from below its triangle's plane), and its vertex's light reflected more than once
scaled by how much of the open scene it sees against how much the vertex's start did
(:func:`.rays.open_fraction`: rays closed within a twentieth of the patch size or on a back
face lend nothing; in a crack they only meet its dark walls). Faces within :data:`TIE_ULPS`
float32 steps of the point (a duplicate face: either may be drawn) cover nothing, nor do backs
of open surfaces (:mod:`..mesh.backs`), which Cycles has not. Corners of elements the scene
does not see at a vertex of one it sees (they count in that vertex's mean) and of buried
vertices (:func:`.sides.buried_side`) keep their vertex's light; a buried vertex's is the light
where its edge from the open side meets what buries it, and the rays from that point start no
further off it than half way to a face over it (:func:`start_offsets`): the point lies against
the burying surface, and rays started past a lip over it read the sun. Geometry only, cached:
a relight casts no ray. World units.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..rays import embree_available, embree_scene, open_fraction, ray_offsets
from ..runtime.cache import array_key, cache_key, cached, geometry_key
from .crease import corner_edges, corner_normals
from .lift import BAKE_NUDGE, face_corners
from .normals import corner_shading_normals

__all__ = ["TIE_ULPS", "LIFT_ULPS", "covered_corners", "covered_light", "start_offsets"]

#: Float32 steps of a point's largest coordinate within which a surface counts as coincident
#: with it (a duplicate face), not as covering it.
TIE_ULPS = 1
#: Float32 steps of a point's largest coordinate its rays start off its surface (or half way to
#: the surface over it, if nearer): as near as Cycles' start, at the corner itself, as a ray off a
#: plane can start without meeting it again.
LIFT_ULPS = 16
#: Cosine rays per covered corner for the share of the open scene it sees.
OPEN_RAYS = 64


def covered_corners(ctx, elements, xv, nv, opened=None, buried=None):
    """The element corners lit at their own bake point (module docstring), or None:
    (p (K,) element, c (K,) corner 0..3, start (K, 3) where it is lit from, geo (K, 3) the
    corner triangle's unit normal). ``xv``, ``nv`` (V, 3): where each vertex was lit and
    its normal; ``opened`` (N,) 0 for elements the scene does not see: their corners at a
    vertex of an element it sees (a floor's under a block resting on it) are not looked at,
    they count in that vertex's mean; nor are the corners of ``buried`` (V,) bool vertices,
    which take the open side's light (:func:`.sides.buried_side`). None without Embree."""
    if not embree_available() or len(elements) == 0:
        return None
    key = cache_key(geometry_key(elements) + array_key(xv) + array_key(nv)
                    + (b"" if opened is None else array_key(np.asarray(opened, dtype=np.float64)))
                    + (b"" if buried is None else np.asarray(buried, bool).tobytes()), ("covered-corners",))
    code = cached(ctx.cache, key, lambda: _find(ctx, elements, xv, nv, opened, buried))
    if len(code) == 0:
        return None
    p, c = code[:, 0].astype(np.int64), code[:, 1].astype(np.int64)
    return p, c, code[:, 2:5], code[:, 5:8]


def _find(ctx, elements, xv, nv, opened, buried) -> np.ndarray:
    """(K, 8) rows (element, corner, start (3), geo (3)) of :func:`covered_corners`."""
    polys = elements.polys
    p, c = np.nonzero(polys >= 0)
    keep = np.ones(len(p), bool)
    if opened is not None:
        seen = np.asarray(opened)[p] > 0
        shared = np.zeros(len(elements.verts), bool)
        shared[polys[p[seen], c[seen]]] = True
        keep &= seen | ~shared[polys[p, c]]
    if buried is not None:
        keep &= ~np.asarray(buried, bool)[polys[p, c]]
    p, c = p[keep], c[keep]
    point = bake_points(elements, ctx.meshes, p, c)
    v = polys[p, c]
    tie = TIE_ULPS * 2.0 ** -23 * np.maximum(np.abs(point).max(axis=1), 1.0)
    geo = corner_normals(elements, p, c)
    eps = ray_offsets(ctx.patches, owner=elements.owner[p])
    fronts, scene = _fronts(ctx, elements)
    own = _face_keys(elements)
    origin = point + tie[:, None] * geo
    # the nearest surface above the point along its triangle's normal, within the ray offset
    up, t = scene.intersect(origin, geo, eps)
    up = np.asarray(up)
    above = up >= 0
    above[above] = own[fronts[up[above]]] != own[p[above]]
    gap = np.where(above, tie + np.asarray(t, dtype=np.float64), np.inf)
    # or the segment from the point to where the vertex's rays start crosses a surface
    seg = xv[v] + eps[:, None] * nv[v] - origin
    length = np.linalg.norm(seg, axis=1)
    hit, _ = scene.intersect(origin, seg / np.maximum(length, 1e-300)[:, None], length)
    hit = np.asarray(hit)
    crossed = (hit >= 0) & (length > 0)
    crossed[crossed] = own[fronts[hit[crossed]]] != own[p[crossed]]
    chosen = crossed | above
    if not chosen.any():
        return np.zeros((0, 9))
    start = point + np.minimum(np.minimum(eps, 0.5 * gap), LIFT_ULPS * tie / TIE_ULPS)[:, None] * geo
    return np.column_stack([p, c, start, geo])[chosen].astype(np.float64)


def bake_points(elements, meshes, p, c):
    """(K, 3) where Cycles bakes corner ``c`` (K,) of element ``p`` (K,). Blender gives a face
    corner one bake point, on the first of its loop triangles holding it (``object_bake_api.cc``
    ``bake_targets_populate_pixels_color_attributes``: "first triangle wins"), and Cycles moves it
    toward that triangle's centre by :data:`.lift.BAKE_NUDGE` of its largest coordinate (at least
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
    face holding it: a triangle's own, a quad's (0, 1, 2) for corners 0-2 and (0, 2, 3) for
    corner 3, or the first row of the mesh's ``face_triangles`` holding it, where that triangle
    has an area; None when there are none."""
    if not meshes:
        return None
    ks, cs = [], []
    size = float(np.linalg.norm(np.ptp(elements.verts, axis=0))) if len(elements.verts) else 1.0
    owner = elements.owner[p]
    for oi, m in enumerate(meshes):
        rows = np.flatnonzero(owner == oi)
        if not rows.size:
            continue
        face = elements.source_face[p[rows]].astype(np.int64)
        j = face_corners(m, face, x[rows], 1e-9 * size)
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
        V = np.asarray(m.verts, dtype=np.float64)[idx[off[face[ok]][:, None] + tri[ok]]]
        # a triangle of no area (a quad with two corners at one point) has no centre to move to
        area2 = np.linalg.norm(np.cross(V[:, 1] - V[:, 0], V[:, 2] - V[:, 0]), axis=1)
        edge2 = np.max([np.sum((V[:, i] - V[:, (i + 1) % 3]) ** 2, axis=1) for i in range(3)], axis=0)
        flat = area2 <= 1e-9 * edge2
        ks.append(rows[ok[~flat]])
        cs.append(V[~flat].mean(axis=1))
    if not ks:
        return None
    return np.concatenate(ks), np.concatenate(cs)


def _fronts(ctx, elements):
    """(rows (F,) of ``elements`` that are no back of an open surface (:mod:`..mesh.backs`),
    the Embree scene of those): Cycles has no backs, and a back lies a hair behind its face, over
    a surface the face touches."""
    meshes = ctx.meshes or ()
    backs = [i for i, m in enumerate(meshes) if getattr(m, "back_of", -1) >= 0]
    if not backs:
        return np.arange(len(elements)), embree_scene(elements)
    rows = np.flatnonzero(~np.isin(elements.owner, backs))
    sub = replace(elements, polys=elements.polys[rows], centers=elements.centers[rows],
                  normals=elements.normals[rows], areas=elements.areas[rows], rho=elements.rho[rows],
                  emission=elements.emission[rows], owner=elements.owner[rows],
                  source_face=elements.source_face[rows])
    return rows, embree_scene(sub)


def _face_keys(elements) -> np.ndarray:
    """(N,) int64 one key per (owner, source face) of the elements."""
    stride = int(elements.source_face.max(initial=0)) + 1
    return elements.owner.astype(np.int64) * stride + elements.source_face.astype(np.int64)


def covered_light(ctx, elements, xv, nv, light_v, creased=None, opened=None, buried=None):
    """(light (N, 4, 3), keep (N, 4)) as :func:`.crease.corner_light`'s, with the corners of
    :func:`covered_corners` lit on their own (module docstring); ``creased``: what
    :func:`.crease.corner_light` gave (None: every corner its vertex's ``light_v`` (V, 3) and
    all of its light reflected more than once). Returns ``creased`` itself when no corner is covered."""
    found = covered_corners(ctx, elements, xv, nv, opened, buried) if ctx.direct is not None else None
    if found is None:
        return creased
    p, c, start, geo = found
    shade, has = corner_shading_normals(elements, ctx.meshes, p, c)
    shade = geo if shade is None else np.where(has[:, None], shade, geo)
    shade = np.where((np.einsum("ij,ij->i", shade, geo) > 0)[:, None], shade, geo)
    D = ctx.direct.at(start, shade, "covered", eps=np.zeros(len(p)), facing=geo)
    reach = 0.05 * float(ctx.settings.patch_size or ctx.settings.element_size or 1.0)
    v = elements.polys[p, c]
    key = cache_key(geometry_key(elements) + array_key(start) + array_key(xv), ("covered-open", reach))

    def shares():
        scene = embree_scene(elements)
        here = open_fraction(elements, start, shade, scene, reach, rays=OPEN_RAYS, eps=np.zeros(len(p)))
        there = open_fraction(elements, xv[v], nv[v], scene, reach, rays=OPEN_RAYS,
                              eps=ray_offsets(ctx.patches, owner=elements.owner[p]))
        return np.minimum(1.0, here / np.maximum(there, 1.0 / OPEN_RAYS))
    k = cached(ctx.cache, key, shares)
    if creased is None:
        light = np.array(light_v, dtype=np.float64)[elements.corner_ids()]
        keep = np.ones(light.shape[:2])
    else:
        light, keep = np.array(creased[0], dtype=np.float64), np.array(creased[1], dtype=np.float64)
    tri = (elements.polys[p, 3] < 0) & (c == 2)
    for out, value in ((light, D), (keep, k)):
        out[p, c] = value
        out[p[tri], 3] = value[tri]
    return light, keep


def start_offsets(ctx, elements, points, normals) -> np.ndarray:
    """(P,) how far rays from ``points`` (P, 3) on the surfaces of ``elements`` start along
    their unit ``normals``: their object's ray offset (:meth:`.light.stage.DirectLight.offsets`),
    but half the way to a face over the point when one lies nearer (at least :data:`LIFT_ULPS`
    float32 steps), as :func:`covered_light` starts a covered corner's: the point where a buried
    vertex's edge meets what buries it (:func:`.sides.buried_side`) lies against that surface,
    and rays started past a face over it read the open side. Geometry only, cached."""
    eps = np.asarray(ctx.direct.offsets(points, normals), dtype=np.float64)
    if not embree_available() or not len(points):
        return eps

    def make():
        _, scene = _fronts(ctx, elements)
        tie = TIE_ULPS * 2.0 ** -23 * np.maximum(np.abs(points).max(axis=1), 1.0)
        hit, t = scene.intersect(points + tie[:, None] * normals, normals, eps)
        gap = np.where(np.asarray(hit) >= 0, tie + np.asarray(t, dtype=np.float64), np.inf)
        return np.minimum(eps, np.maximum(0.5 * gap, LIFT_ULPS * tie / TIE_ULPS))
    key = cache_key(geometry_key(elements) + array_key(points) + array_key(normals), ("start-offsets",))
    return cached(ctx.cache, key, make)
