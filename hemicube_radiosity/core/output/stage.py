"""The output stage: radiosity at the vertices of the mesh that is written.

The output mesh is the patches themselves, or (``settings.element_size`` finer than the patches)
*elements*: the input meshes cut finer, as the paper's "finer elements take detail from a coarse
patch solution". Per output vertex (V, 3), radiance units:

    B_v = E_v + rho_v * D_v + R_v

with D_v the exact direct light at the vertex (:class:`.light.direct.DirectLight`) and R_v the
light reflected more than once, from the patch solution: averaged to the vertices as in the paper,
then for elements gathered by cosine rays that read it where they land (needs Embree) or
interpolated bilinearly (:mod:`.indirect`). A scene too dense for elements (the 'auto' detail
size found none) gathers the same way at its faces' own vertices where the solve grouped them
(:func:`.indirect.gathers_faces`).

Here only the stage; beside it: the elements' geometry (:mod:`.mesh.elements`), what the scene
sees of them (:mod:`.sides`), the gather and interpolation (:mod:`.indirect`, :mod:`.gather`,
:mod:`.interpolate`) with its abrupt elements (:mod:`.abrupt`) and what shines (:mod:`.shine`),
the paper's vertex rule (:mod:`.vertex`) and corner colours (:mod:`.corners`).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..form_factors.glossy import mirrored_arrival
from ..light.emitters import vertex_frames
from ..mesh.elements import cut_elements
from ..rays import embree_available
from ..runtime.cache import array_key, frozen
from .corners import corner_values, vertex_mean
from .covered import covered_light, start_offsets
from .crease import corner_light
from .normals import shading_normals
from .indirect import element_indirect, gather_finds_world, gathered_sky, gathers_faces, start_gather
from .sides import buried_side, open_elements, sided_mesh
from .vertex import exposure, fill_buried, frames, vertex_radiosity

__all__ = ["vertex_stage"]


@dataclass
class _AtVertices:
    """What the stage finds at the V output vertices (``ctx.elements.verts``).

    Attributes
    ----------
    xv, nv : ndarray
        (V, 3) where each vertex is evaluated (world units) and its unit shading normal there.
    rho_v : ndarray
        (V, 3) reflectivity of each vertex (its elements' mean, :func:`.vertex.frames`).
    opened : ndarray or None
        (N,) 1 for an element the scene sees (:func:`.sides.open_elements`); None without Embree.
    D : ndarray
        (V, 3) direct light arriving (radiance: irradiance / pi).
    rest : ndarray
        (V, 3) light reflected more than once: leaving the vertex (radiance), or with
        ``output_pass='lighting'`` arriving there.
    side : OpenSide or None
        The buried vertices' open side (:func:`.sides.buried_side`).
    """

    xv: np.ndarray
    nv: np.ndarray
    rho_v: np.ndarray
    opened: object
    D: np.ndarray
    rest: np.ndarray
    side: object


def vertex_stage(ctx) -> None:
    """Fill ``ctx.elements`` (the output mesh) and ``ctx.vertex_radiosity`` (V, 3) per its verts:
    radiosity, or with ``output_pass='lighting'`` the light arriving (direct + indirect, as
    radiance: irradiance / pi) without the surface's own colour or emission; and where the
    meshes have corner colours (a texture) or a corner is lit on its own (:mod:`.crease`),
    ``ctx.corner_radiosity`` (N, 4, 3): each element corner's own colour times its light
    (:func:`_with_corner_colours`)."""
    lighting = ctx.settings.output_pass == "lighting"
    weights = _exposure_weights(ctx)
    ctx.elements = ctx.patches
    ctx.corner_radiosity = ctx.corner_lighting = ctx.corner_rho = None
    ctx.vertex_direct = ctx.vertex_indirect = ctx.vertex_rho = None
    ctx.corner_direct = ctx.corner_keep = None
    if ctx.direct is None:
        _from_patches_alone(ctx, weights, lighting)
        return
    # direct light again at every output vertex (sharp shadows, exact falloff); only the
    # smoother light reflected more than once comes from the patches (or their clusters), as in
    # the paper
    rest = ctx.reflected - ctx.direct_source
    sided = sided_mesh(ctx, ctx.patches)     # each side of a partition its own vertices
    rest_v = vertex_radiosity(sided, _reflected_by_patches(ctx, rest), weights=weights, cache=ctx.cache)
    in_v = None
    if lighting:
        in_v = vertex_radiosity(sided, ctx.to_patches(_incoming(rest, ctx.unknowns.rho)), weights=weights,
                                cache=ctx.cache)
    if ctx.settings.uses_elements() or gathers_faces(ctx):
        at = _at_elements(ctx, sided, weights, rest_v, in_v)
    else:
        at = _at_sided_patches(ctx, sided, rest_v if in_v is None else in_v)
    if at.side is not None:                             # what a buried vertex gathered: the inside
        at.rest = at.side.spread(at.rest)
    creased = _own_corner_light(ctx, at, lighting)
    _keep_light(ctx, at.D, at.rest, None if lighting else at.rho_v, creased)
    if lighting:
        ctx.vertex_radiosity = at.D + at.rest
        if creased is not None:
            ctx.corner_radiosity = creased[0] + at.rest[ctx.elements.corner_ids()] * creased[1][..., None]
            ctx.vertex_radiosity = vertex_mean(ctx.elements, ctx.corner_radiosity)
        return
    E_v = vertex_radiosity(ctx.elements, ctx.elements.emission, cache=ctx.cache)
    ctx.vertex_radiosity = _with_corner_colours(ctx, E_v, at.rho_v, at.D, at.rest, creased)


def _exposure_weights(ctx) -> np.ndarray:
    """(N,) read-only weight of each patch in its vertices' means and fits: its unknown's
    :func:`.vertex.exposure` (0 for one buried in a solid, else the share of its hemisphere
    that sees front faces or the sky, in [0, 1]). F's and the geometry's only: kept on F, the
    same array every relight (the fits, frames and rings keyed on it hash it once)."""
    F, u = ctx.form_factors, ctx.unknowns
    key = ("exposure-weights", array_key(u.areas), None if ctx.clusters is None else array_key(ctx.clusters.of))
    return F.memo(key, lambda: frozen(np.array(ctx.to_patches(exposure(F, u.areas)), dtype=np.float64)))


def _from_patches_alone(ctx, weights, lighting) -> None:
    """``ctx.vertex_radiosity`` (V, 3) at the patches' vertices without a direct light to find
    again there (``ctx.direct`` None): the patch solution averaged and extrapolated to them
    (``weights`` (N,): :func:`_exposure_weights`); with corner colours (a texture), each
    vertex's own colour times the light arriving there (:func:`_with_corner_colours`)."""
    patches, u = ctx.patches, ctx.unknowns
    textured = not lighting and corner_values(patches, ctx.meshes, "rho") is not None
    if lighting or textured:
        B = ctx.to_patches(_incoming(ctx.solution.B - u.emission, u.rho))
    else:
        B = patches.emission + _reflected_by_patches(ctx, ctx.solution.B - u.emission) \
            if ctx.clusters is not None else ctx.solution.B
    ctx.vertex_radiosity = vertex_radiosity(patches, B, weights=weights, cache=ctx.cache)
    if textured:                          # each vertex its own colour times the light there
        _, _, rho_v = vertex_frames(patches)
        E_v = vertex_radiosity(patches, patches.emission, cache=ctx.cache)
        ctx.vertex_radiosity = _with_corner_colours(ctx, E_v, rho_v, ctx.vertex_radiosity, 0.0)


def _at_elements(ctx, sided, weights, rest_v, in_v) -> _AtVertices:
    """The elements cut finer than the patches (a dense scene's faces themselves:
    :func:`.indirect.gathers_faces`) made ``ctx.elements`` (split per side of a partition) and
    lit at their vertices: the direct light found there, and the light reflected
    more than once gathered by rays from ``rest_v`` (V', 3), the patches' at ``sided``'s
    vertices (``in_v`` (V', 3): what arrives there, for the lighting pass; else None)."""
    if ctx.settings.gather_rays > 0 and embree_available():
        # what the gather's rays read: buried vertices take their open neighbours' light
        # (the output never shows it: it is each vertex's exact direct light and gather)
        rest_v = fill_buried(sided, rest_v, weights, cache=ctx.cache)
    # a dense scene's faces are the output, gathered (:func:`.indirect.gathers_faces`)
    elements = ctx.patches if gathers_faces(ctx) else cut_elements(ctx)
    ctx.elements = sided if elements is ctx.patches else sided_mesh(ctx, elements)
    opened = open_elements(ctx, ctx.elements)
    xv, nv, rho_v = frames(ctx.elements, opened, ctx.cache)
    nv = shading_normals(ctx.elements, ctx.meshes, nv)     # as Cycles shades: smooth, custom
    # the gather's rays (geometry only) cast on the workers while this thread finds the
    # direct light, the open side and what shines (else a core idles through them)
    pending = start_gather(ctx, ctx.elements, xv, nv)
    got = [pending]       # what the gather's reader takes: the gather, or (G, H) once collected

    def sky():            # the gather's rays that hit nothing find the world: no sky rays
        found, got[0] = gathered_sky(ctx, ctx.elements, xv, nv, pending)
        return found
    try:
        side = buried_side(ctx, ctx.elements, xv, nv)
        if side is not None:                            # before the gather: its rays read it
            eps = start_offsets(ctx, ctx.elements, side.points, side.normals)
            open_D = ctx.direct.at(side.points, side.normals, "open-side", eps=eps)
        if gather_finds_world(ctx):       # the sky last: it waits for the gather's rays
            D_vert = ctx.direct.at(xv, nv, "vertices", sky=sky)
        else:
            D_vert = ctx.direct.at(xv, nv, "vertices")     # once: the gather reads it too
        if side is not None:
            D_vert = side.spread(D_vert, open_D)
        rest_v = element_indirect(ctx, ctx.elements, rest_v, xv, nv, rho_v, in_v, D_vert, side, got[0],
                                  _mirrored(ctx, sided, weights))
    finally:
        if pending is not None:                     # stopped early: the workers with it
            pending.close()
    return _AtVertices(xv, nv, rho_v, opened, D_vert, rest_v, side)


def _at_sided_patches(ctx, sided, rest_v) -> _AtVertices:
    """The patches themselves (split per side of a partition: ``sided``) made ``ctx.elements``
    and lit at their vertices: the direct light found there, and ``rest_v`` (V, 3) the light
    reflected more than once, averaged from the patches."""
    ctx.elements = sided
    opened = open_elements(ctx, sided)
    xv, nv, rho_v = frames(sided, opened, ctx.cache)
    nv = shading_normals(sided, ctx.meshes, nv)
    D_vert = ctx.direct.at(xv, nv, "vertices")
    side = buried_side(ctx, sided, xv, nv)
    if side is not None:
        eps = start_offsets(ctx, sided, side.points, side.normals)
        D_vert = side.spread(D_vert, ctx.direct.at(side.points, side.normals, "open-side", eps=eps))
    return _AtVertices(xv, nv, rho_v, opened, D_vert, rest_v, side)


def _own_corner_light(ctx, at: _AtVertices, lighting):
    """Where the faces at a vertex disagree, each corner's own direct light (Cycles' per
    corner): None, or (direct (N, 4, 3) radiance at every element corner, the share (N, 4) of
    its vertex's indirect light each corner keeps) (:func:`.crease.corner_light`, and
    :func:`.covered.covered_light` where another surface lies between a corner and its
    vertex's rays). The gather's rays are let go after."""
    buried = None if at.side is None else at.side.count > 0
    read_v = None if lighting else at.rho_v * at.D + at.rest      # what the gather's rays read
    # a lightmap lights its texels again and reads only the corners' reflected light and its
    # share: no corner's own direct light is found for it (the vertex's stands in)
    own = ctx.settings.target != "lightmap"
    arriving_v = None if lighting else _incoming(at.rest, at.rho_v)     # reflected at least once
    creased = corner_light(ctx, ctx.elements, at.xv, at.nv, at.D, at.opened, buried, read_v, own, arriving_v)
    ctx.gather_rays = ctx.gather_key = None             # its hits go with it
    return covered_light(ctx, ctx.elements, at.xv, at.nv, at.D, creased, at.opened, buried, own,
                         at.rest if lighting else arriving_v)


def _mirrored(ctx, sided, weights):
    """(V, 3) at the vertices of ``sided`` the light arriving by way of glossy patches
    (:func:`..form_factors.glossy.mirrored_arrival`), or None without any (or a gather)."""
    if ctx.specular is None or not (ctx.settings.gather_rays > 0 and embree_available()):
        return None
    return vertex_radiosity(sided, ctx.to_patches(mirrored_arrival(ctx)), weights=weights, cache=ctx.cache)


def _keep_light(ctx, D_vert, rest_v, rho_v, creased=None):
    """``ctx.vertex_direct`` (V, 3) the direct light arriving at each output vertex and
    ``ctx.vertex_indirect`` (V, 3) the light arriving that was reflected at least once (radiance:
    irradiance / pi), with ``ctx.vertex_rho`` (V, 3) the reflectivity that made ``rest_v`` (V, 3)
    of it (``rho_v`` None: the lighting pass, whose ``rest_v`` is the light arriving: ones);
    where corners are lit on their own (``creased``, :func:`.crease.corner_light`), also
    ``ctx.corner_direct`` (N, 4, 3) and ``ctx.corner_keep`` (N, 4), the share of the vertex's
    indirect light each corner keeps. Every corner value is then E + rho * (direct + indirect)
    (:meth:`..pipeline.BakeResult.corner_parts`), so a lightmap can take the direct part exactly
    at its texels (:mod:`.lightmap`)."""
    ctx.vertex_direct = D_vert
    if creased is not None:
        ctx.corner_direct, ctx.corner_keep = creased
    if rho_v is None:
        ctx.vertex_rho, ctx.vertex_indirect = np.ones_like(D_vert), rest_v
        return
    ctx.vertex_rho = rho_v
    ctx.vertex_indirect = _incoming(rest_v, rho_v)


def _reflected_by_patches(ctx, reflected):
    """(N, 3) per patch of the light the unknowns reflect, (K, 3): a patch grouped into a
    cluster of another reflectivity (a textured material, grouped: the cluster solves with the
    area mean) reflects the light arriving at its cluster with its own reflectivity; every
    other patch takes its unknown's value as it is."""
    spread = ctx.to_patches(reflected)
    if ctx.clusters is None:
        return spread
    rho = ctx.patches.rho
    other = np.abs(rho - ctx.to_patches(ctx.clusters.rho)) > 1e-9      # not the mean's rounding
    if not other.any():
        return spread
    return np.where(other, ctx.to_patches(_incoming(reflected, ctx.clusters.rho)) * rho, spread)


def _incoming(reflected, rho):
    """(N, 3) light arriving that leaves as ``reflected``: reflected / rho (0 where rho is 0)."""
    return np.where(rho > 0, reflected / np.where(rho > 0, rho, 1.0), 0.0)


def _with_corner_colours(ctx, E_v, rho_v, light_v, reflected_v, creased=None):
    """E_v + rho_v * light_v + reflected_v, with the source meshes' corner colours (a texture)
    where they have them: emission and reflectivity per vertex, and the light reflected more
    than once (``reflected_v``, made with the faces' reflectivity ``rho_v``) rescaled to it.
    ``creased``: None (each corner takes its vertex's light), or where some corner is lit on its
    own (:func:`.crease.corner_light`) the direct light at every element corner (N, 4, 3) and
    the share (N, 4) of ``reflected_v`` each corner keeps.

    With corner colours or ``creased``, also ``ctx.corner_radiosity`` (N, 4, 3): the same sum at
    every element corner with that corner's own colour and light (E_c + rho_c * light_c + keep *
    reflected_v * rho_c / rho_v, a triangle's fourth corner its third), and with corner
    reflectivities ``ctx.corner_lighting`` (N, 4, 3): the light arriving at each corner
    (light_c + keep * reflected_v / rho_v), which the writer multiplies by a texture. A
    vertex's value is then the mean of its corners'; the corners keep what the mean loses where faces meet with
    different colours or light at one vertex (a UV seam, a texture's tiles, a crease): what
    Cycles shows at each face corner, and what the writer writes."""
    rho_c, em_c = (corner_values(ctx.elements, ctx.meshes, w, ctx.cache) for w in ("rho", "emission"))
    ctx.corner_rho = rho_c
    if rho_c is None and em_c is None and creased is None:
        return E_v + rho_v * light_v + reflected_v
    cv = ctx.elements.corner_ids()                                  # (N, 4) vertex of each corner
    R = np.broadcast_to(np.asarray(reflected_v, dtype=np.float64), np.shape(light_v))
    E_c = E_v[cv] if em_c is None else em_c
    L_c, R_c = (light_v[cv], R[cv]) if creased is None else (creased[0], R[cv] * creased[1][..., None])
    if rho_c is None:
        ctx.corner_radiosity = E_c + (rho_v[cv] * L_c + R_c)
        if creased is not None:
            return vertex_mean(ctx.elements, ctx.corner_radiosity)
        E_v = E_v if em_c is None else vertex_mean(ctx.elements, em_c)
        return E_v + rho_v * light_v + reflected_v
    pos = rho_v > 0
    per_rho = _incoming(R, rho_v)                                   # light reflected again, per rho
    keep = 1.0 if creased is None else creased[1][..., None]
    ctx.corner_radiosity = E_c + rho_c * L_c + np.where(pos[cv], rho_c * per_rho[cv], R[cv]) * keep
    ctx.corner_lighting = L_c + per_rho[cv] * keep
    if creased is not None:
        return vertex_mean(ctx.elements, ctx.corner_radiosity)
    textured = vertex_mean(ctx.elements, rho_c)
    reflected_v = reflected_v * np.where(rho_v > 0, textured / np.where(rho_v > 0, rho_v, 1.0), 1.0)
    if em_c is not None:
        E_v = vertex_mean(ctx.elements, em_c)
    return E_v + textured * light_v + reflected_v
