"""The distinct rows of a 2-D array: what ``np.unique(a, axis=0)`` returns, without its cost.

NumPy finds unique rows by viewing each row as one structured record and sorting the records,
which compares them field by field through a generic comparison: on this project's keys (edges
as vertex pairs, pieces as (object, material, normal bin, cell) rows) that sort was most of a
dense mesh's grouping (``docs/performance.md``).
:func:`unique_rows` sorts integer rows as one packed int64 key when their ranges allow it, and
any other rows with :func:`numpy.lexsort`, and returns the same arrays as ``np.unique``: the
rows in lexicographic order, the inverse (always 1-D) and the counts.
"""
from __future__ import annotations

import math

import numpy as np

__all__ = ["linked_labels", "run_positions", "unique_ints", "unique_rows"]


def unique_rows(a, return_inverse=False, return_counts=False):
    """The distinct rows of ``a`` (N, K), sorted lexicographically (column 0 first), as
    ``np.unique(a, axis=0, return_inverse=..., return_counts=...)`` returns them: ``uniq`` (U, K)
    alone, or a tuple with ``inverse`` (N,) intp (``uniq[inverse] == a``) and/or ``counts`` (U,)
    intp. Rows compare by value (-0.0 equals 0.0; NaN equals nothing, as in NumPy)."""
    a = np.asarray(a)
    if a.ndim != 2 or len(a) == 0 or a.shape[1] == 0:
        out = np.unique(a, axis=0, return_inverse=return_inverse, return_counts=return_counts)
        if return_inverse:
            out = (out[0], np.asarray(out[1]).reshape(-1), *out[2:])
        return out
    n = len(a)
    order = _row_order(a)
    s = a[order]
    new = np.empty(n, bool)
    new[0] = True
    np.any(s[1:] != s[:-1], axis=1, out=new[1:])
    first = np.flatnonzero(new)
    uniq = a[order[first]]
    if not (return_inverse or return_counts):
        return uniq
    out = [uniq]
    if return_inverse:
        inverse = np.empty(n, np.intp)
        inverse[order] = np.cumsum(new) - 1
        out.append(inverse)
    if return_counts:
        out.append(np.diff(np.append(first, n)))
    return tuple(out)


def unique_ints(x, return_index=False, return_inverse=False, return_counts=False, grouped=False):
    """``np.unique(x, return_index=..., return_inverse=..., return_counts=...)`` for an integer
    array (flattened; the inverse is 1-D), the same arrays, faster: each value is packed with its
    position into one int64 and the packed values are sorted, not argsorted (several times
    faster than ``np.unique`` on a gather's chunk of hits). Falls back to ``np.unique`` for other
    dtypes or where value range and position do not fit in 63 bits.

    ``grouped``: ``x`` comes in short runs, each above the one before (a matrix's entries row by
    row, each row's columns in any order: ``row * n + col`` with the rows ascending). The packed
    values are then sorted by NumPy's stable sort, a merge sort that takes runs as it finds them,
    about twice as fast there (the quicksort is faster on values in no order). Every packed value is distinct (each holds its
    position), so both sorts give the same arrays."""
    x = np.asarray(x).reshape(-1)
    flags = dict(return_index=return_index, return_inverse=return_inverse, return_counts=return_counts)
    packed = _packed(x)
    if packed is None:
        out = np.unique(x, **flags)
        return (out[0], *(np.asarray(a).reshape(-1) for a in out[1:])) if isinstance(out, tuple) else out
    packed, bits, lo = packed
    packed.sort(kind="stable" if grouped else "quicksort")
    order = packed & ((1 << bits) - 1)
    packed >>= bits
    new = np.empty(len(x), bool)
    new[0] = True
    np.not_equal(packed[1:], packed[:-1], out=new[1:])
    first = np.flatnonzero(new)
    uniq = (packed[first] + lo).astype(x.dtype)
    if not (return_index or return_inverse or return_counts):
        return uniq
    out = [uniq]
    if return_index:
        out.append(order[first].astype(np.intp))
    if return_inverse:
        inverse = np.empty(len(x), np.intp)
        inverse[order] = np.cumsum(new) - 1
        out.append(inverse)
    if return_counts:
        out.append(np.diff(np.append(first, len(x))))
    return tuple(out)


def _packed(x):
    """(x - min) shifted left past the positions, or'ed with each one's position: (int64 (n,),
    bits of the position, min), or None (empty, not integers, or over 63 bits)."""
    if len(x) == 0 or x.dtype.kind not in "biu" or (x.dtype.kind == "u" and x.dtype.itemsize == 8):
        return None
    lo, hi = int(x.min()), int(x.max())
    bits = max(1, (len(x) - 1).bit_length())
    if (hi - lo).bit_length() + bits > 63:
        return None
    packed = x.astype(np.int64) - lo
    packed <<= bits
    packed |= np.arange(len(x), dtype=np.int64)
    return packed, bits, lo


def _row_order(a) -> np.ndarray:
    """A stable order of ``a``'s rows sorted lexicographically: one argsort of a packed int64 key
    for integer rows whose value ranges multiply to under 2**62, else a lexsort."""
    if a.dtype.kind in "bi" or (a.dtype.kind == "u" and a.dtype.itemsize < 8):
        lo = a.min(axis=0).astype(np.int64)
        span = [int(h) - int(l) + 1 for h, l in zip(a.max(axis=0).tolist(), lo.tolist())]
        if math.prod(span) < 2 ** 62:
            key = np.zeros(len(a), np.int64)
            for j in range(a.shape[1]):
                key *= span[j]
                key += a[:, j].astype(np.int64) - lo[j]
            packed = _packed(key)
            if packed is not None:          # sorted with its positions: a stable order
                packed, bits, _ = packed
                packed.sort()
                return packed & ((1 << bits) - 1)
            return np.argsort(key, kind="stable")
    return np.lexsort(a.T[::-1])


def linked_labels(n, a, b) -> np.ndarray:
    """(n,) int: for each of ``n`` items the smallest item of its connected component, the items
    ``a`` (k,) and ``b`` (k,) being linked pairwise: label propagation with pointer jumping, all
    links at once."""
    label = np.arange(n)
    a, b = np.asarray(a), np.asarray(b)
    while a.size:
        m = np.minimum(label[a], label[b])
        new = label.copy()
        np.minimum.at(new, a, m)
        np.minimum.at(new, b, m)
        new = new[new]
        if np.array_equal(new, label):
            break
        label = new
    return label


def run_positions(counts) -> np.ndarray:
    """(counts.sum(),) int64: each entry's place in its run, for runs of ``counts`` (R,) entries
    laid end to end (0 .. counts[0] - 1, then 0 .. counts[1] - 1, ...): how a ragged list is
    walked without a loop, ``np.repeat(starts, counts) + run_positions(counts)`` its indices."""
    counts = np.asarray(counts, dtype=np.int64)
    return np.arange(int(counts.sum())) - np.repeat(np.cumsum(counts) - counts, counts)
