"""Direct light per element corner where the faces that meet at a vertex disagree.

An output vertex is lit once (:mod:`.stage`): at a point a hair inside the mean of its elements,
with one shading normal. Cycles bakes every face corner on its own triangle
(``intern/cycles/kernel/integrator/init_from_bake.h``: the point nudged toward the triangle's
centre, the bake's ray arriving along the shading normal N there), and its shader set-up
(``kernel/geom/shader_data.h`` ``shader_setup_from_ray``) turns a triangle around whose geometric
normal Ng faces away from that ray: where N . Ng < 0 (a face turned down whose smoothed normal
points up: a kerb's undercut, a fold of grass) both are negated. A diffuse closure then takes
cos(N, L) of a light direction L, and light from below the triangle's plane (Ng . L < 0) is
lost: a bounce sampled there is dropped (``bsdf_diffuse_sample``), and a shadow ray there does
not skip its own triangle (``kernel/light/sample.h`` ``shadow_ray_offset``). So a turned-around
corner sees only the lune between the two planes: a sun above the undercut does not light it,
where one value per vertex, lit along the smoothed normal, gave it the full sun.

Where the triangle is not turned around, Cycles' shadow ray starts lifted toward the smooth
surface (the shadow-terminator geometry offset, 0.1 by default: the start moves by the smooth
surface's height over the triangle at the bake point, which Cycles puts 1e-4 of the coordinates
in from the corner), and then passes light from a little below the plane, more the lower the
corner's neighbours lie: cutting all light from below the plane at such corners made truck
town's error 19.0% (from 15.8%), cutting it where the corner's neighbours lie on or below the
shading normal's tangent plane (no lift) 17.0%. It is not cut there: those corners take the
cosine to the shading normal at their own point.

Here, at every corner whose shading normal (its own face's corner normal, interpolated at the
vertex: :func:`.normals.corner_shading_normals`) leans more than :data:`CREASE_ANGLE` off its
own triangle's geometric normal, or off the normal its vertex was lit with, the direct light is
found again at that corner alone: at a point :data:`INSET` of the way from the vertex to its
element's centre (on the element's plane), the cosine taken to the shading normal, rays starting
off the point by its object's offset (:func:`.rays.ray_offsets`) along the bisector of the two
normals; at a turned-around corner both normals negated, no lamp's or world's light from below
the triangle's plane (``facing`` of :meth:`.light.stage.DirectLight.at`; an emitting face's is
not cut, its shadow rays start above the plane) and its light reflected more than once (per
vertex) scaled by the share of its hemisphere above that plane (:func:`corner_light`). Only
meshes with corner normals (smooth or custom-normal faces as Blender reads them) have such
corners: elsewhere the faces that share a vertex lie in one plane, and the bake is as before
bit for bit. Radiance units; world space.
"""
from __future__ import annotations

import numpy as np

from ..rays import ray_offsets
from .normals import corner_shading_normals

__all__ = ["CREASE_ANGLE", "INSET", "crease_corners", "corner_light"]

#: Degrees: a corner's shading normal leaning this far off its triangle's normal, or off its
#: vertex's normal, gets the corner its own direct light.
CREASE_ANGLE = 5.0
#: How far toward its element's centre a corner is lit (as :func:`.emitters.vertex_frames`' points).
INSET = 1e-2


def crease_corners(elements, meshes, nv, opened=None, buried=None):
    """The element corners lit on their own, or None when there are none:
    (p (K,) element, c (K,) corner 0..3, points (K, 3) where each is lit, shading (K, 3) unit
    normal for the cosine, geometric (K, 3) the corner triangle's unit normal, turned (K,) bool:
    the two faced apart and are both negated, to the side Cycles shades (module docstring)).
    ``nv`` (V, 3) the normals the vertices were lit with; ``opened`` (N,) 0 for elements the
    scene does not see and ``buried`` (V,) bool vertices that take the open side's light
    (:func:`.sides.buried_side`): neither is lit again."""
    polys = elements.polys
    p, c = np.nonzero(polys >= 0)
    shade, has = corner_shading_normals(elements, meshes, p, c)
    if shade is None:
        return None
    keep = has if opened is None else has & (np.asarray(opened)[p] > 0)
    p, c, shade = p[keep], c[keep], shade[keep]
    v = polys[p, c]
    if buried is not None:
        open_v = ~np.asarray(buried, bool)[v]
        p, c, v, shade = p[open_v], c[open_v], v[open_v], shade[open_v]
    geo = corner_normals(elements, p, c)
    cos_max = np.cos(np.radians(CREASE_ANGLE))
    facing = np.einsum("ij,ij->i", shade, geo)
    fire = (facing < cos_max) | (np.einsum("ij,ij->i", shade, nv[v]) < cos_max)
    if not fire.any():
        return None
    p, c, v, shade, geo, facing = p[fire], c[fire], v[fire], shade[fire], geo[fire], facing[fire]
    turn = np.where(facing < 0, -1.0, 1.0)[:, None]
    x = elements.verts[v] + INSET * (elements.centers[p] - elements.verts[v])
    return p, c, x, shade * turn, geo * turn, facing < 0


def corner_normals(elements, p, c) -> np.ndarray:
    """(K, 3) unit normal of the triangle each corner ``c`` (K,) of element ``p`` (K,) makes with
    its two neighbouring corners, turned to the element's side; the element's own normal where
    that triangle has no area."""
    polys = elements.polys
    k = np.where(polys[p, 3] >= 0, 4, 3)
    X = elements.verts
    here = X[polys[p, c]]
    nxt = X[polys[p, (c + 1) % k]] - here
    prv = X[polys[p, (c - 1) % k]] - here
    n = np.cross(nxt, prv)
    length = np.linalg.norm(n, axis=1)
    own = elements.normals[p]
    scale = np.linalg.norm(nxt, axis=1) * np.linalg.norm(prv, axis=1)
    flat = ~(length > 1e-9 * scale)
    n = np.where(flat[:, None], own, n / np.where(flat, 1.0, length)[:, None])
    return np.where((np.einsum("ij,ij->i", n, own) < 0)[:, None], -n, n)


def corner_light(ctx, elements, nv, light_v, opened=None, buried=None):
    """(light (N, 4, 3), keep (N, 4)) at every corner of ``elements``: the direct light
    (radiance arriving), each vertex's ``light_v`` (V, 3) but at the corners of
    :func:`crease_corners` their own, lit by ``ctx.direct`` (a triangle's fourth corner its
    third); and the share of the light reflected more than once that each corner keeps: 1, but
    at a turned-around corner the share of its shading normal's cosine-weighted hemisphere
    above its triangle's plane, (1 + N . Ng) / 2 (the sky view factor of a plane tilted by
    their angle; Cycles' diffuse bounce takes nothing from below that plane). None when no
    corner is lit on its own."""
    found = crease_corners(elements, ctx.meshes, nv, opened, buried)
    if found is None or ctx.direct is None:
        return None
    p, c, x, shade, geo, turned = found
    # rays start off the point along the two normals' bisector: above the triangle's plane and
    # toward the side the smoothing leans to (along the triangle's own normal, a corner a hair
    # from a concave fold started past its neighbour)
    up = shade + geo
    length = np.linalg.norm(up, axis=1)
    up = np.where((length > 1e-6)[:, None], up / np.maximum(length, 1e-300)[:, None], geo)
    eps = ray_offsets(ctx.patches, owner=elements.owner[p])
    D = ctx.direct.at(x + eps[:, None] * up, shade, "corners", eps=np.zeros(len(p)),
                      facing=np.where(turned[:, None], geo, shade))
    k = np.where(turned, (1.0 + np.einsum("ij,ij->i", shade, geo)) / 2, 1.0)
    light = np.array(light_v, dtype=np.float64)[elements.corner_ids()]
    keep = np.ones(light.shape[:2])
    tri = (elements.polys[p, 3] < 0) & (c == 2)
    for out, value in ((light, D), (keep, k)):
        out[p, c] = value
        out[p[tri], 3] = value[tri]
    return light, keep
