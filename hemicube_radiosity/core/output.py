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
from .clusters import _components
from .direct import apply_transport, emitter_transport, vertex_frames
from .direct_light import patch_average
from .errors import RadiosityError
from .gather import apply_gather, correct_hits, gather_matrix
from .interpolate import interpolate_located, locate
from .patches import PatchSet, build_patches
from .progress import Ticker
from .refine import LUMA, _subset, abrupt
from .rays import embree_available, embree_scene, occluder, open_fraction
from .vertex import exposure, vertex_radiosity

__all__ = ["meshes_key", "output_elements", "vertex_stage", "abrupt_elements"]


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
    the part reflected more than once from the patch solution.

    Where the direct part changes abruptly inside an element (a shadow's edge, a lamp hanging
    millimetres under a ceiling), interpolating it from the element's corners would spread a
    corner's light over the whole element: rays that land on such an element read the direct
    light exactly where they land. The brightest of those elements (the ring of ceiling lit by
    a lamp's back) would make rare, very bright hits, blotches: they light the vertices as
    lamps do instead, by their form factor and shadow rays (:func:`_bright_elements`)."""
    rest_e = rest_v if elements is ctx.patches else _interpolated(ctx, elements, rest_v, xv, nv)
    direct_e = rho_v * ctx.direct.at(xv, nv, "vertices")
    G, H = _gather_rays(ctx, elements, xv, nv)
    world = ctx.world if ctx.direct.world is None else None   # else in the vertices' direct light
    out = apply_gather(G, G.sky, direct_e + rest_e, world)
    select = abrupt_elements(elements, direct_e)
    if not select.any():
        return out
    bright, shine = _bright_elements(ctx, elements, select, direct_e)

    def exact(y, pid):
        D = elements.rho[pid] * ctx.direct.at(y, elements.normals[pid], "gather-hits", samples=1)
        return np.where(bright[pid][:, None], 0.0, D)
    out += correct_hits(G, H, elements, direct_e, exact, select)
    if bright.any():
        out += _shine(ctx, elements, np.flatnonzero(bright), shine[bright], xv, nv)
    return out


def _open_elements(ctx, elements):
    """(N,) 1 for an element the scene can see, 0 for one buried in a solid (its centre's rays
    all end on back faces or within a twentieth of the patch size: :func:`.rays.open_fraction`),
    so output vertices on a block's outline are evaluated on the open side. None without
    Embree (every element counts)."""
    if not embree_available():
        return None
    reach = 0.05 * float(ctx.settings.patch_size or ctx.settings.element_size or 1.0)
    key = cache_key(elements.geometry_key(), ("open-centres", reach))
    f = cached(ctx.cache, key, lambda: open_fraction(elements, elements.centers, elements.normals,
                                                     embree_scene(elements), reach))
    return (f > 0.05).astype(np.float64)


def _bright_elements(ctx, elements, select, direct_e, n=6, factor=4.0):
    """(bright (N,) bool, shine (N, 3)): of the ``select``-ed elements, those whose reflected
    direct light, averaged over the part the scene sees (n x n jittered points weighted by
    :func:`.rays.open_fraction`: the light of a lamp's back falls off within millimetres of
    its edge, points fixed at cell centres would over- or undershoot it), exceeds ``factor``
    times the mean over the output vertices; ``shine`` is that average (0 elsewhere)."""
    ids = np.flatnonzero(select)
    sub = _subset(elements, ids)
    reach = 0.05 * float(ctx.settings.patch_size or ctx.settings.element_size or 1.0)
    scene = embree_scene(elements)

    def light_at(x, nrm, where):
        return ctx.direct.at(x, nrm, "bright-" + where)

    def seen(x, nrm):
        key = cache_key(elements.geometry_key() + np.ascontiguousarray(x).tobytes(), ("exposure", reach))
        return np.minimum(1.0, cached(ctx.cache, key, lambda: open_fraction(elements, x, nrm, scene, reach)) / 0.5)

    avg = sub.rho * patch_average(sub, n, light_at, weight_at=seen, rng=np.random.default_rng(0))
    shine = np.zeros((len(elements), 3))
    shine[ids] = avg
    bright = np.zeros(len(elements), bool)
    bright[ids] = avg @ LUMA > factor * float((direct_e @ LUMA).mean())
    return bright, shine


def _shine(ctx, elements, ids, radiance, xv, nv):
    """(V, 3) light arriving at the points ``xv`` from elements ``ids`` shining ``radiance``
    (M, 3) toward their front, with shadows: grouped by object and patch-size cell so the
    shadow rays follow a few areas, not every element (:func:`.direct.emitter_transport`)."""
    size = float(ctx.settings.patch_size or ctx.settings.element_size or 1.0)
    cell = np.floor((elements.centers[ids] - elements.verts.min(axis=0)) / size).astype(np.int64)
    key = np.unique(np.column_stack([elements.owner[ids], cell]), axis=0, return_inverse=True)[1].reshape(-1)
    sub = _subset(elements, ids)
    groups = np.unique(_components(key, sub.polys), return_inverse=True)[1].reshape(-1)
    T = emitter_transport(elements, xv, nv, ids, scene=occluder(elements), samples=ctx.settings.direct_samples,
                          groups=groups, workers=ctx.settings.workers, ticker=Ticker(None, ctx.cancelled))
    a = elements.areas[ids]
    G = int(groups.max()) + 1
    L = np.stack([np.bincount(groups, weights=a * radiance[:, k], minlength=G) for k in range(3)], 1) \
        / np.bincount(groups, weights=a, minlength=G)[:, None]
    return apply_transport(T, L)


def _gather_rays(ctx, elements, xv, nv):
    """The gather matrix G (with ``G.sky``) of ``elements`` at points ``xv`` and its rays' hits
    H (see :func:`.gather.gather_matrix`), cached together: both depend on geometry only."""
    key = cache_key(elements.geometry_key(), ("gather-elements", ctx.settings.gather_rays))
    G = ctx.cache.get(key) if ctx.cache is not None else None
    H = ctx.cache.get(key + "-hits") if ctx.cache is not None else None
    if G is None or H is None:
        G, sky, H = gather_matrix(elements, xv, nv, embree_scene(elements), rays=ctx.settings.gather_rays,
                                  ticker=Ticker(None, ctx.cancelled), workers=ctx.settings.workers,
                                  hits=True)
        G.sky = sky
        if ctx.cache is not None:
            ctx.cache.put(key, G)
            ctx.cache.put(key + "-hits", H)
    return G, H


def abrupt_elements(elements: PatchSet, values_v, ratio=2.0, floor=0.02) -> np.ndarray:
    """(N,) bool: elements across which the vertex field ``values_v`` (V, 3) changes too
    abruptly to interpolate: the luminance at one corner is more than ``ratio`` times another's,
    and the difference is more than ``floor`` of the mean over the vertices (dark corners and
    faint gradients stay interpolated)."""
    Y = np.asarray(values_v, dtype=np.float64) @ LUMA
    polys = np.where(elements.polys < 0, elements.polys[:, :1], elements.polys)
    return abrupt(Y[polys], ratio, floor * max(float(Y.mean()), 1e-300))


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
    weights = ctx.to_patches(exposure(ctx.form_factors, u.areas))
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
    rest = ctx.reflected - ctx.direct_source
    rest_v = vertex_radiosity(patches, ctx.to_patches(rest), weights=weights)
    in_v = None
    if lighting:
        in_v = vertex_radiosity(patches, ctx.to_patches(_incoming(rest, u.rho)), weights=weights)
    if ctx.settings.uses_elements():
        ctx.elements = _cut_elements(ctx)
        xv, nv, rho_v = vertex_frames(ctx.elements, weights=_open_elements(ctx, ctx.elements))
        rest_v = _element_indirect(ctx, ctx.elements, rest_v, xv, nv, rho_v, in_v)
    else:
        xv, nv, rho_v = vertex_frames(patches, weights=_open_elements(ctx, patches))
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
