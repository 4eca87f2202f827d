"""Light per element corner where another surface lies between the corner and its vertex's rays.

An output vertex is lit once (:mod:`.stage`), its rays starting a ray offset off a point a hair
inside its elements (:func:`.rays.ray_offsets`: 1e-5 of the object's diagonal, 2 cm on a 2 km
ground ring). Cycles bakes each face corner at the corner itself, nudged toward its triangle's
centre (:data:`.lift.BAKE_NUDGE`), and its rays start there, skipping only their own triangle
(``kernel/integrator/init_from_bake.h``; self-intersection is avoided by primitive, not by
distance). Where another surface passes closer over the corner than our rays start (a bevel
strip tucked under the slab it meets, a wall's top under a coincident lid, grass lying a few
millimetres under a road, the ground ring under the town's grass), Cycles' rays meet it and
the corner is dark, and the light around it is what a render shows there; ours started above
it and read the open room or the sun.

Here every element corner is baked where Cycles bakes it (:func:`.lift.bake_points`: a corner of
its source face on the first of Blender's triangles holding it, moved toward that triangle's
centre; any other toward its element's), and a bake point is *covered* where another face lies
over it, along its triangle's normal, within its object's ray offset, or between it and where
its vertex's rays start, or on the ray toward the scene's strongest sun before that ray rises a
ray offset over the corner's plane (a kerb's lip beside the grass's corner, not over it: our
sun ray starts over the lip), or where that sun reaches the bake point and not where the
vertex's rays start, or the other way round: a shadow's edge through the vertex (a wall's end
on the floor it stands on, whose faces meet there: one corner in the wall's shadow, the next in
the sun; an overhang's edge over a slope's vertex; :func:`covered_corners`; five rays per
point, those from the point going on past the corner's own face: a warped face's elements,
cut bilinearly, run a hair off Blender's triangle the point lies on, in front of what covers
it). A covered point is lit
on its own (:func:`covered_light`) from :data:`LIFT_ULPS` float32 steps off it (at most half
way to the face over it): its direct light found again there (cosine to its shading normal,
the light from below its triangle's plane by rays from Cycles' lifted start where its shading
normal leans off the triangle's, :func:`.crease.below_plane`; none of the scene's sun where
a face near the bake point meets its own ray toward it, as Cycles' shadow ray starts there:
:func:`_sun_shaded`), and its vertex's light
reflected more than once scaled by how much of the open scene it sees against how much the vertex's start did
(:func:`.hemisphere.open_fraction`: rays closed within a twentieth of the patch size or on a back
face lend nothing; in a crack they only meet its dark walls; :mod:`.near` adds the direct light
of the near faces' fronts those rays meet, lit in a sunlit wedge's apex), the vertex's taken as at least
:data:`OPEN_FLOOR`: a vertex whose rays start inside a solid (a bevelled box resting on a
shelf of the same mesh, its foot's rays starting in the shelf) gathered the light its closed
rays read there, 0.85 of the shelf's radiance where Cycles' corner on the bevel, a hair over the
shelf, has 0.05. Faces within :data:`TIE_ULPS`
float32 steps of the point (a duplicate face: either may be drawn) cover nothing, nor do backs
of open surfaces (:mod:`..mesh.backs`), which Cycles has not. Corners of elements the scene does
not see at a vertex of one it sees (a floor's under a block on it) keep their vertex's light,
whose mean they are part of, unless they are corners of their source face: Cycles bakes a face
corner on its own triangle, so where a face folds down from the open under another surface
(truck town's grass under its ground ring, its road's edge under the grass) the fold's corner is
dark and the open face's corner beside it lit (:func:`.lift.source_corners`). The corners of
buried vertices (:func:`.sides.buried_side`) that are corners of their source face are all lit
at their own bake point, covered or not (a bevel's foot on the shelf the bevelled box rests on:
dark; truck town's slivers of a house's ledge in a nook of its walls, whose open neighbours lie
in a wall's shadow a hair off it: lit, 0.02 where Cycles has 0.21), and one lit there with
nothing over it keeps its vertex's light reflected more than once whole (that was spread from
the open side, not gathered where the vertex's rays start); their other corners keep their
vertex's light. A buried vertex's is the light where its edge from the open side meets what
buries it (the bevel's edge, a little up it: the open room's light, where Cycles' point at the
foot sees the shelf a hair under it and little else), and the rays from that point start no
further off it than half way to a face over it (:func:`start_offsets`): the point lies against
the burying surface, and rays started past a lip over it read the sun. Geometry only, cached:
a relight casts no ray. World units.
"""
from __future__ import annotations


import numpy as np

from ..light.lamps import UNBOUNDED, SunLight
from ..rays import embree_available, embree_scene, ray_offsets
from ..hemisphere import open_fraction
from ..mesh.backs import backs_of_pieces
from ..runtime.cache import array_key, cache_key, cached, geometry_key
from .crease import INSET, below_plane, bisector, inset_points, leans, strongest_sun
from .lift import bake_points, corner_normals, lifted_starts, source_corners
from .near import face_keys, near_part
from .normals import corner_shading_normals

__all__ = ["TIE_ULPS", "LIFT_ULPS", "covered_corners", "covered_light", "front_scene", "open_share",
           "start_offsets"]

#: Float32 steps of a point's largest coordinate within which a surface counts as coincident
#: with it (a duplicate face), not as covering it.
TIE_ULPS = 1
#: Float32 steps of a point's largest coordinate its rays start off its surface (or half way to
#: the surface over it, if nearer): as near as Cycles' start, at the corner itself, as a ray off a
#: plane can start without meeting it again. Cycles' shadow ray toward a sun low over the point
#: that meets a face a few hundredths of a millimetre up passes over its edge from a start lifted
#: higher (truck town's road corner beside the grass: 16 steps, 5.7e-5 m there, lit it, 0.35
#: where Cycles has 0.12; 8 steps: 0.11).
LIFT_ULPS = 8
#: How many times a covering ray goes on past its own face's hits (:func:`_cover_along`).
OWN_PASSES = 3
#: Cosine rays per covered corner for the share of the open scene it sees.
OPEN_RAYS = 64
#: The least rise of the strongest sun over a corner's triangle (the sine of its elevation above
#: the plane) for which its ray is followed until it rises a ray offset: as high as our rays start.
SUN_RISE = 0.1
#: The least cosine between a corner's shading normal and its triangle's normal at which the
#: face counts as flat, so that Cycles' shadow ray toward the sun starts at its bake point.
FLAT_COS = float(np.cos(np.radians(1.0)))
#: Cycles' default shadow terminator geometry offset: on a smooth face its shadow ray starts at the
#: shading point where both the triangle's and the shading normal's cosine to the light reach it.
TERMINATOR = 0.1
#: The least share of the open scene a covered corner's vertex is taken to see: where fewer of
#: its rays leave (its start lies inside a solid: a bevel's foot on a shelf), what it gathered is
#: mostly what those closed rays read, no measure of the open scene's light.
OPEN_FLOOR = 0.5


def covered_corners(ctx, elements, xv, nv, opened=None, buried=None):
    """The element corners lit at their own bake point (module docstring), or None:
    (p (K,) element, c (K,) corner 0..3, start (K, 3) where it is lit from, geo (K, 3) the
    corner triangle's unit normal, alone (K,) bool: a corner of a buried vertex lit there only
    for being Cycles' own point, nothing over it, point (K, 3) its bake point). ``xv``, ``nv`` (V, 3): where each vertex was
    lit and its normal; ``opened`` (N,) 0 for elements the scene does not see: their corners at a
    vertex of an element it sees (a floor's under a block resting on it) are not looked at,
    they count in that vertex's mean; nor are the corners of ``buried`` (V,) bool vertices,
    which take the open side's light (:func:`.sides.buried_side`); either unless it is a
    corner of its source face, where Cycles bakes (a buried vertex's such corners are all
    lit there). None without Embree."""
    if not embree_available() or len(elements) == 0:
        return None
    sun = strongest_sun(ctx)                  # its rays pick corners: a sun turned picks others
    # the meshes' corner normals too: a leaning corner's pick follows its shading normal
    shading = b"".join(array_key(np.asarray(m.corner_normal)) for m in ctx.meshes or ()
                       if getattr(m, "corner_normal", None) is not None)
    key = cache_key(geometry_key(elements) + shading + array_key(xv) + array_key(nv)
                    + (b"" if opened is None else array_key(np.asarray(opened, dtype=np.float64)))
                    + (b"" if buried is None else np.asarray(buried, bool).tobytes())
                    + (b"" if sun is None else array_key(np.asarray(sun, dtype=np.float64))), ("covered-corners", 8, INSET))
    code = cached(ctx.cache, key, lambda: _find(ctx, elements, xv, nv, opened, buried))
    if len(code) == 0:
        return None
    p, c = code[:, 0].astype(np.int64), code[:, 1].astype(np.int64)
    return p, c, code[:, 2:5], code[:, 5:8], code[:, 8] > 0, code[:, 9:12]


def _find(ctx, elements, xv, nv, opened, buried) -> np.ndarray:
    """(K, 12) rows (element, corner, start (3), geo (3), alone, bake point (3)) of
    :func:`covered_corners`."""
    polys = elements.polys
    p, c = np.nonzero(polys >= 0)
    keep = np.ones(len(p), bool)

    def inner(left):          # (left,) True at corners that are no corner of their source face
        k = np.flatnonzero(left)
        return source_corners(elements, ctx.meshes, p[k], elements.verts[polys[p[k], c[k]]]) < 0
    if opened is not None:
        seen = np.asarray(opened)[p] > 0
        shared = np.zeros(len(elements.verts), bool)
        shared[polys[p[seen], c[seen]]] = True
        left = ~seen & shared[polys[p, c]]
        left[left] = inner(left)
        keep &= ~left
    alone = np.zeros(len(p), bool)       # corners of buried vertices lit where Cycles bakes them
    if buried is not None:
        left = np.asarray(buried, bool)[polys[p, c]]
        alone = left.copy()
        left[left] = inner(left)
        alone &= ~left
        keep &= ~left
    p, c, alone = p[keep], c[keep], alone[keep]
    point = bake_points(elements, ctx.meshes, p, c)
    v = polys[p, c]
    tie = TIE_ULPS * 2.0 ** -23 * np.maximum(np.abs(point).max(axis=1), 1.0)
    geo = corner_normals(elements, p, c)
    eps = ray_offsets(ctx.patches, owner=elements.owner[p])
    fronts, scene = _fronts(ctx, elements)
    own = face_keys(elements)
    origin = point + tie[:, None] * geo
    # the nearest surface above the point along its triangle's normal, within the ray offset
    above, t = _cover_along(scene, fronts, own, p, origin, geo, eps, tie)
    gap = np.where(above, tie + t, np.inf)
    # or the segment from the point to where the vertex's rays start crosses a surface
    seg = xv[v] + eps[:, None] * nv[v] - origin
    length = np.linalg.norm(seg, axis=1)
    hit, _ = scene.intersect(origin, seg / np.maximum(length, 1e-300)[:, None], length)
    hit = np.asarray(hit)
    crossed = (hit >= 0) & (length > 0)
    crossed[crossed] = own[fronts[hit[crossed]]] != own[p[crossed]]
    picked = crossed | above
    to_sun = strongest_sun(ctx)
    if to_sun is not None:
        picked |= _sun_picks(ctx, elements, scene, fronts, own, p, c, origin, geo, eps, tie, xv, nv, to_sun)
    chosen = picked | alone
    alone &= ~picked
    if not chosen.any():
        return np.zeros((0, 12))
    start = point + np.minimum(np.minimum(eps, 0.5 * gap), LIFT_ULPS * tie / TIE_ULPS)[:, None] * geo
    return np.column_stack([p, c, start, geo, alone, point])[chosen].astype(np.float64)


def _sun_picks(ctx, elements, scene, fronts, own, p, c, origin, geo, eps, tie, xv, nv, to_sun):
    """(K,) bool: the corners ``c`` of elements ``p`` (K,) whose bake point (rays from
    ``origin``, normal ``geo``) the strongest sun ``to_sun`` lights otherwise than it lights
    their vertex's rays' start (``xv``, ``nv``, offsets ``eps``), for :func:`_find`."""
    v = elements.polys[p, c]
    # the sun's ray meets a surface before it rises as high as our rays start
    rise = geo @ to_sun
    toward = rise > 0.0
    reach = np.where(toward, eps / np.maximum(rise, SUN_RISE), 0.0)
    along = np.broadcast_to(to_sun, origin.shape)
    shaded, _ = _cover_along(scene, fronts, own, p, origin, along, reach, tie)
    picked = toward & shaded
    # or the sun reaches the bake point and not the vertex's start, or the other way round:
    # a shadow's edge through the vertex (a wall's end on the floor it stands on)
    # where Cycles' shadow ray starts at the bake point: a flat face, or a smooth one the sun
    # shines on well enough (else its shadow terminator offset starts it toward the smooth
    # surface); not at a leaning corner (:mod:`.crease` lights it on its own)
    shade, has = corner_shading_normals(elements, ctx.meshes, p, c)
    shade = geo if shade is None else np.where(has[:, None], shade, geo)
    flat = np.einsum("ij,ij->i", shade, geo) >= FLAT_COS
    high = (rise >= TERMINATOR) & (shade @ to_sun >= TERMINATOR)
    k = np.flatnonzero(toward & (flat | high) & ~leans(shade, geo) & ~leans(shade, nv[v]))
    here = _sun_reaches(scene, fronts, own, p[k], origin[k], to_sun, tie[k])
    # each vertex's start once (its corners share it: the same ray)
    starts, back = np.unique(np.column_stack([v[k], eps[k].view(np.int64)]), axis=0, return_inverse=True)
    u, e = starts[:, 0], starts[:, 1].copy().view(np.float64)
    there = _sun_reaches(scene, None, None, None, xv[u] + e[:, None] * nv[u], to_sun)
    there = there[back.ravel()] & (nv[v[k]] @ to_sun > 0.0)
    picked[k[here != there]] = True
    # a leaning corner (:mod:`.crease` lights it from a ray offset off a point :data:`.crease.INSET`
    # into its element, along the bisector of its two normals): the sun reaches its bake point
    # and not that start, or the other way round (the living room's bevel corner 614, in the
    # shadow of the face beside it, 0.3 mm on, which the start passed)
    j = np.flatnonzero(toward & ~picked & leans(shade, geo) & (shade @ to_sun > 0.0))
    if j.size:
        start = inset_points(elements, p[j], v[j]) + eps[j, None] * bisector(shade[j], geo[j])
        here = _sun_reaches(scene, fronts, own, p[j], origin[j], to_sun, tie[j])
        there = _sun_reaches(scene, fronts, own, p[j], start, to_sun, tie[j])
        picked[j[here != there]] = True
    return picked


def _front_rows(ctx, patches):
    """(F,) the rows of ``patches`` (or elements) that are no back of an open surface
    (:mod:`..mesh.backs`), or None where the bake has no backs."""
    back = backs_of_pieces(ctx.meshes, patches)
    return None if back is None else np.flatnonzero(~back)


def _fronts(ctx, elements):
    """(rows (F,) of ``elements`` that are no back of an open surface (:mod:`..mesh.backs`),
    the Embree scene of those): Cycles has no backs, and a back lies a hair behind its face, over
    a surface the face touches."""
    return front_scene(elements, _front_rows(ctx, elements))


def front_scene(elements, rows):
    """(rows (F,), the Embree scene of those rows of ``elements``): ``rows`` those that are no
    back of an open surface, or None where there is none (every row, the whole set's scene)."""
    if rows is None:
        return np.arange(len(elements)), embree_scene(elements)
    return rows, embree_scene(elements.take(rows))


def _cover_along(scene, fronts, own, p, origin, direction, reach, tie):
    """((K,) bool, (K,) distance): whether the ray from each ``origin`` (K, 3) along its unit
    ``direction`` (K, 3) meets, within ``reach`` (K,), another face than that of the corner of
    element ``p`` (K,) it starts from, and how far along (inf where none). A ray that meets the
    corner's own face first goes on past it (up to :data:`OWN_PASSES` times): our
    elements cut a bent face along other diagonals than Blender's triangle the bake point lies
    on, so its first hit may be a hair away on its own face, over the face that covers it (a
    bevel's foot a few microns over the shelf it rests on)."""
    dist, _ = walk_along(scene, own[fronts], own[p], origin, np.asarray(direction, dtype=np.float64), reach, tie)
    return np.isfinite(dist), dist


def walk_along(scene, keys, own, origin, direction, reach, tie, same=False):
    """((n,) distance, (n,) face row or -1): how far along each unit ``direction`` (n, 3) from
    ``origin`` (n, 3) a ray meets, within ``reach`` (n,), a face of ``scene`` whose key (``keys``
    (F,), one per row of the scene) is (``same``) or is not its ``own`` (n,), going on past the
    others' hits (:data:`OWN_PASSES` times, a float32 step ``tie`` (n,) on); inf and -1 where none."""
    origin = np.array(origin, dtype=np.float64)
    left = np.array(reach, dtype=np.float64)
    dist = np.full(len(origin), np.inf)
    row = np.full(len(origin), -1, np.int64)
    gone = np.zeros(len(origin))
    todo = np.arange(len(origin))
    for _ in range(OWN_PASSES):
        hit, t = scene.intersect(origin[todo], direction[todo], left[todo])
        hit, t = np.asarray(hit), np.asarray(t, dtype=np.float64)
        met = hit >= 0
        found = np.zeros(len(todo), bool)
        found[met] = (keys[hit[met]] == own[todo[met]]) == same
        dist[todo[found]] = gone[todo[found]] + t[found]
        row[todo[found]] = hit[found]
        again = met & ~found & (t + tie[todo] < left[todo])
        todo, t = todo[again], t[again]
        if not len(todo):
            break
        step = t + tie[todo]                      # past the other hits, a float32 step on
        origin[todo] += step[:, None] * direction[todo]
        left[todo] -= step
        gone[todo] += step
    return dist, row


def _sun_reaches(scene, fronts, own, p, origin, to_sun, tie=None) -> np.ndarray:
    """(K,) bool: the ray from each ``origin`` (K, 3) toward the sun ``to_sun`` (3,) leaves the
    scene; with ``p`` (K,) it goes on past the own face of the corner of element ``p``
    (:func:`_cover_along`), else it starts where a ray offset put it."""
    along = np.broadcast_to(to_sun, np.shape(origin))
    far = np.full(len(origin), np.inf)
    if p is None:
        hit, _ = scene.intersect(origin, along, far)
        return np.asarray(hit) < 0
    return ~_cover_along(scene, fronts, own, p, origin, along, far, tie)[0]


def covered_light(ctx, elements, xv, nv, light_v, creased=None, opened=None, buried=None, own=True,
                  arriving_v=None):
    """(light (N, 4, 3), keep (N, 4)) as :func:`.crease.corner_light`'s, with the corners of
    :func:`covered_corners` lit on their own (module docstring), but those the crease turned
    around; ``creased``: what :func:`.crease.corner_light` gave (None: every corner its vertex's
    ``light_v`` (V, 3) and all of its light reflected more than once). Returns ``creased``'s
    light and keep when no corner is covered.
    ``own`` False: as :func:`.crease.corner_light`'s, the keep shares only (each covered
    corner's direct light its vertex's: no ray is cast for it). ``arriving_v`` (V, 3) or None:
    the light reflected at least once arriving at each vertex (per rho), of which a corner keeps
    its share; the near fronts' light seen from the vertex's start comes off it (:mod:`.near`)."""
    found = covered_corners(ctx, elements, xv, nv, opened, buried) if ctx.direct is not None else None
    if found is not None and creased is not None:
        # a corner Cycles turns around sees the lune behind its face, not what covers its front
        # (:mod:`.lune`): its light is the crease's
        front = ~creased[2][found[0], found[1]]
        found = tuple(a[front] for a in found) if front.any() else None
    if found is None:
        return None if creased is None else creased[:2]
    p, c, start, geo, alone, point = found
    shade, has = corner_shading_normals(elements, ctx.meshes, p, c)
    shade = geo if shade is None else np.where(has[:, None], shade, geo)
    shade = np.where((np.einsum("ij,ij->i", shade, geo) > 0)[:, None], shade, geo)
    v = elements.polys[p, c]
    D = _front_light(ctx, start, shade, geo, _sun_shaded(ctx, elements, p, point, geo, shade)) if own \
        else np.array(light_v, dtype=np.float64)[v]
    # and the light below the triangle's plane, from Cycles' lifted start (:mod:`.crease`)
    lean = leans(shade, geo) & own
    if lean.any():
        low = np.full((len(p), 3), np.nan)
        low[lean] = lifted_starts(elements, ctx.meshes, p[lean], c[lean])
        D += below_plane(ctx, low, shade, geo, "covered-below")
    reach = 0.05 * float(ctx.settings.patch_size or ctx.settings.element_size or 1.0)
    vstart = xv[v] + ray_offsets(ctx.patches, owner=elements.owner[p])[:, None] * nv[v]
    group = _start_groups(vstart, nv[v])       # each vertex's start once, for both
    k = _open_shares(ctx, elements, p, v, start, shade, xv, nv, reach, group)
    if own:       # what near fronts, lit, hand on, for what its vertex's had of it (:mod:`.near`)
        arriving = None if arriving_v is None else np.asarray(arriving_v, dtype=np.float64)[v]
        D += near_part(ctx, elements, start, shade, vstart, nv[v], group, reach, OPEN_RAYS, k, ~alone, arriving,
                       face_keys(elements)[p])
    # a buried vertex's corner lit here only for being Cycles' own point (nothing over it): the
    # vertex's light reflected more than once was spread from the open side, not gathered at
    # the vertex's start that the shares compare against; kept whole
    k = np.where(alone, 1.0, k)
    if creased is None:
        light = np.array(light_v, dtype=np.float64)[elements.corner_ids()]
        keep = np.ones(light.shape[:2])
    else:
        light, keep = np.array(creased[0], dtype=np.float64), np.array(creased[1], dtype=np.float64)
    tri = (elements.polys[p, 3] < 0) & (c == 2)
    for out, value in ((light, D), (keep, k)):
        out[p, c] = value
        out[p[tri], 3] = value[tri]
    return light, keep


def _open_shares(ctx, elements, p, v, start, shade, xv, nv, reach, group) -> np.ndarray:
    """(K,) the share of its vertex's light reflected more than once that each covered corner
    (of element ``p`` (K,) at vertex ``v`` (K,), lit from ``start`` (K, 3), shading normal
    ``shade``) keeps: the open scene it sees against what its vertex's start (``xv``, ``nv``)
    sees (:func:`.hemisphere.open_fraction`, rays closed within ``reach`` lend nothing), the
    vertex's taken as at least :data:`OPEN_FLOOR`; ``group``: the corners by their vertex's start
    (:func:`_start_groups`). Geometry only, cached."""
    key = cache_key(geometry_key(elements) + array_key(start) + array_key(xv), ("covered-open", reach, OPEN_FLOOR))

    def shares():
        one, of = group             # once per vertex start: each point's fraction is its own rays' alone
        there = (xv[v[one]], nv[v[one]], ray_offsets(ctx.patches, owner=elements.owner[p[one]]))
        return open_share(elements, embree_scene(elements), reach, OPEN_RAYS, (start, shade), there, of)
    return cached(ctx.cache, key, shares)


def open_share(elements, scene, reach: float, rays: int, here, there, of=None) -> np.ndarray:
    """(K,) the share of its light reflected more than once that a point keeps whose rays start
    ``here`` (points (K, 3), unit normals (K, 3)) and not ``there`` (points (U, 3), unit
    normals, ray offsets (U,); its rows ``of`` (K,), None: the same K): the share of the open
    scene seen from the one (:func:`.hemisphere.open_fraction`: ``rays`` cosine rays through
    ``scene``, the Embree scene of ``elements``; those closed within ``reach`` lend nothing)
    over that seen from the other, taken as at least :data:`OPEN_FLOOR`; at most 1. A covered
    corner's (:func:`covered_light`) and a covered texel's (:meth:`.texel_cover.Cover.keep`)."""
    x, n = here
    f = open_fraction(elements, x, n, scene, reach, rays=rays, eps=np.zeros(len(x)))
    y, m, eps = there
    g = open_fraction(elements, y, m, scene, reach, rays=rays, eps=eps)
    return np.minimum(1.0, f / np.maximum(g if of is None else g[of], OPEN_FLOOR))


def _start_groups(vstarts, vnormals):
    """(one (U,), of (K,)): covered corners grouped by where their vertex's rays start,
    ``vstarts`` (K, 3) along ``vnormals`` (K, 3): a corner ``one`` of each start, the starts in
    lexicographic order, and each corner's start. A vertex's covered corners are often several
    and share its start (its rays are cast once: :func:`_open_shares`, :func:`.near.near_part`),
    and coincident vertices share one too. By value, not by (vertex, object): the order of the
    starts is the order their shadow rays toward a sun with a size draw random numbers in
    (:func:`.light.lamps.light_irradiance`), so another order is another (as good) estimate."""
    _, one, of = np.unique(np.column_stack([vstarts, vnormals]), axis=0, return_index=True, return_inverse=True)
    return one, of.ravel()


def _sun_shaded(ctx, elements, p, point, geo, shade) -> np.ndarray:
    """(K,) bool: the bake point ``point`` (K, 3) of a corner of element ``p`` (K,) (its triangle's
    normal ``geo`` (K, 3), shading normal ``shade``) faces the sun and its ray toward it, a
    float32 step off it as :func:`_find`'s, meets a face (going on past the corner's own,
    :func:`_cover_along`) within where the sun's disc casts a penumbra as wide as a ray offset
    (further on, the shadow's edge is soft over more than the bake point and the corner's start
    lie apart, and a single ray tells nothing: zdm2's floor corners in a ceiling's penumbra
    11.7 m off, lit 0.46 in Cycles, read 0.21 with any hit): where Cycles' shadow ray starts there (a flat face, or a smooth one
    the sun shines on well enough, both normals :data:`TERMINATOR` toward it: else its shadow
    terminator offset starts it toward the smooth surface; truck town's corners whose face
    the sun grazes, lit in Cycles past a neighbour their bake point's ray meets), the point
    :data:`LIFT_ULPS` steps over it that the corner's direct light is found at may see past
    the edge of what shades it (the living room's bevel corners beside a wall's edge: 5758,
    0.41 where Cycles has 0.17). Only where the scene's one sun is its only light without
    bounds (the suns' and maps' light comes as one part, :func:`_front_light`); else none."""
    free = [li for li in ctx.direct.lights if isinstance(li, UNBOUNDED)]
    if len(free) != 1 or not isinstance(free[0], SunLight) or not free[0].strength > 0:
        return np.zeros(len(p), bool)
    to_sun = -np.asarray(free[0].direction, dtype=np.float64)
    tie = TIE_ULPS * 2.0 ** -23 * np.maximum(np.abs(point).max(axis=1), 1.0)
    fronts, scene = _fronts(ctx, elements)
    rise = geo @ to_sun
    flat = np.einsum("ij,ij->i", shade, geo) >= FLAT_COS
    high = (rise >= TERMINATOR) & (shade @ to_sun >= TERMINATOR)
    k = np.flatnonzero((rise > 0.0) & (flat | high))
    out = np.zeros(len(p), bool)
    # within where the sun's disc casts a penumbra as wide as a ray offset
    eps = ray_offsets(ctx.patches, owner=elements.owner[p[k]])
    reach = eps / max(np.tan(0.5 * free[0].angle), 1e-300)
    along = np.broadcast_to(to_sun, (len(k), 3))
    out[k] = _cover_along(scene, fronts, face_keys(elements), p[k], point[k] + tie[k, None] * geo[k], along, reach,
                          tie[k])[0]
    return out


def _front_light(ctx, start, shade, geo, shaded=None) -> np.ndarray:
    """(K, 3) the direct light at covered points ``start`` (K, 3) (shading normals ``shade``,
    triangles' normals ``geo``), by shadow rays that the backs of open surfaces
    (:mod:`..mesh.backs`) do not stop: a back lies a quarter of its object's ray offset behind its
    face, and rays from a point a few float32 steps off a face meet the backs of the faces beside
    it, which Cycles has not (the living room's notch: the sun ray from the bevel triangle of wall
    corner 7273 met the back of face 197, 0.2 mm on, and read 0.03 where Cycles has 0.33). The
    emitters' light as the bake's own (an emitting open surface's back shines too); without
    backs, or with see-through faces (their masks are per patch), all of it the bake's own.
    ``shaded`` (K,) bool or None: points whose bake point the scene's one sun does not reach
    (:func:`_sun_shaded`), which take none of its light."""
    direct = ctx.direct
    P = direct.patches
    zero = np.zeros(len(start))
    far = np.zeros((len(start), 3))
    rows = _front_rows(ctx, P)
    if rows is None or rows.size == len(P) or getattr(P, "see_through", None) is not None:
        D = direct.at(start, shade, "covered", eps=zero, facing=geo, unbounded=far, clamp=False)
    else:
        D = direct.over(P.take(rows)).at(start, shade, "covered-fronts", eps=zero, facing=geo, emitters=False,
                                         clamp=False, unbounded=far)
        if direct.emitters.size:
            D += direct.at(start, shade, "covered", eps=zero, facing=geo, lights=False, clamp=False)
    if shaded is not None and shaded.any():
        D[shaded] -= far[shaded]
    return np.maximum(D, 0.0, out=D)


def start_offsets(ctx, elements, points, normals) -> np.ndarray:
    """(P,) how far rays from ``points`` (P, 3) on the surfaces of ``elements`` start along
    their unit ``normals``: their object's ray offset (:meth:`.light.direct.DirectLight.offsets`),
    but half the way to a face over the point when one lies nearer (at least :data:`LIFT_ULPS`
    float32 steps), as :func:`covered_light` starts a covered corner's: the point where a buried
    vertex's edge meets what buries it (:func:`.sides.buried_side`) lies against that surface,
    and rays started past a face over it read the open side. Geometry only, cached."""
    eps = np.asarray(ctx.direct.offsets(points, normals), dtype=np.float64)
    if not embree_available() or not len(points):
        return eps

    def make():
        _, scene = _fronts(ctx, elements)
        tie = TIE_ULPS * 2.0 ** -23 * np.maximum(np.abs(points).max(axis=1), 1.0)
        hit, t = scene.intersect(points + tie[:, None] * normals, normals, eps)
        gap = np.where(np.asarray(hit) >= 0, tie + np.asarray(t, dtype=np.float64), np.inf)
        return np.minimum(eps, np.maximum(0.5 * gap, LIFT_ULPS * tie / TIE_ULPS))
    key = cache_key(geometry_key(elements) + array_key(points) + array_key(normals), ("start-offsets",))
    return cached(ctx.cache, key, make)
