"""Exact k nearest neighbours in 3-D through uniform grids of buckets (pure NumPy: Blender has no SciPy).

:func:`k_nearest` gives, for every query point, the ``k`` sites a full sort of its squared distances
to all the sites would give, ``((point - site) ** 2).sum(-1)`` with ties broken by the lower site
index, at the cost of the sites in the 27 cells around each point instead of all of them.

The sites are hashed into cubic cells of edge ``cell`` (and, when needed, 2, 4, 8... times that).
A point looks at the 3 x 3 x 3 cells around its own: every site outside is farther from the point
than the cube's nearest face, so when the k-th nearest site found is nearer than that face (with a
margin for rounding), the k found are the k nearest. Points for which that does not hold (sparse
sites around them) try the next coarser grid; those that no grid of more than a few cells an axis
settles (a point far off every site) are compared with every site.
"""
from __future__ import annotations

import numpy as np

from .unique import run_positions, unique_ints

__all__ = ["Grid", "k_nearest", "morton_codes", "morton_order", "sq_dist"]

_MARGIN = 1e-6            # relative: a site outside the searched cube may be this much nearer than its faces
MAX_PAIRS = 1 << 20          # (point, site) pairs at a time: at most about 100 MB of temporaries


def morton_codes(points, lo, hi) -> np.ndarray:
    """(n,) int64 Morton (Z-order) codes of ``points`` (n, 3) in boxes ``lo``..``hi`` (n, 3) or
    (3,): each axis quantised to 10 bits and their bits interleaved, so that points close in the
    order are close in space (runs of the order are compact regions)."""
    span = np.maximum(np.asarray(hi) - np.asarray(lo), 1e-12)
    q = np.clip(((points - lo) / span * 1023).astype(np.int64), 0, 1023)
    code = np.zeros(len(points), np.int64)
    for bit in range(10):                  # interleave the three axes' bits
        for ax in range(3):
            code |= ((q[:, ax] >> bit) & 1) << (3 * bit + ax)
    return code


def morton_order(points, groups, count: int) -> np.ndarray:
    """(n,) the order of ``points`` (n, 3) by ``groups`` (n,) int in 0..``count``, then by Morton
    code within each group's bounding box (:func:`morton_codes`): each group's points in a run,
    and a run of that order is a compact region of its group."""
    lo = np.full((count, 3), np.inf)
    hi = np.full((count, 3), -np.inf)
    np.minimum.at(lo, groups, points)
    np.maximum.at(hi, groups, points)
    return np.lexsort((morton_codes(points, lo[groups], hi[groups]), groups))


def sq_dist(a, b):
    """``((a - b) ** 2).sum(-1)`` of broadcastable (..., 3) arrays, to the bit (NumPy adds the
    three squares in order: x, then y, then z), without the (..., 3) temporaries."""
    d = a[..., 0] - b[..., 0]
    out = d * d
    d = a[..., 1] - b[..., 1]
    out += d * d
    d = a[..., 2] - b[..., 2]
    out += d * d
    return out


def _offsets(r):
    a = np.arange(-r, r + 1)
    return np.stack(np.meshgrid(a, a, a, indexing="ij"), -1).reshape(-1, 3)


def _select(row, site, d2, m, k):
    """The k smallest (d2, site) of each row of a ragged list -> (m, k) sites, (m, k) d2 in that
    order, (m,) entries per row; rows with fewer than k entries are padded with -1 / inf.
    ``row`` is non-decreasing (each row's entries together)."""
    n = np.bincount(row, minlength=m)
    first = np.cumsum(n) - n
    if row.size > 2 * k * m and int(n.max()) * m <= 1 << 22:
        # sort only what can be among the k: up to each row's k-th smallest d2, ties included
        pad = np.full((m, int(n.max())), np.inf)
        pad[row, np.arange(row.size) - first[row]] = d2
        kth = np.partition(pad, k - 1, axis=1)[:, k - 1]
        sel = d2 <= kth[row]
        row, site, d2 = row[sel], site[sel], d2[sel]
    row, site, d2 = _sorted(row, site, d2, m)
    kept = np.bincount(row, minlength=m)
    rank = np.arange(row.size) - (np.cumsum(kept) - kept)[row]
    keep = rank < k
    out_s = np.full((m, k), -1, np.int64)
    out_d = np.full((m, k), np.inf)
    out_s[row[keep], rank[keep]] = site[keep]
    out_d[row[keep], rank[keep]] = d2[keep]
    return out_s, out_d, n


def _sorted(row, site, d2, m):
    """``row``, ``site``, ``d2`` ordered by (row, d2, site), as ``np.lexsort((site, d2, row))``
    orders them (each site at most once a row). Where it fits in 63 bits, one sort of int64
    keys (row, rank of d2, site) after one argsort of d2, not lexsort's three stable argsorts
    (most of a k-nearest query's time)."""
    n = row.size
    nsite = int(site.max()) + 1 if n else 1
    bits_r, bits_s = max(int(n).bit_length(), 1), max(nsite.bit_length(), 1)
    if n == 0 or max(m, 1).bit_length() + bits_r + bits_s > 63 or np.isnan(d2).any():
        perm = np.lexsort((site, d2, row))
        return row[perm], site[perm], d2[perm]
    by = np.argsort(d2)
    ds = d2[by]
    new = np.empty(n, bool)
    new[0] = True
    np.not_equal(ds[1:], ds[:-1], out=new[1:])
    rank = np.empty(n, np.int64)
    rank[by] = np.cumsum(new) - 1                      # equal d2, equal rank
    key = (row.astype(np.int64) << (bits_r + bits_s)) | (rank << bits_s) | site.astype(np.int64)
    key.sort()
    rank = (key >> bits_s) & ((1 << bits_r) - 1)
    return key >> (bits_r + bits_s), key & ((1 << bits_s) - 1), ds[np.flatnonzero(new)][rank]


class _Level:
    """The sites hashed into cubic cells of edge ``h`` (from the corner ``lo``)."""

    def __init__(self, sites, lo, h):
        self.lo, self.h = lo, h
        ci = np.floor((sites - lo) / h).astype(np.int64)
        self.dims = ci.max(0) + 1
        key = self._key(ci)
        self.order = np.argsort(key, kind="stable")
        self.keys, self.start, self.count = unique_ints(key[self.order], return_index=True, return_counts=True)

    def _key(self, ci):
        return (ci[..., 0] * self.dims[1] + ci[..., 1]) * self.dims[2] + ci[..., 2]

    def ring(self, sites, p, k, r, upper=None):
        """Candidates of the points p (m, 3) in the cube of (2 r + 1)^3 cells around theirs: (m, k)
        sites and d2 (the k smallest found), (m,) bool where they are certainly the k nearest.
        ``upper`` (m,): each point's k-th smallest d2 among sites of a cube inside this one (a finer
        level's), or inf; cells and sites farther than it cannot be among the k and are skipped
        (the k smallest found are the same)."""
        m, h, dims = len(p), self.h, self.dims
        pc = np.clip(np.floor((p - self.lo) / h), -r - 1, dims + r).astype(np.int64)
        nb = pc[:, None, :] + _offsets(r)[None]                       # (m, c, 3)
        valid = ((nb >= 0) & (nb < dims)).all(-1)
        key = np.where(valid, self._key(nb), -1)
        pos = np.minimum(np.searchsorted(self.keys, key), len(self.keys) - 1)
        hit = valid & (self.keys[pos] == key)
        cnt = np.where(hit, self.count[pos], 0)
        total = cnt.sum(axis=1)                          # sites in the cube, skipped ones included
        if upper is not None and np.isfinite(upper).any():
            # a cell whose box is farther than the bound (a margin for rounding) holds none of the k
            lo = self.lo + nb * h
            gap = np.maximum(np.maximum(lo - p[:, None, :], p[:, None, :] - (lo + h)), 0.0)
            far = ((gap * gap).sum(-1) * (1 - _MARGIN) > upper[:, None]) & np.isfinite(upper)[:, None]
            cnt = np.where(far, 0, cnt)
        if m > 1 and int(cnt.sum()) > MAX_PAIRS:     # crowded cells (sites much denser than the cell): halves
            half = (slice(0, m // 2), slice(m // 2, m))
            parts = [self.ring(sites, p[q], k, r, None if upper is None else upper[q]) for q in half]
            return tuple(np.concatenate(x) for x in zip(*parts))
        cnt = cnt.ravel()
        nz = cnt > 0
        cnt, st = cnt[nz], self.start[pos].ravel()[nz]
        row = np.repeat(np.repeat(np.arange(m), nb.shape[1])[nz], cnt)
        within = run_positions(cnt)
        site = self.order[np.repeat(st, cnt) + within]
        d2 = sq_dist(p[row], sites[site])
        if upper is not None:
            near = d2 <= upper[row]
            row, site, d2 = row[near], site[near], d2[near]
        s, d, _ = _select(row, site, d2, m, k)
        # the distance from each point to its cube's nearest face: every site outside is farther
        bound = np.minimum(p - (self.lo + (pc - r) * h), (self.lo + (pc + r + 1) * h) - p).min(1)
        ok = (total >= k) & (bound > 0) & (d[:, -1] < (bound * (1 - _MARGIN)) ** 2)
        return s, d, ok | (total == len(sites))


class Grid:
    """Sites (N, 3) hashed into cubic cells of edge ``cell``, 2 ``cell``, 4 ``cell``... (each level
    built when a query first needs it), for :meth:`k_nearest` queries."""

    def __init__(self, sites, cell=None):
        sites = np.ascontiguousarray(sites, dtype=np.float64)
        if sites.ndim != 2 or sites.shape[1] != 3 or len(sites) == 0:
            raise ValueError("sites must be a non-empty (N, 3) array")
        self.sites = sites
        self.lo = sites.min(0)
        self.extent = float((sites.max(0) - self.lo).max())
        if cell is None or not np.isfinite(cell) or cell <= 0:
            cell = self.extent / max(np.sqrt(len(sites)), 1.0)     # about one site a cell on a surface
        # at most 2^20 cells an axis (keys fit in int64); a positive edge for coincident sites
        self.cell = max(float(cell), self.extent / 2.0 ** 20, 1e-300)
        self._levels = []

    def _level(self, i):
        while len(self._levels) <= i:
            self._levels.append(_Level(self.sites, self.lo, self.cell * 2.0 ** len(self._levels)))
        return self._levels[i]

    def _worth(self, i) -> bool:
        """Whether :meth:`k_nearest` looks at level ``i``: the first, and each coarser one while
        the one below it has more than 4 cells an axis."""
        return i == 0 or self.cell * 2.0 ** (i - 1) < self.extent / 4

    def build_levels(self) -> None:
        """Build every level :meth:`k_nearest` may look at now (they are built when first needed
        otherwise): threads may then query the grid at once."""
        i = 0
        while self._worth(i):
            self._level(i)
            i += 1

    def _all(self, p, k):
        """Brute force: every site for every point (what :meth:`k_nearest` falls back to)."""
        d2 = sq_dist(p[:, None, :], self.sites[None, :, :])
        if k < d2.shape[1]:
            kth = np.partition(d2, k - 1, axis=1)[:, k - 1:k]
            row, site = np.nonzero(d2 <= kth)                          # at least k a row (ties at the k-th)
        else:
            row, site = np.nonzero(np.ones(d2.shape, bool))
        s, d, _ = _select(row, site, d2[row, site], len(p), k)
        return s, d

    def k_nearest(self, points, k, chunk=4096):
        """(P, k) int64 site indices, each row ascending by (squared distance, index), and (P, k)
        squared distances: each point's k nearest sites, ties at the k-th broken by the lower index.

        Each point looks at the 27 cells around its own, on the finest level first, then on
        coarser ones while that is not enough; with the coarsest worth it (4 cells or fewer an
        axis) not enough either (a point far from every site), at every site."""
        points = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
        P, N = len(points), len(self.sites)
        if not 1 <= k <= N:
            raise ValueError(f"k = {k} must be between 1 and the {N} sites")
        out_s = np.empty((P, k), np.int64)
        out_d = np.empty((P, k))
        for a in range(0, P, chunk):
            ids = np.arange(a, min(a + chunk, P))
            i = 0
            upper = None
            while ids.size and self._worth(i):
                # each coarser cube holds the finer one: its k-th found bounds the k nearest
                s, d, ok = self._level(i).ring(self.sites, points[ids], k, 1, upper)
                out_s[ids[ok]], out_d[ids[ok]] = s[ok], d[ok]
                ids, upper = ids[~ok], d[~ok, -1]
                i += 1
            rows = max(1, MAX_PAIRS // N)
            for b in range(0, ids.size, rows):
                sub = ids[b:b + rows]
                out_s[sub], out_d[sub] = self._all(points[sub], k)
        return out_s, out_d


def k_nearest(sites, points, k, cell=None, chunk=4096):
    """(P, k) indices into ``sites`` (N, 3) of each point's ``k`` nearest sites (1 <= k <= N),
    ascending by squared distance ``((point - site) ** 2).sum(-1)``, ties by the lower index, and
    those (P, k) squared distances. ``cell``: the grid's cell edge, in the sites' units (about the
    spacing between sites times sqrt(k) is good; by default from the sites' spread)."""
    return Grid(sites, cell).k_nearest(points, k, chunk)
