"""Final gather: the light arriving at a point from a coarse patch solution, by cosine rays.

A coarse patch solution is accurate in the power each patch reflects but blurs where light
changes. The finer output elements gather it instead of interpolating it: from each element
vertex, cosine-distributed rays of one even pattern (:func:`.hemisphere.cosine_lattice`) find the
surface they see, and read there the bilinear interpolation of the patches' reflected radiance
(``R = B - E``, at patch vertices).
Their mean is the radiance arriving at the point from reflected light (the emitters' own light
is added exactly by :mod:`.direct`). Rays that see no surface see the world's radiance; rays
that hit the back of a patch see nothing.
"""
from __future__ import annotations

from contextlib import closing
from dataclasses import dataclass
from functools import partial

import numpy as np

from ..util.geometry import in_frames, tangent_frames
from ..runtime.background import Background
from ..runtime.forked import release_tail, shared_array
from ..runtime.parallel import ordered_map, resolve_workers, shares, started_map
from ..mesh.patches import PatchSet
from ..rays import ray_offsets
from ..hemisphere import cosine_lattice
from ..util.sparse import CSR, nonzero_entries, product, summed_entries
from ..util.unique import unique_ints
from .shared import cast_shared
from .through import Through, cast_through

#: Rays (points x rays per point) from which :func:`gather_matrix` casts on forked processes
#: with more than one worker (:mod:`.parallel`); below, threads (None: always threads). On
#: a dense mesh the gather alone runs faster forked than on threads (``bench_parallel.py
#: --gather``, ``docs/performance.md`` 'Both cores'); in whole bakes the difference is small.
PROCESS_RAYS = 1 << 20

__all__ = ["final_gather", "gather_matrix", "apply_gather", "correct_hits", "correction_matrix", "patch_parameters",
           "surface_values", "surface_weights"]


def patch_parameters(patches: PatchSet):
    """Per patch: origin corner c0 (N,3), edge vectors e1, e2 (N,3) and the inverse Gram matrix
    (N,2,2) that turns a point's offset from c0 into (u, v) along e1, e2. Quads use e1 = c1 - c0,
    e2 = c3 - c0 (exact for parallelograms, what patch grids are made of), triangles
    e1 = c1 - c0, e2 = c2 - c0."""
    c = patches.corners()
    tri = patches.polys[:, 3] < 0
    e1 = c[:, 1] - c[:, 0]
    e2 = np.where(tri[:, None], c[:, 2] - c[:, 0], c[:, 3] - c[:, 0])
    a, b, d = (e1 * e1).sum(1), (e1 * e2).sum(1), (e2 * e2).sum(1)
    det = a * d - b * b
    # a patch whose e1 and e2 are parallel (a quad with a straight angle at c0, a sliver of no
    # area) has no inverse: its points are placed along the longer of the two edges instead
    ok = det > 1e-12 * a * d
    inv = np.stack([np.stack([d, -b], 1), np.stack([-b, a], 1)], 1) / np.where(ok, det, 1.0)[:, None, None]
    if not ok.all():
        bad = np.flatnonzero(~ok)
        along = a[bad] >= d[bad]
        inv[bad] = 0.0
        inv[bad[along], 0, 0] = 1.0 / np.maximum(a[bad[along]], 1e-300)
        inv[bad[~along], 1, 1] = 1.0 / np.maximum(d[bad[~along]], 1e-300)
    return c[:, 0], e1, e2, inv, tri


def surface_uv(params, pid, y):
    """(u, v) (H,) each in [0, 1]: where points ``y`` (H, 3) lie on patches ``pid`` (H,) along
    their edges e1, e2 from the first corner (:func:`patch_parameters`), clamped; a triangle's
    may leave it (u + v > 1). Column by column, as :func:`surface_weights` needs it."""
    c0, e1, e2, inv, _ = params
    rel = y - c0.take(pid, axis=0)
    E1, E2, M = e1.take(pid, axis=0), e2.take(pid, axis=0), inv.take(pid, axis=0)
    g0 = rel[:, 0] * E1[:, 0] + rel[:, 1] * E1[:, 1] + rel[:, 2] * E1[:, 2]
    g1 = rel[:, 0] * E2[:, 0] + rel[:, 1] * E2[:, 1] + rel[:, 2] * E2[:, 2]
    return (np.clip(M[:, 0, 0] * g0 + M[:, 0, 1] * g1, 0.0, 1.0),
            np.clip(M[:, 1, 0] * g0 + M[:, 1, 1] * g1, 0.0, 1.0))


def surface_weights(params, polys, pid, y):
    """Corner vertex ids (H, 4) and weights (H, 4) of points ``y`` (H,3) on patches ``pid`` (H,):
    bilinear in a quad, linear in a triangle (its 4th weight is 0). Column by column (a dense
    mesh's gather passes millions of hits through here): the same sums in the same order as
    the row sums and einsum it replaced, bit for bit. Rows are gathered with ``take`` (3-5x
    faster than indexing a 2-D array with an index array in NumPy 1.x: the same copy)."""
    u, v = surface_uv(params, pid, y)
    iu, iv = 1 - u, 1 - v
    t = params[4].take(pid)
    # a triangle's (u, v) can leave it (u + v > 1): fold back onto its hypotenuse
    over = np.maximum(u + v - 1, 0) / 2
    w1, w2 = u - over, v - over
    w = np.empty((len(u), 4))
    w[:, 0] = np.where(t, 1 - w1 - w2, iu * iv)
    w[:, 1] = np.where(t, w1, u * iv)
    w[:, 2] = np.where(t, w2, u * v)
    w[:, 3] = np.where(t, 0.0, iu * v)
    ids = polys.take(pid, axis=0)
    ids[:, 3] = np.where(ids[:, 3] < 0, ids[:, 0], ids[:, 3])
    return ids, w


def surface_values(params, polys, vertex_values, pid, y):
    """Values at points ``y`` (H,3) on patches ``pid`` (H,): bilinear in a quad, linear in a
    triangle, from ``vertex_values`` (V,k) at the patch corners."""
    ids, w = surface_weights(params, polys, pid, y)
    return np.einsum("hc,hck->hk", w, np.asarray(vertex_values, dtype=np.float64)[ids])


def gather_matrix(patches: PatchSet, points, normals, scene, *, rays=256, seed=0,
                  chunk_rays=1 << 16, ticker=None, workers=1, hits=False, background=False, share=None):
    """What a final gather sees, as a matrix: ``(G, sky)`` with G a CSR (P x V) such that the mean
    radiance arriving at ``points`` (P, 3) with unit ``normals`` from surfaces whose outgoing
    radiance is ``vals`` (V, k) at ``patches.verts`` is ``G @ vals + sky * world``.

    ``scene``: :func:`.rays.embree_scene` of ``patches`` (needs ``intersect``). ``rays`` per
    point: one cosine pattern (:func:`.hemisphere.cosine_lattice`, seeded) shared by every point, in
    the point's normal frame. A ray that hits the back of a patch sees nothing. A ray that hits
    a see-through patch (``patches.see_through``) reads part of it and goes on past it
    (:mod:`.through`). G depends on geometry (and what passes) only: a relight reuses it.
    ``workers``: workers casting chunks of points at once (0 = every core, 1 = serial): threads,
    or forked processes from :data:`PROCESS_RAYS` rays on (only the chunk starts go out, each
    chunk's rows come back); G is bit-identical for any count.
    ``chunk_rays``: rays cast and summed at once (65,536: smaller chunks' temporaries fit the
    caches better, about twice as fast as chunks of a million; and a forked worker faults every
    page of its first chunk's temporaries in fresh, zeroed by the kernel, so smaller chunks
    also cost fewer page faults and less system time). ``hits``: also return the rays' hit
    points, ``(G, sky, H)`` with H (h, 5) float32 rows
    ``(point id, patch id, x, y, z)`` of every front hit, in point order (for
    :func:`correct_hits`; each hit carries weight ``1 / rays`` in G; where the rays pass
    see-through patches, (h, 6) rows with the hit's weight last, carrying ``weight / rays``).
    ``background``: return a :class:`.background.Background` whose ``result()`` is what the call
    returns, so the caller can go on with other work while the workers cast (only when the
    chunks run on forked processes: otherwise the result is made before the call returns);
    ``ticker`` is then used only before the call returns: poll cancellation with
    ``result(cancelled)``. ``share``: None (each point casts its own rays), or a
    :class:`.shared.Sharing` of the points: points at one place cast one set of rays between
    them (:mod:`.shared`; H is then (h, 6)); not where rays pass see-through patches.
    """
    points = np.asarray(points, dtype=np.float64)
    normals = np.asarray(normals, dtype=np.float64)
    P = len(points)
    # one even pattern for every point, in a frame that depends on the normal alone:
    # neighbouring points on a surface cast parallel rays, so what remains of the sampling error
    # varies smoothly over the surface instead of as per-vertex speckle
    local = cosine_lattice(rays, seed)
    R = len(local)
    if P:
        scene.intersect(points[:1], normals[:1])  # commit the scene before threads (or forks) share it
    workers = resolve_workers(workers)
    step, forked = _chunking(P, R, chunk_rays, workers)
    through = Through.of(patches) if P else None                # None: every patch opaque
    eps = ray_offsets(patches, points, normals, scene=scene)[:, None]    # the rays' start offsets
    share = share if through is None and P else None
    # forked workers write their rows and hits into shared memory, each chunk of points at its
    # own place (at most 4 entries and one hit per ray), and send back only how many (rays
    # through see-through patches make more: their rows come back as they are)
    out = _SharedRows(P, R, hits, _hit_dtype(P, len(patches)), 5 if share is None else 6) \
        if forked and through is None else None
    cast, starts = _caster(patches, scene, points, normals, eps, local, hits, out, through, share, step,
                           chunk_rays, workers)
    return _GatheredRows(P, len(patches.verts), R, seed, hits, share, out).run(cast, starts, workers, forked,
                                                                               background, ticker)


def _chunking(P, R, chunk_rays, workers):
    """How :func:`gather_matrix` cuts ``P`` points of ``R`` rays each: ``(step, forked)``, the
    points a chunk casts (``chunk_rays`` rays' worth; with more than one of ``workers``, at most
    a quarter of a worker's share, so the chunks end together) and whether the chunks run on
    forked processes (from :data:`PROCESS_RAYS` rays on). Rows never span chunks: G is the same
    for any chunking."""
    step = max(1, chunk_rays // R)
    if workers > 1:
        step = max(1, min(step, -(-P // (4 * workers))))
    forked = workers > 1 and P > step and PROCESS_RAYS is not None and P * R >= PROCESS_RAYS
    return step, forked


def _caster(patches, scene, points, normals, eps, local, hits, out, through, share, step, chunk_rays, workers):
    """``(cast, starts)`` for :func:`gather_matrix`: ``cast(s)`` casts the rays ``local`` (R, 3)
    of the chunk of ``points`` (P, 3, scene units) with unit ``normals`` (P, 3) that starts at
    ``s``, ``eps`` (P, 1) off their surfaces, and returns its rows (:func:`_cast`'s tuple);
    ``starts`` are the chunks' first points. Opaque patches: :func:`_cast`, ``step`` points a
    chunk (``out``: forked workers' :class:`_SharedRows` or None); see-through patches
    (``through``): :func:`.through.cast_through`; points of a :class:`.shared.Sharing`
    (``share``): :func:`.shared.cast_shared`, the points in cluster order, ``chunk_rays`` rays a
    chunk, a few chunks a worker."""
    P, R = len(points), len(local)
    if share is not None:                  # the points cluster by cluster; put back at the end
        points, normals, eps = points[share.order], normals[share.order], eps[share.order]
        C = len(share.clusters) - 1            # chunks of chunk_rays rays, a few a worker
        starts, ends = share.starts(max(1, min(chunk_rays // R, -(-C // (4 * workers)))))
        return partial(cast_shared, share, ends, surface_weights, _hit_dtype(P, len(patches)), patches,
                       patch_parameters(patches), scene, points, normals, eps, local, hits, out), starts
    if through is None:
        return partial(_cast, patches, patch_parameters(patches), scene, points, normals, eps, local, step,
                       hits, out), range(0, P, step)
    return partial(cast_through, through, surface_weights, _hit_dtype(P, len(patches)), patches,
                   patch_parameters(patches), scene, points, normals, eps, local, step, hits), range(0, P, step)


@dataclass
class _GatheredRows:
    """The chunks of :func:`gather_matrix` put together: ``P`` points, ``V`` patch vertices,
    ``R`` rays a point of the pattern ``seed``; ``hits``: kept too; ``share``: the points'
    :class:`.shared.Sharing` (their chunks come in its order) or None; ``out``: the forked
    workers' :class:`_SharedRows` (the chunks send back counts) or None (their rows)."""

    P: int
    V: int
    R: int
    seed: int
    hits: bool
    share: object
    out: object

    def run(self, cast, starts, workers, forked, background, ticker):
        """What :func:`gather_matrix` returns: the chunks ``cast(s)`` for ``s`` in ``starts``
        (on ``workers``, forked processes when ``forked``) collected; with ``background``, a
        :class:`.background.Background` of it."""
        # chunks in point order whatever the worker count: G is bit-identical; each chunk's rows
        # arrive summed and compact (a dense mesh's gather is tens of millions of hits)
        results = (started_map if background and forked else ordered_map)(cast, starts, workers, processes=forked)
        if not background:
            return self.collect(results, tick=ticker)
        if not forked:                   # threads or serial: nothing would be left to overlap
            return Background.ready(self.collect(results, tick=ticker))
        # the workers were forked on this thread (started_map), not beside the caller's code
        # running on; their chunks are collected on a thread while the caller goes on
        return Background(partial(self.collect, results))

    def collect(self, results, stop=None, tick=None):
        """``(G, sky)`` (``(G, sky, H)`` with ``hits``) of :func:`gather_matrix` from the
        chunks' ``results`` (:func:`_cast`'s), in the points' own order; None when ``stop`` (an
        Event) is set between two chunks. ``tick``: a :class:`.progress.Ticker` told the points
        done."""
        P, out = self.P, self.out
        counts, cols, vals, found = np.zeros(P + 1, dtype=np.int64), [], [], []
        written = []                              # forked: (start, entries, hits) of each chunk
        sky = np.zeros(P)
        with closing(results):
            for s, m, sky_s, n, c, w, H in results:
                sky[s:s + m] = sky_s
                counts[s + 1:s + m + 1] = n
                if out is not None:                    # (c, H): how many entries and hits
                    written.append((s, c, H))
                else:
                    found.append(H)
                    cols.append(c)
                    vals.append(w)
                if tick is not None:
                    tick.tick(s + m, P)
                if stop is not None and stop.is_set():
                    return None
        if out is not None:                            # the shared arrays themselves
            c, w, H = out.compact(written)
        else:
            c = np.concatenate(cols) if cols else np.zeros(0, np.int32)
            w = np.concatenate(vals) if vals else np.zeros(0, np.float32)
            H = (np.concatenate(found) if found else np.zeros((0, 5 if self.share is None else 6), np.float32)) \
                if self.hits else None
        indptr, s_ = np.cumsum(counts), sky
        if self.share is not None:                     # back in the points' own order
            indptr, c, w, s_, H = self.share.restore(np.diff(indptr), c, w, sky, H)
        G = CSR(indptr, c, w, (P, self.V), {"rays": self.R, "seed": self.seed})
        return (G, s_, H) if self.hits else (G, s_)


def _hit_dtype(points, patches):
    """float32 holds ids exactly below 2^24 and positions to 1e-7 of the scene."""
    return np.float32 if max(points, patches) < (1 << 24) else np.float64


class _SharedRows:
    """Where forked gather workers put a chunk's rows of G and hits (:func:`.parallel.
    shared_array`): the chunk of points from ``s`` at entries ``4 R s`` and hits ``R s`` on
    (a point's rays make at most 4 entries and one hit each), so chunks never overlap."""

    def __init__(self, P, R, hits, hit_dtype, width=5):
        self.R = R
        self.cols = shared_array(4 * R * P, np.int32)
        self.vals = shared_array(4 * R * P, np.float32)
        self.hits = shared_array((R * P if hits else 0, width), hit_dtype)

    def write(self, s, cols, vals, H):
        """Store a chunk's entries and hits; (entries, hits or None) to send back."""
        e = len(cols)
        self.cols[4 * self.R * s:4 * self.R * s + e] = cols
        self.vals[4 * self.R * s:4 * self.R * s + e] = vals
        if H is None:
            return e, None
        self.hits[self.R * s:self.R * s + len(H)] = H
        return e, len(H)

    def compact(self, chunks):
        """(columns, values, hits or None) of every chunk, in the order of ``chunks`` ((s, e, h)
        as :meth:`write` returned them, ``s`` increasing): each chunk's entries and hits moved
        down to follow the one before, in place, as views of the shared arrays; the pages past
        them are handed back (:func:`.forked.release_tail`). A concatenation into new arrays
        (a dense mesh's hundred MB of rows and hits) had every page of them mapped and zeroed
        anew, in system time on the thread that collected them."""
        e_at = h_at = 0
        for s, e, h in chunks:               # a chunk never moves up: e_at <= 4 R s, h_at <= R s
            a, b = 4 * self.R * s, self.R * s
            if a != e_at:                    # (overlapping ranges: NumPy copies as memmove)
                self.cols[e_at:e_at + e] = self.cols[a:a + e]
                self.vals[e_at:e_at + e] = self.vals[a:a + e]
            e_at += e
            if h is not None:
                if b != h_at:
                    self.hits[h_at:h_at + h] = self.hits[b:b + h]
                h_at += h
        for arr, n in ((self.cols, e_at), (self.vals, e_at), (self.hits.reshape(-1), h_at * self.hits.shape[1])):
            if arr.size:
                release_tail(arr, n)
        return self.cols[:e_at], self.vals[:e_at], self.hits[:h_at] if self.hits.size else None


def _cast(patches, params, scene, points, normals, eps, local, step, hits, out, s):
    """The gather rays ``local`` (R, 3) of the points ``s:s + step``, starting ``eps`` (P, 1) off
    their surfaces: (s, m, sky (m,), the chunk's rows of G as entries per row (m,), columns (e,)
    int32 and values (e,) float32, its hits (h, 5) or None); with ``out`` (a :class:`_SharedRows`), the columns, values and hits
    go there and their counts come back in their place."""
    R = len(local)
    x, n = points[s:s + step], normals[s:s + step]
    m = len(x)
    d = in_frames(local, tangent_frames(n)).reshape(-1, 3)
    lifted = x + eps[s:s + step] * n
    # Embree's float32 starts rounded once and then repeated: the same values as the float64
    # repeat cast whole, without that (m R, 3) float64 copy
    pid, tfar = scene.intersect(np.repeat(lifted.astype(np.float32), R, axis=0), d)
    pid = np.asarray(pid)
    hit = pid >= 0
    sky_s = (~hit).reshape(m, R).mean(axis=1)
    # rows by ``take`` (indexing a 2-D array with an index array is several times slower)
    f = np.flatnonzero(hit)
    pf, df = pid[f], d.take(f, axis=0)
    front = np.flatnonzero(np.einsum("ij,ij->i", df, patches.normals.take(pf, axis=0)) < 0)
    f, pf, df = f[front], pf[front], df.take(front, axis=0)             # front faces only
    y = lifted.take(f // R, axis=0) + np.asarray(tfar, np.float64)[f, None] * df
    ids, w = surface_weights(params, patches.polys, pf, y)
    H = None
    if hits:
        H = np.empty((f.size, 5), _hit_dtype(len(points), len(patches)))    # (no float64 copy first:
        H[:, 0], H[:, 1], H[:, 2:] = s + f // R, pf, y                     # ids below 2^24, exact)
    # the chunk's rows of G, duplicates summed (as CSR.from_coo would: float64, then float32)
    counts, cols, vals = summed_entries(f // R, ids, w / R, len(patches.verts), m)
    if out is not None:
        e, h = out.write(s, cols, vals, H)
        return s, m, sky_s, counts, e, None, h
    return s, m, sky_s, counts, cols, vals, H


def correct_hits(G, H, patches: PatchSet, vertex_values, exact, select) -> np.ndarray:
    """(P, k) what to add to ``G @ vertex_values`` so that the hits on the patches ``select``
    (N,) bool read ``exact(points (h, 3), patch ids (h,)) -> (h, k)`` instead of the
    interpolation of ``vertex_values`` (V, k). ``G``, ``H`` from :func:`gather_matrix` with
    ``hits=True``."""
    k = np.asarray(vertex_values).shape[1]
    out = np.zeros((G.shape[0], k))
    H = H[select[H[:, 1].astype(np.int64)]]
    if not len(H):
        return out
    row, pid, y = H[:, 0].astype(np.int64), H[:, 1].astype(np.int64), H[:, 2:5].astype(np.float64)
    d = np.asarray(exact(y, pid), dtype=np.float64) - surface_values(patch_parameters(patches), patches.polys,
                                                                      vertex_values, pid, y)
    if H.shape[1] > 5:                          # rays through see-through patches: their weights
        d *= H[:, 5:6].astype(np.float64)
    for c in range(k):
        out[:, c] = np.bincount(row, weights=d[:, c], minlength=G.shape[0])
    return out / G.meta["rays"]


#: The fewest hits a thread of :func:`correction_matrix` takes.
CORRECTION_SHARE = 1 << 15
#: Hits a share of :func:`correction_matrix` makes into rows at once.
CORRECTION_RUN = 1 << 15


def correction_matrix(G, H, patches: PatchSet, select, read=None, extra=0, workers=1, hit_select=None) -> CSR:
    """:func:`correct_hits` as a matrix, for values that change while the hits and their choice
    do not (a relight): C (P x (V + ``extra``)), float64, such that ``C @ [vertex_values; x]``
    is what :func:`correct_hits` adds when ``exact(y, pid)`` reads ``x`` (``extra``, k) through
    ``read(y, pid, hits) -> (columns (h, m) into x, weights (h, m))`` (``hits`` their rows of
    H; None: reads nothing, 0; it is called from ``workers`` threads at once, each on its own
    hits). ``hit_select`` (h,) bool or None: the hits corrected, besides those on ``select``.

    ``workers`` (0 = every core): the hits are cut at row boundaries into shares of at least
    :data:`CORRECTION_SHARE`, each made into its rows of C on its own thread
    (:func:`.parallel.shares`; NumPy lets go of the GIL in the large array operations). H's rows
    are in order (the gather's chunks are), so each share's entries come sorted and summed in
    the same order as in one piece: C is the same, bit for bit, for any count. Why: on
    one thread, a dense curved mesh's many hits on abrupt elements kept the other core
    waiting."""
    P, V = G.shape
    R = G.meta["rays"]
    on = select[H[:, 1].astype(np.int64)]
    H = H[on if hit_select is None else on | hit_select]
    n = V + int(extra)
    entries = partial(_correction_entries, patch_parameters(patches), patches.polys, read, V, n, R)
    bounds = _hit_shares(H[:, 0], workers)
    parts = shares(lambda i: _in_runs(entries, H[bounds[i]:bounds[i + 1]]), len(bounds) - 1)
    key, summed = (np.concatenate([p[j] for p in parts]) for j in (0, 1))
    indptr = np.zeros(P + 1, np.int64)
    np.cumsum(np.bincount(key // n, minlength=P), out=indptr[1:])
    return CSR(indptr, (key % n).astype(np.int32 if n < 2 ** 31 else np.int64), summed, (P, n),
               {"rays": R})


def _hit_shares(rows, workers):
    """Where :func:`correction_matrix` cuts its hits into shares, one a thread: ``[0, ..., h]``
    (k + 1 ints) for the hits' ``rows`` (h,) in ascending order (their points), k at most
    ``workers`` (0 = every core) and at most one per :data:`CORRECTION_SHARE` hits, each cut at
    its row's first hit (a row never spans two shares)."""
    k = max(1, min(resolve_workers(workers), len(rows) // CORRECTION_SHARE))
    at = np.linspace(0, len(rows), k + 1)[1:-1].astype(np.int64)
    return [0, *np.searchsorted(rows, rows[at]).tolist(), len(rows)]


def _in_runs(entries, h):
    """``entries`` (:func:`_correction_entries`) of the hits ``h`` (h, 5 or 6), in runs of about
    :data:`CORRECTION_RUN` hits cut at row boundaries, concatenated: (keys (e,) int64, values
    (e,) float64). Each run's temporaries (tens of bytes a hit) then come from the heap's kept
    pages, not freshly faulted ones (the whole share's, hundreds of megabytes, were mapped and
    zeroed anew)."""
    cut = np.searchsorted(h[:, 0], h[np.arange(CORRECTION_RUN, len(h), CORRECTION_RUN), 0])
    runs = [entries(h[a:b]) for a, b in zip([0, *cut.tolist()], [*cut.tolist(), len(h)]) if b > a]
    if not runs:
        return np.zeros(0, np.int64), np.zeros(0)
    return tuple(np.concatenate([r[j] for r in runs]) for j in (0, 1))


def _correction_entries(params, polys, read, V, n, R, h):
    """The entries of :func:`correction_matrix` made by the hits ``h`` (h, 5) float rows
    ``(point, patch, x, y, z)`` (the position in the scene's units; a 6th column where rays
    pass see-through patches: the weight the ray still carries), ``R`` rays a point: minus each
    hit's interpolation weights (:func:`surface_weights` on the patches' ``params`` and corner
    ids ``polys``) at its patch's corner vertices (columns below ``V``), plus the weights
    ``read`` gives at the extra columns ``V + c``; summed per entry, divided by R, zeros left
    out. Returns (keys (e,) int64, ascending, ``point * n + column``; values (e,) float64,
    dimensionless)."""
    row, pid, y = h[:, 0].astype(np.int64), h[:, 1].astype(np.int64), h[:, 2:5].astype(np.float64)
    ids, w = surface_weights(params, polys, pid, y)
    if h.shape[1] > 5:                      # rays through see-through patches: their weights
        w = w * h[:, 5:6].astype(np.float64)
    rows, cols, vals = [np.repeat(row, 4)], [ids.ravel()], [-w.ravel()]
    if read is not None and len(h):
        c, r = read(y, pid, h)
        if h.shape[1] > 5:
            r = np.asarray(r, np.float64) * h[:, 5:6].astype(np.float64)
        rows.append(np.repeat(row, c.shape[1]))
        cols.append(V + np.asarray(c, np.int64).ravel())
        vals.append(np.asarray(r, np.float64).ravel())
    # the entries of weight 0 left out (a triangle's fourth corner, a hot cell's): the same sums
    key, vals = nonzero_entries(np.concatenate(rows) * n + np.concatenate(cols), np.concatenate(vals))
    if not len(key):
        return np.zeros(0, np.int64), np.zeros(0)
    key, inv = unique_ints(key, return_inverse=True, grouped=True)   # two runs of rows
    summed = np.bincount(inv.reshape(-1), weights=vals, minlength=key.size) / R
    keep = summed != 0
    return key[keep], summed[keep]


def final_gather(patches: PatchSet, vertex_values, points, normals, scene, *, rays=256, seed=0,
                 world=None, ticker=None) -> np.ndarray:
    """(P, k) mean radiance arriving at ``points`` from surfaces whose outgoing radiance is
    ``vertex_values`` (V, k) at ``patches.verts``; ``world`` (k,) is seen by rays that hit
    nothing (None: black). See :func:`gather_matrix`."""
    G, sky = gather_matrix(patches, points, normals, scene, rays=rays, seed=seed, ticker=ticker)
    return apply_gather(G, sky, vertex_values, world)


def apply_gather(G, sky, vertex_values, world=None, workers=1) -> np.ndarray:
    """``G @ vals + sky * world`` (see :func:`gather_matrix`). ``workers`` (0 = every core):
    threads that take a share of G's rows each (NumPy lets go of the GIL in the gathers and
    sums), at most one per million entries. Rows are summed as :meth:`.sparse.CSR.matvec` sums
    them: the same result, bit for bit, for any count."""
    out = product(G, vertex_values, workers)
    if world is not None:
        out = out + sky[:, None] * np.asarray(world, dtype=np.float64)[None, :]
    return out
