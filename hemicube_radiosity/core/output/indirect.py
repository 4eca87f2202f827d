"""Light reflected more than once at the output vertices: gathered, or interpolated.

Per output vertex (V, 3), radiance: the element vertices read the patch solution either by a
final gather (Embree: :func:`.gather.gather_matrix`'s cosine rays, cached as a matrix G with
their hits H; the rays read the direct light exact at the output's own vertices, abrupt
elements' grids (:mod:`.abrupt`), nothing where something shines (:mod:`.shine`), then
:data:`GATHER_PASSES` bounces more at the elements' level), or by bilinear interpolation of
the patch solution (:func:`_interpolated`, without Embree or gather rays).
:func:`start_gather` casts the gather's rays in the background while the vertex stage does
the rest; :func:`element_indirect` is the entry point.
"""
from __future__ import annotations

import numpy as np

from ..mesh.patches import PatchSet
from ..rays import embree_available, embree_scene
from ..runtime.cache import cache_key, cached, geometry_key
from ..runtime.parallel import resolve_workers
from ..runtime.progress import Ticker
from ..util.geometry import bilinear
from ..util.sparse import product
from ..util.unique import unique_ints
from .abrupt import AbruptGrid, abrupt_elements, shadowed_inside
from .gather import apply_gather, correction_matrix, gather_matrix, patch_parameters
from .interpolate import interpolate_corners, located_corners, locate
from .shared import corner_sharing
from .shine import BUDGET, HOT, hot_elements, mean_light, shine
from .short_hits import MOST as SHORT_MOST, RATIO as SHORT_RATIO, ShortCells, short_hits
from .corners import corner_columns
from .sides import open_elements, seen_fraction, sided_mesh
from .through import through_key

__all__ = ["DENSE_GATHER_PASSES", "GATHER_PASSES", "element_indirect", "gather_finds_world", "gathered_sky",
           "gathers_faces", "start_gather"]


#: Passes of :func:`_bounce_again` over output elements. Measured against Cycles (raw RMS /
#: bias): one pass, yard 0.89% / -0.26%, Cornell 1.13% / +0.09%, room 3.17% / -0.26%;
#: converged (8 at most), 0.84%, 1.10% and 3.18% with the room's bias at -0.55%: at the
#: elements' level each bounce loses a little more (rays through the cracks of touching
#: objects) than the patch solution does. On the real scenes (``bench/real_scenes.py``, rms
#: against Cycles 256 spp, 1 / 2 / 3 / 8 passes) godot_zdm2 13.41% / 12.61% / 12.50% / 12.73%,
#: where light bounced between a sunlit floor and wall at their junction is an element's, not a
#: patch's; at 3 sauer_pandora 29.0% -> 27.1%, the living room 4.98% -> 4.94%, the terrain and
#: the bunny a hundredth of a point better, truck town the same, at ~2% more time.
GATHER_PASSES = 3
#: ... and where a dense scene's faces gather (:func:`gathers_faces`): each pass reads again
#: what the faces' gather reads through pockets it cannot resolve (a moulding 2 cm off a wall
#: reads the wall's lit corners), so the error compounds: bitterli_wooden_staircase 27.89% at
#: one pass, 29.23% at 3 (bitterli_grey_white_room 21.4% -> 19.9%).
DENSE_GATHER_PASSES = 1

#: The gather at a dense scene's faces (:func:`gathers_faces`) casts the Gather Rays setting
#: over this: the staircase's 256,004 vertices with 128 rays each peaked at 4.7 GB (its hits and
#: matrix), with 64 at 3.6 GB in 85% of the CPU time, its RMS against Cycles 16.25% -> 16.78% raw.
DENSE_RAY_DIVISOR = 2

#: The most sky rays per gather ray for which the gather's rays find the world as well
#: (:func:`gather_finds_world`).
SKY_PER_GATHER = 2
#: ... and the least share of the receivers' hemi-cubes that sees the sky (``F.sky``, their
#: mean): where most rays hit a surface, each is a gather hit to read rather than a cheap
#: occlusion test. Measured (bench/real_scenes.py): the bunny and the terrain (0.87) gained
#: (1.28% -> 1.02%, 0.32% -> 0.20% RMS, no slower), the truck town (0.50) and the living room
#: (0.42) were as fast, zdm2's closed rooms (0.15) took 60 s in its vertex stage instead of 46.
SKY_SHARE_OPEN = 0.3


def element_indirect(ctx, elements, rest_v, xv, nv, rho_v, in_v=None, light_v=None, side=None,
                     pending=None, mirror_v=None):
    """Light reflected more than once arriving at element vertices, times their reflectivity
    (with ``in_v``, the patches' incoming indirect light at their vertices: as it arrives, for
    the lighting-only pass): gathered (Embree) or the patch solution's bilinear interpolation.
    ``light_v``: the direct light arriving at ``xv``, when the caller has it. ``pending``: the
    gather started by :func:`start_gather`. ``mirror_v`` (V', 3) or None: the light arriving
    by way of glossy patches (:func:`..form_factors.glossy.mirrored_arrival`) at the patches'
    vertices, which the gather's rays, reading a glossy surface's diffuse part only, miss: added
    to what they find, interpolated as the patch solution is."""
    if ctx.settings.gather_rays > 0 and embree_available():
        gathered = _gathered(ctx, elements, rest_v, xv, nv, rho_v, light_v, side, pending, mirror_v)
        return gathered if in_v is not None else rho_v * gathered
    if ctx.settings.gather_rays > 0:
        ctx.notes.append("Embree is not available: element vertices interpolate the patch solution "
                         "instead of gathering it")
    rest_v = rest_v if in_v is None else in_v
    if elements is ctx.patches:               # faces already finer than the detail size
        return rest_v
    return _interpolated(ctx, elements, rest_v, xv, nv)


def _gathered(ctx, elements, rest_v, xv, nv, rho_v, light_v=None, side=None, pending=None, mirror_v=None):
    """Reflected light R at element vertices by a final gather (the gather's ray hits cached as a
    matrix): (V, 3), before the elements' reflectivity. The rays read the light reflected by the
    output mesh itself: the direct part exact at each of its vertices (as fine as the output, so
    a two-sided lamp's few-centimetre hot spot on a ceiling is not spread over whole patches),
    the part reflected more than once from the patch solution. ``light_v``: the direct light
    arriving at ``xv``, when the caller has it already.

    Where the direct part changes abruptly inside an element (a shadow's edge, a lamp hanging
    millimetres under a ceiling), interpolating it from the element's corners would spread a
    corner's light over the whole element: rays that land on such an element read the exact
    direct light on a fine grid of its points instead (:class:`AbruptGrid`: the same points
    for every ray, so neighbouring vertices read the same light and the result stays smooth).

    A small, bright area would make rare, very bright hits, blotches. What is brighter than
    :data:`HOT` times the mean (:func:`mean_light`), a smooth element (:func:`hot_elements`:
    the spot a pendant lamp's back lights on a ceiling, the floor under a lamp) or a cell of an
    abrupt element's grid (the glow a lamp's back casts on a ceiling within millimetres of its
    edge), lights the vertices as lamps do instead, by its form factor and shadow rays
    (:func:`shine`), and the rays that land on it read nothing.

    ``pending``: the gather's rays started by :func:`start_gather`; what does not read them
    (the corrections' choice of elements, what shines) is done before waiting for them."""
    rest_e = rest_v if _the_patches(ctx, elements) else _interpolated(ctx, elements, rest_v, xv, nv)
    if side is not None:          # buried vertices on an outline read as their open side
        rest_e = side.spread(rest_e)
    light_v = ctx.direct.at(xv, nv, "vertices") if light_v is None else light_v
    direct_e = rho_v * light_v
    got = {}

    def rays(hits=True):          # G (and with ``hits`` H), once, when first read
        if "G" not in got or (hits and got["H"] is None):
            got["G"], got["H"] = _gather_rays(ctx, elements, xv, nv, pending, hits)
        return got["G"], got["H"]
    ctx.gather_rays = rays        # the corners lit on their own read its hits (:mod:`.above`)
    ctx.gather_key = _gather_key(ctx, elements)
    corrections = _corrections(ctx, elements, rays, xv, nv, light_v, direct_e)
    G = rays(hits=False)[0]       # a relight whose corrections are cached reads no hits
    world = ctx.world if ctx.direct.world is None else None   # else in the vertices' direct light
    out = apply_gather(G, G.sky, direct_e + rest_e, world, ctx.settings.workers)
    out += corrections
    if mirror_v is not None:      # what glossy patches mirror: the patch solution's, interpolated
        mirror_e = mirror_v if _the_patches(ctx, elements) else _interpolated(ctx, elements, mirror_v, xv, nv)
        out += mirror_e if side is None else side.spread(mirror_e)
    return _bounce_again(G, rho_v, out, rest_e, DENSE_GATHER_PASSES if gathers_faces(ctx) else GATHER_PASSES,
                         workers=ctx.settings.workers, spread=None if side is None else side.spread)


def _the_patches(ctx, elements) -> bool:
    """Whether ``elements`` are the patches themselves (or their :func:`.sides.sided_mesh`,
    the same faces with some vertices split), whose vertices the patch solution's fields are
    at already: nothing to interpolate."""
    return elements is ctx.patches or elements.centers is ctx.patches.centers


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
    """What the gather of ``direct_e`` misses: the exact light of abrupt elements' grids, of the
    cells short rays land in (:mod:`.short_hits`) and what shines (see :func:`_gathered`);
    (V, 3). ``rays()``: the gather's (G, H), asked for only after what shines is found (a
    gather started in the background casts meanwhile)."""
    out = np.zeros((len(xv), 3))
    # what is abrupt or hot is judged on the light arriving, not on what the surfaces make of it:
    # a relight that changes a colour or scales the lamps picks the same elements and finds
    # their grids and shine in the cache (no ray)
    select = abrupt_elements(elements, light_v, cache=ctx.cache)
    opened = open_elements(ctx, elements)
    faces = gathers_faces(ctx)
    small = _open_small_faces(ctx, elements, xv, nv, opened) if faces else np.zeros(len(elements), bool)
    select &= ~small
    select |= shadowed_inside(ctx, elements, xv, nv, light_v, select | small, opened)
    bar = HOT * mean_light(elements, light_v, opened, ctx.cache)
    grid = AbruptGrid(ctx, elements, np.flatnonzero(select), 0.02 * bar / HOT, bar,
                      whole=faces) if select.any() else None
    # at most a budget of groups shines, the grid's hot cells counted (those left out: read);
    # a dense scene's faces none (:func:`_open_small_faces` says why)
    hot, hot_light = hot_elements(ctx, elements, light_v, bar, ~select, opened, grid=grid,
                                  budget=0 if faces else BUDGET)
    cells = None
    x, masks = np.zeros((0, 3)), [select, hot]
    if grid is not None:
        cells = grid.hot_cells()
        x, masks = grid.readable(), masks + [grid.spiky, grid.hot]
    shone = None
    if hot.any() or (cells is not None and len(cells[0])):
        shone = shine(ctx, elements, np.flatnonzero(hot), hot_light, xv, nv, cells)
    short = _short_cells(ctx, elements, rays, xv, hot) if faces else None    # (waits for the gather's hits)
    if not (select.any() or hot.any() or short is not None):
        return out
    read = _reader(elements, xv, select, grid, short, len(x))
    if short is not None:
        light = ctx.direct.at(short.points, short.normals, "short-hits")
        x = np.concatenate([x, elements.rho.take(short.faces, axis=0) * light])
    # the hits' correction as a matrix: it depends on geometry and on what was chosen (on the
    # light arriving), so a relight that chooses the same reads its new light through it
    s = ctx.settings
    key = cache_key(geometry_key(elements) + through_key(elements) + b"".join(np.packbits(m).tobytes() for m in masks),
                    ("gather-correction", gather_count(ctx), s.element_size, s.patch_size, "strata", "graded2")
                    + (("whole",) if faces else ()) + (("short", SHORT_RATIO) if short is not None else ()))

    def correction():
        G, H = rays()
        on = None if short is None else short_hits(elements, xv, H, SHORT_RATIO, exclude=hot)
        return correction_matrix(G, H, elements, select | hot, read, len(x), workers=s.workers, hit_select=on)
    C = cached(ctx.cache, key, correction)
    out += product(C, np.concatenate([direct_e, x]))
    if shone is not None:
        out += shone
    return out


def _short_cells(ctx, elements, rays, xv, hot):
    """The :class:`.short_hits.ShortCells` of the gather's hits (none on elements ``hot``, which
    shine), cached on the geometry; None where no ray is short."""
    key = cache_key(geometry_key(elements) + through_key(elements) + np.packbits(hot).tobytes(),
                    ("short-cells", gather_count(ctx), SHORT_RATIO, SHORT_MOST))
    cells = cached(ctx.cache, key, lambda: ShortCells(elements, xv, rays()[1], SHORT_RATIO, exclude=hot))
    return cells if len(cells.keys) else None


def _reader(elements, xv, select, grid, short, before):
    """``read(y, pid, hits)`` for :func:`.gather.correction_matrix`: hits on abrupt elements
    (``select``) read their ``grid`` (nothing where it shines), short hits (``short``) their
    cell's point, column ``before`` on (after the grid's), unless they land on a grid's cell
    that shines."""
    params = patch_parameters(elements) if short is not None else None

    def read(y, pid, hits):
        cols, w = np.zeros((len(pid), 4), np.int64), np.zeros((len(pid), 4))
        on = select[pid]
        if on.any():
            cols[on], w[on] = grid.weights(y[on], pid[on])
        if short is not None:
            near, at = short.columns(elements, params, xv, hits)
            near &= ~on | (w.sum(axis=1) > 0)
            cols[near], w[near] = (before + at[near])[:, None], (1.0, 0.0, 0.0, 0.0)
        return cols, w
    return read


def _open_small_faces(ctx, elements, xv, nv, opened) -> np.ndarray:
    """(N,) bool: the faces of a scene too dense for elements (:func:`gathers_faces`) whose
    light the gather reads interpolated from their vertices' exact light, even where it changes
    abruptly: no larger than a cell of an abrupt element's grid (a quarter of the patch size
    across) and every corner fully seen (:func:`.sides.seen_fraction`: nothing stands within
    its reach). The vertices are as fine as such a grid; what the grid adds there is only that
    its points read what the scene sees of them, and that counts where something stands over a
    corner: a candle top's centre under its flame, which read the rim's light through its
    buried vertex and lit the flame's base 0.1 to 3 mm above (0.43 where Cycles has 0.17).

    Measured on ../shared/scenes' staircase (262,663 triangles; its 54,315 abrupt faces, 36,980
    of them small and open): every abrupt face with a 4 x 4 grid, 1.36 million points, took
    156 s of the grid's light under load; these interpolated, 428,000 points and 49 s, at
    16.25% raw RMS against Cycles instead of 16.45%. Nor does anything shine in such a scene
    (:func:`.shine.hot_elements`' budget 0): its 14,797 hot faces in 64 groups cost every vertex
    a form factor to each (179 s), and with the small faces not abrupt, 22,588 of them 661 s;
    read by the gather's rays instead the RMS went 16.45% -> 16.25% with the choice above."""
    size = float(ctx.settings.element_size or ctx.settings.patch_size or 1.0)
    small = np.sqrt(elements.areas) <= size / AbruptGrid.CELLS
    seen = seen_fraction(ctx, elements, xv, nv, corner_sharing(ctx.cache, elements, xv, nv, opened))
    return small & (seen.take(corner_columns(elements, ctx.cache)[0]).min(axis=0) >= 1.0)


def _gather_key(ctx, elements):
    return cache_key(geometry_key(elements) + through_key(elements), ("gather-elements", gather_count(ctx)))


def gathers_faces(ctx) -> bool:
    """Whether the patches themselves gather at their vertices as elements do: where the 'auto'
    detail size found the scene's faces finer than any detail size the elements' limit allows
    (``ctx.dense``: :func:`..mesh.sizes.fitted_detail` gave None; ../shared/scenes' staircase
    hall, 262,663 triangles), so no element is cut, yet the solve grouped the faces into
    clusters of one value each. Without a gather every face of a cluster showed that one value
    of the light reflected more than once: a candle's flame base 0.1 to 3 mm over its top, dark
    there under the flame, read the top's mean. Needs gather rays and Embree; not in place, nor
    for a lightmap (its texels read the corners' parts)."""
    s = ctx.settings
    return (bool(getattr(ctx, "dense", False)) and getattr(ctx, "clusters", None) is not None
            and s.gather_rays > 0 and s.output_mode != "in_place" and s.direct == "exact"
            and s.target != "lightmap" and embree_available())


def gather_finds_world(ctx) -> bool:
    """Whether the gather's rays also find the constant world's light at the element vertices:
    the gather runs (a detail size, gather rays, Embree) and the world is direct light
    (``ctx.direct.world``). Its rays that hit nothing are then what the vertices' sky rays would
    be (cosine rays from the same points: :func:`.hemisphere.sky_fraction`), so the vertices cast
    no sky rays of their own (:func:`gathered_sky`) and the gather casts the sky's count
    (:func:`gather_count`). Not where the sky asks for more than :data:`SKY_PER_GATHER` times
    the gather's rays (the quality levels ask twice): the gather's matrix and hits grow with its
    rays, the sky's rays cost no memory. Nor where the receivers see little sky (their
    ``F.sky`` below :data:`SKY_SHARE_OPEN` on the mean: an indoor level)."""
    s = ctx.settings
    F = getattr(ctx, "form_factors", None)
    sky = None if F is None else getattr(F, "sky", None)
    open_ = sky is None or not len(sky) or float(np.mean(sky)) >= SKY_SHARE_OPEN
    return (s.uses_elements() and 0 < s.gather_rays and s.sky_rays <= SKY_PER_GATHER * s.gather_rays
            and open_ and embree_available()
            and getattr(ctx, "direct", None) is not None and ctx.direct.world is not None)


def gather_count(ctx) -> int:
    """Rays per vertex of the gather: ``gather_rays``, or ``sky_rays`` where more and the gather
    finds the world (:func:`gather_finds_world`). On the bench's bunny (sun and sky), its 128
    gather rays made 0.77% of its 1.28% RMS against Cycles as noise (another ray pattern moved
    the light reflected once by 10%) and its 256 sky rays about a third of its bake: 256 rays
    that do both took it to 1.02%, the terrain from 0.32% to 0.20%, in as much CPU time. The
    same rays make the sky's and the gather's errors cancel: a ray that finds a wall instead
    of the sky reads the wall (the terrain's noise went from 0.24% to 0.05%)."""
    s = ctx.settings
    if gathers_faces(ctx):                # a dense scene's faces: a share of the setting
        return max(1, int(s.gather_rays) // DENSE_RAY_DIVISOR)
    return max(int(s.gather_rays), int(s.sky_rays)) if gather_finds_world(ctx) else int(s.gather_rays)


def gathered_sky(ctx, elements, xv, nv, pending=None):
    """(sky (V,), got): the cosine-weighted share of each element vertex's hemisphere where the
    gather's rays hit nothing (``G.sky``), waiting for the gather (``pending``, from
    :func:`start_gather`) if it is casting; ``got`` is what :func:`element_indirect` takes as
    its ``pending`` then (the gather collected)."""
    G, H = _gather_rays(ctx, elements, xv, nv, pending, hits=False)
    return np.asarray(G.sky, dtype=np.float64), (G, H)


def start_gather(ctx, elements, xv, nv):
    """The gather of :func:`_gather_rays` started on its forked workers, collected on a thread
    while the vertex stage goes on (the vertices' direct light, the open side, what shines: the
    work that does not read G); a :class:`.background.Background` for :func:`_gather_rays`, or
    None where G is cached or the gather would not run on forked workers (one worker, few rays,
    no Embree): then it is made where it is read, as before. The same G, bit for bit."""
    if ctx.settings.gather_rays <= 0 or not embree_available() or resolve_workers(ctx.settings.workers) <= 1:
        return None
    if ctx.cache is not None:
        key = _gather_key(ctx, elements)
        if ctx.cache.has(key) and ctx.cache.has(key + "-hits"):     # (not read here: a relight may need neither)
            return None
    return gather_matrix(elements, xv, nv, embree_scene(elements), rays=gather_count(ctx),
                         ticker=Ticker(None, ctx.cancelled), workers=ctx.settings.workers,
                         hits=True, background=True, share=_sharing(ctx, elements, xv, nv))


def _sharing(ctx, elements, xv, nv):
    """Which element vertices cast their gather rays together (:func:`.shared.corner_sharing`:
    a flat-shaded mesh's corners at one place), their elements buried in a solid
    (:func:`.sides.open_elements`) left out; None: each its own."""
    return corner_sharing(ctx.cache, elements, xv, nv, open_elements(ctx, elements))


def _gather_rays(ctx, elements, xv, nv, pending=None, hits=True):
    """The gather matrix G (with ``G.sky``) of ``elements`` at points ``xv`` and its rays' hits
    H (see :func:`.gather.gather_matrix`), cached together: both depend on geometry only.
    ``pending``: the gather started by :func:`start_gather` (its result is taken here), or
    (G, H) collected already (:func:`gathered_sky`).
    ``hits`` False: H only if it is made now, else None (read from the cache only when asked:
    it is the largest item of a bake, and only a new correction matrix reads it)."""
    if isinstance(pending, tuple):
        if pending[1] is not None or not hits:
            return pending
        pending = None                            # H was not made: from the cache (G came from it)
    key = _gather_key(ctx, elements)
    G = ctx.cache.get(key) if ctx.cache is not None else None
    H = ctx.cache.get(key + "-hits") if ctx.cache is not None and (hits or G is None) else None
    if G is None or (hits and H is None):
        if pending is not None:
            G, sky, H = pending.result(ctx.cancelled)
        else:
            G, sky, H = gather_matrix(elements, xv, nv, embree_scene(elements), rays=gather_count(ctx),
                                      ticker=Ticker(None, ctx.cancelled), workers=ctx.settings.workers,
                                      hits=True, share=_sharing(ctx, elements, xv, nv))
        G.sky = sky
        if ctx.cache is not None:
            ctx.cache.put(key, G)
            ctx.cache.put(key + "-hits", H)
    return G, H


def _interpolated(ctx, elements, field_v, xv, nv):
    """A patch-vertex field (per vertex of :func:`sided_mesh` patches, 3) at the element vertices
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
        w = ctx.settings.workers
        i1, uv1 = locate(ctx.patches, xv[rest], owner=owner_v[rest], normals=nv[rest], workers=w)
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
            i1[off], uv1[off] = locate(ctx.patches, xv[far], owner=owner_v[far], normals=nv[far], candidates=64,
                                       workers=w)
        idx[rest], uv[rest] = i1, uv1
        return idx, uv

    key = cache_key(geometry_key(ctx.patches) + geometry_key(elements), ("located",))
    sided = sided_mesh(ctx, ctx.patches)
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
