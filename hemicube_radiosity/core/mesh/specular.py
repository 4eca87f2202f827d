# SPDX-License-Identifier: GPL-3.0-or-later
"""Light off specular and metallic layers, carried by the solve as diffuse light.

A metal floor reflects no diffuse light (Cycles' DIFFUSE bake of it is black), but in a render
the light it mirrors reaches the walls: with the floor's reflectance left out, a room with a
metallic floor bakes half as bright as Cycles draws it. The paper's solve knows one reflectance
per patch, spread as a Lambertian. So with ``specular_bounce`` a face bounces

    rho_solve = rho_diffuse + rho_glossy          (clipped below 1)

(``MeshInput.face_glossy``: Cycles' glossy albedo of the material at normal incidence) while its
output shows only its diffuse part: the corners keep ``rho_diffuse`` as their own colour
(``MeshInput.corner_rho``), which the output stage multiplies by the light arriving
(:func:`..output.stage.vertex_stage`). The energy of the specular bounce is kept, its direction
is not: a mirror's reflection of a lamp becomes light spread over the room.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from .patches import RHO_MAX, MeshInput

__all__ = ["with_specular_bounce"]


def with_specular_bounce(meshes) -> list:
    """``meshes`` with each face's glossy reflectance added to what the solve bounces; the
    diffuse colour kept at the corners for the output. Meshes without a glossy layer (``face_glossy``
    None or 0) are returned as they are, the same objects."""
    return [_bounced(m) for m in meshes]


def _bounced(m: MeshInput) -> MeshInput:
    g = m.face_glossy
    if g is None or not np.any(np.asarray(g) > 0):
        return m
    counts = np.diff(m.face_offsets)
    shown = m.corner_rho if m.corner_rho is not None else np.repeat(m.face_rho, counts, axis=0)
    rho = np.clip(np.asarray(m.face_rho, float) + np.asarray(g, float), 0.0, RHO_MAX)
    return replace(m, face_rho=rho, corner_rho=np.asarray(shown, float), face_glossy=None)
