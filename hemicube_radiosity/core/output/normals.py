"""Shading normals at the output vertices: the normal Cycles shades with, not the faces' own.

A smooth-shaded mesh, and more so one with custom normals (a bevel's Harden Normals, weighted
normals, normals from a game asset), is shaded in Cycles with the normal interpolated over each
face from its corners, and a diffuse surface's light is the cosine to that normal. The output
vertices took the mean of their elements' geometric normals: on a bevelled room whose corner
normals lean 10-30 degrees off their small faces (a real scene's walls), the direct sun at
those corners came out up to 2x off Cycles' (24.5% RMS over the scene; 11.2% with these).

Here each output vertex takes its source face's corner normals (``MeshInput.corner_normal``)
interpolated at its position: bilinearly over a quad (inverse bilinear coordinates), by
barycentric weights over a triangle, by inverse squared distances over an n-gon. The vertex's
positions, its elements and the solve stay geometric; where a mesh has no corner normals, or the
shading normal leans :data:`MAX_LEAN` or more off the geometric one, the geometric one is kept.
Unitless; world space.
"""
from __future__ import annotations

import numpy as np

from ..mesh.patches import PatchSet, read_only
from ..runtime.cache import Memo, frozen
from ..util.geometry import barycentric
from .interpolate import inverse_bilinear

__all__ = ["shading_normals", "corner_shading_normals", "MAX_LEAN"]

#: Degrees: a shading normal leaning this far off the vertex's geometric normal is not used.
MAX_LEAN = 89.0


def shading_normals(elements: PatchSet, meshes, normals) -> np.ndarray:
    """(V, 3) unit normals at the vertices of the output ``elements``: ``normals`` (V, 3) (the
    geometric ones) with the source meshes' interpolated corner normals where they have them
    (module docstring). ``meshes``: the bake's :class:`.patches.MeshInput` list, indexed by
    ``elements.owner``. Returns ``normals`` itself when no mesh has corner normals."""
    if meshes is None or all(getattr(m, "corner_normal", None) is None for m in meshes):
        return normals
    held = tuple(a for m in meshes for a in (m.corner_normal, m.verts, m.face_offsets, m.face_indices))
    if not all(read_only(a) for a in held):           # may change in place: made every time
        return _shading_normals(elements, meshes, normals)

    def make():
        return frozen(_shading_normals(elements, meshes, normals))
    # geometry only: a relight's elements, normals and meshes' arrays are the same objects
    return _SHADED.of((elements.verts, elements.polys, elements.owner, elements.source_face, normals) + held, make)


_SHADED = Memo(4)        # the elements', normals' and meshes' arrays -> shading_normals


def _shading_normals(elements, meshes, normals):
    out = np.array(normals, dtype=np.float64, copy=True)
    polys = elements.polys
    p, c = np.nonzero(polys >= 0)
    v = polys[p, c]
    first = np.full(len(elements.verts), -1, dtype=np.int64)
    first[v[::-1]] = p[::-1]                         # an element of each vertex (its first)
    has = first >= 0
    owner = np.full(len(first), -1, dtype=np.int64)
    owner[has] = elements.owner[first[has]]
    cos_max = np.cos(np.radians(MAX_LEAN))
    for oi, m in enumerate(meshes):
        cn = getattr(m, "corner_normal", None)
        if cn is None:
            continue
        vs = np.flatnonzero(owner == oi)
        if not vs.size:
            continue
        face = elements.source_face[first[vs]].astype(np.int64)
        n = _at(m, np.asarray(cn, dtype=np.float64), face, elements.verts[vs])
        length = np.linalg.norm(n, axis=1)
        n = n / np.maximum(length, 1e-300)[:, None]
        ok = (length > 1e-12) & (np.einsum("ij,ij->i", n, out[vs]) > cos_max)
        out[vs[ok]] = n[ok]
    return out


def corner_shading_normals(elements: PatchSet, meshes, p, c, at=None):
    """(shading (K, 3), has (K,) bool) at corners ``c`` (K,) of elements ``p`` (K,): each corner's
    own source face's corner normals interpolated at its vertex, or at the points ``at`` (K, 3)
    on the face (unit; Cycles shades that face's triangles with them), ``has`` False (and the row
    0) where the element's mesh has no corner normals; (None, None) when no mesh has any."""
    if meshes is None or all(getattr(m, "corner_normal", None) is None for m in meshes):
        return None, None
    p = np.asarray(p, dtype=np.int64)
    out = np.zeros((len(p), 3))
    has = np.zeros(len(p), bool)
    owner = elements.owner[p]
    for oi, m in enumerate(meshes):
        cn = getattr(m, "corner_normal", None)
        rows = np.flatnonzero(owner == oi) if cn is not None else ()
        if not len(rows):
            continue
        x = elements.verts[elements.polys[p[rows], np.asarray(c)[rows]]] if at is None else np.asarray(at)[rows]
        n = _at(m, np.asarray(cn, dtype=np.float64), elements.source_face[p[rows]].astype(np.int64), x)
        length = np.linalg.norm(n, axis=1)
        ok = length > 1e-12
        out[rows[ok]] = n[ok] / length[ok, None]
        has[rows[ok]] = True
    return out, has


def _at(mesh, cn, face, x) -> np.ndarray:
    """(n, 3) the corner normals ``cn`` (L, 3) of ``mesh``'s faces ``face`` (n,) interpolated at
    the points ``x`` (n, 3) on them (not normalised)."""
    off = np.asarray(mesh.face_offsets, dtype=np.int64)
    idx = np.asarray(mesh.face_indices, dtype=np.int64)
    verts = np.asarray(mesh.verts, dtype=np.float64)
    start, size = off[face], off[face + 1] - off[face]
    out = np.zeros((len(face), 3))
    for k in np.unique(size):
        s = np.flatnonzero(size == k)
        loops = start[s][:, None] + np.arange(k)[None, :]
        X, N = verts[idx[loops]], cn[loops]                   # (m, k, 3)
        if k == 3:
            out[s] = _barycentric(X, N, x[s])
        elif k == 4:
            u, w = inverse_bilinear(X, x[s])
            u, w = np.clip(u, 0.0, 1.0)[:, None], np.clip(w, 0.0, 1.0)[:, None]
            out[s] = (1 - u) * (1 - w) * N[:, 0] + u * (1 - w) * N[:, 1] + u * w * N[:, 2] + (1 - u) * w * N[:, 3]
        else:                                                 # an n-gon: inverse squared distances
            d2 = np.einsum("mkj,mkj->mk", X - x[s][:, None], X - x[s][:, None])
            w = 1.0 / np.maximum(d2, 1e-30)
            out[s] = np.einsum("mk,mkj->mj", w, N)
    return out


def _barycentric(X, N, x) -> np.ndarray:
    """(m, 3) ``N`` (m, 3, 3) at the corners of triangles ``X`` (m, 3, 3) weighted by the
    barycentric coordinates of ``x`` (m, 3), clipped to the triangle."""
    w = np.clip(barycentric(X, x), 0.0, 1.0)
    w /= np.maximum(w.sum(axis=1, keepdims=True), 1e-300)
    return np.einsum("mk,mkj->mj", w, N)
