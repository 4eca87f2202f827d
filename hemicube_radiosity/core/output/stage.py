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

from ..runtime.cache import array_key, cache_key, cached, geometry_key
from ..mesh.clusters import connected_components
from ..mesh.contact import cut_along_contacts, open_side
from ..light.emitters import apply_transport, emitter_transport, vertex_frames
from ..runtime.errors import RadiosityError
from ..util.geometry import bilinear
from .gather import (
    apply_gather, correction_matrix, gather_matrix, product, transport_product,
    transposed_transport
)
from .interpolate import inverse_bilinear, interpolate_corners, located_corners, locate
from ..mesh.patches import PatchSet, poly_geometry
from ..mesh.subdivide import build_patches, keeps_faces_whole
from ..runtime.background import Ahead
from ..runtime.parallel import resolve_workers
from ..runtime.progress import Ticker
from ..mesh.refine import LUMA
from ..rays import embree_available, embree_scene, occluder, open_fraction
from .vertex import exposure, fill_buried, frames, vertex_radiosity
from ..util.unique import unique_ints, unique_rows

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
    _, inv = unique_rows(np.concatenate([keys, ek]), return_inverse=True)
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


#: Passes of :func:`_bounce_again`. Measured against Cycles (raw RMS / bias): one pass, yard
#: 0.89% / -0.26%, Cornell 1.13% / +0.09%, room 3.17% / -0.26%; converged (8 at most), 0.84%,
#: 1.10% and 3.18% with the room's bias at -0.55%: at the elements' level each bounce loses a
#: little more (rays through the cracks of touching objects) than the patch solution does.
GATHER_PASSES = 1


def _gathered(ctx, elements, rest_v, xv, nv, rho_v, light_v=None, side=None, pending=None):
    """Reflected light R at element vertices by a final gather (the gather's ray hits cached as a
    matrix): (V, 3), before the elements' reflectivity. The rays read the light reflected by the
    output mesh itself: the direct part exact at each of its vertices (as fine as the output, so
    a two-sided lamp's few-centimetre hot spot on a ceiling is not spread over whole patches),
    the part reflected more than once from the patch solution. ``light_v``: the direct light
    arriving at ``xv``, when the caller has it already.

    Where the direct part changes abruptly inside an element (a shadow's edge, a lamp hanging
    millimetres under a ceiling), interpolating it from the element's corners would spread a
    corner's light over the whole element: rays that land on such an element read the exact
    direct light on a fine grid of its points instead (:class:`_AbruptGrid`: the same points
    for every ray, so neighbouring vertices read the same light and the result stays smooth).

    A small, bright area would make rare, very bright hits, blotches. What is brighter than
    :data:`HOT` times the mean (:func:`_mean_light`), a smooth element (:func:`_hot_elements`:
    the spot a pendant lamp's back lights on a ceiling, the floor under a lamp) or a cell of an
    abrupt element's grid (the glow a lamp's back casts on a ceiling within millimetres of its
    edge), lights the vertices as lamps do instead, by its form factor and shadow rays
    (:func:`_shine`), and the rays that land on it read nothing.

    ``pending``: the gather's rays started by :func:`_start_gather`; what does not read them
    (the corrections' choice of elements, what shines) is done before waiting for them."""
    rest_e = rest_v if elements is ctx.patches else _interpolated(ctx, elements, rest_v, xv, nv)
    if side is not None:          # buried vertices on an outline read as their open side
        rest_e = side.spread(rest_e)
    light_v = ctx.direct.at(xv, nv, "vertices") if light_v is None else light_v
    direct_e = rho_v * light_v
    got = []

    def rays():                   # G and H, once, when first read
        if not got:
            got.append(_gather_rays(ctx, elements, xv, nv, pending))
        return got[0]
    corrections = _corrections(ctx, elements, rays, xv, nv, light_v, direct_e)
    G, H = rays()
    world = ctx.world if ctx.direct.world is None else None   # else in the vertices' direct light
    out = apply_gather(G, G.sky, direct_e + rest_e, world, ctx.settings.workers)
    out += corrections
    return _bounce_again(G, rho_v, out, rest_e, workers=ctx.settings.workers,
                         spread=None if side is None else side.spread)


def _bounce_again(G, rho_v, out, rest_e, passes=GATHER_PASSES, tol=1e-4, workers=1, spread=None):
    """The gather again, reading the light reflected more than once as the elements reflect what
    it found (rho_v * out) instead of the patch solution's (``rest_e``); ``passes`` times, or
    until it changes by less than ``tol`` of its largest value (many passes: the element-level
    solution, with the patch solution as the first guess). The patches straddle walls' feet and
    contacts, the elements do not: the foot of the bench yard's walls read 10% dark after one
    gather (against a 4,096-ray gather of the output itself), and one pass more took the
    yard's RMS error against Cycles from 1.42% to 0.89%, the Cornell box's from 1.38% to
    1.13%. One sparse product per pass: a relight casts no ray."""
    zero = np.zeros_like(G.sky)
    before = rest_e
    for i in range(passes):
        now = rho_v * out if spread is None else spread(rho_v * out)
        step = apply_gather(G, zero, now - before, None, workers)
        before = now
        out = out + step
        if i + 1 < passes and np.abs(step).max() <= tol * max(float(np.abs(out).max()), 1e-300):
            break                              # (after the last pass there is nothing to decide)
    return out


def _corrections(ctx, elements, rays, xv, nv, light_v, direct_e):
    """What the gather of ``direct_e`` misses: the exact light of abrupt elements' grids and
    what shines (see :func:`_gathered`); (V, 3). ``rays()``: the gather's (G, H), asked for
    only after what shines is found (a gather started in the background casts meanwhile)."""
    out = np.zeros((len(xv), 3))
    # what is abrupt or hot is judged on the light arriving, not on what the surfaces make of it:
    # a relight that changes a colour or scales the lamps picks the same elements and finds
    # their grids and shine in the cache (no ray)
    select = abrupt_elements(elements, light_v, cache=ctx.cache)
    opened = _open_elements(ctx, elements)
    bar = HOT * _mean_light(elements, light_v, opened, ctx.cache)
    hot, shine = _hot_elements(ctx, elements, light_v, bar, ~select, opened)
    if not (select.any() or hot.any()):
        return out
    grid = cells = None
    x, masks = np.zeros((0, 3)), [select, hot]
    if select.any():
        grid = _AbruptGrid(ctx, elements, np.flatnonzero(select), 0.02 * bar / HOT, bar)
        cells = grid.hot_cells()
        x, masks = np.concatenate([grid.values, grid.cell_mean]), masks + [grid.spiky, grid.hot]

    def read(y, pid):               # abrupt elements: their grid (none where it shines)
        cols, w = np.zeros((len(pid), 4), np.int64), np.zeros((len(pid), 4))
        on = select[pid]
        if on.any():
            cols[on], w[on] = grid.weights(y[on], pid[on])
        return cols, w
    # the hits' correction as a matrix: it depends on geometry and on what was chosen (on the
    # light arriving), so a relight that chooses the same reads its new light through it
    s = ctx.settings
    key = cache_key(geometry_key(elements) + b"".join(np.packbits(m).tobytes() for m in masks),
                    ("gather-correction", s.gather_rays, s.element_size, s.patch_size))
    shone = None
    if hot.any() or (cells is not None and len(cells[0])):
        shone = _shine(ctx, elements, np.flatnonzero(hot), shine, xv, nv, cells)
    C = cached(ctx.cache, key, lambda: correction_matrix(*rays(), elements, select | hot, read, len(x),
                                                        workers=ctx.settings.workers))
    out += product(C, np.concatenate([direct_e, x]))
    if shone is not None:
        out += shone
    return out


#: What shines instead of being gathered (:func:`_gathered`): reflected direct light brighter
#: than this many times its mean over what the scene sees (:func:`_mean_light`). At 2 the
#: Cornell box shone a third more elements and its RMS error against Cycles rose from 1.16% to
#: 1.42% (each group shines its mean); at 4 the pendant-lit room and a lamp-lit floor kept
#: more of their bright spot to the gather's rays.
HOT = 3.0


def _corner_columns(elements, cache=None):
    """(cols (4, N) intp, quad (N,) float, count (N,) float, quad3 (N, 3), count3 (N, 3)): each
    element's corner vertices, one contiguous row per corner (a triangle's fourth is its first),
    1.0 where the fourth is a corner, and how many corners, the last two also repeated over
    three bands (for (N, 3) values: a (N, 1) factor broadcast along the short axis took 5x as
    long): geometry only, kept in ``cache`` (a relight reads its elements' light through them)."""
    def make():
        polys = elements.polys
        quad = (polys[:, 3] >= 0).astype(np.float64)
        cols = np.ascontiguousarray(np.where(polys < 0, polys[:, :1], polys).T, dtype=np.intp)
        count = (polys >= 0).sum(axis=1).astype(np.float64)
        return (cols, quad, count) + tuple(np.ascontiguousarray(np.repeat(a[:, None], 3, axis=1))
                                           for a in (quad, count))
    if cache is None:
        return make()
    return cached(cache, cache_key(geometry_key(elements), ("corner-columns",)), make)


def _corner_sum(values, cols, quad, quad3=None):
    """Each element's corners of ``values`` (V,) or (V, k) summed in order, one corner at a
    time, the fourth times ``quad`` (as the (N, 4) array of corners times their validity sums
    over its corners, bit for bit: a triangle adds 0), from :func:`_corner_columns`. Whole
    columns at a time: summing the (N, 4) array over its short axis and taking
    ``values[polys]`` were most of the dense room's relight in :func:`_hot_elements`,
    :func:`_mean_light` (with the validity's sum over the corners). ``quad3``: ``quad`` over
    three bands, for (N, 3) values."""
    q = quad if values.ndim == 1 else quad3 if quad3 is not None and values.shape[1] == 3 else quad[:, None]
    total = values.take(cols[0], axis=0) + values.take(cols[1], axis=0)
    total += values.take(cols[2], axis=0)
    total += values.take(cols[3], axis=0) * q
    return total


def _mean_light(elements, values_v, opened=None, cache=None) -> float:
    """The mean luminance of the vertex field ``values_v`` (V, 3) over the surfaces the scene
    sees: each element's corner mean, weighted by its area and ``opened`` (N,) (None: all). Not
    over vertices: a face cut into many, vertices repeated along a face's edges, a floor
    running on under a block, would each weigh in. ``cache``: where :func:`_corner_columns`
    are kept."""
    cols, quad, count = _corner_columns(elements, cache)[:3]
    Y = _corner_sum(np.asarray(values_v, dtype=np.float64) @ LUMA, cols, quad) / count
    w = elements.areas if opened is None else elements.areas * opened
    total = float(w.sum())
    return float((w * Y).sum()) / total if total > 0 else float(Y.mean())


def _hot_elements(ctx, elements, light_v, bar, smooth, opened=None, budget=64):
    """(hot (N,) bool, radiance (h, 3)): of the elements whose direct light changes ``smooth``-ly,
    those whose direct light arriving (the mean of ``light_v`` (V, 3) over their corners)
    passes the luminance ``bar`` (:data:`HOT` times its :func:`_mean_light`), with
    ``radiance`` their reflectivity times it (the hot ones', in order): the spot a pendant lamp's back lights on a
    ceiling, the floor under a lamp, a block's top beside it. A gather's rays find such a spot
    by chance, a few at a vertex and one more or fewer at its neighbour: each ray there
    carries many times the light of the others, so the vertices blotch (a room whose lamp
    hangs 0.3 m under the ceiling: the walls 6.4% rough, by the bench's smoothness figure,
    against 3.3% for Cycles at 4,096 samples; 0.9% shining). Shining, they light every vertex
    by their form factor.

    Only elements the scene sees (``opened``, :func:`_open_elements`: not the ceiling right
    above a lamp's back), and at most ``budget`` groups of them (:func:`_shine_groups`), the
    brightest: each group costs every vertex a form factor and shadow rays, and a scene lit
    mostly in one area should not pay that for hundreds of them."""
    # the corners summed in order, one at a time (as the (N, 4, 3) array's sum over its corners
    # adds them, bit for bit): that gather and its strided sum were 5.7 of this function's
    # 7 ms in the dense room's relight
    cols, quad, count, quad3, count3 = _corner_columns(elements, ctx.cache)
    light_v = np.asarray(light_v, dtype=np.float64)
    arriving = _corner_sum(light_v, cols, quad, quad3) / (count3 if light_v.shape[1] == 3 else count[:, None])
    hot = smooth & (arriving @ LUMA > bar)
    if opened is not None:
        hot &= opened > 0
    ids = np.flatnonzero(hot)
    if ids.size:
        groups = _shine_groups(ctx, elements, ids)
        if groups.max() >= budget:
            a = elements.areas[ids]
            Y = np.bincount(groups, weights=a * (arriving[ids] @ LUMA)) / np.bincount(groups, weights=a)
            hot[ids[~np.isin(groups, np.argsort(-Y, kind="stable")[:budget])]] = False
            ids = np.flatnonzero(hot)
    return hot, elements.rho[ids] * arriving[ids]


def _place_uniforms(points, verts, count) -> np.ndarray:
    """(P, count) uniforms in [0, 1) drawn from the place of each of ``points`` (P, 3) (a hash of
    its position within the bounding box of ``verts``, to 2^-32 of its size): the same point
    draws the same numbers in any scene, in any order."""
    lo = verts.min(axis=0)
    size = max(float(np.max(verts.max(axis=0) - lo)), 1e-300)
    q = np.floor((np.asarray(points, dtype=np.float64) - lo) / size * 2.0 ** 32).astype(np.int64).astype(np.uint64)
    with np.errstate(over="ignore"):
        key = (q[:, 0] * np.uint64(0x9E3779B97F4A7C15)) ^ (q[:, 1] * np.uint64(0xC2B2AE3D27D4EB4F)) \
            ^ (q[:, 2] * np.uint64(0x165667B19E3779F9))
        z = key[:, None] + (np.arange(1, count + 1, dtype=np.uint64) * np.uint64(0x9E3779B97F4A7C15))[None]
        z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)          # splitmix64's finaliser
        z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
        z ^= z >> np.uint64(31)
    return (z >> np.uint64(11)).astype(np.float64) / 2.0 ** 53


class _AbruptGrid:
    """The reflected direct light ``rho * D`` on a grid of points of each element ``ids`` (M,)
    (their light changes abruptly), read anywhere on them by bilinear interpolation.

    Element m gets n x n cells (n + 1 points a side) of its bilinear map, n = its edge over a
    quarter of the detail size, 1 to :attr:`CELLS`; the points are moved ``inset`` of the way
    toward the centre, as the vertices are (a point exactly on a contact edge sees the wall it
    touches edge-on). The light there is the vertices' exact light, every shadow ray and its
    penumbra refinement, evaluated once per point: a gather ray reads it where it lands, so
    every ray that lands near a point reads the same light and a vertex's neighbours, whose
    parallel rays land a little aside, read nearly the same. (Reading fresh light at every hit,
    with one shadow ray per emitter, made each vertex's gather of a shadow's edge a new draw:
    speckle, and the bake's costliest step on a dense mesh.)

    Points the scene cannot see (:func:`_seen`: a ceiling above a lamp's back, a floor inside
    a block) lend a ray none of their light: a cell across a lamp's edge would otherwise carry
    the light above the lamp onto the ceiling beside it. A cell whose corners differ more than
    ``ratio`` times (and by more than ``floor``) holds light a bilinear map cannot carry, the
    glow a lamp's back casts on a ceiling within millimetres of its edge: caught at its peak by
    a corner beside the edge, it was spread over the cell (the walls of a 1 m room with such a
    lamp 0.9% too bright),
    missed by corners farther off. Such a cell is read as its mean over :attr:`SPIKE` x
    :attr:`SPIKE` stratified points (seeded, weighted by :func:`_seen`).

    A cell whose mean passes the luminance ``bar`` is read as nothing: it shines instead
    (:meth:`hot_cells`)."""

    CELLS = 4
    SPIKE = 4

    def __init__(self, ctx, elements, ids, floor, bar, ratio=4.0, inset=1e-2):
        size = float(ctx.settings.element_size or ctx.settings.patch_size or 1.0)
        self.inset, self.elements = inset, elements
        # the grid's geometry, cached on the elements chosen (a relight that chooses the same
        # only lights its points again); the patch size sets :func:`_seen`'s reach
        key = cache_key(geometry_key(elements) + np.ascontiguousarray(ids, np.int64).tobytes(),
                        ("abrupt-grid", size, ctx.settings.patch_size, self.CELLS, inset))
        (self.n, self.offset, self.cell_offset, self.local, self.corners, x, owner, nrm, self.seen,
         loc, i, j, k, w) = cached(ctx.cache, key, lambda: self._layout(ctx, elements, ids, size, inset))
        n = self.n
        light = ctx.direct.at(x, nrm, "abrupt-grid")
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
        if s.any():
            mean[s], seen[s] = self._means(ctx, ids, loc[s], i[s], j[s])
        self.cell_mean = mean
        rho = elements.rho.take(ids[loc], axis=0)
        arriving = np.where(rho > 0, mean / np.where(rho > 0, rho, 1.0), 0.0)
        self.hot = (seen > 0) & (arriving @ LUMA > bar)
        self.ids, self.cell_loc, self.cell_i, self.cell_j = ids, loc, i, j

    def _layout(self, ctx, elements, ids, size, inset):
        """The grid's geometry: (n, offset, cell_offset, local, corners, points (X, 3), their
        elements and normals, :func:`_seen` at them, every cell's element (local index), row i,
        column j, corner point ids (4, cells) and :func:`_seen` at its corners (cells, 4))."""
        n = np.ceil(np.sqrt(elements.areas[ids]) / (size / self.CELLS))
        n = np.clip(n, 1, self.CELLS).astype(np.int64)
        count = (n + 1) ** 2
        self.n = n
        self.offset = np.concatenate([[0], np.cumsum(count)[:-1]])
        self.cell_offset = np.concatenate([[0], np.cumsum(n * n)[:-1]])
        local = np.full(len(elements), -1, np.int64)
        local[ids] = np.arange(len(ids))
        corners = elements.corners()
        x = np.empty((int(count.sum()), 3))
        for k in np.unique(n):
            m = np.flatnonzero(n == k)
            t = inset + (1 - 2 * inset) * np.arange(k + 1) / k
            u, v = (a.reshape(1, -1, 1) for a in np.meshgrid(t, t, indexing="ij"))   # point i * (k+1) + j
            p = bilinear(corners[ids[m]][:, None], u, v)                            # (m, (k+1)^2, 3)
            x[(self.offset[m, None] + np.arange((k + 1) ** 2)[None]).ravel()] = p.reshape(-1, 3)
        owner = np.repeat(ids, count)
        nrm = elements.normals[owner]
        seen = _seen(ctx, elements, x, nrm)
        # every cell: its element (local index), row i, column j
        loc = np.repeat(np.arange(len(ids)), n * n)
        r = np.arange(loc.size) - self.cell_offset[loc]
        i, j = r // n[loc], r % n[loc]
        k = np.stack(self._corner_ids(loc, i, j))
        return (n, self.offset, self.cell_offset, local, corners, x, owner, nrm, seen, loc, i, j, k,
                seen[k.T])

    def hot_cells(self):
        """The cells that shine: (elements (c,), corners (c, 4, 3), radiance (c, 3)). A cell is the
        part of its element's bilinear map between (i, j) / n and (i + 1, j + 1) / n, corners
        in the element's order (adjacent cells share theirs bit for bit, so :func:`_shine`'s
        groups see one outline); its radiance is its mean over the part the scene sees, and
        the part it does not (above a lamp's back) is what the shadow rays find hidden."""
        h = np.flatnonzero(self.hot)
        loc, i, j = self.cell_loc[h], self.cell_i[h], self.cell_j[h]
        n = self.n[loc]
        c = self.corners[self.ids[loc]][:, None]                                      # (c, 1, 4, 3)
        u = (i[:, None] + np.array([0, 1, 1, 0])[None]) / n[:, None]
        v = (j[:, None] + np.array([0, 0, 1, 1])[None]) / n[:, None]
        corners = bilinear(c, u[..., None], v[..., None])                            # (c, 4, 3)
        return self.ids[loc], corners, self.cell_mean[h]

    def _corner_ids(self, loc, i, j):
        """Grid point ids of the corners (0,0), (1,0), (1,1), (0,1) of cells (i, j) of elements
        ``loc`` (local indices)."""
        base, side = self.offset[loc], self.n[loc] + 1
        return [base + (i + a) * side + (j + b) for a, b in ((0, 0), (1, 0), (1, 1), (0, 1))]

    def _means(self, ctx, ids, loc, i, j):
        """((c, 3), (c,)): each cell (i, j) of elements ``loc`` (c,): its light's mean over the
        part seen and the part seen, from SPIKE x SPIKE jittered points weighted by :func:`_seen`
        (the plain mean where none is seen). Each cell's jitter is drawn from where it is
        (:func:`_place_uniforms`): a cell's mean depends neither on which others there are nor
        on their order, and the cells along a lamp's edge do not all sample its glow at the same
        distance (one pattern for every cell made a room's walls 3.7% too bright)."""
        S = self.SPIKE

        def points():               # geometry, cached on the cells (a relight finds them)
            a, b = (g.ravel()[None] for g in np.meshgrid(np.arange(S), np.arange(S), indexing="ij"))
            n = self.n[loc][:, None]
            c = self.corners[ids[loc]][:, None]                                       # (c, 1, 4, 3)
            centre = bilinear(c, ((i + 0.5) / self.n[loc])[:, None, None], ((j + 0.5) / self.n[loc])[:, None, None])
            ju, jv = _place_uniforms(centre[:, 0], self.elements.verts, 2 * S * S).reshape(-1, 2, S * S) \
                .transpose(1, 0, 2)
            su = (i[:, None] + (a + ju) / S) / n
            sv = (j[:, None] + (b + jv) / S) / n
            u, v = (self.inset + (1 - 2 * self.inset) * t for t in (su, sv))
            x = bilinear(c, u[..., None], v[..., None]).reshape(-1, 3)
            el = np.repeat(ids[loc], S * S)
            nrm = self.elements.normals[el]
            return x, el, nrm, _seen(ctx, self.elements, x, nrm).reshape(loc.size, S * S)
        key = cache_key(geometry_key(self.elements) + b"".join(np.ascontiguousarray(a, np.int64).tobytes()
                                                                for a in (ids, self.n, loc, i, j)),
                        ("abrupt-cells", ctx.settings.patch_size, ctx.settings.element_size, self.SPIKE,
                         self.inset))
        x, el, nrm, w = cached(ctx.cache, key, points)
        # one shadow ray per emitting patch and point: the mean over the points is what counts
        D = self.elements.rho.take(el, axis=0) * ctx.direct.at(x, nrm, "abrupt-cells", samples=1)
        D = D.reshape(loc.size, S * S, 3)
        seen = w.mean(axis=1)
        w = np.where(w.sum(axis=1, keepdims=True) > 0, w, 1.0)
        return np.einsum("cs,csk->ck", w, D) / w.sum(axis=1)[:, None], seen

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
        the cell each falls in over its corners seen, its mean where it is spiky, nothing where
        it shines."""
        cols, w = self.weights(y, pid)
        return np.einsum("hc,hck->hk", w, np.concatenate([self.values, self.cell_mean])[cols])

    def weights(self, y, pid):
        """(columns (h, 4), weights (h, 4)): :meth:`at` as weights of the rows of
        ``[values; cell_mean]`` (a relight reads new light through the same weights)."""
        loc = self.local[pid]
        n = self.n[loc]
        u, v = self.uv(np.asarray(y, dtype=np.float64), pid)
        su = np.clip((u - self.inset) / (1 - 2 * self.inset), 0.0, 1.0) * n
        sv = np.clip((v - self.inset) / (1 - 2 * self.inset), 0.0, 1.0) * n
        i, j = np.minimum(su.astype(np.int64), n - 1), np.minimum(sv.astype(np.int64), n - 1)
        fu, fv = (su - i)[:, None], (sv - j)[:, None]
        k = self._corner_ids(loc, i, j)
        w = np.concatenate([(1 - fu) * (1 - fv), fu * (1 - fv), fu * fv, (1 - fu) * fv], axis=1)   # (h, 4)
        seen = w * np.stack([self.seen[q] for q in k], axis=1)
        total = seen.sum(axis=1, keepdims=True)
        w = np.where(total > 0, seen / np.where(total > 0, total, 1.0), w)
        cols = np.stack(k, axis=1)
        cell = self.cell_offset[loc] + i * n + j
        spiky = self.spiky[cell]
        cols[spiky] = len(self.values) + cell[spiky, None]
        w[spiky] = (1.0, 0.0, 0.0, 0.0)
        w[self.hot[cell]] = 0.0
        return cols, w


def _open_elements(ctx, elements):
    """(N,) 1 for an element the scene can see, 0 for one buried in a solid (its centre's rays
    all end on back faces or within a twentieth of the patch size: :func:`.rays.open_fraction`),
    so output vertices on a block's outline are evaluated on the open side. None without
    Embree (every element counts). Read-only, kept beside the fractions: the same array at
    every call (a relight's frames and fits key on it, hashing it once)."""
    if not embree_available():
        return None
    reach = 0.05 * float(ctx.settings.patch_size or ctx.settings.element_size or 1.0)
    key = cache_key(geometry_key(elements), ("open-centres", reach))
    f = cached(ctx.cache, key, lambda: open_fraction(elements, elements.centers, elements.normals,
                                                     embree_scene(elements), reach,
                                                     workers=ctx.settings.workers))

    def weights():
        w = (f > 0.05).astype(np.float64)
        w.flags.writeable = False
        return w
    return cached(ctx.cache, key + "-weights", weights, disk=False)


def _sided(ctx, mesh: PatchSet) -> PatchSet:
    """``mesh`` (patches or elements) with a vertex split where elements that share it, both
    seen by the scene (:func:`_open_elements`), lie on the two sides of another surface: a floor
    running on under a single-plane partition, the side walls and ceiling it stands against.
    Each side's copy of the vertex is evaluated on its side (:func:`.direct.vertex_frames`
    moves it toward its own elements), averages and extrapolates its own side's patches, and
    the gather's rays read it on its side: shared, the vertices on the partition's line took
    half the lit side's light into the dark half (2.7% of the lit floor next to the line). A
    floor under a block standing on it is not split (the side under the block is not seen:
    its vertices on the outline are evaluated on the open side already). The same object when
    nothing is split, as in a scene without such contacts. Cached (geometry only)."""
    if not embree_available() or len(mesh) == 0:
        return mesh
    def split():                              # one array, so the cache keeps it on disk too
        out = _split_sides(ctx, mesh)
        if out is None:
            return np.zeros(0, np.int64)      # nothing split: remembered as well (a relight casts no ray)
        return np.concatenate([[out[0].size], out[0].reshape(-1), out[1]]).astype(np.int64)

    code = cached(ctx.cache, cache_key(geometry_key(mesh), ("sides",)), split)
    if code.size == 0:
        return mesh
    n = int(code[0])
    polys, origin = code[1:1 + n].reshape(mesh.polys.shape), code[1 + n:]
    out = PatchSet(mesh.verts[origin], polys, mesh.centers, mesh.normals, mesh.areas, mesh.rho,
                   mesh.emission, mesh.owner, mesh.source_face, list(mesh.object_names))
    # the elements are the same: what is known of them carries over (no second ray cast)
    reach = 0.05 * float(ctx.settings.patch_size or ctx.settings.element_size or 1.0)
    if ctx.cache is not None:
        seen = ctx.cache.get(cache_key(geometry_key(mesh), ("open-centres", reach)))
        if seen is not None:
            ctx.cache.put(cache_key(geometry_key(out), ("open-centres", reach)), seen)
    return out


def _split_sides(ctx, mesh: PatchSet, inset=1e-2):
    """(polys (N, 4), origin (V',)) of :func:`_sided`, or None when no vertex is split.

    Two elements seen by the scene that share a vertex are parted there when the segment
    between points a hair inside each (``inset`` of the way from the vertex to their centres,
    as the vertices are evaluated), lifted off the surface along their mean normal by the two
    insets' length, crosses another surface. Each element is tested against the first at its
    vertex; where one is parted, every pair there (elements refined on one side meet the other
    side's at a corner, not an edge), and the corners are grouped by the pairs not parted, one
    vertex a group (a buried element's corner is a group of its own)."""
    opened = _open_elements(ctx, mesh)
    if opened is None:
        return None
    polys = mesh.polys
    N, V = len(polys), len(mesh.verts)
    p, c = np.nonzero(polys >= 0)
    v = polys[p, c]
    on = opened[p] > 0
    p, c, v = p[on], c[on], v[on]
    order = np.lexsort((p, v))
    p, c, v = p[order], c[order], v[order]
    first = np.ones(len(v), bool)
    first[1:] = v[1:] != v[:-1]
    head = p[np.maximum.accumulate(np.where(first, np.arange(len(v)), 0))]
    scene = embree_scene(mesh)
    reach = 0.05 * float(ctx.settings.patch_size or ctx.settings.element_size or 1.0)

    def parted(e1, e2, at):
        x = mesh.verts[at]
        d1, d2 = inset * (mesh.centers[e1] - x), inset * (mesh.centers[e2] - x)
        n = mesh.normals[e1] + mesh.normals[e2]
        n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
        lift = (np.linalg.norm(d1, axis=1) + np.linalg.norm(d2, axis=1))[:, None] * n
        p1, p2 = x + d1 + lift, x + d2 + lift
        out = scene.occluded(p1, p2 - p1, np.ones(len(p1))) if len(p1) else np.zeros(0, bool)
        # only between points the scene sees: two floor patches whose corners meet under a
        # block standing on them are parted by the block, but nothing sees either corner
        k = np.flatnonzero(out)
        if k.size:
            x2 = np.concatenate([x[k] + d1[k], x[k] + d2[k]])
            n2 = np.concatenate([mesh.normals[e1[k]], mesh.normals[e2[k]]])
            f = open_fraction(mesh, x2, n2, scene, reach, workers=ctx.settings.workers).reshape(2, -1)
            out[k] = (f > 0.05).all(axis=0)
        return out

    rest = ~first
    cut = parted(head[rest], p[rest], v[rest])
    if not cut.any():
        return None
    split_v = np.zeros(V, bool)
    split_v[v[rest][cut]] = True
    # every pair of seen elements at a split vertex
    at = np.flatnonzero(split_v[v])
    sv, sp, sc = v[at], p[at], c[at]
    start = np.flatnonzero(np.r_[True, sv[1:] != sv[:-1]])
    size = np.diff(np.r_[start, len(sv)])
    i_l, j_l = [], []
    for k in np.unique(size):
        base = start[size == k]
        i, j = np.triu_indices(k, 1)
        i_l.append((base[:, None] + i[None]).ravel())
        j_l.append((base[:, None] + j[None]).ravel())
    i, j = np.concatenate(i_l), np.concatenate(j_l)
    joined = ~parted(sp[i], sp[j], sv[i])
    slot = sp * 4 + sc
    sa, sb = slot[i[joined]], slot[j[joined]]
    label = np.arange(4 * N)
    while True:                               # label propagation over the joined corner slots
        m = np.minimum(label[sa], label[sb])
        new = label.copy()
        np.minimum.at(new, sa, m)
        np.minimum.at(new, sb, m)
        new = new[new]
        if np.array_equal(new, label):
            break
        label = new
    # a vertex whose seen elements all join up (a floor around a block's corner, whose edge
    # grazes the segment across the corner) is not split: not even its buried corners
    pairs = unique_rows(np.column_stack([sv, label[slot]]))
    split_v[:] = False
    split_v[pairs[1:, 0][pairs[1:, 0] == pairs[:-1, 0]]] = True
    if not split_v.any():
        return None
    flat = polys.reshape(-1).copy()
    at = np.flatnonzero((flat >= 0) & split_v[np.maximum(flat, 0)])
    groups, inv = unique_rows(np.column_stack([flat[at], label[at]]), return_inverse=True)
    inv = inv.reshape(-1)
    lead = np.ones(len(groups), bool)
    lead[1:] = groups[1:, 0] != groups[:-1, 0]
    ids = np.where(lead, groups[:, 0], 0)
    extra = np.flatnonzero(~lead)
    ids[extra] = V + np.arange(extra.size)
    flat[at] = ids[inv]
    return flat.reshape(polys.shape), np.concatenate([np.arange(V), groups[extra, 0]])


def _seen(ctx, elements, x, nrm):
    """(P,) in [0, 1]: how much of the scene sees the points ``x`` (P, 3) on ``elements`` with
    normals ``nrm``: :func:`.rays.open_fraction` (reach a twentieth of the patch size) over a
    half, so a point with half its hemisphere open (in a corner) counts fully, one a few
    millimetres above a lamp's back or inside a block not at all. Cached (geometry only)."""
    reach = 0.05 * float(ctx.settings.patch_size or ctx.settings.element_size or 1.0)
    key = cache_key(geometry_key(elements) + array_key(x), ("exposure", reach))   # x hashed once per array
    f = cached(ctx.cache, key, lambda: open_fraction(elements, x, nrm, embree_scene(elements), reach,
                                                     workers=ctx.settings.workers))
    return np.minimum(1.0, f / 0.5)


def seen_vertices(ctx, elements) -> np.ndarray:
    """(V,) bool: output vertices the scene sees (:func:`_seen` at their evaluation points of
    the vertex stage, at least a half), not those buried under what stands on their surface;
    all of them without Embree."""
    if not embree_available():
        return np.ones(len(elements.verts), bool)
    xv, nv, _ = vertex_frames(elements, weights=_open_elements(ctx, elements))
    return _seen(ctx, elements, xv, nv) >= 0.5


def _open_side(ctx, elements, xv, nv):
    """The :class:`.contact.OpenSide` of the output vertices buried under what stands on their
    surface (:func:`_seen` below a half: less than a quarter of their rays leave into the
    open), or None without Embree. Geometry only, cached: a relight casts no ray."""
    if ctx.direct is None or not embree_available():
        return None
    buried = _seen(ctx, elements, xv, nv) < 0.5
    if not buried.any():
        return None
    key = cache_key(geometry_key(elements) + array_key(xv), ("open-side",))
    return cached(ctx.cache, key, lambda: open_side(elements, buried, embree_scene(elements),
                                                    _open_elements(ctx, elements)))


def _shine_groups(ctx, elements, ids, scale=1.0) -> np.ndarray:
    """(M,) group of each element ``ids``: connected elements of one object in one cell of
    ``scale`` times the patch size shine as one (:func:`_shine`). Elements touch where they
    have a corner at the same place, whether or not the mesh shares the vertex (a floor
    modelled as four faces around a hole groups as one floor would)."""
    size = scale * float(ctx.settings.patch_size or ctx.settings.element_size or 1.0)

    def groups():
        cell = np.floor((elements.centers[ids] - elements.verts.min(axis=0)) / size).astype(np.int64)
        key = unique_rows(np.column_stack([elements.owner[ids], cell]), return_inverse=True)[1].reshape(-1)
        place = unique_rows(elements.verts, return_inverse=True)[1].reshape(-1)
        polys = elements.polys[ids]
        polys = np.where(polys >= 0, place[np.maximum(polys, 0)], -1)
        return unique_ints(connected_components(key, polys), return_inverse=True)[1].reshape(-1)
    # geometry only (a relight that shines the same elements finds them grouped)
    ids = np.ascontiguousarray(ids, dtype=np.int64)
    return cached(ctx.cache, cache_key(geometry_key(elements) + ids.tobytes(), ("shine-groups", size)), groups)


def _shine(ctx, elements, ids, radiance, xv, nv, cells=None):
    """(V, 3) light arriving at the points ``xv`` from elements ``ids`` shining ``radiance``
    (M, 3) toward their front, with shadows: grouped by object and patch-size cell so the
    shadow rays follow a few areas, not every element (:func:`_shine_groups`,
    :func:`.direct.emitter_transport`). ``cells``: (elements (c,), corners (c, 4, 3), radiance
    (c, 3)), parts of elements that shine by themselves (:meth:`_AbruptGrid.hot_cells`),
    grouped as their elements would be, apart from whole elements.

    A group shines its area-weighted mean radiance; its shadow rays go to points spread over it
    by power (area times the luminance arriving), not area, so a bright piece's light is shadowed as that
    piece is, not as its dim neighbours are (spread by area, the cells beside a lamp 5 mm
    under a ceiling, hidden from most of the room by the lamp, shone 3x what they do alone)."""
    groups = _shine_groups(ctx, elements, ids) if ids.size else np.zeros(0, np.int64)
    every, L = ids, radiance
    verts, polys = elements.verts, elements.polys[ids]
    if cells is not None and len(cells[0]):
        parent, corners, cell_light = cells
        first, inv = unique_ints(parent, return_inverse=True)
        after = int(groups.max()) + 1 if groups.size else 0
        # half-patch cells: a lamp's glow seen beside the lamp and hidden behind it across the
        # lamp must not share one group's visibility (a patch-size group made the walls of a
        # 1 m room with a lamp 2 mm under its ceiling 0.5% too bright)
        groups = np.concatenate([groups, after + _shine_groups(ctx, elements, first, 0.5)[inv.reshape(-1)]])
        V, c = len(verts), len(parent)
        verts = np.concatenate([verts, corners.reshape(-1, 3)])
        polys = np.concatenate([polys, V + np.arange(4 * c).reshape(c, 4)])
        every, L = np.concatenate([ids, parent]), np.concatenate([radiance, cell_light])
    # the shining pieces' geometry hashed once (the cells' corners after the elements' own
    # vertices, and the pieces), their centres and areas kept under it: a relight that shines
    # the same pieces does not make them again
    V = len(elements.verts)
    h = hashlib.sha256(np.ascontiguousarray(verts[V:]).tobytes())
    h.update(np.ascontiguousarray(polys).tobytes())
    shape = geometry_key(elements) + h.digest()
    centers, area = cached(ctx.cache, cache_key(shape, ("shine-geometry",)),
                           lambda: poly_geometry(verts, polys)[::2], disk=False)
    rho = elements.rho.take(every, axis=0)
    arriving = np.where(rho > 0, L / np.where(rho > 0, rho, 1.0), 0.0)
    power = area * np.maximum(arriving @ LUMA, 1e-300)     # where the shadow rays go (light arriving:
                                                           # the same after a change of colour)
    # relative power to 6 digits: a relight that scales the light finds the same transport in
    # the cache (no ray), and a first bake draws from exactly what a relight would
    power = np.maximum(np.round(power / power.max(), 6), 1e-12)
    source = PatchSet(verts, polys, centers, elements.normals.take(every, axis=0), power, rho,
                      np.zeros((len(every), 3)), elements.owner[every], elements.source_face[every],
                      list(elements.object_names))
    # a quarter of the lamps' shadow rays (penumbrae refined all the same): what shines here is a
    # few percent of the light (3.4% of the Cornell box's), and at 4 or 16 rays its part of the
    # bench's smoothness figure is the same (0.24-0.25%); the rays were most of its cost
    samples = max(4, int(ctx.settings.direct_samples) // 4)
    # the elements' geometry and the points hashed once per array (a relight's are cached)
    key = cache_key(shape + groups.tobytes() + power.tobytes() + array_key(xv),
                    ("shine", samples, len(verts) - V, len(every)))
    T = cached(ctx.cache, key, lambda: emitter_transport(
        source, xv, nv, np.arange(len(every)), scene=occluder(elements), samples=samples, groups=groups,
        workers=ctx.settings.workers, ticker=Ticker(None, ctx.cancelled)))
    G = int(groups.max()) + 1
    L = np.stack([np.bincount(groups, weights=area * L[:, k], minlength=G) for k in range(3)], 1) \
        / np.bincount(groups, weights=area, minlength=G)[:, None]
    # kept transposed beside T in memory: a relight neither transposes nor casts it
    Tt = cached(ctx.cache, key + "-t", lambda: transposed_transport(T), disk=False)
    return transport_product(Tt, L, transposed=True)


def _gather_key(ctx, elements):
    return cache_key(geometry_key(elements), ("gather-elements", ctx.settings.gather_rays))


def _start_gather(ctx, elements, xv, nv):
    """The gather of :func:`_gather_rays` started on its forked workers, collected on a thread
    while the vertex stage goes on (the vertices' direct light, the open side, what shines: the
    work that does not read G); a :class:`.parallel.Background` for :func:`_gather_rays`, or
    None where G is cached or the gather would not run on forked workers (one worker, few rays,
    no Embree): then it is made where it is read, as before. The same G, bit for bit."""
    if ctx.settings.gather_rays <= 0 or not embree_available() or resolve_workers(ctx.settings.workers) <= 1:
        return None
    if ctx.cache is not None:
        key = _gather_key(ctx, elements)
        if ctx.cache.get(key) is not None and ctx.cache.get(key + "-hits") is not None:
            return None
    return gather_matrix(elements, xv, nv, embree_scene(elements), rays=ctx.settings.gather_rays,
                         ticker=Ticker(None, ctx.cancelled), workers=ctx.settings.workers,
                         hits=True, background=True)


def _gather_rays(ctx, elements, xv, nv, pending=None):
    """The gather matrix G (with ``G.sky``) of ``elements`` at points ``xv`` and its rays' hits
    H (see :func:`.gather.gather_matrix`), cached together: both depend on geometry only.
    ``pending``: the gather started by :func:`_start_gather` (its result is taken here)."""
    key = _gather_key(ctx, elements)
    G = ctx.cache.get(key) if ctx.cache is not None else None
    H = ctx.cache.get(key + "-hits") if ctx.cache is not None else None
    if G is None or H is None:
        if pending is not None:
            G, sky, H = pending.result(ctx.cancelled)
        else:
            G, sky, H = gather_matrix(elements, xv, nv, embree_scene(elements), rays=ctx.settings.gather_rays,
                                      ticker=Ticker(None, ctx.cancelled), workers=ctx.settings.workers,
                                      hits=True)
        G.sky = sky
        if ctx.cache is not None:
            ctx.cache.put(key, G)
            ctx.cache.put(key + "-hits", H)
    return G, H


def abrupt_elements(elements: PatchSet, values_v, ratio=2.0, floor=0.02, cache=None) -> np.ndarray:
    """(N,) bool: elements across which the vertex field ``values_v`` (V, 3) changes too
    abruptly to interpolate: the luminance at one corner is more than ``ratio`` times another's,
    and the difference is more than ``floor`` of the mean over the vertices (dark corners and
    faint gradients stay interpolated): :func:`.refine.abrupt`'s rule on the corners, their
    largest and smallest taken a corner column at a time (:func:`_corner_columns`, kept in
    ``cache``; the same values: the (N, 4) array's max and min over its short axis were 1.5 of
    this function's 1.8 ms in the dense room's relight)."""
    Y = np.asarray(values_v, dtype=np.float64) @ LUMA
    c = Y.take(_corner_columns(elements, cache)[0])
    hi = np.maximum(np.maximum(c[0], c[1]), np.maximum(c[2], c[3]))
    lo = np.minimum(np.minimum(c[0], c[1]), np.minimum(c[2], c[3]))
    return (hi > ratio * lo) & (hi - lo > floor * max(float(Y.mean()), 1e-300))


def _interpolated(ctx, elements, field_v, xv, nv):
    """A patch-vertex field (per vertex of :func:`_sided` patches, 3) at the element vertices
    ``xv``: bilinear in the patches, each element vertex in its own object's patches (the one
    ``xv`` lies in: on its own side of a partition standing on a patch edge)."""
    def where():
        owner_v = np.zeros(len(elements.verts), np.int64)
        for c in range(4):
            on = elements.polys[:, c] >= 0
            owner_v[elements.polys[on, c]] = elements.owner[on]
        # a face kept whole as a patch and as an element (a dense object in a coarse room: its
        # faces are finer than both sizes): its element's corners are its patch's, at (u, v) of
        # the corner, with no search (Suzanne in the Cornell box: most of her vertices)
        e, pid = _whole_faces(ctx.patches, elements)
        idx, uv = np.zeros(len(xv), np.int64), np.zeros((len(xv), 2))
        known = np.zeros(len(xv), bool)
        for c, corner_uv in enumerate(((0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0))):
            on = elements.polys[e, c] >= 0
            v = elements.polys[e[on], c]
            idx[v], uv[v], known[v] = pid[on], corner_uv, True
        rest = np.flatnonzero(~known)
        i1, uv1 = locate(ctx.patches, xv[rest], owner=owner_v[rest], normals=nv[rest])
        # a point beside small patches (refined along a partition) may not have the patch it
        # lies in among the nearest centres: clamped into a neighbour across the partition, it
        # read the other side's light. Those off their patch along it look again, farther (off
        # it across by a hair: a curved mesh's vertex moved in toward its elements lies a
        # thousandth of a face or less under the faces, and is where it belongs)
        c = ctx.patches.corners(i1)
        d = bilinear(c, uv1[:, :1], uv1[:, 1:]) - xv[rest]
        n = ctx.patches.normals[i1]
        across = np.einsum("ij,ij->i", d, n)
        size = np.sqrt(ctx.patches.areas[i1])
        off = (np.linalg.norm(d - across[:, None] * n, axis=1) > 1e-6 * size) | (np.abs(across) > 1e-3 * size)
        if off.any():
            far = rest[off]
            i1[off], uv1[off] = locate(ctx.patches, xv[far], owner=owner_v[far], normals=nv[far], candidates=64)
        idx[rest], uv[rest] = i1, uv1
        return idx, uv

    key = cache_key(geometry_key(ctx.patches) + geometry_key(elements), ("located",))
    sided = _sided(ctx, ctx.patches)
    # the located points' corners and weights, geometry only: a relight reads its field through them
    corners = cached(ctx.cache, cache_key(geometry_key(sided) + geometry_key(elements), ("located-corners",)),
                     lambda: located_corners(sided, *cached(ctx.cache, key, where)))
    return interpolate_corners(field_v, corners)


def _whole_faces(patches: PatchSet, elements: PatchSet):
    """(element ids (m,), patch ids (m,)): the input faces that are one element and one patch,
    their corners at the same places in the same order."""
    def one(ps):
        key = ps.owner.astype(np.int64) * (1 << 32) + ps.source_face.astype(np.int64)
        k, first, count = unique_ints(key, return_index=True, return_counts=True)
        return k[count == 1], first[count == 1]
    ke, fe = one(elements)
    kp, fp = one(patches)
    common, ie, ip = np.intersect1d(ke, kp, assume_unique=True, return_indices=True)
    e, p = fe[ie], fp[ip]
    pe, pp = elements.polys[e], patches.polys[p]
    same = np.all((pe < 0) == (pp < 0), axis=1)
    ce = elements.verts[np.maximum(pe, 0)]
    cp = patches.verts[np.maximum(pp, 0)]
    same &= np.all((ce == cp).all(axis=2) | (pe < 0), axis=1)
    return e[same], p[same]


def _element_indirect(ctx, elements, rest_v, xv, nv, rho_v, in_v=None, light_v=None, side=None,
                      pending=None):
    """Light reflected more than once arriving at element vertices, times their reflectivity
    (with ``in_v``, the patches' incoming indirect light at their vertices: as it arrives, for
    the lighting-only pass): gathered (Embree) or the patch solution's bilinear interpolation.
    ``light_v``: the direct light arriving at ``xv``, when the caller has it. ``pending``: the
    gather started by :func:`_start_gather`."""
    if ctx.settings.gather_rays > 0 and embree_available():
        gathered = _gathered(ctx, elements, rest_v, xv, nv, rho_v, light_v, side, pending)
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
    elements = _uncut_elements(ctx)
    if geometry_key(elements) == geometry_key(ctx.patches):
        return ctx.patches                    # the input is finer than the detail: its own faces
    # no element across a wall's foot: cut along where surfaces stand on others
    key = cache_key(_meshes_key(ctx), ("elements-cut", s.element_size))
    ahead = ctx.ahead.pop("elements", None) if hasattr(ctx, "ahead") else None
    if ahead is not None:                     # cut on a process of its own since the bake began
        cut = ahead.result(ctx.cancelled)
        if cut is not None and ctx.cache is not None and ctx.cache.get(key) is None:
            ctx.cache.put(key, cut)
    elements = cached(ctx.cache, key, lambda: _cut(ctx.meshes, elements, mesh_faces(ctx))).with_mesh_materials(ctx.meshes)
    _refuse_elements(s, len(elements))
    return elements


def _meshes_key(ctx):
    # :func:`output_elements`' cached geometry, the meshes hashed once: its materials are read
    # only onto the elements that are output (a relight read them twice, 0.75 ms each, on the
    # dense Cornell room)
    return ctx.meshes_key() if hasattr(ctx, "meshes_key") else meshes_key(ctx.meshes)


def _uncut_elements(ctx) -> PatchSet:
    """The meshes cut to the detail size (geometry only, cached), before the cut along contacts:
    the meshes' faces (:func:`mesh_faces`, built once a bake) where the detail size cuts none."""
    s = ctx.settings

    def make():
        if _faces_whole(ctx, s.element_size):
            return mesh_faces(ctx)
        return build_patches(ctx.meshes, s.element_size)
    return cached(ctx.cache, cache_key(_meshes_key(ctx), ("elements", s.element_size)), make)


def _faces_whole(ctx, size) -> bool:
    """:func:`.patches.keeps_faces_whole` of the meshes at ``size``, once a bake (the start of the
    bake asks it for the detail size, and the elements again)."""
    return cached(ctx.cache, cache_key(_meshes_key(ctx), ("faces-whole", size)),
                  lambda: keeps_faces_whole(ctx.meshes, size), disk=False)


def mesh_faces(ctx) -> PatchSet:
    """``build_patches(ctx.meshes)``: the meshes' own faces as patches, geometry only, built once
    a bake (kept in memory: the patches of a mesh finer than the patch size, its output elements
    where it is finer than the detail size, and the cutters of the cut along contacts; the
    54k-triangle box built them three times, 0.2 s each)."""
    return cached(ctx.cache, cache_key(_meshes_key(ctx), ("faces",)), lambda: build_patches(ctx.meshes, None),
                  disk=False)


def _cut(meshes, elements, faces=None) -> PatchSet:
    """``elements`` cut along the contacts of the meshes' faces (:func:`.contact.cut_along_contacts`;
    ``faces``: ``build_patches(meshes)`` when the caller has it)."""
    faces = build_patches(meshes, None) if faces is None else faces
    return cut_along_contacts(elements.with_mesh_materials(meshes), faces)


def _refuse_elements(settings, count) -> None:
    if count > settings.max_elements:
        raise RadiosityError(f"a detail size of {settings.element_size} cuts the scene into {count} "
                             f"output elements, more than the limit of {settings.max_elements}: use a "
                             "larger detail size")


def output_vertices_ahead(ctx) -> int:
    """About how many vertices the output will have, before the form factors (the forecast's
    count, :mod:`.forecast`): the elements before their cut along contacts (a few more vertices
    come with the cut), or the patches when they are the output; refuses, as the vertex stage
    would, more elements than ``max_elements`` (the cut only adds)."""
    if not ctx.settings.uses_elements():
        return len(ctx.patches.verts)
    elements = _uncut_elements(ctx)
    if geometry_key(elements) == geometry_key(ctx.patches):
        return len(ctx.patches.verts)
    _refuse_elements(ctx.settings, len(elements))
    return len(elements.verts)


def start_elements(ctx):
    """The output elements' cut along contacts (:func:`_cut_elements`: the bake's one long piece
    of geometry work done on one core; Suzanne at level 3 in the Cornell box, 1.1 s) started on
    a forked process at the start of the bake, beside the patches, the refinement, the form
    factors and the direct light; :func:`_cut_elements` takes it. A :class:`.parallel.Ahead`,
    or None: one worker, no elements, the elements cached (a relight forks nothing: forking
    took its median from 40 to 71 ms), or no face cut to the detail size (the elements are the
    input's faces: nothing to cut), no process forked. The process returns the same cut as
    :func:`_cut_elements` makes."""
    s = ctx.settings
    if not s.uses_elements() or ctx.meshes is None or resolve_workers(s.workers) <= 1:
        return None
    if ctx.cache is not None and any(ctx.cache.get(cache_key(_meshes_key(ctx), (what, s.element_size))) is not None
                                     for what in ("elements", "elements-cut")):
        return None                           # made by a bake before (a relight): cut, or nothing to cut
    meshes, size = ctx.meshes, s.element_size
    try:
        if _faces_whole(ctx, size):
            # the elements are the faces: the process would only build them twice to say so
            # (the 54k-triangle box: 0.4 s of a core the form factors' workers want)
            return None
    except RadiosityError:
        return None                           # unusable faces: the patch stage says which
    return Ahead.start(lambda: _cut(meshes, build_patches(meshes, size), build_patches(meshes, None)))


def _incoming(reflected, rho):
    """(N, 3) light arriving that leaves as ``reflected``: reflected / rho (0 where rho is 0)."""
    return np.where(rho > 0, reflected / np.where(rho > 0, rho, 1.0), 0.0)


def vertex_stage(ctx) -> None:
    """Fill ``ctx.elements`` (the output mesh) and ``ctx.vertex_radiosity`` (V, 3) per its verts:
    radiosity, or with ``output_pass='lighting'`` the light arriving (direct + indirect, as
    radiance: irradiance / pi) without the surface's own colour or emission."""
    patches, u = ctx.patches, ctx.unknowns
    lighting = ctx.settings.output_pass == "lighting"
    # F's and the geometry's only: kept on F, the same array every relight (the fits, frames and
    # rings keyed on it hash it once)
    F = ctx.form_factors
    key = ("exposure-weights", array_key(u.areas), None if ctx.clusters is None else array_key(ctx.clusters.of))

    def make():
        w = np.array(ctx.to_patches(exposure(F, u.areas)), dtype=np.float64)
        w.flags.writeable = False
        return w
    weights = F.memo(key, make)
    ctx.elements = patches
    if ctx.direct is None:
        textured = not lighting and corner_values(patches, ctx.meshes, "rho") is not None
        B = _incoming(ctx.solution.B - u.emission, u.rho) if lighting or textured else ctx.solution.B
        ctx.vertex_radiosity = vertex_radiosity(patches, ctx.to_patches(B), weights=weights, cache=ctx.cache)
        if textured:                          # each vertex its own colour times the light there
            _, _, rho_v = vertex_frames(patches)
            E_v = vertex_radiosity(patches, patches.emission, cache=ctx.cache)
            ctx.vertex_radiosity = _with_corner_colours(ctx, E_v, rho_v, ctx.vertex_radiosity, 0.0)
        return
    # direct light again at every output vertex (sharp shadows, exact falloff); only the
    # smoother light reflected more than once comes from the patches (or their clusters), as in
    # the paper
    rest = ctx.reflected - ctx.direct_source
    sided = _sided(ctx, patches)              # each side of a partition its own vertices
    rest_v = vertex_radiosity(sided, ctx.to_patches(rest), weights=weights, cache=ctx.cache)
    in_v = None
    if lighting:
        in_v = vertex_radiosity(sided, ctx.to_patches(_incoming(rest, u.rho)), weights=weights,
                                cache=ctx.cache)
    if ctx.settings.uses_elements():
        if ctx.settings.gather_rays > 0 and embree_available():
            # what the gather's rays read: buried vertices take their open neighbours' light
            # (the output never shows it: it is each vertex's exact direct light and gather)
            rest_v = fill_buried(sided, rest_v, weights, cache=ctx.cache)
        elements = _cut_elements(ctx)
        ctx.elements = sided if elements is patches else _sided(ctx, elements)
        xv, nv, rho_v = frames(ctx.elements, _open_elements(ctx, ctx.elements), ctx.cache)
        # the gather's rays (geometry only) cast on the workers while this thread finds the
        # direct light, the open side and what shines: with two workers the vertices stage
        # left a core idle for ~2 s of its ~5 s on the 54k-triangle box
        pending = _start_gather(ctx, ctx.elements, xv, nv)
        try:
            D_vert = ctx.direct.at(xv, nv, "vertices")     # once: the gather reads it too
            side = _open_side(ctx, ctx.elements, xv, nv)
            if side is not None:                            # before the gather: its rays read it
                D_vert = side.spread(D_vert, ctx.direct.at(side.points, side.normals, "open-side"))
            rest_v = _element_indirect(ctx, ctx.elements, rest_v, xv, nv, rho_v, in_v, D_vert, side,
                                       pending)
        finally:
            if pending is not None:                     # stopped early: the workers with it
                pending.close()
    else:
        ctx.elements = sided
        xv, nv, rho_v = frames(sided, _open_elements(ctx, sided), ctx.cache)
        rest_v = rest_v if in_v is None else in_v
        D_vert = ctx.direct.at(xv, nv, "vertices")
        side = _open_side(ctx, sided, xv, nv)
        if side is not None:
            D_vert = side.spread(D_vert, ctx.direct.at(side.points, side.normals, "open-side"))
    if side is not None:                                # what a buried vertex gathered: the inside
        rest_v = side.spread(rest_v)
    if lighting:
        ctx.vertex_radiosity = D_vert + rest_v
        return
    E_v = vertex_radiosity(ctx.elements, ctx.elements.emission, cache=ctx.cache)
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
