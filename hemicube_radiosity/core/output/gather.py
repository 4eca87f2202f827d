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
from ..util.sparse import CSR, nonzero_entries, summed_entries
from ..util.unique import unique_ints
from .shared import cast_shared
from .through import Through, cast_through

#: Rays (points x rays per point) from which :func:`gather_matrix` casts on forked processes
#: with more than one worker (:mod:`.parallel`); below, threads (None: always threads). On
#: a dense mesh the gather alone runs faster forked than on threads (``bench_parallel.py
#: --gather``, ``docs/performance.md`` 'Both cores'); in whole bakes the difference is small.
PROCESS_RAYS = 1 << 20

__all__ = ["final_gather", "gather_matrix", "apply_gather", "correct_hits", "correction_matrix", "patch_parameters",
           "product", "surface_values", "surface_weights"]


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


def surface_weights(params, polys, pid, y):
    """Corner vertex ids (H, 4) and weights (H, 4) of points ``y`` (H,3) on patches ``pid`` (H,):
    bilinear in a quad, linear in a triangle (its 4th weight is 0). Column by column (a dense
    mesh's gather passes millions of hits through here): the same sums in the same order as
    the row sums and einsum it replaced, bit for bit. Rows are gathered with ``take`` (3-5x
    faster than indexing a 2-D array with an index array in NumPy 1.x: the same copy)."""
    c0, e1, e2, inv, tri = params
    rel = y - c0.take(pid, axis=0)
    E1, E2, M = e1.take(pid, axis=0), e2.take(pid, axis=0), inv.take(pid, axis=0)
    g0 = rel[:, 0] * E1[:, 0] + rel[:, 1] * E1[:, 1] + rel[:, 2] * E1[:, 2]
    g1 = rel[:, 0] * E2[:, 0] + rel[:, 1] * E2[:, 1] + rel[:, 2] * E2[:, 2]
    u = np.clip(M[:, 0, 0] * g0 + M[:, 0, 1] * g1, 0.0, 1.0)
    v = np.clip(M[:, 1, 0] * g0 + M[:, 1, 1] * g1, 0.0, 1.0)
    iu, iv = 1 - u, 1 - v
    t = tri.take(pid)
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
    step = max(1, chunk_rays // R)
    if P:
        scene.intersect(points[:1], normals[:1])  # commit the scene before threads (or forks) share it
    workers = resolve_workers(workers)
    if workers > 1:        # a few chunks a worker, so they end together (rows never span chunks:
        step = max(1, min(step, -(-P // (4 * workers))))      # G is the same for any chunking)
    forked = workers > 1 and P > step and PROCESS_RAYS is not None and P * R >= PROCESS_RAYS
    through = Through.of(patches) if P else None                # None: every patch opaque
    # forked workers write their rows and hits into shared memory, each chunk of points at its
    # own place (at most 4 entries and one hit per ray), and send back only how many (rays
    # through see-through patches make more: their rows come back as they are)
    eps = ray_offsets(patches, points, normals, scene=scene)[:, None]    # the rays' start offsets
    share = share if through is None and P else None
    out = _SharedRows(P, R, hits, _hit_dtype(P, len(patches)), 5 if share is None else 6) \
        if forked and through is None else None
    starts = range(0, P, step)
    if share is not None:                  # the points cluster by cluster; put back at the end
        points, normals, eps = points[share.order], normals[share.order], eps[share.order]
        C = len(share.clusters) - 1            # chunks of chunk_rays rays, a few a worker
        starts, ends = share.starts(max(1, min(chunk_rays // R, -(-C // (4 * workers)))))
        cast = partial(cast_shared, share, ends, surface_weights, _hit_dtype(P, len(patches)), patches,
                       patch_parameters(patches), scene, points, normals, eps, local, hits, out)
    elif through is None:
        cast = partial(_cast, patches, patch_parameters(patches), scene, points, normals, eps, local, step, hits, out)
    else:
        cast = partial(cast_through, through, surface_weights, _hit_dtype(P, len(patches)), patches,
                       patch_parameters(patches), scene, points, normals, eps, local, step, hits)
    # chunks in point order whatever the worker count: G is bit-identical; each chunk's rows
    # arrive summed and compact (a dense mesh's gather is tens of millions of hits)
    results = (started_map if background and forked else ordered_map)(cast, starts, workers, processes=forked)
    rows = _GatheredRows(P, len(patches.verts), R, seed, hits, share, out)
    if not background:
        return rows.collect(results, tick=ticker)
    if not forked:                   # threads or serial: nothing would be left to overlap
        return Background.ready(rows.collect(results, tick=ticker))
    # the workers were forked on this thread (started_map), not beside the caller's code
    # running on; their chunks are collected on a thread while the caller goes on
    return Background(partial(rows.collect, results))


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


def correction_matrix(G, H, patches: PatchSet, select, read=None, extra=0, workers=1) -> CSR:
    """:func:`correct_hits` as a matrix, for values that change while the hits and their choice
    do not (a relight): C (P x (V + ``extra``)), float64, such that ``C @ [vertex_values; x]``
    is what :func:`correct_hits` adds when ``exact(y, pid)`` reads ``x`` (``extra``, k) through
    ``read(y, pid) -> (columns (h, m) into x, weights (h, m))`` (None: reads nothing, 0; it is
    called from ``workers`` threads at once, each on its own hits).

    ``workers`` (0 = every core): the hits are cut at row boundaries into shares of at least
    :data:`CORRECTION_SHARE`, each made into its rows of C on its own thread
    (:func:`.parallel.shares`; NumPy lets go of the GIL in the large array operations). H's rows
    are in order (the gather's chunks are), so each share's entries come sorted and summed in
    the same order as in one piece: C is the same, bit for bit, for any count. Why: on
    one thread, a dense curved mesh's many hits on abrupt elements kept the other core
    waiting."""
    P, V = G.shape
    R = G.meta["rays"]
    H = H[select[H[:, 1].astype(np.int64)]]
    n = V + int(extra)
    params = patch_parameters(patches)
    k = max(1, min(resolve_workers(workers), len(H) // CORRECTION_SHARE))
    at = np.linspace(0, len(H), k + 1)[1:-1].astype(np.int64)          # each cut at its row's first hit
    bounds = [0, *np.searchsorted(H[:, 0], H[at, 0]).tolist(), len(H)]

    def share(i):
        # in runs of about CORRECTION_RUN hits, cut at row boundaries: each run's temporaries
        # (tens of bytes a hit) then come from the heap's kept pages, not freshly faulted ones
        # (the whole share's, hundreds of megabytes, were mapped and zeroed anew)
        h = H[bounds[i]:bounds[i + 1]]
        cut = np.searchsorted(h[:, 0], h[np.arange(CORRECTION_RUN, len(h), CORRECTION_RUN), 0])
        runs = [run(h[a:b]) for a, b in zip([0, *cut.tolist()], [*cut.tolist(), len(h)]) if b > a]
        if not runs:
            return np.zeros(0, np.int64), np.zeros(0)
        return tuple(np.concatenate([r[j] for r in runs]) for j in (0, 1))

    def run(h):
        row, pid, y = h[:, 0].astype(np.int64), h[:, 1].astype(np.int64), h[:, 2:5].astype(np.float64)
        ids, w = surface_weights(params, patches.polys, pid, y)
        if h.shape[1] > 5:                      # rays through see-through patches: their weights
            w = w * h[:, 5:6].astype(np.float64)
        rows, cols, vals = [np.repeat(row, 4)], [ids.ravel()], [-w.ravel()]
        if read is not None and len(h):
            c, r = read(y, pid)
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
    parts = shares(share, len(bounds) - 1)
    key, summed = (np.concatenate([p[j] for p in parts]) for j in (0, 1))
    indptr = np.zeros(P + 1, np.int64)
    np.cumsum(np.bincount(key // n, minlength=P), out=indptr[1:])
    return CSR(indptr, (key % n).astype(np.int32 if n < 2 ** 31 else np.int64), summed, (P, n),
               {"rays": R})


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


def product(M, x, workers=1) -> np.ndarray:
    """``M @ x`` for a CSR ``M`` and ``x`` (n,) or (n, k), float64, as :meth:`.sparse.CSR.matvec`
    computes it (bit for bit), faster on large matrices (:func:`_rows_product`); ``workers``
    (0 = every core) take a share of the rows each, at most one per million entries: the
    calling thread and ``workers - 1`` threads (:func:`.parallel.shares`)."""
    x = np.asarray(x, dtype=np.float64)
    one = x.ndim == 1
    xt = np.ascontiguousarray((x[:, None] if one else x).T)     # (k, n): contiguous gathers
    out = np.zeros((M.shape[0], xt.shape[0]))
    n = min(resolve_workers(workers), max(1, M.nnz >> 20))
    bounds = M.memo(("product-bounds", n), lambda: [   # the threads' rows, kept on M
        0, *np.searchsorted(M.indptr, np.linspace(0, M.nnz, n + 1)[1:-1]).tolist(), M.shape[0]])
    shares(lambda i: _rows_product(M, xt, bounds[i], bounds[i + 1], out), n)   # the caller takes one
    return out[:, 0] if one else out


def _rows_product(G, xt, r0, r1, out, chunk=1 << 16) -> None:
    """``out[r0:r1] = (G @ x)[r0:r1]`` for ``xt`` = x.T (k, V), in runs of rows of about ``chunk``
    entries, so that the products stay in the CPU's cache (whole-matrix temporaries, hundreds of
    megabytes on a dense mesh's G, made the product twice as slow); each row is summed as
    :meth:`.sparse.CSR.matvec` sums it. The runs (:func:`_row_runs`) are kept on G.

    A run's columns and values are read as stored (int32, float32: half the memory traffic of
    whole-matrix intp and float64 copies) and widened once into buffers that every band reads
    (float32 to float64 is exact: the same products). A dense mesh's G is read from memory, not the
    caches, at every product: widened copies kept on G made the product slower, not faster."""
    cols, data = G.indices, G.data
    wide = data.dtype == np.float64
    ibuf, dbuf, buf = np.empty(0, np.intp), np.empty(0), np.empty(0)
    for s, e, rows, starts in G.memo(("row-runs", r0, r1, chunk), lambda: _row_runs(G.indptr, r0, r1, chunk)):
        if buf.size < e - s:
            m = max(e - s, chunk)
            ibuf, dbuf, buf = np.empty(m, np.intp), np.empty(m), np.empty(m)
        p = buf[:e - s]
        if cols.dtype == np.intp:
            idx = cols[s:e]
        else:                           # take converts other index types on every call
            idx = ibuf[:e - s]
            idx[...] = cols[s:e]
        if wide:
            d = data[s:e]
        else:
            d = dbuf[:e - s]
            d[...] = data[s:e]
        for k in range(xt.shape[0]):
            # 'wrap' (the columns are in range: the same values) skips take's buffered bounds
            # check: with it the gathers were half a dense mesh's product
            np.take(xt[k], idx, out=p, mode="wrap")
            np.multiply(p, d, out=p)
            out[rows, k] = np.add.reduceat(p, starts)


def _row_runs(ip, r0, r1, chunk) -> list:
    """The runs of :func:`_rows_product` over rows ``r0:r1`` of a CSR with row pointers ``ip``:
    (first entry, end entry, the run's non-empty rows (a slice where all are), their first
    entries' offsets in the run), for runs of whole rows of about ``chunk`` entries (a relight's
    products make them once per matrix)."""
    cuts = np.unique(np.r_[np.searchsorted(ip, np.arange(ip[r0], ip[r1], chunk), side="right") - 1, r1])
    cuts = cuts[(cuts >= r0) & (cuts <= r1)]
    runs = []
    for a, b in zip(cuts[:-1].tolist(), cuts[1:].tolist()):
        s, e = int(ip[a]), int(ip[b])
        if e == s:
            continue
        nz = np.flatnonzero(np.diff(ip[a:b + 1]))
        rows = slice(a, b) if nz.size == b - a else a + nz
        runs.append((s, e, rows, ip[a:b][nz] - s))
    return runs
