"""Compressed sparse rows in plain NumPy (SciPy is not inside Blender).

A form-factor matrix F is stored as CSR: row i holds the patches j that receiver i sees,
``F[i, indices[indptr[i]:indptr[i+1]]] = data[indptr[i]:indptr[i+1]]``. Zero entries
(occluded, facing away, the patch itself) are never stored. :func:`product` is ``M @ x`` as
:meth:`CSR.matvec` sums it, bit for bit, in cache-sized runs of rows and on threads.
"""
from __future__ import annotations

import ast

from dataclasses import dataclass, field

import numpy as np

from ..runtime.parallel import resolve_workers, shares
from ..runtime.stored import storable
from .unique import unique_ints

__all__ = ["CSR", "nonzero_entries", "product", "summed_entries"]


@storable
@dataclass
class CSR:
    indptr: np.ndarray   # (N+1,) int64
    indices: np.ndarray  # (nnz,) int32 column ids, sorted within a row
    data: np.ndarray     # (nnz,) float32 values
    shape: tuple
    meta: dict = field(default_factory=dict)  # settings that made it (method, resolution, ...)
    # Form factors only: (N,) fraction of each receiver's hemisphere that sees no surface at all
    # (the world/sky). Back faces block the view but are not sky. None when not known.
    sky: np.ndarray | None = None

    @property
    def nnz(self) -> int:
        return int(self.indices.size)

    @property
    def nbytes(self) -> int:
        return int(self.indptr.nbytes + self.indices.nbytes + self.data.nbytes)

    @classmethod
    def from_coo(cls, rows, cols, vals, shape, meta=None) -> "CSR":
        """From triplets; duplicates are summed, zeros dropped."""
        rows = np.asarray(rows, dtype=np.int64)
        cols = np.asarray(cols, dtype=np.int64)
        vals = np.asarray(vals, dtype=np.float64)
        key = rows * shape[1] + cols
        uk, inv = unique_ints(key, return_inverse=True)
        summed = np.bincount(inv.reshape(-1), weights=vals, minlength=uk.size)
        keep = summed != 0
        uk, summed = uk[keep], summed[keep]
        r = uk // shape[1]
        indptr = np.zeros(shape[0] + 1, dtype=np.int64)
        np.cumsum(np.bincount(r, minlength=shape[0]), out=indptr[1:])
        return cls(indptr, (uk % shape[1]).astype(np.int32), summed.astype(np.float32),
                   (int(shape[0]), int(shape[1])), dict(meta or {}))

    @classmethod
    def from_dense(cls, a, meta=None) -> "CSR":
        a = np.asarray(a)
        r, c = np.nonzero(a)
        return cls.from_coo(r, c, a[r, c], a.shape, meta)

    def memo(self, name, make):
        """F never changes once built (it is cached and shared by relights): derived arrays are
        computed once per matrix."""
        memo = self.__dict__.setdefault("_derived", {})
        if name not in memo:
            memo[name] = make()
        return memo[name]

    def row_ids(self) -> np.ndarray:
        """(nnz,) the row of every stored entry."""
        idx = np.int32 if self.shape[0] < 2 ** 31 else np.int64   # half the memory of int64 indices
        return self.memo("row_ids", lambda: np.repeat(np.arange(self.shape[0], dtype=idx), np.diff(self.indptr)))

    def row(self, i):
        s, e = self.indptr[i], self.indptr[i + 1]
        return self.indices[s:e], self.data[s:e]

    def row_sums(self) -> np.ndarray:
        return self.memo("row_sums", lambda: np.bincount(self.row_ids(), weights=self.data.astype(np.float64),
                                                          minlength=self.shape[0]))

    def matvec(self, x: np.ndarray, row_ids: np.ndarray | None = None) -> np.ndarray:
        """F @ x for x of shape (N,) or (N, k), in float64 (``row_ids`` is accepted for
        compatibility and not needed)."""
        x = np.asarray(x, dtype=np.float64)
        one = x.ndim == 1
        xt = np.ascontiguousarray((x[:, None] if one else x).T)   # (k, N): contiguous gathers
        counts = np.diff(self.indptr)
        nonempty = np.flatnonzero(counts)
        starts = self.indptr[:-1][nonempty]
        out = np.zeros((self.shape[0], xt.shape[0]))
        if starts.size:
            for k in range(xt.shape[0]):   # float32 data times float64 x: products in float64
                out[nonempty, k] = np.add.reduceat(self.data * xt[k][self.indices], starts)
        return out[:, 0] if one else out

    def transpose(self) -> "CSR":
        return CSR.from_coo(self.indices, self.row_ids(), self.data, (self.shape[1], self.shape[0]), self.meta)

    def to_dense(self) -> np.ndarray:
        a = np.zeros(self.shape, dtype=np.float64)
        a[self.row_ids(), self.indices] = self.data
        return a

    def save(self, path) -> None:
        extra = {} if self.sky is None else {"sky": self.sky}
        # not compressed: a relight in a new process reads a dense mesh's gather matrix (hundreds
        # of megabytes) several times faster than it inflates it
        np.savez(path, indptr=self.indptr, indices=self.indices, data=self.data,
                 shape=np.array(self.shape), meta=np.array(repr(self.meta)), **extra)

    @classmethod
    def load(cls, path) -> "CSR":
        with np.load(path, allow_pickle=False) as z:
            return cls(z["indptr"], z["indices"], z["data"], tuple(int(s) for s in z["shape"]),
                       ast.literal_eval(str(z["meta"])), z["sky"] if "sky" in z.files else None)


def summed_entries(rows, ids, weights, width, m):
    """A block of ``m`` sparse rows from entries that may repeat: ``rows`` (h,) each entry
    group's row, ``ids`` (h, k) its columns (below ``width``), ``weights`` (h, k) their values;
    duplicates summed in float64 (as :meth:`CSR.from_coo` sums them), zeros dropped. Returns
    (counts (m,) entries per row, cols (n,) int32, vals (n,) float32), row by row.

    Entries of weight 0 are left out before the sort (a triangle's fourth corner in a gather's
    hits: a fifth of zdm2's entries): adding 0 changes no partial sum (none is -0 from a start at
    +0), so every sum is the same, bit for bit, and a key of only zeros is dropped either way."""
    k = np.shape(ids)[1]
    key, w = np.repeat(rows, k) * width + np.ravel(ids), np.ravel(weights)
    key, w = nonzero_entries(key, w)
    if not key.size:
        return np.zeros(m, np.int64), np.zeros(0, np.int32), np.zeros(0, np.float32)
    key, inv = unique_ints(key, return_inverse=True, grouped=True)
    summed = np.bincount(inv.reshape(-1), weights=w, minlength=key.size)
    keep = summed != 0
    key, summed = key[keep], summed[keep]
    return np.bincount(key // width, minlength=m), (key % width).astype(np.int32), summed.astype(np.float32)


def nonzero_entries(*arrays):
    """``arrays`` (keys (n,), ..., weights (n,)) without the entries whose weight (the last) is
    0, in their order (the same arrays when none is): what a sum over them by key leaves alone."""
    w = arrays[-1]
    nz = w != 0
    if nz.all():
        return arrays
    return tuple(a[nz] for a in arrays)


def product(M, x, workers=1) -> np.ndarray:
    """``M @ x`` for a CSR ``M`` and ``x`` (n,) or (n, k), float64, as :meth:`CSR.matvec`
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
    :meth:`CSR.matvec` sums it. The runs (:func:`_row_runs`) are kept on G.

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
