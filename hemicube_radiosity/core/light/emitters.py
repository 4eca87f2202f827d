"""Direct light from emissive patches, exact in geometry, at any points (patch centres, vertices).

The hemi-cube samples a small bright emitter with a handful of pixels (the paper's own
aliasing warning), and the patch-centre approximation blurs shadows to the patch size. Direct
light is most of the detail in a bake, so it is computed apart:

    D(x) = sum_e L_e * F(x -> e) * V(x, e)

with F the exact unoccluded point-to-polygon form factor (Lambert's contour formula, after
clipping the emitter to the receiver's horizon: :func:`.polygon_ff.polygon_form_factors`) and V
the visible share of that form factor, from stratified sample points on the emitter (shadow
rays, :mod:`.rays`), each weighted by its part of F (cos at x times cos at the emitter over the
squared distance): a large lamp half hidden from a point near it is dimmed by the part of F it
loses, not by the part of its area. D is the radiance arriving from the emitters, so a receiver
with reflectivity rho reflects ``rho * D`` of it; the radiosity solve then carries only the
reflected light (see :mod:`.pipeline`), never the emitters' E.
"""
from __future__ import annotations

import hashlib

import numpy as np

from ..runtime.cache import Memo
from ..util.geometry import bilinear
from ..util.sampling import jittered_grid, keyed_uniforms
from .outline import GroupOutline
from .polygon_ff import GROUP_LOOP, group_form_factors, in_front, polygon_form_factors
from ..runtime.parallel import ordered_map, resolve_workers
from ..mesh.patches import PatchSet
from ..util.spatial import morton_order
from ..rays import ray_offsets
from .transmit import visibility

#: Shadow rays (points x emitter units x samples) from which a transport with several workers
#: runs on forked processes: below, forking costs more than it saves.
PROCESS_RAYS = 1 << 20

__all__ = ["emitter_transport", "emitter_direct", "apply_transport", "transport_product", "transposed_transport",
           "vertex_frames"]


def vertex_weights(patches: PatchSet, weights=None):
    """How :func:`vertex_frames` averages over the patches around each vertex: (patch p (I,),
    vertex v (I,), weight w (I,), weight sum per vertex (V, 1)) over every patch corner I;
    ``weights`` (N,) or None (all 1), a vertex whose patches all weigh 0 weighing them all."""
    V = len(patches.verts)
    p, c = np.nonzero(patches.polys >= 0)
    v = patches.polys[p, c]
    w = np.ones(len(p)) if weights is None else np.asarray(weights, dtype=np.float64)[p]
    total = np.bincount(v, weights=w, minlength=V)
    w = np.where(total[v] > 0, w, 1.0)
    return p, v, w, np.maximum(np.bincount(v, weights=w, minlength=V), 1e-300)[:, None]


def vertex_frames(patches: PatchSet, inset=1e-2, weights=None):
    """Per patch vertex: an evaluation point, unit normal and reflectivity.

    Normal and reflectivity are the means over the patches around the vertex. The point is the
    vertex moved ``inset`` of the way toward the mean of those patches' centres: exactly at a
    corner the walls that meet there pass through the point and Lambert's formula cannot see
    them, while the radiosity on a wall is continuous up to the corner; the inset point gives
    that limit. ``weights`` (N,) >= 0: how much each patch counts in those means (a patch
    buried under a block, 0: a floor vertex on the block's outline takes the open floor's
    limit, not a point inside the block); a vertex whose patches all weigh 0 takes them all.
    On a convex curve (a smooth cylinder's vertex, shared by faces that meet at an angle) the
    centres' mean lies inside the solid: the point is then lifted along the normal onto the
    front of every patch that counts (the sunlit side of a smooth cylinder read no sun: its
    shadow rays started inside it).
    """
    V = len(patches.verts)
    p, v, w, total = vertex_weights(patches, weights)

    def mean(a):
        return np.stack([np.bincount(v, weights=w * a[p, k], minlength=V) for k in range(a.shape[1])], 1) / total

    n = mean(patches.normals)
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    x = patches.verts + inset * (mean(patches.centers) - patches.verts)
    # how far behind each counting patch's plane the point lies, along the vertex normal
    behind = np.einsum("ij,ij->i", patches.centers[p] - x[v], patches.normals[p])
    facing = np.einsum("ij,ij->i", n[v], patches.normals[p])
    size = float(np.linalg.norm(np.ptp(patches.verts, axis=0))) if V else 1.0
    up = (w > 0) & (behind > 1e-12 * size) & (facing > 0.1)
    if up.any():
        lift = np.zeros(V)
        np.maximum.at(lift, v[up], behind[up] / facing[up])
        x = x + lift[:, None] * n
    return x, n, mean(patches.rho)


def _emitter_samples(corners, samples, rng):
    """(M, S, 3) stratified points on each emitter patch (bilinear map of jittered grid cells)."""
    u, v = jittered_grid(rng, len(corners), samples)
    return bilinear(corners[:, None], u[..., None], v[..., None])


def _group_samples(corners, areas, groups, samples, rng, keys=None):
    """(G, S, 3) points spread over each group of emitter patches by area, and (G, S) the patch
    (row of ``corners``) each lies on.

    The group's patches are put in Morton order of their centres (within the group's bounding
    box) and its area is cut into S strata along that order, one random point in each: a run of
    the order is a compact region, so the strata are spread over the group in both directions,
    not in bands. The points that fall on one patch lie on a jittered grid over it (m of its
    g x g cells, g = ceil(sqrt m), evenly spaced from a random cell: each point is uniform over
    the patch), so a group of one patch and S = 16 gets the 4 x 4 grid a patch shining alone
    has. (Random points within the patches, strata in the order the patches came: a lamp cut
    into 9 patches, 16 rays, lit a soft shadow with 2.9% RMS error.)

    ``keys`` (G,) uint64 (None: every number from ``rng``): each group draws its numbers from
    its own key (:func:`..util.sampling.keyed_uniforms`, salted by one draw of ``rng``), so a
    group's points depend on that group alone, not on how many others there are or where their
    points fell (one stream for all let a change of one group move every other group's points:
    :func:`..output.shine.shine`'s glow around a lamp, 4 points a group seen alike from a whole
    far floor, lit it 0.8% brighter when 12 more elements of a block's top shone)."""
    G = int(groups.max()) + 1
    if keys is not None:
        salt = np.uint64(rng.integers(0, 2 ** 63))
        drawn = keyed_uniforms(np.asarray(keys, np.uint64) ^ salt, 4 * samples)
        drawn = drawn.reshape(G, 4, samples).transpose(1, 0, 2)          # t, offset, u, v: (G, S) each
    order = morton_order(corners.mean(axis=1), groups, G)
    cum = np.cumsum(areas[order])
    start = np.searchsorted(groups[order], np.arange(G))
    before = np.where(start > 0, cum[start - 1], 0.0)
    total = np.bincount(groups, weights=areas, minlength=G)
    jitter = rng.uniform(0, 1, (G, samples)) if keys is None else drawn[0]
    t = before[:, None] + total[:, None] * (np.arange(samples)[None] + jitter) / samples
    pos = np.minimum(np.searchsorted(cum, t.ravel(), side="right"), len(cum) - 1)
    # the points on one patch are a run of ``pos`` (t rises along each group, the groups in order)
    n = pos.size
    new = np.r_[True, pos[1:] != pos[:-1]]
    first = np.flatnonzero(new)
    run = np.cumsum(new) - 1
    rank = np.arange(n) - first[run]
    m = np.diff(np.r_[first, n])[run]
    g = np.ceil(np.sqrt(m)).astype(np.int64)
    cells = g * g
    at = rng.uniform(0, 1, first.size) if keys is None else drawn[1].ravel()[first]
    offset = np.floor(at * cells[first]).astype(np.int64)
    cell = (offset[run] + rank * cells // m) % cells
    ju, jv = rng.uniform(0, 1, (2, n)) if keys is None else (drawn[2].ravel(), drawn[3].ravel())
    u = ((cell // g + ju) / g).reshape(G, samples, 1)
    v = ((cell % g + jv) / g).reshape(G, samples, 1)
    k = order[pos].reshape(G, samples)
    return bilinear(corners[k], u, v), k                              # corners[k]: (G, S, 4, 3)


def _visible_fraction(scene, origins, targets, normals, target_normals):
    """Which of the segments origins (r, 3) -> targets (r, S, 3) nothing blocks, each weighted
    by its part of the form factor: cos at the point (its unit ``normals`` (r, 3); 0 below its
    horizon) times cos at the target (``target_normals`` (r, S, 3), the emitting side's; 0
    where the target faces away: a curved group's far side sends the point nothing, and the
    group itself blocks the ray to it) over the squared length, squared again for the
    unnormalised direction. (visible weight (r,), weight (r,), none blocked (r,), all blocked
    (r,)): the weights' ratio is the visible share of the emitter's form factor, not of its
    area."""
    S = targets.shape[1]
    d = targets - origins[:, None, :]
    seen = visibility(scene, np.repeat(origins, S, axis=0), d.reshape(-1, 3),
                      np.full(len(origins) * S, 1 - 1e-4)).reshape(-1, S)
    r2 = np.einsum("rsk,rsk->rs", d, d)
    w = np.maximum(np.einsum("rsk,rk->rs", d, normals), 0.0) * np.maximum(-np.einsum("rsk,rsk->rs", d, target_normals), 0.0) \
        / np.maximum(r2 * r2, 1e-300)
    if seen.dtype == bool:
        blocked = ~seen
        return np.einsum("rs,rs->r", w, 1.0 - blocked), w.sum(axis=1), ~blocked.any(axis=1), blocked.all(axis=1)
    return np.einsum("rs,rs->r", w, seen), w.sum(axis=1), (seen >= 1).all(axis=1), (seen <= 0).all(axis=1)


def _sample_drawer(patches, em, corners, groups, units, eps, keys=None):
    """``draw(count, rng)``: (units, count, 3) shadow-ray targets on the emitters (per patch, or
    spread over each group by area), from the random stream ``rng``, and (units, count, 3) the
    unit normals of the patches they lie on (a curved group's targets face their own ways).

    The points are lifted off the emitter along its normal (a group's area-weighted mean
    normal) by ``eps`` (M,) of each emitter patch (a group: its largest): a shadow ray that
    ends exactly on a surface would graze it at float32 precision (a wall lighting the floor at
    their shared edge). ``keys``: as :func:`_group_samples` takes them."""
    normals = patches.normals[em]
    if groups is None:
        def draw(count, rng):
            y = _emitter_samples(corners, count, rng) + eps[:, None, None] * normals[:, None, :]
            return y, np.broadcast_to(normals[:, None, :], y.shape)
        return draw
    lift = np.zeros((units, 3))
    np.add.at(lift, groups, patches.normals[em] * patches.areas[em, None])
    size = np.zeros(units)
    np.maximum.at(size, groups, eps)
    lift *= size[:, None] / np.maximum(np.linalg.norm(lift, axis=1, keepdims=True), 1e-300)

    def draw(count, rng):
        y, k = _group_samples(corners, patches.areas[em], groups, count, rng, keys)
        return y + lift[:, None, :], normals[k]
    return draw


def _share(seen, weight):
    """The visible share ``seen / weight``: 0 where no segment has any weight (every target below
    the point's horizon, where the horizon-clipped form factor is tiny)."""
    return np.where(weight > 0, seen / np.where(weight > 0, weight, 1.0), 0.0)


def _outline(corners, groups, em_normals):
    """:meth:`.outline.GroupOutline.of` the emitter groups, kept for the :data:`OUTLINES_KEPT`
    most recent emitter sets (by the bytes of their corners, groups and normals): a bake's
    transports ask for the same lamps again and again, and a dense lamp's outline is not free."""
    h = hashlib.sha256()
    for a in (corners, groups, em_normals):
        a = np.ascontiguousarray(a)
        h.update(str(a.dtype).encode() + str(a.shape).encode() + a.tobytes())
    return _OUTLINES.get(h.digest(), lambda: GroupOutline.of(corners, groups, em_normals))


#: Emitter outlines :func:`_outline` keeps.
OUTLINES_KEPT = 4
_OUTLINES = Memo(OUTLINES_KEPT)


class _Transport:
    """The work of one :func:`emitter_transport` call, in chunks of ``step`` points.

    ``points``, ``normals`` (P, 3) float64; ``corners`` (M, 4, 3) and ``em_normals`` (M, 3) of
    the emitter patches; ``groups`` (M,) int64 or None; ``eps`` (P,) the points' rays' start
    offsets off their surfaces (:func:`.rays.ray_offsets`); ``draw`` from :func:`_sample_drawer`; ``ys`` (units, S, 3) the first
    ``samples`` targets per emitter unit (from ``seed``) and ``extra`` the penumbra's ``refine``
    times as many more (their own stream), ``yn`` and ``extra_n`` their patches' normals, all
    shared by every point: T is the same for any chunk
    size and whoever computes the chunks (they are cut to share the work evenly), and
    neighbouring points, whichever chunk they fall in, aim at the same targets (a penumbra
    varies smoothly, and two coplanar faces read the same light).
    """

    def __init__(self, points, normals, corners, em_normals, groups, scene, refine, eps, draw,
                 samples, chunk_rays, seed=0):
        self.points, self.normals, self.corners, self.em_normals = points, normals, corners, em_normals
        self.groups, self.scene, self.refine, self.eps, self.draw = groups, scene, refine, eps, draw
        self.seed = seed
        # the groups' outlines once, not per chunk (a few straight edges per group, see GroupOutline)
        self.outline = None if groups is None else _outline(corners, groups, em_normals)
        self.ys, self.yn = draw(samples, np.random.default_rng(seed))    # (units, S, 3) twice
        self.S = self.ys.shape[1]
        units = self.ys.shape[0]
        self.step = max(1, min(len(points), chunk_rays // max(units * self.S, 1), 4096))
        self.extra, self.extra_n = draw(refine * self.S, np.random.default_rng((seed, 1))) if refine > 0 else (None, None)

    def first_pass(self, s):
        """Form factors of the chunk starting at point ``s`` and the visible fraction from the
        first ``samples`` rays: (s, F, pi, mi, o, (v, seen, weight, n), penumbra) with F (p, units)
        unshadowed, (pi, mi) its nonzero entries, o (r, 3) the ray origins, v (r,) the visible
        shares of F (seen / weight: :func:`_visible_fraction`'s sums, for the penumbra's rays to
        add to), n (r, 3) the points' normals and penumbra (r,) bool where some rays pass and some
        do not (None: nothing to refine)."""
        x = self.points[s:s + self.step]
        nx = self.normals[s:s + self.step]
        if self.groups is not None and self.scene is not None:
            return self._rays_first(s, x, nx)
        if self.groups is None:
            F = polygon_form_factors(x, nx, self.corners, self.em_normals)                # (p, M)
        else:
            F = group_form_factors(x, nx, self.corners, self.groups, self.em_normals, self.outline)  # (p, G)
        if self.scene is None:
            return s, F, None, None, None, None, None
        pi, mi = np.nonzero(F > 0)
        if not pi.size:
            return self._none_cast(s, F)
        return self._passed(s, F, pi, mi, *self._first_rays(s, x, nx, pi, mi))

    def _first_rays(self, s, x, nx, pi, mi):
        """(o (r, 3), n (r, 3), seen, weight, lit, dark): the first ``samples`` rays of the pairs
        (pi, mi) (points of the chunk at ``s``, emitter units), :func:`_visible_fraction`'s."""
        # rows by ``take``: indexing a 2-D array with an index array is several times slower
        o = x.take(pi, axis=0) + self.eps[s:s + self.step].take(pi)[:, None] * nx.take(pi, axis=0)  # (r, 3)
        n = nx.take(pi, axis=0)
        return (o, n) + tuple(_visible_fraction(self.scene, o, self.ys.take(mi, axis=0), n,
                                                self.yn.take(mi, axis=0)))

    def _passed(self, s, F, pi, mi, o, n, seen, weight, lit, dark):
        """:meth:`first_pass`'s result for the pairs (pi, mi) and their first rays."""
        # exactly 1 where every ray passes and 0 where none does (a ratio of sums rounds)
        v = np.where(lit, 1.0, np.where(dark, 0.0, _share(seen, weight)))
        # penumbra: where some rays pass and some do not, cast ``refine`` times more
        part = ~lit & ~dark
        return s, F, pi, mi, o, (v, seen, weight, n), part if self.refine > 0 and part.any() else None

    @staticmethod
    def _none_cast(s, F):
        """:meth:`first_pass`'s result where no pair has a ray to cast."""
        z = np.zeros(0, np.int64)
        return s, F, z, z, np.zeros((0, 3)), (np.zeros(0), np.zeros(0), np.zeros(0), np.zeros((0, 3))), None

    def _rays_first(self, s, x, nx):
        """:meth:`first_pass` for groups: the first rays first, for every pair whose point is in
        front of the group (:func:`.polygon_ff.in_front`: the pairs of F > 0 and a few more),
        then the contour integral only for the pairs some ray reaches. In a level of many
        rooms most of a point's pairs are walls away (sauer_pandora: 2.5% of them lit), and
        the contours were nine tenths of the time; the rays are a tenth of a contour's cost.
        T is the same, bit for bit: a pair no ray reaches is 0 either way, and every other
        pair's F, rays and penumbra are as they were."""
        front = in_front(x, self.outline)
        pi, mi = np.nonzero(front[0] > 0)
        if not pi.size:
            return self._none_cast(s, np.zeros(front[0].shape))
        o, n, seen, weight, lit, dark = self._first_rays(s, x, nx, pi, mi)
        reached = np.zeros(front[0].shape, bool)
        reached[pi[~dark], mi[~dark]] = True
        F = group_form_factors(x, nx, self.corners, self.groups, self.em_normals, self.outline,
                               pairs=reached, front=front)
        on = F[pi, mi] > 0                               # the pairs the contours' path would cast
        return self._passed(s, F, *(a[on] for a in (pi, mi, o, n, seen, weight, lit, dark)))

    def chunk(self, s):
        """(s, T rows (p, units) float32) of the chunk starting at point ``s``: its
        :meth:`first_pass`, then ``refine * S`` more rays where it has a penumbra, aimed at
        the penumbra's shared targets."""
        s, F, pi, mi, o, v, part = self.first_pass(s)
        if self.scene is None:
            return s, F.astype(np.float32)
        v, seen, weight, n = v
        if part is not None:
            on = np.flatnonzero(part)
            more, w, _, _ = _visible_fraction(self.scene, o.take(on, axis=0), self.extra.take(mi[on], axis=0),
                                              n.take(on, axis=0), self.extra_n.take(mi[on], axis=0))
            v[on] = _share(seen[on] + more, weight[on] + w)
        vis = np.zeros(F.shape)
        vis[pi, mi] = v
        return s, (F * vis).astype(np.float32)

    def run(self, T, workers, ticker):
        """Fill T (P, units) chunk by chunk on ``workers`` (resolved), ticking ``ticker``.

        Chunks are independent (:meth:`chunk`), so T is the same for any worker count. With
        more than one worker and enough rays to pay for a fork, the chunks run on forked
        processes (:func:`.parallel.ordered_map`): the many small NumPy steps of the contour
        integrals hold the GIL, so on threads the chunks did not scale; on processes they do.
        (embreex itself lets go of the GIL while it casts: casts on two threads scale.)
        Otherwise on threads.

        Grouped emitters (a few groups, each one contour over its outline) are mostly rays, and
        run on threads: no fork, no copy-on-write, nothing pickled (on a dense mesh threads were
        as fast as forked processes, or a little faster). Patches shining one by one stay
        forked: a lamp cut into many patches is contour integrals, which forked processes ran
        far faster than threads."""
        P, step = len(self.points), self.step
        rays = P * self.ys.shape[0] * max(self.S, 1) * (self.scene is not None)
        if workers > 1:          # a few chunks a worker, so that they end together
            step = self.step = max(1, min(step, -(-P // (CHUNKS_PER_WORKER * workers))))
        starts = list(range(0, P, step))
        mostly_rays = self.groups is not None and self.ys.shape[0] <= GROUP_LOOP
        forked = workers > 1 and len(starts) > 1 and rays >= PROCESS_RAYS and not mostly_rays
        if forked and self.scene is not None:     # Embree commits its BVH on the first query:
            self.scene.occluded(self.points[:1], self.normals[:1], np.ones(1))  # here, before the fork
        done = 0
        for s, F in ordered_map(self.chunk, starts, workers, processes=forked):
            T[s:s + step] = F
            done = min(s + step, P)
            if ticker is not None:
                ticker.tick(done, P)


#: Chunks per worker a transport on several workers is cut into (they take different times: a
#: penumbra casts four times the rays), so the workers end close together.
CHUNKS_PER_WORKER = 4


def emitter_transport(patches: PatchSet, points, normals, emitters, *, scene=None, samples=16,
                      seed=0, refine=3, chunk_rays=1 << 18, ticker=None, groups=None,
                      workers=1, eps=None, group_keys=None) -> np.ndarray:
    """(P, M) float32 ``T[p, m] = F(x_p -> e_m) * V(x_p, e_m)``: how much of emitter patch m's
    radiance arrives at point p. Geometry only, so a change of emission strength or colour is
    ``T @ L`` and needs no rays.

    ``scene``: anything with ``occluded(origins, directions, tfar)`` (Embree scene or NumPy BVH,
    see :func:`.rays.occluder`) for shadow rays; None means no shadows. ``samples``: shadow
    rays per point and emitter patch (stratified over the patch, seeded); where they disagree
    (a penumbra) ``refine * samples`` more are cast, so soft shadow edges are not noisy while
    fully lit or fully shadowed points cost only ``samples``.
    ``groups``: (M,) int, emitter patches that shine as one (a lamp modelled as many faces):
    T is then (P, G), F summed over each group's patches and ``samples`` rays spread over the
    whole group by area, so the cost follows the lamps, not their faces.
    ``workers``: workers computing chunks of points at once (0 = every core, 1 = serial; forked
    processes for large transports, see :meth:`_Transport.run`); T is bit-identical for any
    count. ``ticker`` is polled after every chunk. ``chunk_rays``: first-pass rays a chunk casts
    at most (at most 4,096 points a chunk): the chunks are independent, so T is the same for any
    size. A quarter million keeps a chunk's temporaries in the heap's kept pages: a million (a dense
    mesh's lamp groups) faulted many fresh pages in. ``eps`` (P,): how far the points' shadow
    rays start off their surfaces (default :func:`.rays.ray_offsets`). ``group_keys`` (G,)
    uint64 or None: each group's targets drawn from its own key (:func:`_group_samples`).
    """
    points = np.asarray(points, dtype=np.float64)
    normals = np.asarray(normals, dtype=np.float64)
    em = np.asarray(emitters, dtype=np.int64)
    units = em.size if groups is None else int(np.max(groups, initial=-1)) + 1
    T = np.zeros((len(points), units), dtype=np.float32)
    if em.size == 0 or len(points) == 0:
        return T
    if groups is not None:
        groups = np.asarray(groups, dtype=np.int64)
    corners = patches.corners(em)
    eps = ray_offsets(patches, points, normals) if eps is None else np.asarray(eps, dtype=np.float64)
    draw = _sample_drawer(patches, em, corners, groups, units, ray_offsets(patches, owner=patches.owner[em]),
                          None if groups is None else group_keys)
    work = _Transport(points, normals, corners, patches.normals[em], groups, scene, refine, eps, draw,
                      samples, chunk_rays, seed)
    work.run(T, resolve_workers(workers), ticker)
    return T


def emitter_direct(patches: PatchSet, points, normals, *, scene=None, samples=16, seed=0,
                   emitters=None, ticker=None) -> np.ndarray:
    """(P, 3) radiance arriving directly from the emissive patches at ``points`` with ``normals``
    (``emitters`` default: every patch with emission > 0). See :func:`emitter_transport`."""
    em = np.flatnonzero(patches.emitting()) if emitters is None else np.asarray(emitters)
    T = emitter_transport(patches, points, normals, em, scene=scene, samples=samples, seed=seed,
                          ticker=ticker)
    return apply_transport(T, patches.emission[em])


def apply_transport(T, L):
    """``T @ L`` for a (P, M) transport and (M, k) emitter radiances, without BLAS: a BLAS
    product starts threads that, on a busy machine (or inside Blender's own threads), turned
    a product of milliseconds into seconds of waiting."""
    return np.einsum("pm,mk->pk", T, np.asarray(L, dtype=np.float64), dtype=np.float64)


def transport_product(T, L, transposed=False) -> np.ndarray:
    """``T @ L`` for a dense (P, M) transport (float32) and (M, 3) radiances, in float64, equal
    bit for bit to :func:`apply_transport` (each sum runs over m in order; with one
    band einsum sums otherwise, to the last bit) and, without BLAS either, several times
    faster: the sums run down the rows of T transposed, whole rows at a time (einsum's
    mixed-precision loop is the slow part). ``transposed``: ``T`` is given as
    :func:`transposed_transport` made it, (M, P) float64 (kept with a cached transport, so a
    relight neither transposes nor casts it), the same sums."""
    L = np.asarray(L, dtype=np.float64)
    Tt = np.asarray(T) if transposed else np.ascontiguousarray(np.asarray(T).T)
    if Tt.shape[0] == 0:
        return np.zeros((Tt.shape[1], L.shape[1]))
    return np.stack([np.add.reduce(Tt * L[:, k, None], axis=0) for k in range(L.shape[1])], 1)


def transposed_transport(T) -> np.ndarray:
    """(M, P) float64, contiguous: a (P, M) transport as :func:`transport_product` reads it with
    ``transposed=True`` (float32 to float64 is exact: the same products)."""
    return np.ascontiguousarray(np.asarray(T).T, dtype=np.float64)
