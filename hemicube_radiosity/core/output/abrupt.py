"""Elements whose direct light changes abruptly, and the exact light on a grid of their points.

Interpolating the direct light from an element's corners spreads a corner's light over the
whole element where it changes abruptly inside it (a shadow's edge, a lamp hanging millimetres
under a ceiling). :func:`abrupt_elements` finds them (on the light arriving, (V, 3) radiance
at the vertices); :class:`AbruptGrid` holds their reflected direct light ``rho * D`` (radiance)
on a fixed grid of points per element, which the final gather's rays read where they land
(:mod:`.indirect`).
"""
from __future__ import annotations

import hashlib

import numpy as np

from ..mesh.patches import PatchSet
from ..util.colour import LUMA
from ..runtime.cache import Memo, cache_key, cached, frozen, geometry_key
from ..util.geometry import bilinear
from ..util.sampling import keyed_uniforms, place_keys
from ..util.unique import run_positions
from .corners import corner_columns
from .interpolate import inverse_bilinear
from .sides import seen_fraction

__all__ = ["abrupt_elements", "shadowed_inside", "grid_sides", "AbruptGrid"]


def abrupt_elements(elements: PatchSet, values_v, ratio=2.0, floor=0.02, cache=None) -> np.ndarray:
    """(N,) bool: elements across which the vertex field ``values_v`` (V, 3) changes too
    abruptly to interpolate: the luminance at one corner is more than ``ratio`` times another's,
    and the difference is more than ``floor`` of the mean over the vertices (dark corners and
    faint gradients stay interpolated): :func:`.refine.abrupt`'s rule on the corners, their
    largest and smallest taken a corner column at a time (:func:`corner_columns`, kept in
    ``cache``; the same values as the (N, 4) array's max and min over its short axis, faster)."""
    Y = np.asarray(values_v, dtype=np.float64) @ LUMA
    c = Y.take(corner_columns(elements, cache)[0])
    hi = np.maximum(np.maximum(c[0], c[1]), np.maximum(c[2], c[3]))
    lo = np.minimum(np.minimum(c[0], c[1]), np.minimum(c[2], c[3]))
    return (hi > ratio * lo) & (hi - lo > floor * max(float(Y.mean()), 1e-300))


#: At most this many cells a side where :func:`shadowed_inside` looks inside an element.
INSIDE_CELLS = 8


def shadowed_inside(ctx, elements, xv, nv, light_v, select, opened=None, ratio=2.0, floor=0.02) -> np.ndarray:
    """(N,) bool: elements whose corners agree but whose centre's light from the lamps and
    emitters does not (more than ``ratio`` times above their largest or below their smallest,
    and by more than ``floor`` of the mean light arriving ``light_v`` (V, 3)): a shadow or a
    pool of light that lies inside an element and reaches none of its corners (the ground under
    a bridge in the middle of a 70 m triangle, sunlit at all three corners), which
    :func:`abrupt_elements` cannot see. Elements already in ``select`` (N,) and those the scene
    does not see (``opened`` 0) are left out. Looked for at the centre of each element, or of
    n x n cells of an element n detail sizes across (on a huge object's elements, cells of
    the detail size along each side: :func:`grid_sides`); the world's light is not cast again (it
    changes slowly); the lamps' rays are cached, so a relight casts none."""
    out = np.zeros(len(elements), bool)
    if ctx.direct is None or not (ctx.direct.lights or ctx.direct.emitters.size):
        return out
    ask = ~np.asarray(select, bool) if opened is None else ~np.asarray(select, bool) & (np.asarray(opened) > 0)
    ids = np.flatnonzero(ask)
    if not ids.size:
        return out
    # the centres of n x n cells of each element's bilinear map, n its side over the detail size
    # (1 to INSIDE_CELLS), or on a huge object's elements cells of the detail size along each side
    size = float(ctx.settings.element_size or ctx.settings.patch_size or 1.0)
    at, x, nx = _inside_points(elements, ids, size, huge_elements(ctx, elements, ids))
    inside = ctx.direct.sources_at(x, nx, "element-inside", world=False).sum(1)
    at_v = ctx.direct.sources_at(xv, nv, "vertices", world=False).sum(1)
    c = at_v.take(corner_columns(elements, ctx.cache)[0][:, ids])   # (4, M): a triangle's 4th is its 1st
    hi = np.maximum(np.maximum(c[0], c[1]), np.maximum(c[2], c[3]))[at]
    lo = np.minimum(np.minimum(c[0], c[1]), np.minimum(c[2], c[3]))[at]
    bar = floor * max(float((np.asarray(light_v, dtype=np.float64) @ LUMA).mean()), 1e-300)
    off = ((inside > ratio * hi) | (inside * ratio < lo)) & (np.abs(inside - c.mean(axis=0)[at]) > bar)
    out[ids[np.unique(at[off])]] = True
    return out


#: :func:`_inside_points` by the identity of the elements' geometry arrays (never changed in
#: place) and the digest of the elements asked: a relight asks for the same points (15 ms of the
#: bunny's relight), and the light's cache, keyed on the points' array, then hashes them no more
_INSIDE = Memo(4)


def _inside_points(elements, ids, size, huge):
    """(at, x, normals): :func:`shadowed_inside`'s points, the centres of the cells of elements
    ``ids`` (cells of the detail ``size``; ``huge`` (M,) bool: cut along each side), the index
    into ``ids`` of each point's element, and its element's normal; geometry only."""
    def make():
        corners = elements.corners(ids)
        nu, nv_ = grid_sides(corners, elements.areas[ids], size, INSIDE_CELLS, INSIDE_CELLS ** 2,
                             huge, rounding=np.round)
        at = np.repeat(np.arange(ids.size), nu * nv_)
        k = run_positions(nu * nv_)
        u, v = ((k % nu[at]) + 0.5) / nu[at], ((k // nu[at]) + 0.5) / nv_[at]
        return frozen(at, bilinear(corners[at], u[:, None], v[:, None]), elements.normals[ids[at]])
    ask = hashlib.sha256(np.asarray(ids, np.int64).tobytes() + np.asarray(huge, bool).tobytes()).digest()
    return _INSIDE.of((elements.verts, elements.polys), make, key=(size, INSIDE_CELLS, ask))


def _place_uniforms(points, verts, count) -> np.ndarray:
    """(P, count) uniforms in [0, 1) drawn from the place of each of ``points`` (P, 3) (a hash of
    its position within the bounding box of ``verts``, to 2^-32 of its size,
    :func:`..util.sampling.place_keys`): the same point draws the same numbers in any scene, in
    any order."""
    lo = verts.min(axis=0)
    return keyed_uniforms(place_keys(points, lo, max(float(np.max(verts.max(axis=0) - lo)), 1e-300)), count)


def stratum_edges(i, n, strata, grade=2.0) -> np.ndarray:
    """(c, strata + 1) the bounds in [0, 1] of the strata along one side of cells ``i`` (c,) of
    ``n`` (c,) (a cell's place along its element's side and their count): even inside the
    element, graded as a power ``grade`` toward a side that is the element's edge (toward both,
    half the cell each, where the cell spans the element): 4 strata 1/16, 3/16, 5/16, 7/16 of
    the cell wide from that edge. A wall stands on a floor along an element's edge
    (:mod:`..mesh.contact` cuts elements there) and the gather's rays from its foot land within
    millimetres of it: they read a point at most 1/16 of the cell out, not 1/4, where the sun
    may already shine past a narrow shadow (godot_zdm2: 11.66% -> 11.40% RMS against Cycles;
    graded as a cube 11.24%, but the living room 4.52% -> 4.58%: the thin strata's points,
    each read alone by more rays, carry their own shadow rays' and sky share's noise)."""
    t = np.arange(strata + 1) / strata
    lo, hi = (np.asarray(i) == 0)[:, None], (np.asarray(i) == np.asarray(n) - 1)[:, None]
    both = np.where(t < 0.5, 0.5 * (2 * t) ** grade, 1 - 0.5 * (2 - 2 * t) ** grade)
    return np.where(lo & hi, both, np.where(lo, t ** grade, np.where(hi, 1 - (1 - t) ** grade, t)))


def huge_elements(ctx, elements, ids) -> np.ndarray:
    """(M,) bool: which of the elements ``ids`` belong to an object cut at a size of its own (a
    huge ground, :mod:`..mesh.sizes`: its ``size_scale`` above 1)."""
    scales = np.array([float(getattr(m, "size_scale", 1.0)) for m in ctx.meshes or ()] + [1.0])
    return scales[np.minimum(elements.owner[ids], len(scales) - 1)] > 1.0


def grid_sides(corners, areas, step, square, most, huge, huge_step=None, rounding=np.ceil):
    """((M,), (M,)) int64 cells along e1 (corners 0 -> 1) and e2 (0 -> 3) of the elements of
    ``corners`` (M, 4, 3) (a triangle's 4th corner its 3rd) of ``areas`` (M,): n x n, n the
    square root of the area over ``step`` (``rounding``), 1 to ``square``; or where ``huge``
    (M,) (an object cut at a size of its own, :mod:`..mesh.sizes`), each side's longer edge
    over ``huge_step`` (None: ``step``; ``rounding``), both scaled down together to at most
    ``most`` cells: a long element many steps across (a 68 m x 11 m piece of a huge ground under
    a racetrack) gets cells of the step along its length and across it, not ``square`` x
    ``square``."""
    n = np.clip(rounding(np.sqrt(areas) / step), 1.0, square)
    lu = np.maximum(np.linalg.norm(corners[:, 1] - corners[:, 0], axis=1),
                    np.linalg.norm(corners[:, 2] - corners[:, 3], axis=1))
    lv = np.maximum(np.linalg.norm(corners[:, 3] - corners[:, 0], axis=1),
                    np.linalg.norm(corners[:, 2] - corners[:, 1], axis=1))
    nu, nv = (np.maximum(rounding(length / (huge_step or step)), 1.0) for length in (lu, lv))
    over = np.sqrt(np.maximum(nu * nv / most, 1.0))
    nu, nv = (np.clip(np.floor(k / over), 1, most) for k in (nu, nv))
    return tuple(np.where(huge, k, n).astype(np.int64) for k in (nu, nv))


class AbruptGrid:
    """The reflected direct light ``rho * D`` on a grid of points of each element ``ids`` (M,)
    (their light changes abruptly), read anywhere on them by bilinear interpolation.

    Element m gets nu x nv cells ((nu + 1) x (nv + 1) points) of its bilinear map: n x n, n
    its edge over a quarter of the detail size, 1 to :attr:`CELLS`; on a huge object, cut at a
    size of its own (:mod:`..mesh.sizes`), each side's length over the scene's detail size
    over :attr:`HUGE_CELLS`, at most :attr:`MOST` cells (:func:`grid_sides`): the scene's
    shadows fall on it as sharp as elsewhere; the points are moved ``inset`` of the way
    toward the centre, as the vertices are (a point exactly on a contact edge sees the wall it
    touches edge-on). The light there is the vertices' exact light, every shadow ray and its
    penumbra refinement, evaluated once per point: a gather ray reads it where it lands, so
    every ray that lands near a point reads the same light and a vertex's neighbours, whose
    parallel rays land a little aside, read nearly the same. (Reading fresh light at every hit,
    with one shadow ray per emitter, made each vertex's gather of a shadow's edge a new draw:
    speckle, and the bake's costliest step on a dense mesh.)

    Points the scene cannot see (:func:`seen_fraction`: a ceiling above a lamp's back, a floor inside
    a block) lend a ray none of their light: a cell across a lamp's edge would otherwise carry
    the light above the lamp onto the ceiling beside it. A cell whose corners differ more than
    ``ratio`` times (and by more than ``floor``) holds light a bilinear map cannot carry, the
    glow a lamp's back casts on a ceiling within millimetres of its edge: caught at its peak by
    a corner beside the edge, it was spread over the cell (the walls of a 1 m room with such a
    lamp 0.9% too bright),
    missed by corners farther off. Such a cell holds :attr:`SPIKE` x :attr:`SPIKE` stratified
    points (seeded) and a ray reads the point of the stratum it lands in (where that point is
    unseen, the cell's mean over those seen, weighted by :func:`seen_fraction`). The cell's
    mean alone lent its lit part to every ray landing in it: at a concave contact in the shade
    (a wall's foot on a floor whose sunlit part begins a few centimetres out, inside the cell
    beside the wall) the rays from the foot land within millimetres of it and read the sun's
    light (godot_zdm2's wall feet 10% too bright; its RMS against Cycles 12.34% -> 11.66%). In
    a cell at its element's edge the strata are graded toward that edge
    (:func:`stratum_edges`), and the mean weights each point by its stratum's area.

    A cell whose mean passes the luminance ``bar`` is read as nothing: it shines instead
    (:meth:`hot_cells`).

    ``whole``: every element gets :attr:`CELLS` x :attr:`CELLS` cells however small (the faces
    of a scene too dense for elements, :func:`.indirect.gathers_faces`: a quarter of the patch
    size is no scale for them; the staircase's candle tops are fans of slivers 1.7 cm long,
    dark under the flame and lit at the rim, and one cell each let the flame's base, 0.1 to
    3 mm above, read the sliver's mean: 0.77 where Cycles has 0.18)."""

    CELLS = 4
    #: The most cells of one element's grid.
    MOST = 1024
    #: Cells a detail size on a huge object's elements. Truck town: 4 took its RMS error to
    #: 7.50% with 72,000 cells (15,000 before) and twice the grid's time, 2 to 7.56% with 35,000.
    HUGE_CELLS = 2
    SPIKE = 4
    #: The grid's points share the sky's rays out in 4 x 4 blocks (:meth:`_sky_parts`; a square).
    #: In 2 x 2 blocks (4) they cast zdm2's 8.6 million sky rays, the truck town's 4.6 million.
    SKY_SPLIT = 16

    def __init__(self, ctx, elements, ids, floor, bar, ratio=4.0, inset=1e-2, whole=False):
        size = float(ctx.settings.element_size or ctx.settings.patch_size or 1.0)
        self.inset, self.elements, self.whole = inset, elements, whole
        # the grid's geometry, cached on the elements chosen (a relight that chooses the same
        # only lights its points again); the patch size sets :func:`seen_fraction`'s reach
        # elements of an object cut at a size of its own (:mod:`..mesh.sizes`): their grids' cells
        # are the scene's, not a quarter of the object's own size
        huge = huge_elements(ctx, elements, ids)
        key = cache_key(geometry_key(elements) + np.ascontiguousarray(ids, np.int64).tobytes()
                        + np.packbits(huge).tobytes(),
                        ("abrupt-grid", size, ctx.settings.patch_size, self.CELLS, self.MOST, self.HUGE_CELLS,
                         inset) + (("whole",) if whole else ()))
        (self.nu, self.nv, self.offset, self.cell_offset, self.local, self.corners, x, owner, nrm,
         self.seen, loc, i, j, k, w) = cached(ctx.cache, key,
                                              lambda: self._layout(ctx, elements, ids, size, inset, huge))
        split = self.SKY_SPLIT if ctx.direct.sky_rays % self.SKY_SPLIT == 0 else 1
        light = ctx.direct.at(x, nrm, "abrupt-grid", split=split, part=self._sky_parts(len(x)) if split > 1 else None)
        self.values = elements.rho.take(owner, axis=0) * light     # take: rows 3x as fast as [owner]
        Y = light @ LUMA                      # decisions on the light arriving (a relight keeps them)
        Yc = Y[k.T]
        # spiky: the brightest corner, seen or not, against the darkest seen one (a corner
        # buried in a block is dark for want of light, not a peak to look for between corners)
        hi, lo = Yc.max(axis=1), np.where(w > 0, Yc, np.inf).min(axis=1)
        self.spiky = (hi > ratio * lo) & (hi - lo > floor)
        # each cell's mean over the part seen, and how much of it is seen
        seen = w.mean(axis=1)
        w = np.where(w.sum(axis=1, keepdims=True) > 0, w, 1.0)
        mean = np.einsum("cq,cqk->ck", w, self.values.take(k.T, axis=0))
        mean /= w.sum(axis=1)[:, None]
        s = self.spiky
        #: the spiky cells' strata: their points' light (S^2 rows a cell, in order) and how
        #: much the scene sees of each (:meth:`weights` reads a stratum or the cell's mean)
        self.strata, self.strata_seen = np.zeros((0, 3)), np.zeros((0, self.SPIKE ** 2))
        if s.any():
            mean[s], seen[s], self.strata, self.strata_seen = self._means(ctx, ids, loc[s], i[s], j[s])
        self.spiky_rank = np.cumsum(s) - 1                    # each spiky cell's place among them
        self.cell_mean = mean
        rho = elements.rho.take(ids[loc], axis=0)
        arriving = np.where(rho > 0, mean / np.where(rho > 0, rho, 1.0), 0.0)
        self.hot = (seen > 0) & (arriving @ LUMA > bar)
        self.ids, self.cell_loc, self.cell_i, self.cell_j = ids, loc, i, j

    def _layout(self, ctx, elements, ids, size, inset, huge):
        """The grid's geometry: (nu, nv, offset, cell_offset, local, corners, points (X, 3), their
        elements and normals, :func:`seen_fraction` at them, every cell's element (local index), row i,
        column j, corner point ids (4, cells) and :func:`seen_fraction` at its corners (cells, 4))."""
        corners = elements.corners()
        nu, nv = grid_sides(corners[ids], elements.areas[ids], size / self.CELLS, self.CELLS, self.MOST, huge,
                            size / self.HUGE_CELLS)
        if self.whole:                        # every element CELLS x CELLS, however small
            nu, nv = (np.where(huge, k, self.CELLS).astype(np.int64) for k in (nu, nv))
        count = (nu + 1) * (nv + 1)
        self.nu, self.nv = nu, nv
        self.offset = np.concatenate([[0], np.cumsum(count)[:-1]])
        self.cell_offset = np.concatenate([[0], np.cumsum(nu * nv)[:-1]])
        local = np.full(len(elements), -1, np.int64)
        local[ids] = np.arange(len(ids))
        x = np.empty((int(count.sum()), 3))
        sides = nu * (self.MOST + 1) + nv
        for key in np.unique(sides):
            m = np.flatnonzero(sides == key)
            a, b = int(nu[m[0]]), int(nv[m[0]])
            tu = inset + (1 - 2 * inset) * np.arange(a + 1) / a
            tv = inset + (1 - 2 * inset) * np.arange(b + 1) / b
            u, v = (g.reshape(1, -1, 1) for g in np.meshgrid(tu, tv, indexing="ij"))   # point i * (b+1) + j
            p = bilinear(corners[ids[m]][:, None], u, v)                              # (m, (a+1)(b+1), 3)
            x[(self.offset[m, None] + np.arange((a + 1) * (b + 1))[None]).ravel()] = p.reshape(-1, 3)
        owner = np.repeat(ids, count)
        nrm = elements.normals[owner]
        seen = seen_fraction(ctx, elements, x, nrm)
        # every cell: its element (local index), row i, column j
        loc = np.repeat(np.arange(len(ids)), nu * nv)
        r = np.arange(loc.size) - self.cell_offset[loc]
        i, j = r // nv[loc], r % nv[loc]
        k = np.stack(self._corner_ids(loc, i, j))
        return (nu, nv, self.offset, self.cell_offset, local, corners, x, owner, nrm, seen, loc, i, j, k,
                seen[k.T])

    def _sky_parts(self, count) -> np.ndarray:
        """(X,) which share of the sky's rays each grid point casts (:func:`..hemisphere.sky_fraction`'s
        ``part``), in blocks of b x b points (b^2 = :data:`SKY_SPLIT`): (row % b) * b + column % b,
        so every block of b x b points casts all of them once and a gather ray landing in a
        cell reads about what a share of one point's full pattern would, smoothed over the
        block's cells (the sky's part of the grid, a b^2-th of the rays)."""
        b = int(round(np.sqrt(self.SKY_SPLIT)))
        points = (self.nu + 1) * (self.nv + 1)
        side = np.repeat(self.nv + 1, points)
        r = np.arange(count) - np.repeat(self.offset, points)
        return (r // side % b) * b + r % side % b

    def hot_cells(self):
        """The cells that shine: (elements (c,), corners (c, 4, 3), radiance (c, 3)). A cell is the
        part of its element's bilinear map between (i, j) / n and (i + 1, j + 1) / n, corners
        in the element's order (adjacent cells share theirs bit for bit, so :func:`.shine.shine`'s
        groups see one outline); its radiance is its mean over the part the scene sees, and
        the part it does not (above a lamp's back) is what the shadow rays find hidden."""
        h = np.flatnonzero(self.hot)
        loc, i, j = self.cell_loc[h], self.cell_i[h], self.cell_j[h]
        nu, nv = self.nu[loc], self.nv[loc]
        c = self.corners[self.ids[loc]][:, None]                                      # (c, 1, 4, 3)
        u = (i[:, None] + np.array([0, 1, 1, 0])[None]) / nu[:, None]
        v = (j[:, None] + np.array([0, 0, 1, 1])[None]) / nv[:, None]
        corners = bilinear(c, u[..., None], v[..., None])                            # (c, 4, 3)
        return self.ids[loc], corners, self.cell_mean[h]

    def hot_parts(self, cells):
        """(elements (c,), areas (c,), luminance arriving (c,)) of the cells ``cells`` (indices
        into the grid's cells): what :func:`.shine.hot_elements` ranks them by."""
        loc = self.cell_loc[cells]
        el = self.ids[loc]
        rho = self.elements.rho.take(el, axis=0)
        mean = self.cell_mean[cells]
        arriving = np.where(rho > 0, mean / np.where(rho > 0, rho, 1.0), 0.0)
        return el, self.elements.areas[el] / (self.nu[loc] * self.nv[loc]), arriving @ LUMA

    def _corner_ids(self, loc, i, j):
        """Grid point ids of the corners (0,0), (1,0), (1,1), (0,1) of cells (i, j) of elements
        ``loc`` (local indices)."""
        base, side = self.offset[loc], self.nv[loc] + 1
        return [base + (i + a) * side + (j + b) for a, b in ((0, 0), (1, 0), (1, 1), (0, 1))]

    def _means(self, ctx, ids, loc, i, j):
        """((c, 3), (c,), (c S^2, 3), (c, S^2)): each cell (i, j) of elements ``loc`` (c,): its
        light's mean over the part seen and the part seen, from SPIKE x SPIKE jittered points
        (one a stratum, row-major in (u, v)) weighted by :func:`seen_fraction` (the plain mean
        where none is seen); and those points' light and :func:`seen_fraction`. Each cell's
        jitter is drawn from where it is (:func:`_place_uniforms`): a cell's mean depends
        neither on which others there are nor on their order, and the cells along a lamp's edge
        do not all sample its glow at the same distance (one pattern for every cell made a
        room's walls 3.7% too bright). The sky's rays are shared out among a cell's points
        (:func:`..hemisphere.sky_fraction`'s ``split``): the cell's mean casts the pattern once,
        as one point does, not SPIKE^2 times (a stratum's point read alone holds its share's
        sky: noisier, the many rays landing in a cell's strata averaging it out)."""
        S = self.SPIKE

        def points():               # geometry, cached on the cells (a relight finds them)
            a, b = (g.ravel() for g in np.meshgrid(np.arange(S), np.arange(S), indexing="ij"))
            nu, nv = self.nu[loc][:, None], self.nv[loc][:, None]
            c = self.corners[ids[loc]][:, None]                                       # (c, 1, 4, 3)
            centre = bilinear(c, ((i + 0.5) / self.nu[loc])[:, None, None], ((j + 0.5) / self.nv[loc])[:, None, None])
            ju, jv = _place_uniforms(centre[:, 0], self.elements.verts, 2 * S * S).reshape(-1, 2, S * S) \
                .transpose(1, 0, 2)
            eu, ev = stratum_edges(i, nu[:, 0], S), stratum_edges(j, nv[:, 0], S)
            du, dv = np.diff(eu, axis=1), np.diff(ev, axis=1)
            su = (i[:, None] + eu[:, a] + ju * du[:, a]) / nu            # stratum (a, b)'s bounds and jitter
            sv = (j[:, None] + ev[:, b] + jv * dv[:, b]) / nv
            u, v = (self.inset + (1 - 2 * self.inset) * t for t in (su, sv))
            x = bilinear(c, u[..., None], v[..., None]).reshape(-1, 3)
            el = np.repeat(ids[loc], S * S)
            nrm = self.elements.normals[el]
            area = du[:, a] * dv[:, b] * S * S                        # each stratum's share (1: even)
            return x, el, nrm, seen_fraction(ctx, self.elements, x, nrm).reshape(loc.size, S * S), area
        key = cache_key(geometry_key(self.elements) + b"".join(np.ascontiguousarray(a, np.int64).tobytes()
                                                                for a in (ids, self.nu, self.nv, loc, i, j)),
                        ("abrupt-cells", ctx.settings.patch_size, ctx.settings.element_size, self.SPIKE,
                         self.inset, "graded2"))
        x, el, nrm, w, area = cached(ctx.cache, key, points)
        # one shadow ray per emitting patch and point, and the sky's rays shared out among a
        # cell's points: the mean over the points is what counts
        split = S * S if ctx.direct.sky_rays % (S * S) == 0 else 1
        D = self.elements.rho.take(el, axis=0) * ctx.direct.at(x, nrm, "abrupt-cells", samples=1, split=split)
        D = D.reshape(loc.size, S * S, 3)
        seen, points_seen = (w * area).mean(axis=1), w
        w = np.where(w.sum(axis=1, keepdims=True) > 0, w, 1.0) * area
        return np.einsum("cs,csk->ck", w, D) / w.sum(axis=1)[:, None], seen, D.reshape(-1, 3), points_seen

    def uv(self, y, pid):
        """(u, v) (h,) of points ``y`` (h, 3) in the bilinear map of elements ``pid`` (h,) (a
        triangle: the quad with its last two corners equal, closed form)."""
        c = self.corners[pid]
        tri = self.elements.polys[pid, 3] < 0
        u, v = np.empty(len(pid)), np.empty(len(pid))
        if (~tri).any():
            u[~tri], v[~tri] = inverse_bilinear(c[~tri], y[~tri])
        if tri.any():   # y = c0 + u (1 - v) (c1 - c0) + v (c2 - c0)
            t = np.flatnonzero(tri)
            e1, e2, r = c[t, 1] - c[t, 0], c[t, 2] - c[t, 0], y[t] - c[t, 0]
            a11, a12, a22 = (e1 * e1).sum(1), (e1 * e2).sum(1), (e2 * e2).sum(1)
            b1, b2 = (r * e1).sum(1), (r * e2).sum(1)
            det = np.maximum(a11 * a22 - a12 * a12, 1e-300)
            s, w = (a22 * b1 - a12 * b2) / det, (a11 * b2 - a12 * b1) / det
            v[t] = w
            u[t] = np.where(w < 1 - 1e-9, s / np.maximum(1 - w, 1e-9), 0.5)
        return np.clip(u, 0.0, 1.0), np.clip(v, 0.0, 1.0)

    def at(self, y, pid):
        """(h, 3) the grid's light at points ``y`` (h, 3) on elements ``pid`` (h,): bilinear in
        the cell each falls in over its corners seen, its stratum's point where it is spiky (its
        mean where that point is unseen), nothing where it shines."""
        cols, w = self.weights(y, pid)
        return np.einsum("hc,hck->hk", w, self.readable()[cols])

    def readable(self):
        """(X + cells + strata, 3): the rows :meth:`weights`' columns index: the grid points'
        light, the cells' means, the spiky cells' strata."""
        return np.concatenate([self.values, self.cell_mean, self.strata])

    def weights(self, y, pid):
        """(columns (h, 4), weights (h, 4)): :meth:`at` as weights of the rows of
        :meth:`readable` (a relight reads new light through the same weights)."""
        loc = self.local[pid]
        nu, nv = self.nu[loc], self.nv[loc]
        u, v = self.uv(np.asarray(y, dtype=np.float64), pid)
        su = np.clip((u - self.inset) / (1 - 2 * self.inset), 0.0, 1.0) * nu
        sv = np.clip((v - self.inset) / (1 - 2 * self.inset), 0.0, 1.0) * nv
        i, j = np.minimum(su.astype(np.int64), nu - 1), np.minimum(sv.astype(np.int64), nv - 1)
        fu, fv = (su - i)[:, None], (sv - j)[:, None]
        k = self._corner_ids(loc, i, j)
        w = np.concatenate([(1 - fu) * (1 - fv), fu * (1 - fv), fu * fv, (1 - fu) * fv], axis=1)   # (h, 4)
        seen = w * np.stack([self.seen[q] for q in k], axis=1)
        total = seen.sum(axis=1, keepdims=True)
        w = np.where(total > 0, seen / np.where(total > 0, total, 1.0), w)
        cols = np.stack(k, axis=1)
        cell = self.cell_offset[loc] + i * nv + j
        spiky = self.spiky[cell]
        cols[spiky] = len(self.values) + cell[spiky, None]
        w[spiky] = (1.0, 0.0, 0.0, 0.0)
        h = np.flatnonzero(spiky)
        if h.size:                  # the stratum's point, where the scene sees it
            S = self.SPIKE
            a, b = ((f[h] >= stratum_edges(c[h], n[h], S)[:, 1:S]).sum(axis=1)
                    for f, c, n in ((fu, i, nu), (fv, j, nv)))
            q = a * S + b                                 # row-major, as :meth:`_means` draws them
            rank = self.spiky_rank[cell[h]]
            ok = self.strata_seen[rank, q] > 0
            cols[h[ok], 0] = len(self.values) + len(self.cell_mean) + rank[ok] * S * S + q[ok]
        w[self.hot[cell]] = 0.0
        return cols, w
