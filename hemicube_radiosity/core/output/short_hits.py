"""Gather rays that land close by on a face whose corners lie far away read the direct light
where they land, not the corners' interpolation.

A face's corners say nothing of a point far inside it that something stands close over: the
back of a panel moulding 1.7 cm in front of a wall sees, a ray's length of 2 to 5 cm away, the
wall in the moulding's shadow, on triangles 0.8 m across whose corners are out in the lit room
(../shared/scenes' staircase hall). Interpolated, the wall there reads the room's light.
What stands that close over a point shades it more than its corners can tell: a ray whose
length is under 1 / :data:`RATIO` of its distance to the nearest corner of the face it lands on
(:func:`short_hits`) reads the exact reflected direct light ``rho * D`` of a small cell of that
face around its hit point (:class:`ShortCells`): cells a power of two across, the largest not
above the ray's length, so that the rays of neighbouring vertices, which land a little aside,
read the same points and the result stays smooth; one point a cell, lit once
(:meth:`.direct.DirectLight.at`, as the output's vertices are), cached with the geometry so a
relight finds it.
"""
from __future__ import annotations

import numpy as np

from ..mesh.patches import PatchSet
from .gather import patch_parameters, surface_uv

__all__ = ["RATIO", "MOST", "ShortCells", "short_hits"]

#: A hit is short when its ray is shorter than its distance to the nearest corner of its face
#: over this.
RATIO = 4.0
#: The most cells across a face's side (the smallest cell a face is cut into).
MOST = 1024
#: Hits looked at at once (their corners are (n, 4, 3) float64).
CHUNK = 1 << 18
LEVELS = 64          # cell sizes 2^(k - 32) m, k in [0, LEVELS)


def _keys(elements: PatchSet, params, xv, hits, ratio):
    """(short (h,) bool, keys (h,) int64) of the hits ``hits`` (h, >= 5) rows ``(point, element,
    x, y, z)``: whether each is short (see the module) and, where it is, its cell's key
    ``((element * LEVELS + level) * MOST + i) * MOST + j``, the cell ``(i, j)`` of side
    ``2^(level - 32)`` (m) along the element's edges e1, e2 from its first corner."""
    row, pid = hits[:, 0].astype(np.int64), hits[:, 1].astype(np.int64)
    y = hits[:, 2:5].astype(np.float64)
    t = np.linalg.norm(y - xv.take(row, axis=0), axis=1)
    ids = elements.polys.take(pid, axis=0)
    ids = np.where(ids < 0, ids[:, :1], ids)
    d2 = np.full(len(y), np.inf)
    for c in range(4):
        d = y - elements.verts.take(ids[:, c], axis=0)
        d2 = np.minimum(d2, np.einsum("ij,ij->i", d, d))
    short = ratio * t < np.sqrt(d2)
    _, e1, e2, _, _ = params
    l1 = np.linalg.norm(e1.take(pid, axis=0), axis=1)
    l2 = np.linalg.norm(e2.take(pid, axis=0), axis=1)
    # a cell a power of two across, not above the ray's length, nor under MOST cells a side
    least = np.maximum(l1, l2) / MOST
    level = np.floor(np.log2(np.maximum(np.maximum(t, least), 1e-300)))
    level = np.clip(level, -32, LEVELS - 33)
    size = np.exp2(level)
    u, v = surface_uv(params, pid, y)
    i = np.minimum((u * l1 / size).astype(np.int64), MOST - 1)
    j = np.minimum((v * l2 / size).astype(np.int64), MOST - 1)
    keys = ((pid * LEVELS + (level.astype(np.int64) + 32)) * MOST + i) * MOST + j
    return short, keys


def short_hits(elements: PatchSet, xv, H, ratio=RATIO, exclude=None) -> np.ndarray:
    """(h,) bool: the gather's hits ``H`` (h, >= 5) from the points ``xv`` (P, 3) whose ray is
    short for the element it lands on (see the module); none on elements ``exclude`` (N,) bool."""
    params = patch_parameters(elements)
    out = np.zeros(len(H), bool)
    for s in range(0, len(H), CHUNK):
        out[s:s + CHUNK] = _keys(elements, params, xv, H[s:s + CHUNK], ratio)[0]
    if exclude is not None:
        out &= ~exclude[H[:, 1].astype(np.int64)]
    return out


class ShortCells:
    """The cells the short hits of a gather land in (see the module): ``keys`` (c,) int64
    ascending, their centres ``points`` (c, 3), the elements ``faces`` (c,) they lie on and those
    elements' ``normals`` (c, 3). Geometry only: cache it, and light its points anew on a
    relight."""

    def __init__(self, elements: PatchSet, xv, H, ratio=RATIO, exclude=None):
        self.ratio = ratio
        params = patch_parameters(elements)
        found = []
        for s in range(0, len(H), CHUNK):
            h = H[s:s + CHUNK]
            short, keys = _keys(elements, params, xv, h, ratio)
            if exclude is not None:
                short &= ~exclude[h[:, 1].astype(np.int64)]
            found.append(np.unique(keys[short]))
        self.keys = np.unique(np.concatenate(found)) if found else np.zeros(0, np.int64)
        self.points, self.faces = self._centres(elements, params, self.keys)
        self.normals = elements.normals[self.faces]

    @staticmethod
    def _centres(elements, params, keys):
        """(points (c, 3), elements (c,)) of the cells ``keys``: each cell's centre (clamped to
        its element's edges, folded into a triangle as :func:`.gather.surface_weights` folds)."""
        j, r = keys % MOST, keys // MOST
        i, r = r % MOST, r // MOST
        level, pid = r % LEVELS - 32, r // LEVELS
        size = np.exp2(level.astype(np.float64))
        c0, e1, e2, _, tri = params
        E1, E2 = e1[pid], e2[pid]
        u = np.clip((i + 0.5) * size / np.maximum(np.linalg.norm(E1, axis=1), 1e-300), 0.0, 1.0)
        v = np.clip((j + 0.5) * size / np.maximum(np.linalg.norm(E2, axis=1), 1e-300), 0.0, 1.0)
        t = tri[pid]
        over = np.where(t, np.maximum(u + v - 1, 0) / 2, 0.0)
        u, v = u - over, v - over
        corners = elements.corners(pid)
        quad = corners[:, 0] + u[:, None] * (corners[:, 1] - corners[:, 0]) \
            + v[:, None] * (corners[:, 3] - corners[:, 0]) \
            + (u * v)[:, None] * (corners[:, 2] - corners[:, 1] - corners[:, 3] + corners[:, 0])
        flat = c0[pid] + u[:, None] * E1 + v[:, None] * E2
        return np.where(t[:, None], flat, quad), pid

    def columns(self, elements: PatchSet, params, xv, hits):
        """(short (h,) bool, cell index (h,)) of the hits ``hits`` (h, >= 5): whether each is a
        short hit whose cell is one of these, and which (where not, 0)."""
        short, keys = _keys(elements, params, xv, hits, self.ratio)
        at = np.minimum(np.searchsorted(self.keys, keys), max(len(self.keys) - 1, 0))
        short &= len(self.keys) > 0
        if len(self.keys):
            short &= self.keys[at] == keys
        return short, np.where(short, at, 0)

