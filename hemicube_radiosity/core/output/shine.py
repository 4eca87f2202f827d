"""What shines instead of being gathered: small, bright areas lighting the vertices as lamps do.

A final gather's rays find a small, bright spot by chance (the ceiling above a pendant lamp's
back, the floor under a lamp): a few rays at one vertex, one more or fewer at its neighbour,
each carrying many times the light of the others, and the vertices blotch. Elements (or
cells of :class:`.abrupt.AbruptGrid`) brighter than :data:`HOT` times the mean
(:func:`mean_light`) are chosen by :func:`hot_elements` and light the output vertices by their
form factor and shadow rays instead (:func:`shine`, through :func:`.emitters.emitter_transport`):
(V, 3) radiance arriving, cached as a transport (a relight casts no ray).
"""
from __future__ import annotations

import hashlib

import numpy as np

from ..light.emitters import emitter_transport, transport_product, transposed_transport
from ..mesh.clusters import connected_components
from ..mesh.patches import PatchSet, poly_geometry
from ..util.colour import LUMA
from ..util.sampling import place_keys
from ..rays import occluder
from ..runtime.cache import array_key, cache_key, cached, geometry_key
from ..runtime.progress import Ticker
from ..util.unique import unique_ints, unique_rows
from .corners import corner_columns, corner_sum

__all__ = ["HOT", "BUDGET", "mean_light", "hot_elements", "shine"]


#: What shines instead of being gathered (:func:`.indirect._gathered`): reflected direct light
#: brighter than this many times its mean over what the scene sees (:func:`mean_light`). At 2
#: the Cornell box shone a third more elements and its RMS error against Cycles rose from 1.16%
#: to 1.42% (each group shines its mean); at 4 the pendant-lit room and a lamp-lit floor kept
#: more of their bright spot to the gather's rays.
HOT = 3.0


def mean_light(elements, values_v, opened=None, cache=None) -> float:
    """The mean luminance of the vertex field ``values_v`` (V, 3) over the surfaces the scene
    sees: each element's corner mean, weighted by its area and ``opened`` (N,) (None: all). Not
    over vertices: a face cut into many, vertices repeated along a face's edges, a floor
    running on under a block, would each weigh in. ``cache``: where :func:`corner_columns`
    are kept."""
    cols, quad, count = corner_columns(elements, cache)[:3]
    Y = corner_sum(np.asarray(values_v, dtype=np.float64) @ LUMA, cols, quad) / count
    w = elements.areas if opened is None else elements.areas * opened
    total = float(w.sum())
    return float((w * Y).sum()) / total if total > 0 else float(Y.mean())


#: Groups that shine at most (:func:`hot_elements`), elements' and abrupt grids' cells together:
#: each costs every output vertex a form factor and shadow rays, so the output's cost follows
#: the vertices, not how many bright areas the light makes. sauer_pandora (six lamps in a
#: level of many rooms) shone 64 groups of elements and 401 of cells: 465 transports per
#: vertex, 2,191 s of a bake forecast at 250.
BUDGET = 64


#: First-pass rays a chunk of :func:`shine`'s transport casts at most: its chunks of points are
#: the transport's largest (4,096) for up to :data:`BUDGET` groups of 4 rays. With the
#: transport's default (a quarter of this) zdm2's 64 groups came 1,024 points a chunk, and the
#: contours' many small steps per chunk and group cost 15% more CPU (T is the same, bit for bit:
#: every chunk's rows are its points' own).
CHUNK_RAYS = 1 << 20


def hot_elements(ctx, elements, light_v, bar, smooth, opened=None, budget=BUDGET, grid=None):
    """(hot (N,) bool, radiance (h, 3)): of the elements whose direct light changes ``smooth``-ly,
    those whose direct light arriving (the mean of ``light_v`` (V, 3) over their corners)
    passes the luminance ``bar`` (:data:`HOT` times its :func:`mean_light`), with
    ``radiance`` their reflectivity times it (the hot ones', in order): the spot a pendant lamp's back lights on a
    ceiling, the floor under a lamp, a block's top beside it. A gather's rays find such a spot
    by chance, a few at a vertex and one more or fewer at its neighbour: each ray there
    carries many times the light of the others, so the vertices blotch (a room whose lamp
    hangs 0.3 m under the ceiling: the walls 6.4% rough, by the bench's smoothness figure,
    against 3.3% for Cycles at 4,096 samples; 0.9% shining). Shining, they light every vertex
    by their form factor.

    Only elements the scene sees (``opened``, :func:`.sides.open_elements`: not the ceiling right
    above a lamp's back), and at most ``budget`` groups (:func:`_shine_groups`), the brightest
    (their area-weighted mean light arriving), counting the hot cells of ``grid``
    (:class:`.abrupt.AbruptGrid` or None) as :func:`shine` groups them: each group costs every
    vertex a form factor and shadow rays, and a scene lit mostly in one area should not pay that
    for hundreds of them. What is left out is gathered as before (the grid's cells left out
    are no longer ``grid.hot``: the grid is changed in place)."""
    # the corners summed in order, one at a time (as the (N, 4, 3) array's sum over its corners
    # adds them, bit for bit), not gathered into that array and summed along its short axis
    cols, quad, count, quad3, count3 = corner_columns(elements, ctx.cache)
    light_v = np.asarray(light_v, dtype=np.float64)
    arriving = corner_sum(light_v, cols, quad, quad3) / (count3 if light_v.shape[1] == 3 else count[:, None])
    hot = smooth & (arriving @ LUMA > bar)
    if opened is not None:
        hot &= opened > 0
    ids = np.flatnonzero(hot)
    cells = np.flatnonzero(grid.hot) if grid is not None else np.zeros(0, np.int64)
    groups = _shine_groups(ctx, elements, ids) if ids.size else np.zeros(0, np.int64)
    a, Y = elements.areas[ids], arriving[ids] @ LUMA
    if cells.size:
        parent, cell_a, cell_Y = grid.hot_parts(cells)
        groups = _with_cell_groups(ctx, elements, groups, parent)
        a, Y = np.concatenate([a, cell_a]), np.concatenate([Y, cell_Y])
    if groups.size and groups.max() >= budget:
        mean = np.bincount(groups, weights=a * Y) / np.maximum(np.bincount(groups, weights=a), 1e-300)
        # ranked to 9 digits of the brightest: groups alike but for rounding (a symmetric room)
        # keep their order when a relight scales the light, and the relight finds its shine kept
        mean = np.round(mean / max(float(mean.max()), 1e-300), 9)
        keep = np.isin(groups, np.argsort(-mean, kind="stable")[:budget])
        hot[ids[~keep[:ids.size]]] = False
        if cells.size:
            grid.hot[cells[~keep[ids.size:]]] = False
        ids = np.flatnonzero(hot)
    return hot, elements.rho[ids] * arriving[ids]


def _shine_groups(ctx, elements, ids, scale=1.0) -> np.ndarray:
    """(M,) group of each element ``ids``: connected elements of one object in one cell of
    ``scale`` times the patch size shine as one (:func:`shine`). Elements touch where they
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


def _with_cell_groups(ctx, elements, groups, parent) -> np.ndarray:
    """``groups`` (M,) of shining elements followed by the groups of cells of the elements
    ``parent`` (c,), numbered after them: the cells of one element group by that element, in
    half-patch cells (a lamp's glow seen beside the lamp and hidden behind it across the lamp
    must not share one group's visibility: a patch-size group made the walls of a 1 m room with
    a lamp 2 mm under its ceiling 0.5% too bright)."""
    first, inv = unique_ints(parent, return_inverse=True)
    after = int(groups.max()) + 1 if groups.size else 0
    return np.concatenate([groups, after + _shine_groups(ctx, elements, first, 0.5)[inv.reshape(-1)]])


def shine(ctx, elements, ids, radiance, xv, nv, cells=None):
    """(V, 3) light arriving at the points ``xv`` from elements ``ids`` shining ``radiance``
    (M, 3) toward their front, with shadows: grouped by object and patch-size cell so the
    shadow rays follow a few areas, not every element (:func:`_shine_groups`,
    :func:`.emitters.emitter_transport`). ``cells``: (elements (c,), corners (c, 4, 3), radiance
    (c, 3)), parts of elements that shine by themselves (:meth:`.abrupt.AbruptGrid.hot_cells`),
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
        groups = _with_cell_groups(ctx, elements, groups, parent)
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
    keys = _group_keys(ctx, groups, centers)
    # the elements' geometry and the points hashed once per array (a relight's are cached)
    key = cache_key(shape + groups.tobytes() + power.tobytes() + array_key(xv),
                    ("shine", samples, len(verts) - V, len(every), "keyed"))
    T = cached(ctx.cache, key, lambda: emitter_transport(
        source, xv, nv, np.arange(len(every)), scene=occluder(elements), samples=samples, groups=groups,
        workers=ctx.settings.workers, ticker=Ticker(None, ctx.cancelled), chunk_rays=CHUNK_RAYS,
        group_keys=keys))
    G = int(groups.max()) + 1
    L = np.stack([np.bincount(groups, weights=area * L[:, k], minlength=G) for k in range(3)], 1) \
        / np.bincount(groups, weights=area, minlength=G)[:, None]
    # kept transposed beside T in memory: a relight neither transposes nor casts it
    Tt = cached(ctx.cache, key + "-t", lambda: transposed_transport(T), disk=False)
    return transport_product(Tt, L, transposed=True)


def _group_keys(ctx, groups, centers) -> np.ndarray:
    """(G,) uint64: what each of the shining ``groups`` (n,) draws its shadow rays' targets from
    (:func:`.emitters.emitter_transport`'s ``group_keys``): the lowest corner of its pieces'
    ``centers`` (n, 3), to 2^-20 of the patch size. A group's few targets are seen alike from a
    whole floor far off; drawn from one stream for all, they moved when any group came or went
    anywhere (12 more elements of a block's top shining moved the targets of a lamp's glow on
    the ceiling, 4 a group, behind the lamp: the far floor 0.8% brighter,
    tests/core/test_hard_cases.py)."""
    G = int(groups.max()) + 1
    lo = np.full((G, 3), np.inf)
    np.minimum.at(lo, groups, centers)
    return place_keys(lo, 0.0, float(ctx.settings.patch_size or ctx.settings.element_size or 1.0) * 2.0 ** 12)
