# SPDX-License-Identifier: GPL-3.0-or-later
"""Light off specular and metallic layers: which faces mirror it, which spread it as diffuse.

A metal floor reflects no diffuse light (Cycles' DIFFUSE bake of it is black), but in a render
the light it mirrors reaches the walls: with the floor's reflectance left out, a room with a
metallic floor bakes half as bright as Cycles draws it. ``MeshInput.face_glossy`` (F, 3) is
Cycles' glossy albedo of each face's material at normal incidence. With ``specular_bounce``:

* faces whose glossy albedo reaches :data:`..form_factors.glossy.GLOSSY_MIN` in some band (a
  metal, a lacquer) keep it as ``face_glossy``: the solve carries their light with its direction,
  by extended form factors (:mod:`..form_factors.glossy`), Embree's rays;
* the others (Blender's default material, 0.037), and every face where Embree is missing, add it
  to the reflectance the solve bounces, spread as a Lambertian::

      rho_solve = rho_diffuse + rho_glossy          (clipped below 1)

  (the energy of the specular bounce kept, not its direction: a mirror's reflection of a lamp
  becomes light spread over the room).

Either way the output shows each face's diffuse part only: a spread face's corners keep
``rho_diffuse`` as their own colour (``MeshInput.corner_rho``), which the output stage
multiplies by the light arriving (:func:`..output.stage.vertex_stage`).
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from .patches import RHO_MAX, MeshInput

__all__ = ["with_specular_bounce", "patch_glossy"]


def with_specular_bounce(meshes, directional: bool = False, threshold: float = 0.1) -> list:
    """``meshes`` with each face's glossy reflectance added to what the solve bounces (the
    diffuse colour kept at the corners for the output), except, with ``directional``, faces whose
    glossy albedo reaches ``threshold`` in some band: those keep it as ``face_glossy`` (and only
    those: the others' is 0 there). Meshes without a glossy layer (``face_glossy`` None or 0)
    are returned as they are, the same objects."""
    return [_bounced(m, directional, threshold) for m in meshes]


def _bounced(m: MeshInput, directional: bool, threshold: float) -> MeshInput:
    g = m.face_glossy
    if g is None or not np.any(np.asarray(g) > 0):
        return m
    g = np.asarray(g, float)
    mirror = (g.max(axis=1) >= threshold) if directional else np.zeros(len(g), bool)
    kept = np.where(mirror[:, None], g, 0.0)
    if mirror.all():
        return replace(m, face_glossy=kept)
    counts = np.diff(m.face_offsets)
    shown = m.corner_rho if m.corner_rho is not None else np.repeat(m.face_rho, counts, axis=0)
    rho = np.clip(np.asarray(m.face_rho, float) + np.where(mirror[:, None], 0.0, g), 0.0, RHO_MAX)
    return replace(m, face_rho=rho, corner_rho=np.asarray(shown, float),
                   face_glossy=kept if mirror.any() else None)


def patch_glossy(meshes, patches) -> np.ndarray | None:
    """(N, 3) the glossy albedo of every patch (its source face's ``face_glossy``), or None when
    no mesh keeps one."""
    meshes = list(meshes or ())
    if not any(getattr(m, "face_glossy", None) is not None for m in meshes):
        return None
    out = np.zeros((len(patches), 3))
    owner = np.asarray(patches.owner, np.int64)
    face = np.asarray(patches.source_face, np.int64)
    for i, m in enumerate(meshes):
        if m.face_glossy is None:
            continue
        sel = np.flatnonzero(owner == i)
        out[sel] = np.asarray(m.face_glossy, float)[face[sel]]
    return out if np.any(out > 0) else None
