# SPDX-License-Identifier: GPL-3.0-or-later
"""Lightmap texels under a surface closer than our rays start: lit where Cycles' rays start.

Cycles bakes a texel at its point on the triangle and starts its rays there, skipping only their
own triangle (``kernel/integrator/init_from_bake.h``); ours start a ray offset off the point
(:func:`..rays.ray_offsets`: 1e-5 of the object's diagonal, 0.2 mm in the living room). Where
another face lies over the point within that offset (the living room's strips of a floor 0.13 mm
under the slab over them, a bevel's foot tucked under the face it meets), ours pass it and read
the open sun and sky; Cycles' meet it, and the texel is dark (1.09 ours, 0.000 Cycles). As
:mod:`.covered` does for an element corner: a texel's point is *covered* where another face (no
back of an open surface, :mod:`..mesh.backs`, which Cycles has not) lies over it along its
triangle's normal within its object's ray offset, going on past its own face's hits (a warped
face's elements run a hair off Blender's triangle). Faces within :data:`.covered.TIE_ULPS`
float32 steps of the point (a duplicate face, modelled onto another) cover nothing, as they
cover no corner: where two faces coincide Cycles' bake is black or half black by float32's tie,
and the light there is the open room's (``tests/blender/test_lightmap_coincident.py``).

A covered point's rays start :data:`.covered.LIFT_ULPS` float32 steps off it (at most half way
to the face over it: :meth:`Cover.lifts`), for its direct light (:func:`.texels.as_cycles`), and
its light reflected more than once is scaled by the share of the open scene seen from there
against the share seen from where its rays start otherwise (:meth:`Cover.keep`, as
:func:`.covered.covered_light` scales a covered corner's).

The same rays find where a texel lies among its face's elements when the nearest centres
mislead :func:`.interpolate.locate` (:meth:`Cover.relocate`: a bent face cut into slivers).
Geometry only; world units.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..mesh.patches import PatchSet
from ..rays import embree_available, embree_scene, ray_offsets
from ..util.geometry import bilinear
from .covered import LIFT_ULPS, TIE_ULPS, front_scene, open_share, walk_along
from .interpolate import inverse_bilinear

__all__ = ["Cover", "lifts_of", "apart", "OPEN_RAYS", "OFF"]

#: Cosine rays per covered texel for the share of the open scene it sees (a corner casts 64:
#: texels are many, their keep is mostly 0 under a face; the living room's Cube lightmap read
#: 4.01% RMS against Cycles with every keep 1, 4.00% with 64 rays).
OPEN_RAYS = 16
#: A located texel whose element's point lies farther off it than this share of the element's
#: size is found again (:meth:`Cover.relocate`).
OFF = 1e-3


@dataclass
class Cover:
    """What covers the texels of object ``owner`` among the bake's output ``elements``.

    ``backs``: the owners that are backs of open surfaces (:mod:`..mesh.backs`: no cover);
    ``reach``: world units within which a ray that meets a surface lends nothing to the open
    share (:meth:`keep`; :func:`.covered.covered_light`'s, a twentieth of the patch size)."""

    elements: PatchSet
    owner: int
    backs: tuple = ()
    reach: float = 0.05
    _scenes: dict = field(default_factory=dict, repr=False)

    @classmethod
    def of(cls, result, owner) -> "Cover":
        """The cover of object ``owner``'s texels in a bake's ``result``
        (:class:`..pipeline.BakeResult`: its output elements, backs and patch size)."""
        size = float(result.settings.patch_size or result.settings.element_size or 1.0)
        backs = tuple(j for j, b in enumerate(result.back_of) if b >= 0)
        return cls(result.elements, int(owner), backs, 0.05 * size)

    def _fronts(self):
        """(rows of the elements that are no back, their Embree scene), made once."""
        if "fronts" not in self._scenes:
            back = np.isin(self.elements.owner, np.asarray(self.backs, dtype=np.int64))
            self._scenes["fronts"] = front_scene(self.elements, np.flatnonzero(~back) if back.any() else None)
        return self._scenes["fronts"]

    def _keys(self, owner, faces):
        """(n,) int64 one key per (owner, source face): ``owner`` (n,), ``faces`` (n,)."""
        stride = int(max(self.elements.source_face.max(initial=0), np.max(faces, initial=0))) + 1
        return np.asarray(owner, dtype=np.int64) * stride + np.asarray(faces, dtype=np.int64)

    def lifts(self, points, normals, faces) -> np.ndarray:
        """(n,) how far off each of ``points`` (n, 3) (unit triangle ``normals`` (n, 3), on source
        ``faces`` (n,) of the object) its rays start where another face covers it (module
        docstring); NaN where none does. All NaN without Embree."""
        points = np.asarray(points, dtype=np.float64)
        normals = np.asarray(normals, dtype=np.float64)
        out = np.full(len(points), np.nan)
        if not len(points) or not embree_available() or not len(self.elements):
            return out
        rows, scene = self._fronts()
        keys = self._keys(self.elements.owner[rows], self.elements.source_face[rows])
        own = self._keys(np.full(len(points), self.owner), faces)
        tie = TIE_ULPS * 2.0 ** -23 * np.maximum(np.abs(points).max(axis=1), 1.0)
        eps = ray_offsets(self.elements, owner=np.full(len(points), self.owner))
        gap = walk_along(scene, keys, own, points + tie[:, None] * normals, normals, eps, tie)[0]
        covered = np.isfinite(gap)
        lift = np.minimum(np.minimum(eps, 0.5 * (gap + tie)), LIFT_ULPS * tie / TIE_ULPS)
        out[covered] = lift[covered]
        return out

    def keep(self, points, normals, shading, lift) -> np.ndarray:
        """(n,) the share of the light reflected more than once kept at ``points`` (n, 3) whose
        rays start ``lift`` (n,) off them along their triangle ``normals`` (1 where ``lift`` is
        NaN): the open share seen from there, cosine about ``shading`` (n, 3), over the share
        seen from a ray offset off the point (at least :data:`.covered.OPEN_FLOOR`), at most 1:
        :func:`.covered.open_share`, as a covered corner keeps it."""
        lift = np.asarray(lift, dtype=np.float64)
        out = np.ones(len(lift))
        c = np.flatnonzero(np.isfinite(lift))
        if not c.size:
            return out
        p, n, s = (np.asarray(a, dtype=np.float64)[c] for a in (points, normals, shading))
        s = np.where((np.einsum("ij,ij->i", s, n) > 0)[:, None], s, n)
        there = (p, s, ray_offsets(self.elements, owner=np.full(c.size, self.owner)))
        out[c] = open_share(self.elements, embree_scene(self.elements), self.reach, OPEN_RAYS,
                            (p + lift[c, None] * n, s), there)
        return out

    def relocate(self, points, normals, faces, idx, uv):
        """(idx (n,), uv (n, 2)): ``points`` (n, 3) (unit triangle ``normals``, source ``faces``
        (n,)) located in elements ``idx`` at bilinear ``uv`` (:func:`.lightmap.locate_texels`),
        those whose element's point at ``uv`` lies more than :data:`OFF` of its size off them
        found again: the element of their own face that a ray along the normal meets at the
        point (from the element's size over it). Among a bent face's slivers, 42 cm by 2 mm
        across a bevel strip 3 cm wide (the living room's), the nearest centres are those of
        slivers a column over, and a texel read a sliver 2 cm away across the strip: the dark
        foot's light on the lit edge and the other way round (6,006 of its 507,328 texels)."""
        idx, uv = np.array(idx, dtype=np.int64), np.array(uv, dtype=np.float64)
        if not len(idx) or not embree_available():
            return idx, uv
        points, normals = np.asarray(points, dtype=np.float64), np.asarray(normals, dtype=np.float64)
        C = self.elements.corners()
        off = np.linalg.norm(bilinear(C[idx], uv[:, :1], uv[:, 1:]) - points, axis=1)
        size = np.sqrt(self.elements.areas[idx])
        bad = np.flatnonzero(off > OFF * size)
        if not bad.size:
            return idx, uv
        rows, scene = self._fronts()
        keys = self._keys(self.elements.owner[rows], self.elements.source_face[rows])
        own = self._keys(np.full(bad.size, self.owner), np.asarray(faces)[bad])
        tie = TIE_ULPS * 2.0 ** -23 * np.maximum(np.abs(points[bad]).max(axis=1), 1.0)
        h, n = size[bad], normals[bad]
        row = walk_along(scene, keys, own, points[bad] + h[:, None] * n, -n, 2.0 * h, tie, same=True)[1]
        bad, row = bad[row >= 0], rows[row[row >= 0]]
        u, v = (np.clip(w, 0.0, 1.0) for w in inverse_bilinear(C[row], points[bad]))
        now = np.linalg.norm(bilinear(C[row], u[:, None], v[:, None]) - points[bad], axis=1)
        better = now < off[bad]
        idx[bad[better]] = row[better]
        uv[bad[better]] = np.stack([u, v], 1)[better]
        return idx, uv


def lifts_of(cover, points, normals, faces):
    """(n,) :meth:`Cover.lifts` of the texel ``points`` (n, 3) (triangle ``normals``,
    source ``faces`` (n,)), or None where no point is covered (or no ``cover``, no ``faces``)."""
    if cover is None or faces is None:
        return None
    lift = cover.lifts(points, normals, faces)
    return lift if np.isfinite(lift).any() else None


def apart(faces, lift):
    """(n,) ``faces`` with each covered texel (``lift`` finite; None: none) a face of its own:
    :func:`.texels.by_source` interpolates none across it, nor it from its neighbours."""
    if lift is None:
        return faces
    faces = np.array(faces, dtype=np.int64)
    c = np.flatnonzero(np.isfinite(lift))
    faces[c] = int(faces.max(initial=0)) + 1 + np.arange(c.size)
    return faces
