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
starts lifted toward the smooth surface (the shadow-terminator geometry offset, the whole of it
for every such light) and does not skip its own triangle: the slope's corner is dark where that
ray meets the slope, lit where it passes over the lip's edge. A crest of grass whose steep
triangle's corner is shaded with the hilltop's normal is lit by a sun a little below the
triangle's plane wherever the lift carries the ray past the triangle's far edge.

Here, at every corner whose shading normal (its own face's corner normal, interpolated at the
vertex: :func:`.normals.corner_shading_normals`) leans more than :data:`CREASE_ANGLE` off its
own triangle's geometric normal, or off the normal its vertex was lit with, the direct light is
found again for that corner alone, the cosine taken to its shading normal
(:func:`corner_light`), and its light reflected more than once (per vertex) scaled by the share
of its hemisphere above the triangle's plane; a turned-around corner's by what its own rays
read in its lune, which lies behind the face, where the vertex's gather did not look
(:mod:`.lune`: inside a game level's brushes, nothing), and it is lit so even where its element
is one the scene does not see or its vertex is buried. A turned-around corner has both normals
negated and takes no light from below its triangle's plane. The lamps' and the world's light
from above the plane (``facing`` of :meth:`.light.direct.DirectLight.at`; an emitting face's is
not limited: its shadow rays start above the plane) is found by rays from a point :data:`INSET`
of the way into the corner's element, off it by its object's offset (:func:`.rays.ray_offsets`)
along the two normals' bisector; the lamps' from below the plane by rays from Cycles' lifted
start (:func:`.lift.lifted_starts`, where Cycles bakes the corner: the first of Blender's
triangles of its face holding it), and the world's so too, :data:`BELOW_WORLD` of it
(:func:`below_plane`).
Where Cycles' bake point is not known (an element corner inside its face), the rays start at
the vertex's own point (on the front of all its elements), as Cycles' leave the corner itself,
nothing cut. Only meshes with corner normals (smooth or custom-normal faces as Blender reads
them) have such corners: elsewhere the faces that share a vertex lie in one plane, and the bake
is as before bit for bit. Radiance units; world space.
"""
from __future__ import annotations

import numpy as np

from ..rays import ray_offsets
from ..light.lamps import SunLight
from ..mesh.patches import meshes_key
from ..runtime.cache import array_key, cache_key, cached, geometry_key
from .above import above_shares
from .lift import ON_PLANE_ULPS, bake_points, corner_normals, lifted_starts
from .indirect import gather_count
from .lune import lune_shares
from .normals import corner_shading_normals

__all__ = ["CREASE_ANGLE", "INSET", "bisector", "crease_corners", "corner_light", "inset_points", "leans",
           "strongest_sun"]

#: Degrees: a corner's shading normal leaning this far off its triangle's normal, or off its
#: vertex's normal, gets the corner its own direct light. Truck town: 5 degrees lit 63,204 of
#: its 91,431 corners on their own, 15 degrees 31,467, for the same error (11.21%, 11.22%).
CREASE_ANGLE = 15.0
#: How far toward its element's centre a corner is lit (as :func:`.emitters.vertex_frames`' points).
INSET = 1e-2
#: Degrees: a corner shaded at its bake point with a normal turned this far off its vertex's
#: takes that normal (:func:`_at_bake_points`).
BAKE_TURN = 1.0
#: A corner whose shading normal's cosine to its triangle's normal is smaller than this (in
#: magnitude) is turned around or not as its normal at Cycles' bake point says (:func:`_turned`),
#: and its rays start off the plane along the two normals' bisector.
NEAR_PERPENDICULAR = 0.05
#: A normal at the bake point within this cosine of its triangle's plane is not turned around:
#: along the plane to rounding, Cycles shades its front (godot_zdm2: of the 1,911 corners whose
#: normal lies within 1e-6 of their plane, Cycles' NORMAL bake turns 7%).
TIE = 1e-6


def leans(a, b) -> np.ndarray:
    """(K,) bool: unit normals ``a`` (K, 3) more than :data:`CREASE_ANGLE` off ``b`` (K, 3)."""
    return np.einsum("ij,ij->i", a, b) < np.cos(np.radians(CREASE_ANGLE))


def bisector(shade, geo) -> np.ndarray:
    """(K, 3) the unit bisector of unit normals ``shade`` and ``geo`` (K, 3), where a corner's
    rays leave it: above its triangle's plane and toward the side its smoothing leans to;
    ``geo`` where the two cancel."""
    up = shade + geo
    length = np.linalg.norm(up, axis=1)
    return np.where((length > 1e-6)[:, None], up / np.maximum(length, 1e-300)[:, None], geo)


def inset_points(elements, p, v) -> np.ndarray:
    """(K, 3) vertex ``v`` (K,) of element ``p`` (K,) moved :data:`INSET` of the way toward
    the element's centre: where a corner lit on its own is lit."""
    return elements.verts[v] + INSET * (elements.centers[p] - elements.verts[v])


def crease_corners(elements, meshes, nv, opened=None, buried=None):
    """The element corners lit on their own, or None when there are none:
    (p (K,) element, c (K,) corner 0..3, points (K, 3) where each is lit, shading (K, 3) unit
    normal for the cosine, geometric (K, 3) the corner triangle's unit normal, turned (K,) bool:
    the two faced apart and are both negated, to the side Cycles shades (module docstring)).
    ``nv`` (V, 3) the normals the vertices were lit with; ``opened`` (N,) 0 for elements the
    scene does not see and ``buried`` (V,) bool vertices that take the open side's light
    (:func:`.sides.buried_side`): neither is lit again, but where Cycles turns the corner
    around (those rows last)."""
    polys = elements.polys
    p, c = np.nonzero(polys >= 0)
    shade, has = corner_shading_normals(elements, meshes, p, c)
    if shade is None:
        return None
    p, c, shade = p[has], c[has], shade[has]
    v = polys[p, c]
    seen = np.ones(len(p), bool)
    if opened is not None:
        seen &= np.asarray(opened)[p] > 0
    if buried is not None:
        seen &= ~np.asarray(buried, bool)[v]
    # the corners the scene does not see are lit again only where Cycles turns them around:
    # their lune lies behind the face, where the vertex's light says nothing (:mod:`.lune`);
    # after the others, which are found as before
    rows = [_fired(elements, meshes, p[seen], c[seen], shade[seen], nv, False),
            _fired(elements, meshes, p[~seen], c[~seen], shade[~seen], nv, True)]
    rows = [r for r in rows if r is not None]
    if not rows:
        return None
    return tuple(np.concatenate(a) for a in zip(*rows))


def _fired(elements, meshes, p, c, shade, nv, turned_only):
    """:func:`crease_corners`' rows among corners ``c`` (K,) of elements ``p`` (K,) with
    shading normals ``shade`` (K, 3), or None; ``turned_only``: only those turned around."""
    v = elements.polys[p, c]
    geo = corner_normals(elements, p, c)
    cos_max = np.cos(np.radians(CREASE_ANGLE))
    facing = np.einsum("ij,ij->i", shade, geo)
    if turned_only:
        fire = facing < NEAR_PERPENDICULAR
    else:
        fire = (facing < cos_max) | (np.einsum("ij,ij->i", shade, nv[v]) < cos_max)
    if not fire.any():
        return None
    p, c, v, shade, geo, facing = p[fire], c[fire], v[fire], shade[fire], geo[fire], facing[fire]
    turned = _turned(elements, meshes, p, c, geo, facing)
    if turned_only:
        if not turned.any():
            return None
        p, c, v, shade, geo = p[turned], c[turned], v[turned], shade[turned], geo[turned]
        turned = turned[turned]
    shade = _at_bake_points(elements, meshes, p, c, shade)
    turn = np.where(turned, -1.0, 1.0)[:, None]
    return p, c, inset_points(elements, p, v), shade * turn, geo * turn, turned


def _at_bake_points(elements, meshes, p, c, shade) -> np.ndarray:
    """``shade`` (K, 3), but the normal where Cycles bakes corner ``c`` (K,) of element ``p``
    (K,) (:func:`.lift.bake_points`: nudged toward its triangle's centre by
    :data:`.lift.BAKE_NUDGE` of its coordinates, 0.47 mm in the staircase hall, interpolated
    there from the triangle's three corner normals) where it turns more than
    :data:`BAKE_TURN` degrees off the vertex's: on a triangle a millimetre across (a candle
    flame's tip, a pole of 32 faces) the bake point lies half way in, and the tip's corners are
    shaded with normals leaning each toward its own face (Cycles 0.9 to 2.1 round one tip,
    one value of 1.15 from the vertex's normal); elsewhere the two agree."""
    at = bake_points(elements, meshes, p, c)
    n, has = corner_shading_normals(elements, meshes, p, c, at)
    move = has & (np.einsum("ij,ij->i", n, shade) < np.cos(np.radians(BAKE_TURN)))
    if not move.any():
        return shade
    out = np.array(shade, dtype=np.float64)
    out[move] = n[move]
    return out


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


def corner_light(ctx, elements, xv, nv, light_v, opened=None, buried=None, read_v=None, own=True,
                 arriving_v=None):
    """(light (N, 4, 3), keep (N, 4), turned (N, 4) bool) at every corner of ``elements``: the
    direct light (radiance arriving), each vertex's ``light_v`` (V, 3) (lit at ``xv`` (V, 3)
    along ``nv`` (V, 3)) but at the corners of :func:`crease_corners` their own, lit by
    ``ctx.direct`` (a triangle's fourth corner its third); and the share of the light reflected
    more than once that each corner keeps: 1, but at those corners the share of what the
    vertex's gather read (as ``read_v`` (V, 3), the light leaving the vertices) that arrived
    from above the triangle's plane (:func:`.above.above_shares`; Cycles' diffuse bounce takes
    nothing from below that plane, ``bsdf_diffuse_sample``), or where that is not known the
    share of the shading normal's cosine-weighted hemisphere above the plane, (1 + N . Ng) / 2
    (the sky view factor of a plane tilted by their angle: the light arriving taken as even
    over the hemisphere); at a turned-around corner, what its own rays read in the lune behind
    its face over the light reflected more than once arriving at its vertex, ``arriving_v`` (V,
    3) (:func:`.lune.lune_shares`; the vertex's gather looked the other way); and which corners
    are turned around. None when no corner is lit on its own. ``own`` False: the keep shares
    only, every corner's light its vertex's (a lightmap finds the direct light again at its
    texels and reads only the corners' light reflected more than once,
    :meth:`..pipeline.BakeResult.corner_parts`: no ray is cast for the corners' own)."""
    if ctx.direct is None:
        return None
    found = _corner_rays(ctx, elements, xv, nv, opened, buried)
    if not found:
        return None
    p, c, start, shade, geo, facing, same, low, turned = found
    # a corner lit as its vertex was (from the same start, along the same normal, nothing cut)
    # takes the vertex's light: only the others cast rays
    D = np.array(light_v, dtype=np.float64)[elements.polys[p, c]]
    o = ~same & own
    if o.any():
        D[o] = ctx.direct.at(start[o], shade[o], "corners", eps=np.zeros(int(o.sum())), facing=facing[o])
    if own:
        D += below_plane(ctx, low, shade, geo, "corners-below")     # Cycles' lifted rays
    k = (1.0 + np.einsum("ij,ij->i", shade, geo)) / 2           # the hemisphere's share above the plane
    share = above_shares(ctx, elements, p, c, geo, xv, read_v)   # the gather's hits say it,
    # where the vertex gathered about the corner's own shading normal (not where Cycles wrote
    # another face's normal over the vertex, :mod:`..mesh.cycles_normals`)
    about = ~leans(shade, nv[elements.polys[p, c]])
    k = np.where(np.isfinite(share) & about, share, k)
    if turned.any():               # the lune lies behind the face, where the vertex did not look
        t = np.flatnonzero(turned)
        lune = lune_shares(ctx, elements, bake_points(elements, ctx.meshes, p[t], c[t]),
                           ray_offsets(ctx.patches, owner=elements.owner[p[t]]), shade[t], geo[t],
                           elements.polys[p[t], c[t]], read_v, arriving_v, gather_count(ctx))
        k[t] = np.where(np.isfinite(lune), lune, k[t])
    light = np.array(light_v, dtype=np.float64)[elements.corner_ids()]
    keep = np.ones(light.shape[:2])
    tri = (elements.polys[p, 3] < 0) & (c == 2)
    around = np.zeros(light.shape[:2], bool)
    for out, value in ((light, D), (keep, k), (around, turned)):
        out[p, c] = value
        out[p[tri], 3] = value[tri]
    return light, keep, around


def _corner_rays(ctx, elements, xv, nv, opened, buried):
    """The corners :func:`corner_light` lights on their own and their rays, () when none:
    (p (K,), c (K,), start (K, 3) of the rays, shading (K, 3) and geometric (K, 3) normals as
    :func:`crease_corners` gives them, facing (K, 3) what the lamps' and the world's light is
    limited by, same (K,) bool: lit as the vertex was, its light the vertex's: nothing cut, the
    shading normal the vertex's (to 1e-9) and the rays' start its (the offsets equal to a
    millionth: only corners whose bake point is not known), low (K, 3) where the rays toward
    the light below the triangle's plane start (:func:`.lift.lifted_starts`, NaN: none, the
    corner turned around or its bake point not known), turned (K,) bool: turned around.
    Geometry only: cached (a relight in a new process reads them from the cache folder)."""
    mk = ctx.meshes_key() if hasattr(ctx, "meshes_key") else meshes_key(ctx.meshes)
    for m in ctx.meshes or ():
        mk += b"|" + repr(getattr(m, "back_of", -1)).encode()
        if getattr(m, "corner_normal", None) is not None:
            mk += array_key(np.asarray(m.corner_normal))
    mk += b"".join(b"-" if a is None else array_key(np.asarray(a)) for a in (xv, nv, opened, buried))
    key = cache_key(geometry_key(elements) + geometry_key(ctx.patches) + mk, ("crease-rays-turned", CREASE_ANGLE, INSET, ON_PLANE_ULPS))
    return cached(ctx.cache, key, lambda: _make_corner_rays(ctx, elements, xv, nv, opened, buried))


def _make_corner_rays(ctx, elements, xv, nv, opened, buried):
    found = crease_corners(elements, ctx.meshes, nv, opened, buried)
    if found is None:
        return ()
    p, c, x, shade, geo, turned = found
    # Cycles' rays toward the lights below the triangle's plane start from the bake point
    # lifted by the shadow-terminator offset (:func:`.lift.lifted_starts`); the others from
    # the corner
    low = np.where(turned[:, None], np.nan, lifted_starts(elements, ctx.meshes, p, c))
    cut = turned | np.all(np.isfinite(low), axis=1)
    # rays start off the point along the two normals' bisector: above the triangle's plane and
    # toward the side the smoothing leans to (along the triangle's own normal, a corner a hair
    # from a concave fold started past its neighbour)
    up = bisector(shade, geo)
    eps = ray_offsets(ctx.patches, owner=elements.owner[p])
    # where Cycles' bake point is not known (a vertex cut inside a face), the ray leaves the
    # corner itself, over the edges that meet there: from the vertex's own point (on the front
    # of all its elements, :func:`.emitters.vertex_frames`) along the corner's shading normal,
    # or the bisector where that normal lies along the plane (off it along the normal, a hair
    # behind the plane, the ray met the corner's own face: Cycles' skips it)
    v = elements.polys[p, c]
    along = np.where((np.einsum("ij,ij->i", shade, geo) < NEAR_PERPENDICULAR)[:, None], up, shade)
    start = np.where(cut[:, None], x + eps[:, None] * up, xv[v] + eps[:, None] * along)
    own = ctx.direct.offsets(xv, nv)[v]         # the vertex's rays' (a hit: it was lit with them)
    same = ~cut & (np.abs(shade - nv[v]).max(axis=1) <= 1e-9) & (np.abs(eps - own) <= 1e-6 * own)
    return p, c, start, shade, geo, np.where(cut[:, None], geo, shade), same, low, turned


#: The share of the world's light from below a corner's triangle's plane that counts (the lamps'
#: counts whole): Cycles' bounce drops those directions, its light sampling keeps its multiple
#: importance weight for them. Truck town's corners whose sun lies below their shading normal
#: (1,068): 0.106 with all of it, 0.080 with none, 0.093 with half, Cycles 0.092.
BELOW_WORLD = 0.5


def below_plane(ctx, low, shade, geo, where) -> np.ndarray:
    """(K, 3) the lamps' (and the world's, :data:`BELOW_WORLD`) light arriving from below the
    plane of each corner's triangle (unit normal ``geo`` (K, 3)) and above its shading normal's
    ``shade`` (K, 3), by shadow rays from ``low`` (K, 3), Cycles' lifted start for such light
    (:func:`.lift.lifted_starts`; NaN rows: none, 0). Not the emitters': the light above the
    plane counted them whole (their shadow rays start above it), so they would count twice."""
    out = np.zeros((len(low), 3))
    r = np.flatnonzero(np.all(np.isfinite(low), axis=1))
    if r.size and ctx.direct is not None:
        out[r] = ctx.direct.lamps_at(low[r], shade[r], where, eps=np.zeros(r.size), facing=-geo[r])
        if BELOW_WORLD and ctx.direct.world is not None:
            out[r] += BELOW_WORLD * ctx.direct.world_at(low[r], shade[r], where, eps=np.zeros(r.size), facing=-geo[r])
    return out


def strongest_sun(ctx):
    """(3,) the direction toward the scene's strongest sun, or None without one."""
    suns = [li for li in ctx.direct.lights if isinstance(li, SunLight) and li.strength > 0]
    if not suns:
        return None
    return -max(suns, key=lambda li: li.strength * float(np.max(li.color))).direction
