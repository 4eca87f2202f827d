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

Where the triangle is not turned around, Cycles' shadow ray toward a light below the plane
starts lifted toward the smooth surface (the shadow-terminator geometry offset) and does not
skip its own triangle: the slope's corner is dark where that ray meets the slope, lit where it
passes over the lip's edge (:mod:`.lift` says which, for the scene's strongest sun, from
Blender's triangles of the face). Cutting all light from below the plane there made truck
town's error 19.0% (from 15.8%); cutting it where :mod:`.lift` finds the ray blocked, 12.0%.

Here, at every corner whose shading normal (its own face's corner normal, interpolated at the
vertex: :func:`.normals.corner_shading_normals`) leans more than :data:`CREASE_ANGLE` off its
own triangle's geometric normal, or off the normal its vertex was lit with, the direct light is
found again for that corner alone, the cosine taken to its shading normal
(:func:`corner_light`), and its light reflected more than once (per vertex) scaled by the share
of its hemisphere above the triangle's plane. A turned-around corner has both normals negated.
There, and where :mod:`.lift` finds the sun's ray blocked, the lamps' and the world's light from
below the triangle's plane is cut (``facing`` of :meth:`.light.stage.DirectLight.at`; an
emitting face's is not: its shadow rays start above the plane), the rays starting at a point
:data:`INSET` of the way into the corner's element, off it by its object's offset
(:func:`.rays.ray_offsets`) along the two normals' bisector. Elsewhere they start at the
vertex's own point (on the front of all its elements), as Cycles' leave the corner itself. Only
meshes with corner normals (smooth or custom-normal faces as Blender reads them) have such
corners: elsewhere the faces that share a vertex lie in one plane, and the bake is as before
bit for bit. Radiance units; world space.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..rays import occluder, ray_offsets
from ..light.lamps import SunLight
from ..mesh.patches import meshes_key
from ..runtime.cache import array_key, cache_key, cached, geometry_key
from .lift import bake_points, blocked_share, corner_edges, corner_normals, face_corners
from .normals import corner_shading_normals

__all__ = ["CREASE_ANGLE", "INSET", "crease_corners", "corner_light", "strongest_sun"]

#: Degrees: a corner's shading normal leaning this far off its triangle's normal, or off its
#: vertex's normal, gets the corner its own direct light. Truck town: 5 degrees lit 63,204 of
#: its 91,431 corners on their own, 15 degrees 31,467, for the same error (11.21%, 11.22%).
CREASE_ANGLE = 15.0
#: How far toward its element's centre a corner is lit (as :func:`.emitters.vertex_frames`' points).
INSET = 1e-2
#: A corner whose shading normal's cosine to its triangle's normal is smaller than this (in
#: magnitude) is turned around or not as its normal at Cycles' bake point says (:func:`_turned`),
#: and its rays start off the plane along the two normals' bisector.
NEAR_PERPENDICULAR = 0.05
#: A normal at the bake point within this cosine of its triangle's plane is not turned around:
#: along the plane to rounding, Cycles shades its front (godot_zdm2: of the 1,911 corners whose
#: normal lies within 1e-6 of their plane, Cycles' NORMAL bake turns 7%).
TIE = 1e-6


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
    turned = _turned(elements, meshes, p, c, geo, facing)
    turn = np.where(turned, -1.0, 1.0)[:, None]
    x = elements.verts[v] + INSET * (elements.centers[p] - elements.verts[v])
    return p, c, x, shade * turn, geo * turn, turned


def _turned(elements, meshes, p, c, geo, facing) -> np.ndarray:
    """(K,) bool: Cycles turns corner ``c`` (K,) of element ``p`` (K,) around, its shading normal
    at its bake point (:func:`.lift.bake_points`, where the smooth normal is interpolated from
    the triangle's other corners too) facing away from its triangle's normal ``geo`` (K, 3) by
    more than :data:`TIE`.
    ``facing`` (K,): the corner's own normal's cosine to ``geo``, which says it where the two
    are not near perpendicular (a normal written over a vertex by another face,
    :mod:`..mesh.cycles_normals`, often is: a wall's corner shaded with the floor's)."""
    turned = facing < 0
    near = np.flatnonzero(np.abs(facing) < NEAR_PERPENDICULAR)
    if near.size:
        at = bake_points(elements, meshes, p[near], c[near])
        n, has = corner_shading_normals(elements, meshes, p[near], c[near], at)
        turned[near[has]] = np.einsum("ij,ij->i", n[has], geo[near[has]]) < -TIE
    return turned


def corner_light(ctx, elements, xv, nv, light_v, opened=None, buried=None):
    """(light (N, 4, 3), keep (N, 4)) at every corner of ``elements``: the direct light
    (radiance arriving), each vertex's ``light_v`` (V, 3) (lit at ``xv`` (V, 3) along ``nv``
    (V, 3)) but at the corners of :func:`crease_corners` their own, lit by ``ctx.direct`` (a
    triangle's fourth corner its third); and the share of the light reflected more than once that each corner keeps: 1, but
    at those corners the share of the shading normal's cosine-weighted hemisphere above the
    triangle's plane, (1 + N . Ng) / 2 (the sky view factor of a plane tilted by their angle;
    Cycles' diffuse bounce takes nothing from below that plane, ``bsdf_diffuse_sample``), the
    light arriving at the vertex taken as even over its hemisphere. None when no corner is lit
    on its own."""
    if ctx.direct is None:
        return None
    found = _corner_rays(ctx, elements, xv, nv, opened, buried)
    if not found:
        return None
    p, c, start, shade, geo, facing, same = found
    # a corner lit as its vertex was (from the same start, along the same normal, nothing cut)
    # takes the vertex's light: only the others cast rays
    D = np.array(light_v, dtype=np.float64)[elements.polys[p, c]]
    o = ~same
    if o.any():
        D[o] = ctx.direct.at(start[o], shade[o], "corners", eps=np.zeros(int(o.sum())), facing=facing[o])
    k = (1.0 + np.einsum("ij,ij->i", shade, geo)) / 2           # the hemisphere's share above the plane
    light = np.array(light_v, dtype=np.float64)[elements.corner_ids()]
    keep = np.ones(light.shape[:2])
    tri = (elements.polys[p, 3] < 0) & (c == 2)
    for out, value in ((light, D), (keep, k)):
        out[p, c] = value
        out[p[tri], 3] = value[tri]
    return light, keep


def _corner_rays(ctx, elements, xv, nv, opened, buried):
    """The corners :func:`corner_light` lights on their own and their rays, () when none:
    (p (K,), c (K,), start (K, 3) of the rays, shading (K, 3) and geometric (K, 3) normals as
    :func:`crease_corners` gives them, facing (K, 3) what the lamps' and the world's light is
    limited by, same (K,) bool: lit as the vertex was, its light the vertex's: nothing cut, the
    shading normal the vertex's (to 1e-9) and the rays' start its (the offsets equal to a
    millionth; truck town: 20,200 of its 32,826 corners)). Geometry and the strongest sun's
    direction only: cached (a relight in a new process reads them from the cache folder)."""
    mk = ctx.meshes_key() if hasattr(ctx, "meshes_key") else meshes_key(ctx.meshes)
    for m in ctx.meshes or ():
        mk += b"|" + repr(getattr(m, "back_of", -1)).encode()
        if getattr(m, "corner_normal", None) is not None:
            mk += array_key(np.asarray(m.corner_normal))
    sun = strongest_sun(ctx)
    mk += b"" if sun is None else np.asarray(sun, np.float64).tobytes()
    mk += b"".join(b"-" if a is None else array_key(np.asarray(a)) for a in (xv, nv, opened, buried))
    key = cache_key(geometry_key(elements) + geometry_key(ctx.patches) + mk, ("crease-rays-same", CREASE_ANGLE, INSET))
    return cached(ctx.cache, key, lambda: _make_corner_rays(ctx, elements, xv, nv, opened, buried))


def _make_corner_rays(ctx, elements, xv, nv, opened, buried):
    found = crease_corners(elements, ctx.meshes, nv, opened, buried)
    if found is None:
        return ()
    p, c, x, shade, geo, turned = found
    cut = turned | _sun_blocked(ctx, elements, p, c, turned)
    # rays start off the point along the two normals' bisector: above the triangle's plane and
    # toward the side the smoothing leans to (along the triangle's own normal, a corner a hair
    # from a concave fold started past its neighbour)
    up = shade + geo
    length = np.linalg.norm(up, axis=1)
    up = np.where((length > 1e-6)[:, None], up / np.maximum(length, 1e-300)[:, None], geo)
    eps = ray_offsets(ctx.patches, owner=elements.owner[p])
    # where the light below the plane is not cut, Cycles' ray leaves the corner itself, over
    # the edges that meet there: from the vertex's own point (on the front of all its
    # elements, :func:`.emitters.vertex_frames`) along the corner's shading normal, or the
    # bisector where that normal lies along the plane (off it along the normal, a hair behind
    # the plane, the ray met the corner's own face: Cycles' skips it)
    v = elements.polys[p, c]
    along = np.where((np.einsum("ij,ij->i", shade, geo) < NEAR_PERPENDICULAR)[:, None], up, shade)
    start = np.where(cut[:, None], x + eps[:, None] * up, xv[v] + eps[:, None] * along)
    own = ctx.direct.offsets(xv, nv)[v]         # the vertex's rays' (a hit: it was lit with them)
    same = ~cut & (np.abs(shade - nv[v]).max(axis=1) <= 1e-9) & (np.abs(eps - own) <= 1e-6 * own)
    return p, c, start, shade, geo, np.where(cut[:, None], geo, shade), same


def strongest_sun(ctx):
    """(3,) the direction toward the scene's strongest sun, or None without one."""
    suns = [li for li in ctx.direct.lights if isinstance(li, SunLight) and li.strength > 0]
    if not suns:
        return None
    return -max(suns, key=lambda li: li.strength * float(np.max(li.color))).direction


def _sun_blocked(ctx, elements, p, c, turned) -> np.ndarray:
    """(K,) bool: corners (not ``turned``) of ``elements`` at a corner of their source face on
    whose Blender triangles (most of them) Cycles' shadow ray toward the scene's strongest sun
    is blocked below the triangle's plane, from its lifted start (:func:`.lift.blocked_share`):
    their light from below that plane is cut. False elsewhere, and without a sun."""
    out = np.zeros(len(p), bool)
    to_sun = strongest_sun(ctx)
    if to_sun is None:
        return out
    scene = _fronts_scene(ctx)

    def occluded(x, d):
        return scene.occluded(x, np.broadcast_to(d, x.shape), None)
    owner = elements.owner[p]
    size = float(np.linalg.norm(np.ptp(elements.verts, axis=0))) if len(elements.verts) else 1.0
    for oi, m in enumerate(ctx.meshes):
        if getattr(m, "corner_normal", None) is None or getattr(m, "back_of", -1) >= 0:
            continue
        rows = np.flatnonzero((owner == oi) & ~turned)
        if not rows.size:
            continue
        face = elements.source_face[p[rows]].astype(np.int64)
        j = face_corners(m, face, elements.verts[elements.polys[p[rows], c[rows]]], 1e-9 * size)
        at = j >= 0
        out[rows[at]] = blocked_share(m, face[at], j[at], to_sun, occluded) >= 0.5
    return out


def _fronts_scene(ctx):
    """The shadow rays' scene without the backs of open surfaces (:mod:`..mesh.backs`), which
    Cycles has not: a ray lifted a few micrometres off a slope's corner passes over the lip's
    edge there, and the slope's back, a hair behind it, stopped it here."""
    P = ctx.patches
    fronts = [i for i, m in enumerate(ctx.meshes or ()) if getattr(m, "back_of", -1) < 0]
    keep = np.isin(P.owner, fronts)
    if keep.all():
        return ctx.direct.scene()
    return occluder(replace(P, polys=P.polys[keep], centers=P.centers[keep], normals=P.normals[keep],
                            areas=P.areas[keep], rho=P.rho[keep], emission=P.emission[keep],
                            owner=P.owner[keep], source_face=P.source_face[keep]), "auto")
