# SPDX-License-Identifier: GPL-3.0-or-later
"""Lightmaps: the bake's output read at the texel centres of an image through a UV map.

The same solution as the vertex colours, read at the surface point under each texel centre as
the output vertices read it (:mod:`.stage`): E + rho * (D + I), with D the direct light computed
again exactly at that point (lamps, emitters, the world, with shadow rays: a shadow's edge is as
sharp as the texels, not as the detail size) and the smoother rest, the emission E, reflectivity
rho and light reflected at least once I, the bilinear interpolation of the output elements'
corners (``BakeResult.corner_parts()``; the paper's rendering step, :mod:`.interpolate`).
Without the exact direct light (the paper's 'hemicube' path) a texel is the bilinear
interpolation of ``BakeResult.corner_values()``, what the vertex-colour copy shows there.

Steps, all NumPy:

1. :func:`.uv_raster.rasterize`: every texel whose centre lies in a UV triangle, or within
   ``reach`` texels of one (conservative: a sliver triangle thinner than a texel still gets its
   texels), gets that triangle and the barycentric coordinates of its centre (clamped onto the
   triangle when the centre is outside it). Where triangles share a texel, the one the centre
   lies deepest in wins. A triangle without area in the world (:func:`.uv_raster.flat_triangles`)
   gets none: its texels go to the triangles beside it and the dilation.
2. :func:`texel_points`: barycentric -> world point and the triangle's normal.
3. :func:`texel_values` (or :func:`evaluate`): :func:`.interpolate.locate` among one object's
   output elements (with the normals, so the two sides of a thin wall are told apart), bilinear
   in the element found (:func:`texel_light`), and the direct light at the texel centres, each
   source apart, exact at a coarse grid of texels and wherever the light is not smooth between
   them, interpolated elsewhere (:mod:`.texels`); where a source's light varies between
   neighbours (:func:`varying`), its mean over points of the texel's square, as Cycles' bake
   averages there.
4. :func:`dilate`: texels outside every island are filled from their filled neighbours (the mean
   of the filled ones among their 8), ``margin`` passes: bilinear filtering and mip-maps read no
   black across an island's border.

Image convention: arrays are (H, W, ...), row 0 at v = 0 (Blender's ``Image.pixels`` order, bottom
row first), texel (r, c) centred at uv ((c + 0.5) / W, (r + 0.5) / H). Values are whatever
``corner_values`` holds (radiance, an emission strength of 1 in white is 1.0).
"""
from __future__ import annotations

from contextlib import closing
from dataclasses import dataclass, replace

import numpy as np

from ..runtime.parallel import ordered_map, resolve_workers
from .interpolate import interpolate_corner_values, locate
from .lift import lift
from .uv_raster import REACH, edge_distances, flat_triangles, rasterize
from ..util.colour import LUMA
from .texels import as_cycles, by_source, from_inside
from .texel_cover import apart, lifts_of

__all__ = ["Lightmap", "image_size", "rasterize", "flat_triangles", "texel_points", "evaluate", "texel_light", "texel_values",
           "varying", "dilate", "bake_lightmap", "REACH", "MARGIN", "INSET", "VARIES", "FLOOR", "SUBTEXELS",
           "FOOTPRINT"]

INSET = 1e-3       # texel points are lit this share of the way toward their triangle's centre
VARIES = 0.1       # light differing this much between neighbours: averaged over the texel,
FLOOR = 0.05       # ... and by this much of its 99th percentile over the object
SUBTEXELS = 4      # ... at SUBTEXELS x SUBTEXELS points of its square
FOOTPRINT = 0.5    # ... the square this many texels wide around the centre (Cycles' bake's)
SUB_RAYS = 4       # ... each point with this many shadow rays per emitter and lamp (64 a texel),
SUB_SKY = 16       # ... the world's rays shared out among this many of a texel's points
MARGIN = 8         # texels of dilation around every island


@dataclass
class Lightmap:
    """One object's lightmap.

    ``image`` (H, W, 3) float32: the value at every texel, 0 where neither an island nor its
    dilation reached. ``covered`` (H, W) bool: texels of a UV island (centre within ``REACH``
    texels of a triangle). ``filled`` (H, W) bool: texels holding a value (islands and margin).
    ``unset`` int: island texels left without a finite value (0 when the bake is whole).
    ``inside`` (H, W) bool: texels whose centre lies inside a triangle (not clamped onto one).
    ``lighting`` (H, W, 3) float32 or None: the lighting-only pass (the light arriving times the
    material's albedo scale), filled and dilated as ``image``."""

    image: np.ndarray
    covered: np.ndarray
    filled: np.ndarray
    inside: np.ndarray
    unset: int
    lighting: np.ndarray | None = None

    @property
    def size(self) -> tuple:
        """(width, height) in texels."""
        return self.image.shape[1], self.image.shape[0]


def image_size(area, density, max_size, min_size=8) -> int:
    """Texels along a side of a square lightmap: ``density`` (texels per world unit) times the
    square root of the surface ``area`` (world units squared), clamped to [min_size, max_size]."""
    n = int(np.ceil(float(density) * np.sqrt(max(float(area), 0.0))))
    return int(np.clip(n, min_size, max(int(max_size), min_size)))


def texel_points(world, tri, bary, flip=False):
    """World points (n, 3) and unit normals (n, 3) of the n texels with a triangle.

    ``world`` (T, 3, 3) each UV triangle's corners in world space (same order as the UVs);
    ``tri`` (n,) and ``bary`` (n, 3) from :func:`rasterize` (rows with tri >= 0). The normal is
    the triangle's (right-handed in its corner order), turned around with ``flip`` (a mirrored
    object: its world-space winding is reversed)."""
    world = np.asarray(world, dtype=np.float64)
    c = world[tri]                                          # (n, 3, 3)
    points = np.einsum("nk,nkj->nj", bary, c)
    normal = np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0])
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-300)
    return points, -normal if flip else normal


def evaluate(elements, corner_values, points, normals, owner, faces=None):
    """(n, 3) the output at world ``points`` (n, 3) with face ``normals`` (n, 3) on the output
    elements of object ``owner`` (an ``elements.owner`` value): located with
    :func:`locate_texels` (on their own ``faces`` (n,) where given), then bilinear in that
    element's ``corner_values`` (N, 4, 3)."""
    if len(points) == 0:
        return np.zeros((0, 3))
    idx, uv = locate_texels(elements, points, normals, owner, faces)
    return interpolate_corner_values(corner_values, idx, uv)


def locate_texels(elements, points, normals, owner, faces=None, workers=1):
    """(element index (n,), bilinear (u, v) (n, 2)) of world ``points`` (n, 3) with face
    ``normals`` among the output elements of object ``owner`` (:func:`.interpolate.locate`).

    ``faces`` (n,) int or None: the source face (``elements.source_face``) each point lies on. A
    point whose face has elements is located among its own face's (:func:`.interpolate.locate`
    keyed by face: among the object's, the 8 element centres nearest a point on a strip 2 cm
    wide beside a large wall, a bevel or a window frame, may all be the wall's): the texel
    shows its own surface's light, not a neighbour's; and a face's few elements are searched
    faster than the object's (a third of the time on the living room's 512,720 texels). The
    others are located among the object's elements. ``workers`` (0 = every core): forked
    processes (threads where there are none) that take a share of the faces each (a point's
    result is its face's alone: the same, bit for bit, for any count; NumPy's small steps per
    face hold the GIL, so threads barely overlap)."""
    owners = np.full(len(points), int(owner), np.int64)
    if faces is None or len(points) == 0:
        return locate(elements, points, owners, normals)
    faces = np.asarray(faces, dtype=np.int64)
    mine = np.flatnonzero(elements.owner == owner)
    key = np.asarray(elements.source_face, dtype=np.int64)[mine]
    own = np.isin(faces, key)
    idx, uv = np.zeros(len(points), np.int64), np.zeros((len(points), 2))
    if own.any():
        sub = replace(elements.take(mine), owner=key, source_face=key)

        def one(ids):
            return locate(sub, points[ids], faces[ids], None if normals is None else normals[ids])
        shares = _face_shares(faces, np.flatnonzero(own), resolve_workers(workers))
        with closing(ordered_map(one, shares, len(shares), processes=True)) as found:
            for ids, (j, at) in zip(shares, found):
                idx[ids], uv[ids] = mine[j], at
    if not own.all():
        idx[~own], uv[~own] = locate(elements, points[~own], owners[~own],
                                     None if normals is None else normals[~own])
    return idx, uv


def _face_shares(faces, ids, workers, least=20000):
    """``ids`` (m,) cut into at most ``workers`` lists of about as many points, a face's points
    all in one (one list of them all below ``least`` points a worker)."""
    count = min(int(workers), len(ids) // least)
    if count <= 1:
        return [ids]
    ids = ids[np.argsort(faces[ids], kind="stable")]
    f = faces[ids]
    cut = np.searchsorted(f, f[np.arange(1, count) * len(ids) // count])      # at a face's first point
    return [s for s in np.split(ids, np.unique(cut)) if s.size]


def dilate(image, known, passes=MARGIN):
    """``image`` (H, W, C) with the texels not ``known`` (H, W) bool filled from their known
    neighbours, ``passes`` times: each pass gives every unknown texel with a known one among its
    8 neighbours the mean of those. Returns (image, known) as new arrays."""
    img = np.where(known[..., None], image, 0.0).astype(np.float64)    # 0 where unknown: sums skip them
    known = known.copy()
    for _ in range(int(passes)):
        if known.all():
            break
        count = _box3(known.astype(np.float64))             # the unknown texel's own is 0 in both
        new = ~known & (count > 0)
        if not new.any():
            break
        img[new] = _box3(img)[new] / count[new][:, None]
        known = known | new
    return img, known


def _box3(a):
    """(H, W, ...) the sum of ``a`` over each texel's 3 x 3 block (zero beyond the border): along
    the rows, then the columns."""
    p = np.pad(a, ((1, 1), (0, 0)) + ((0, 0),) * (a.ndim - 2))
    rows = p[:-2] + p[1:-1] + p[2:]
    p = np.pad(rows, ((0, 0), (1, 1)) + ((0, 0),) * (a.ndim - 2))
    return p[:, :-2] + p[:, 1:-1] + p[:, 2:]


def texel_light(elements, parts, points, normals, owner, D, faces=None):
    """(radiosity (n, 3), light arriving (n, 3)) at n texels' world ``points`` (n, 3) with face
    ``normals`` (n, 3) on the output elements of object ``owner``, given ``D`` (n, 3) the direct
    light arriving there (radiance: irradiance / pi).

    ``parts`` (emission, reflectivity, direct, indirect), each (N, 4, 3) per element corner
    (:meth:`..pipeline.BakeResult.corner_parts`, any exposure already in the emission and the
    light). Each texel is E + rho * (D + I), with E, rho and I the bilinear interpolation of the
    corners' emission, reflectivity and indirect light in the element that holds the point
    (:func:`.interpolate.locate`), as the output vertices are made (:mod:`.stage`). The light
    arriving returned is D + I (what the lighting-only pass holds). ``faces`` (n,): each point's
    source face, as :func:`locate_texels` takes it."""
    E, rho, indirect = located_parts(elements, parts, points, normals, owner, faces)
    light = np.asarray(D, dtype=np.float64) + indirect
    return E + rho * light, light


def located_parts(elements, parts, points, normals, owner, faces=None, workers=1, cover=None):
    """(E, rho, I) (n, 3) each: the emission, reflectivity and indirect light of ``parts``
    (:func:`texel_light`) interpolated at ``points`` (located by :func:`locate_texels`, on
    ``workers``; with a :class:`.texel_cover.Cover` and ``faces``, those whose element does not
    hold them found again on their own face: :meth:`.texel_cover.Cover.relocate`)."""
    if len(points) == 0:
        return np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 3))
    idx, uv = locate_texels(elements, points, normals, owner, faces, workers)
    if cover is not None and faces is not None:
        idx, uv = cover.relocate(points, normals, faces, idx, uv)
    E, rho, indirect = (interpolate_corner_values(parts[k], idx, uv) for k in (0, 1, 3))   # not the direct
    return E, rho, indirect


def _lit_points(world, normals, tri, bary, flip):
    """(points, face normals, shading normals, lifted starts or None) (n, 3) each of texels
    ``tri``, ``bary`` (n,), (n, 3), the points moved :data:`INSET` of the way toward their
    triangle's centre (a point on an edge where two walls meet sees neither); shading normals
    interpolated from ``normals`` (T, 3, 3) where given (whichever side of the face they point
    to, as Cycles shades: only a zero one falls back to the face's), else the faces'; where
    Cycles' shadow rays toward a light below the face's plane start (:func:`.lift.lift`, with
    ``normals``)."""
    w = bary * (1.0 - INSET) + INSET / 3.0
    pts, nrm = texel_points(world, tri, w, flip)
    if normals is None:
        return pts, nrm, nrm, None
    N = np.asarray(normals, dtype=np.float64)[tri]
    shading = np.einsum("nk,nkj->nj", bary, N)
    length = np.linalg.norm(shading, axis=1, keepdims=True)
    shading = np.where(length > 1e-12, shading / np.maximum(length, 1e-300), nrm)
    low = np.full(pts.shape, np.nan)                  # none where no light below the plane is seen
    lean = np.flatnonzero(~np.all(shading == nrm, axis=1))
    low[lean] = lift(np.asarray(world, dtype=np.float64)[tri[lean]], N[lean], nrm[lean], pts[lean], w[lean])
    return pts, nrm, shading, low


def varying(values, known, ratio=VARIES, surface=None, floor=FLOOR, channels=False):
    """(H, W) bool (``channels``: (H, W, k), channel by channel): texels of ``known`` (H, W)
    where any channel of ``values`` (H, W, k) differs
    from a known 4-neighbour's by more than ``ratio`` of the larger of the two and by more than
    ``floor`` of the channel's 99th percentile over the known texels: where a texel's own centre
    does not stand for its square (a shadow's edge, a lamp's hot spot, a block's foot), not
    where a faint light falls off (both tests keep their answer when a channel is scaled).
    ``surface`` (points (H, W, 3), normals (H, W, 3), pitch (H, W)): only neighbours on one
    surface count, facing within 25 degrees and less than two texels (``pitch``, world units)
    apart, so that islands packed side by side do not mark each other's borders."""
    values = np.asarray(values, dtype=np.float64)
    out = np.zeros(values.shape, bool)
    if not known.any():
        return out if channels else out.any(axis=-1)
    least = floor * np.percentile(values[known], 99, axis=0)          # (k,)
    for axis in (0, 1):
        def pair(a):
            a = np.swapaxes(a, 0, axis)
            return a[:-1], a[1:]
        (a, b), (ka, kb) = pair(values), pair(known)
        step = np.abs(a - b)
        same = ka & kb
        if surface is not None:
            (pa, pb), (na, nb), (sa, sb) = (pair(x) for x in surface)
            same &= (np.einsum("...k,...k->...", na, nb) > 0.9) & \
                (np.linalg.norm(pa - pb, axis=-1) < 2.0 * np.maximum(sa, sb))
        jump = (step > ratio * np.maximum(a, b)) & (step > least) & same[..., None]
        o = np.swapaxes(out, 0, axis)
        o[:-1] |= jump
        o[1:] |= jump
    return out if channels else out.any(axis=-1)


def _sub_texels(px, tri, centre, grid=SUBTEXELS):
    """(texel (m,), barycentric (m, 3)) ``grid`` x ``grid`` points spread evenly over the square
    :data:`FOOTPRINT` texels wide around each texel ``centre`` (n, 2) (texel units) that lie
    inside its triangle ``tri`` (n,) of ``px`` (T, 3, 2): Cycles' bake jitters its samples over
    that square (Blender's bake differentials are half a texel's), keeping those inside the
    triangle; ``texel`` indexes the n texels."""
    off = ((np.arange(grid) + 0.5) / grid - 0.5) * FOOTPRINT
    off = np.stack(np.meshgrid(off, off, indexing="ij"), -1).reshape(-1, 2)
    n, k = len(tri), len(off)
    texel = np.repeat(np.arange(n), k)
    t = tri[texel]
    _, b = edge_distances((centre[:, None, :] + off[None]).reshape(-1, 2), px[t, 0], px[t, 1], px[t, 2])
    ok = np.all(b >= 0, axis=1)
    return texel[ok], b[ok]


def _pitch(uv, world, width, height):
    """(T,) the world length of a texel's side on each triangle: sqrt(world area / texel area)."""
    px = np.asarray(uv, dtype=np.float64).reshape(-1, 3, 2) * np.array([width, height], float)
    w = np.asarray(world, dtype=np.float64)
    a_uv = 0.5 * np.abs(np.cross(px[:, 1] - px[:, 0], px[:, 2] - px[:, 0]))
    a_w = 0.5 * np.linalg.norm(np.cross(w[:, 1] - w[:, 0], w[:, 2] - w[:, 0]), axis=1)
    return np.sqrt(a_w / np.maximum(a_uv, 1e-300))


def _surface(covered, points, normals, pitch):
    """(points, normals, pitch) of the covered texels as (H, W, ...) images (:func:`varying`)."""
    out = []
    for a in (points, normals, pitch):
        img = np.zeros(covered.shape + np.shape(a)[1:])
        img[covered] = a
        out.append(img)
    return tuple(out)


def texel_values(elements, parts, split, owner, uv, world, normals, tri, bary, flip=False, probed=None,
                 faces=None, inside=None, workers=1, cover=None):
    """(radiosity (n, 3), light arriving (n, 3)) at the n covered texels (``tri`` (H, W) >= 0,
    in that order; ``bary`` (H, W, 3) from :func:`rasterize` of ``uv`` (T, 3, 2)), by
    :func:`texel_light` with ``split(points, normals, samples=None, which=None, facing=None, low=None, split=1,
    part=None) -> (n, S, 3)`` the direct light of each source apart (:meth:`..light.direct.DirectLight.split_at`): at the
    texel centres, exact where the light needs it and interpolated where it is smooth
    (:func:`.texels.by_source`; ``probed`` (S,) bool: the sources a one-ray probe stands for);
    then, where a source's light varies between neighbours (:func:`varying`: a shadow's edge, a
    lamp's hot spot), that source's mean over the :data:`SUBTEXELS` squared points of the square
    :data:`FOOTPRINT` texels wide around the centre that lie in its triangle (a box filter, as
    Cycles' bake averages its samples over that square: a shadow's edge falls across a texel as
    a share of it, not all or nothing), every source's where the reflected light starts (a
    block's foot). Emission, reflectivity and reflected light are read at the centre.

    Which texels vary is judged on each source's light apart and on where any light arrives
    reflected: both keep their shape when a source's strength or colour or a surface's colour
    changes, so a relight picks the same texels and finds their transport cached. ``world``
    (T, 3, 3), ``normals`` (T, 3, 3) or None and ``flip`` as for :func:`bake_lightmap`;
    ``inside`` (H, W) bool from :func:`rasterize` or None: a texel whose centre lies outside its
    triangle takes the direct light of its neighbours inside on the same face where it has any.
    ``workers``: where the texels are located (:func:`locate_texels`). ``cover``: a
    :class:`.texel_cover.Cover` of the object, or None: a texel whose point (or sub-point) lies
    under another face nearer than our rays start is lit from where Cycles' rays start, and its
    reflected light scaled by what it sees of the open scene there; a texel its element does not
    hold is found again on its own face (:meth:`.texel_cover.Cover.relocate`; needs ``faces``)."""
    covered = tri >= 0
    height, width = covered.shape
    t, b = tri[covered], bary[covered]
    pts, nrm, shading, low = _lit_points(world, normals, t, b, flip)
    pitch = _pitch(uv, world, width, height)[t]
    own = None if faces is None else faces[t]
    lift = lifts_of(cover, pts, nrm, own)
    Ds = by_source(as_cycles(split, pts, nrm, shading, low, probed, lift), covered,
                   texel_points(world, t, b)[0], nrm, apart(t if own is None else own, lift), pitch, probed,
                   None if inside is None else inside[covered])[0]
    E, rho, indirect = _read_parts(elements, parts, pts, nrm, owner, own, workers, covered,
                                   None if inside is None else inside[covered], t if own is None else own, cover)
    if lift is not None:
        indirect = indirect * cover.keep(pts, nrm, shading, lift)[:, None]
    D = np.maximum(Ds.sum(axis=1), 0.0)
    S = Ds.shape[1]
    img = np.zeros(covered.shape + (S + 1,))
    img[covered] = np.column_stack([Ds @ LUMA, np.any(indirect > 0, axis=1)])
    need = varying(img, covered, surface=_surface(covered, pts, nrm, pitch), channels=True)[covered]
    # a bounded source's shadow edge or hot spot: that source; where reflected light starts (a
    # block's foot), every source; the world's light is smooth elsewhere (no edge to average)
    need = (need[:, :S] & (True if probed is None else np.asarray(probed, bool))) | need[:, S:]
    edge = np.flatnonzero(need.any(axis=1))
    if edge.size:
        rows, cols = np.nonzero(covered)
        px = np.asarray(uv, dtype=np.float64).reshape(-1, 3, 2) * np.array([width, height], float)
        which, sub = _sub_texels(px, t[edge], np.stack([cols[edge] + 0.5, rows[edge] + 0.5], 1))
        D[edge] = _sub_mean(split, world, normals, flip, t[edge], which, sub, Ds[edge], need[edge], D[edge],
                            probed, cover, faces)
    light = D + indirect
    return E + rho * light, light


def _read_parts(elements, parts, pts, nrm, owner, own, workers, covered, inside, faces, cover=None):
    """(E, rho, I) (n, 3) each at the n covered texels (:func:`located_parts`): a texel whose
    centre lies outside its triangle (an island's rim, ``inside`` (n,) False) with texels
    inside on its face (``faces`` (n,)) beside it takes their mean, as its direct light does
    (:func:`.texels.from_inside`; Cycles' margin extends an island from its texels): only the
    others are located (the living room's rim: 95,534 of its 507,328 texels)."""
    if inside is None:
        return located_parts(elements, parts, pts, nrm, owner, own, workers, cover)
    got, done = np.zeros((len(pts), 3, 3)), np.zeros((len(pts), 3), bool)
    for ids in (np.flatnonzero(inside), None):
        if ids is None:
            from_inside(got, done, inside, faces, covered)
            ids = np.flatnonzero(~done[:, 0])
        if ids.size:
            got[ids] = np.stack(located_parts(elements, parts, pts[ids], nrm[ids], owner,
                                              None if own is None else own[ids], workers, cover), 1)
            done[ids] = True
    return got[:, 0], got[:, 1], got[:, 2]


def _sub_mean(split, world, normals, flip, tri, which, sub, Ds, need, D, probed=None, cover=None, faces=None):
    """(m, 3) the direct light of m texels (triangles ``tri`` (m,)) averaged over their sub-texel
    points (``which`` (k,) texel, ``sub`` (k, 3) barycentric: :func:`_sub_texels`): the sources
    ``need`` (m, S) bool lit again at each point, the others the centre's ``Ds`` (m, S, 3); a
    texel with no point keeps ``D`` (m, 3). The world (a source not ``probed``) is read as the
    texel's mean, so its points share the sky's pattern out (:data:`SUB_SKY`: point j of a
    texel casts rays j, j + 16, ... of the 256, :func:`..hemisphere.sky_fraction`'s ``split``):
    the texel's rays once over its square, not 16 times (a block's foot: 33,036 points in the
    living room, 8.5 M sky rays before). ``cover``, ``faces`` (T,): as :func:`texel_values`'s."""
    at = _lit_points(world, normals, tri[which], sub, flip)
    lit = as_cycles(split, *at, probed,
                    lifts_of(cover, at[0], at[1], None if faces is None else faces[tri[which]]))
    per = Ds[which].copy()                                            # (k, S, 3)
    wide = np.zeros(Ds.shape[1], bool) if probed is None else ~np.asarray(probed, bool)
    for k in range(Ds.shape[1]):
        at = np.flatnonzero(need[which, k])
        if not at.size:
            continue
        shared = {}
        if wide[k] and SUB_SKY > 1:    # the world: a texel's points share its rays out
            rank = np.arange(at.size) - np.searchsorted(which[at], which[at])
            shared = {"split": SUB_SKY, "part": rank % SUB_SKY}
        per[at, k] = lit(at, SUB_RAYS, np.arange(Ds.shape[1]) == k, **shared)[:, k]
    per = np.maximum(per.sum(axis=1), 0.0)
    m = len(tri)
    count = np.bincount(which, minlength=m)
    mean = np.stack([np.bincount(which, weights=per[:, c], minlength=m) for c in range(3)], 1)
    return np.where(count[:, None] > 0, mean / np.maximum(count, 1)[:, None], D)


def bake_lightmap(elements, corner_values, owner, uv, world, width, height=None, flip=False,
                  margin=MARGIN, reach=REACH, *, parts=None, direct=None, normals=None,
                  lighting_scale=None, split=None, probed=None, faces=None, workers=1, cover=None) -> Lightmap:
    """One object's lightmap from the bake's output elements.

    ``elements`` the bake's output PatchSet, ``corner_values`` (N, 4, 3) its corner values
    (``BakeResult.corner_values()``, times any exposure), ``owner`` the object's owner index in
    ``elements.owner``; ``uv`` (T, 3, 2) and ``world`` (T, 3, 3) the object's triangles in the
    lightmap's UV map and in world space; ``width`` x ``height`` texels (square by default).
    ``flip``: the object's world matrix mirrors (negative determinant). Texels of no island are
    dilated ``margin`` times (:func:`dilate`); an island texel whose value is not finite is
    dilated over too and, if still unset, counted in ``Lightmap.unset``.

    With ``parts`` and ``split(points, normals, samples=None, which=None, facing=None, low=None) -> (n, S, 3)`` (the
    bake's exact direct light of each source apart, times the exposure:
    :meth:`..light.direct.DirectLight.split_at`; ``probed`` (S,) bool the sources a one-ray
    probe stands for), or ``direct(points, normals) -> (n, 3)`` (one source, no probe), the
    direct light is taken at the texels (exact where it needs to be, :func:`texel_values`), the
    rest interpolated, and texels where the light varies are the mean over their square, lit
    with ``normals`` (T, 3, 3) the triangles'
    corner normals in world space where given (smooth shading), else the triangles' own; without
    them every texel is the bilinear interpolation of ``corner_values``. ``lighting_scale`` (T, 3)
    per triangle (needs ``parts``): also the lighting-only pass, the light arriving times it (a
    material's albedo scale), in ``Lightmap.lighting``. ``faces`` (T,) int: each triangle's face in
    the object's mesh (``elements.source_face``): a texel is read on its own face's elements
    (:func:`locate_texels`, on ``workers``: 0 every core). ``cover`` (with ``faces``): a
    :class:`.texel_cover.Cover` of the object: texels under a face nearer than our rays start
    are lit as Cycles' bake lights them there (:func:`texel_values`)."""
    faces = None if faces is None else np.asarray(faces, dtype=np.int64)
    height = int(width if height is None else height)
    width = int(width)
    tri, bary, inside = rasterize(uv, width, height, reach, flat_triangles(world))
    covered = tri >= 0
    image = np.zeros((height, width, 3))
    lighting = None
    t, b = tri[covered], bary[covered]
    if split is None and direct is not None:
        def split(points, normals, samples=None, which=None, facing=None, low=None, **_):   # one source, no probe
            return np.asarray(direct(points, normals), dtype=np.float64)[:, None, :]
    if parts is None or split is None:
        pts, nrm = texel_points(world, t, b, flip)
        image[covered] = evaluate(elements, corner_values, pts, nrm, owner, None if faces is None else faces[t])
    else:
        image[covered], light = texel_values(elements, parts, split, owner, uv, world, normals, tri, bary,
                                             flip, probed, faces, inside, workers, cover)
        if lighting_scale is not None:
            lighting = np.zeros((height, width, 3))
            lighting[covered] = light * np.asarray(lighting_scale, dtype=np.float64)[t]
    good = covered & np.all(np.isfinite(image), axis=-1)
    if lighting is None:
        image, filled = dilate(np.nan_to_num(image), good, margin)
    else:       # both passes in one (channel by channel: the same texels, the same values)
        both, filled = dilate(np.nan_to_num(np.concatenate([image, lighting], axis=-1)), good, margin)
        image, lighting = both[..., :3], both[..., 3:].astype(np.float32)
    # an island texel that had no finite value takes its neighbours' (counted if none reached it)
    unset = int(np.count_nonzero(covered & ~filled))
    return Lightmap(image.astype(np.float32), covered, filled, inside & good, unset, lighting)
