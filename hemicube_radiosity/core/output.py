"""The output stage: radiosity at the vertices of the mesh that is written.

The output mesh is the patches themselves, or (``settings.element_size`` finer than the patches)
*elements*: the input meshes cut finer, as the paper's "finer elements take detail from a coarse
patch solution". Per output vertex (V, 3), radiance units:

    B_v = E_v + rho_v * D_v + R_v

with D_v the exact direct light at the vertex (:class:`.direct_light.DirectLight`) and R_v the
light reflected more than once, from the patch solution: averaged to the vertices as in the paper,
then for elements gathered by cosine rays that read it where they land (:mod:`.gather`, needs
Embree) or interpolated bilinearly (:mod:`.interpolate`).
"""
from __future__ import annotations

import hashlib

import numpy as np

from .cache import cache_key, cached
from .direct import vertex_frames
from .errors import RadiosityError
from .gather import apply_gather, gather_matrix
from .interpolate import interpolate_located, locate
from .patches import PatchSet, build_patches
from .progress import Ticker
from .rays import embree_available, embree_scene
from .vertex import exposure, vertex_radiosity

__all__ = ["meshes_key", "output_elements", "vertex_stage"]


def meshes_key(meshes) -> bytes:
    """Bytes that change exactly when the source meshes' geometry changes (not materials)."""
    h = hashlib.sha256()
    for m in meshes:
        for a in (m.verts, m.face_offsets, m.face_indices):
            a = np.ascontiguousarray(a)
            h.update(str(a.shape).encode() + a.tobytes())
    return h.digest()


def output_elements(meshes, settings, cache=None) -> PatchSet:
    """The output mesh cut to ``settings.element_size``; its geometry is cached (a relight only
    re-reads reflectivity and emission from the meshes)."""
    key = cache_key(meshes_key(meshes), ("elements", settings.element_size))
    return cached(cache, key, lambda: build_patches(meshes, settings.element_size)).with_mesh_materials(meshes)


def corner_values(elements: PatchSet, meshes, which) -> np.ndarray | None:
    """(N, 4, 3) ``which`` ('rho' or 'emission') at every corner of the output ``elements``: the
    source mesh's corner value (``MeshInput.corner_<which>``) where an element corner is a corner
    of its source face, the element's own (per-face) value elsewhere; None when no mesh has
    corner values."""
    if meshes is None or all(getattr(m, "corner_" + which) is None for m in meshes):
        return None
    keys, vals = [], []
    for oi, m in enumerate(meshes):
        sizes = np.diff(m.face_offsets)
        face = np.repeat(np.arange(sizes.size), sizes)
        v = getattr(m, "corner_" + which)
        v = np.asarray(getattr(m, "face_" + which), float)[face] if v is None else np.asarray(v, float)
        pos = np.asarray(m.verts, float)[m.face_indices]
        keys.append(np.column_stack([np.full(face.size, oi), face, pos]))
        vals.append(v)
    keys, vals = np.concatenate(keys), np.concatenate(vals)
    polys = np.where(elements.polys < 0, elements.polys[:, 2:3], elements.polys)
    ek = np.concatenate([np.repeat(np.column_stack([elements.owner, elements.source_face]), 4, axis=0),
                         elements.verts[polys.reshape(-1)]], axis=1)
    _, inv = np.unique(np.concatenate([keys, ek]), axis=0, return_inverse=True)
    inv = inv.reshape(-1)
    slot = np.full(inv.max() + 1, -1)
    slot[inv[:len(keys)]] = np.arange(len(keys))
    found = slot[inv[len(keys):]]
    own = np.repeat(np.asarray(getattr(elements, which), float), 4, axis=0)
    out = np.where((found >= 0)[:, None], vals[np.maximum(found, 0)], own)
    return out.reshape(len(elements), 4, 3)


def vertex_mean(elements: PatchSet, per_corner) -> np.ndarray:
    """(V, 3) mean over each vertex's element corners of a (N, 4, 3) per-corner array."""
    p, c = np.nonzero(elements.polys >= 0)
    v = elements.polys[p, c]
    V = len(elements.verts)
    cnt = np.maximum(np.bincount(v, minlength=V), 1)
    return np.stack([np.bincount(v, weights=per_corner[p, c, k], minlength=V) for k in range(3)], 1) / cnt[:, None]


def _gathered(ctx, elements, rest_v, xv, nv, rho_v):
    """Reflected light R at element vertices by a final gather (the gather's ray hits cached as a
    matrix): (V, 3), before the elements' reflectivity. The rays read the light reflected by the
    output mesh itself: the direct part exact at each of its vertices (as fine as the output, so
    a two-sided lamp's few-centimetre hot spot on a ceiling is not spread over whole patches),
    the part reflected more than once from the patch solution."""
    rest_e = rest_v if elements is ctx.patches else _interpolated(ctx, elements, rest_v, xv, nv)
    R_e = rho_v * ctx.direct.at(xv, nv, "vertices") + rest_e

    def make():
        G, sky = gather_matrix(elements, xv, nv, embree_scene(elements), rays=ctx.settings.gather_rays,
                               ticker=Ticker(None, ctx.cancelled), workers=ctx.settings.workers)
        G.sky = sky
        return G

    key = cache_key(elements.geometry_key(), ("gather-elements", ctx.settings.gather_rays))
    G = cached(ctx.cache, key, make)
    return apply_gather(G, G.sky, R_e, ctx.world)


def _interpolated(ctx, elements, field_v, xv, nv):
    """A patch-vertex field (V_patches, 3) at the element vertices ``xv``: bilinear in the
    patches, each element vertex in its own object's patches."""
    def where():
        owner_v = np.zeros(len(elements.verts), np.int64)
        for c in range(4):
            on = elements.polys[:, c] >= 0
            owner_v[elements.polys[on, c]] = elements.owner[on]
        return locate(ctx.patches, xv, owner=owner_v, normals=nv)

    key = cache_key(ctx.patches.geometry_key() + elements.geometry_key(), ("located",))
    return interpolate_located(ctx.patches, field_v, *cached(ctx.cache, key, where))


def _element_indirect(ctx, elements, rest_v, xv, nv, rho_v, in_v=None):
    """Light reflected more than once arriving at element vertices, times their reflectivity
    (with ``in_v``, the patches' incoming indirect light at their vertices: as it arrives, for
    the lighting-only pass): gathered (Embree) or the patch solution's bilinear interpolation."""
    if ctx.settings.gather_rays > 0 and embree_available():
        gathered = _gathered(ctx, elements, rest_v, xv, nv, rho_v)
        return gathered if in_v is not None else rho_v * gathered
    if ctx.settings.gather_rays > 0:
        ctx.notes.append("Embree is not available: element vertices interpolate the patch solution "
                         "instead of gathering it")
    rest_v = rest_v if in_v is None else in_v
    if elements is ctx.patches:               # faces already finer than the detail size
        return rest_v
    return _interpolated(ctx, elements, rest_v, xv, nv)


def _cut_elements(ctx) -> PatchSet:
    s = ctx.settings
    ctx.say(0.0, f"cutting output elements of {s.element_size:g}")
    elements = output_elements(ctx.meshes, s, ctx.cache)
    if elements.geometry_key() == ctx.patches.geometry_key():
        return ctx.patches                    # the input is finer than the detail: its own faces
    if len(elements) > s.max_elements:
        raise RadiosityError(f"a detail size of {s.element_size} cuts the scene into {len(elements)} "
                             f"output elements, more than the limit of {s.max_elements}: use a "
                             "larger detail size")
    return elements


def _incoming(reflected, rho):
    """(N, 3) light arriving that leaves as ``reflected``: reflected / rho (0 where rho is 0)."""
    return np.where(rho > 0, reflected / np.where(rho > 0, rho, 1.0), 0.0)


def vertex_stage(ctx) -> None:
    """Fill ``ctx.elements`` (the output mesh) and ``ctx.vertex_radiosity`` (V, 3) per its verts:
    radiosity, or with ``output_pass='lighting'`` the light arriving (direct + indirect, as
    radiance: irradiance / pi) without the surface's own colour or emission."""
    patches, u = ctx.patches, ctx.unknowns
    lighting = ctx.settings.output_pass == "lighting"
    weights = ctx.to_patches(exposure(ctx.form_factors))
    ctx.elements = patches
    if ctx.direct is None:
        textured = not lighting and corner_values(patches, ctx.meshes, "rho") is not None
        B = _incoming(ctx.solution.B - u.emission, u.rho) if lighting or textured else ctx.solution.B
        ctx.vertex_radiosity = vertex_radiosity(patches, ctx.to_patches(B), weights=weights)
        if textured:                          # each vertex its own colour times the light there
            _, _, rho_v = vertex_frames(patches)
            ctx.vertex_radiosity = _with_corner_colours(ctx, vertex_radiosity(patches, patches.emission),
                                                        rho_v, ctx.vertex_radiosity, 0.0)
        return
    # direct light again at every output vertex (sharp shadows, exact falloff); only the
    # smoother light reflected more than once comes from the patches (or their clusters), as in
    # the paper
    rest = ctx.reflected - ctx.to_unknowns(patches.rho * ctx.direct_patch)
    rest_v = vertex_radiosity(patches, ctx.to_patches(rest), weights=weights)
    in_v = None
    if lighting:
        in_v = vertex_radiosity(patches, ctx.to_patches(_incoming(rest, u.rho)), weights=weights)
    if ctx.settings.uses_elements():
        ctx.elements = _cut_elements(ctx)
        xv, nv, rho_v = vertex_frames(ctx.elements)
        rest_v = _element_indirect(ctx, ctx.elements, rest_v, xv, nv, rho_v, in_v)
    else:
        xv, nv, rho_v = vertex_frames(patches)
        rest_v = rest_v if in_v is None else in_v
    D_vert = ctx.direct.at(xv, nv, "vertices")
    if lighting:
        ctx.vertex_radiosity = D_vert + rest_v
        return
    E_v = vertex_radiosity(ctx.elements, ctx.elements.emission)
    ctx.vertex_radiosity = _with_corner_colours(ctx, E_v, rho_v, D_vert, rest_v)


def _with_corner_colours(ctx, E_v, rho_v, light_v, reflected_v):
    """E_v + rho_v * light_v + reflected_v, with the source meshes' corner colours (a texture)
    where they have them: emission and reflectivity per vertex, and the light reflected more
    than once (``reflected_v``, made with the faces' reflectivity ``rho_v``) rescaled to it."""
    rho_c, em_c = (corner_values(ctx.elements, ctx.meshes, w) for w in ("rho", "emission"))
    if rho_c is not None:
        textured = vertex_mean(ctx.elements, rho_c)
        reflected_v = reflected_v * np.where(rho_v > 0, textured / np.where(rho_v > 0, rho_v, 1.0), 1.0)
        rho_v = textured
    if em_c is not None:
        E_v = vertex_mean(ctx.elements, em_c)
    return E_v + rho_v * light_v + reflected_v
