"""Values at the corners of the output elements, and sums over each element's corners.

An element is a quad or a triangle (``polys`` (N, 4), -1 for a triangle's fourth corner).
:func:`corner_values` and :func:`vertex_mean` carry the source meshes' corner colours (a
texture) to the output vertices; :func:`corner_columns` and :func:`corner_sum` sum a vertex
field (V,) or (V, k) over each element's corners a column at a time, bit for bit as the
(N, 4) array's sum over its corners, for the elements' light (:mod:`.abrupt`, :mod:`.shine`).
"""
from __future__ import annotations

import numpy as np

from ..mesh.patches import PatchSet
from ..mesh.patches import meshes_key
from ..runtime.cache import Memo, array_key, cache_key, cached, frozen, geometry_key
from ..util.unique import unique_rows

__all__ = ["corner_values", "vertex_mean", "corner_columns", "corner_sum"]


def corner_values(elements: PatchSet, meshes, which, cache=None) -> np.ndarray | None:
    """(N, 4, 3) ``which`` ('rho' or 'emission') at every corner of the output ``elements``: the
    source mesh's corner value (``MeshInput.corner_<which>``) where an element corner is a corner
    of its source face, elsewhere the mean of its source face's corner values (the face's own
    value where the mesh has none); None when no mesh has corner values. (The mean, not the
    element's own value: with a specular bounce (:mod:`..mesh.specular`) the faces' values are
    what the solve bounces, the corners' what the surface shows.) ``cache``: where the
    geometry-only part (which source corner each element corner is: :func:`_corner_slots`) is
    kept (a relight's colours change, not that)."""
    if meshes is None or all(getattr(m, "corner_" + which) is None for m in meshes):
        return None
    vals, means = [], []
    for m in meshes:
        sizes = np.diff(m.face_offsets)
        v = getattr(m, "corner_" + which)
        per_face = np.asarray(getattr(m, "face_" + which), float)
        if v is None:
            v = per_face[np.repeat(np.arange(sizes.size), sizes)]
        else:
            v = np.asarray(v, float)
            per_face = np.add.reduceat(v, m.face_offsets[:-1], axis=0) / sizes[:, None]
        vals.append(v)
        means.append(per_face)
    means, vals = np.concatenate(means), np.concatenate(vals)
    found, own_face = _corner_slots(elements, meshes, cache)
    out = np.where((found >= 0)[:, None], vals[np.maximum(found, 0)], np.repeat(means[own_face], 4, axis=0))
    return out.reshape(len(elements), 4, 3)


_SLOTS = Memo(4)       # (elements' arrays), meshes' geometry -> _corner_slots (rho and emission ask)


def _corner_slots(elements, meshes, cache=None):
    """(found (N * 4,) the source corner (over the meshes' corners, in order) at each element
    corner, -1 where it is none; own_face (N,) each element's face over the meshes' faces):
    geometry only, made once per elements and meshes in this process and kept in ``cache``."""
    def make():
        keys, first = [], [0]
        for oi, m in enumerate(meshes):
            sizes = np.diff(m.face_offsets)
            face = np.repeat(np.arange(sizes.size), sizes)
            pos = np.asarray(m.verts, float)[m.face_indices]
            keys.append(np.column_stack([np.full(face.size, oi), face, pos]))
            first.append(first[-1] + sizes.size)
        keys = np.concatenate(keys)
        ek = np.concatenate([np.repeat(np.column_stack([elements.owner, elements.source_face]), 4, axis=0),
                             elements.verts[elements.corner_ids().reshape(-1)]], axis=1)
        _, inv = unique_rows(np.concatenate([keys, ek]), return_inverse=True)
        inv = inv.reshape(-1)
        slot = np.full(inv.max() + 1, -1)
        slot[inv[:len(keys)]] = np.arange(len(keys))
        return frozen(slot[inv[len(keys):]], np.asarray(first)[elements.owner] + elements.source_face)
    mk = meshes_key(meshes)
    arrays = (elements.verts, elements.polys, elements.owner, elements.source_face)

    def stored():
        if cache is None:
            return make()
        key = cache_key(geometry_key(elements) + mk + array_key(elements.owner) + array_key(elements.source_face),
                        ("corner-slots",))
        return tuple(cached(cache, key, make))
    return _SLOTS.of(arrays, stored, mk)


def vertex_mean(elements: PatchSet, per_corner) -> np.ndarray:
    """(V, 3) mean over each vertex's element corners of a (N, 4, 3) per-corner array."""
    p, c = np.nonzero(elements.polys >= 0)
    v = elements.polys[p, c]
    V = len(elements.verts)
    cnt = np.maximum(np.bincount(v, minlength=V), 1)
    return np.stack([np.bincount(v, weights=per_corner[p, c, k], minlength=V) for k in range(3)], 1) / cnt[:, None]


def corner_columns(elements, cache=None):
    """(cols (4, N) intp, quad (N,) float, count (N,) float, quad3 (N, 3), count3 (N, 3)): each
    element's corner vertices, one contiguous row per corner (a triangle's fourth is its first),
    1.0 where the fourth is a corner, and how many corners, the last two also repeated over
    three bands (for (N, 3) values: faster than a (N, 1) factor broadcast along the short
    axis): geometry only, kept in ``cache`` (a relight reads its elements' light through them)."""
    def make():
        polys = elements.polys
        quad = (polys[:, 3] >= 0).astype(np.float64)
        cols = np.ascontiguousarray(np.where(polys < 0, polys[:, :1], polys).T, dtype=np.intp)
        count = (polys >= 0).sum(axis=1).astype(np.float64)
        return (cols, quad, count) + tuple(np.ascontiguousarray(np.repeat(a[:, None], 3, axis=1))
                                           for a in (quad, count))
    if cache is None:
        return make()
    return cached(cache, cache_key(geometry_key(elements), ("corner-columns",)), make)


def corner_sum(values, cols, quad, quad3=None):
    """Each element's corners of ``values`` (V,) or (V, k) summed in order, one corner at a
    time, the fourth times ``quad`` (as the (N, 4) array of corners times their validity sums
    over its corners, bit for bit: a triangle adds 0), from :func:`corner_columns`. Whole
    columns at a time: summing the (N, 4) array over its short axis after taking
    ``values[polys]`` is much slower (:func:`.shine.hot_elements`, :func:`.shine.mean_light`
    run it every relight). ``quad3``: ``quad`` over three bands, for (N, 3) values."""
    q = quad if values.ndim == 1 else quad3 if quad3 is not None and values.shape[1] == 3 else quad[:, None]
    total = values.take(cols[0], axis=0) + values.take(cols[1], axis=0)
    total += values.take(cols[2], axis=0)
    total += values.take(cols[3], axis=0) * q
    return total
