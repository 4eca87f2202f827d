"""The rasteriser: convex polygons in pixel coordinates drawn into item buffers, in NumPy.

A polygon is given as K lists of corners ``px``, ``py`` (M,) float32 on its face (pixels are
unit squares, centre of pixel (i, j) at (i + 1/2, j + 1/2)), the rows of its face (R or R/2),
where its face starts in the item buffer, its reciprocal depth ``1/w = a px + b py + c`` and
the id to write. It is drawn as pixel spans: per polygon and pixel row, the edge functions
bound the run of pixel centres inside. Polygons are grouped by height and their rows laid out
(height, polygons), spans are grouped by length and expanded as (length, spans) grids, so
per-row and per-pixel work is broadcasting rather than gathers and ``np.repeat``.

Watertight: an edge function is evaluated in one canonical direction and negated for the
polygon that runs the other way, and a pixel centre on an edge goes by a fill rule
(:func:`_covers`), so a centre on a shared edge is covered by one of the two polygons and
never by neither (the callers give neighbours the same corners bit for bit).

The item buffer (P,) int64 keeps the nearest fragment per pixel (``np.minimum.at``): a key packs
the fragment's reciprocal depth, nearer is smaller, over its id (:func:`_fragment_keys`); a
pixel that sees nothing holds :func:`empty_key`.
"""
from __future__ import annotations

import sys

import numpy as np

__all__ = ["rasterise", "can_cover", "empty_key", "fold", "ID_MASK", "SNAP",
           "FRAGMENTS_PER_CHUNK"]

#: Span ends this close (in pixels) to a pixel centre are decided by the edge inequalities.
SNAP = 1e-3
#: Bound on the fragments expanded at once in the rasteriser (about 40 bytes each).
FRAGMENTS_PER_CHUNK = 1 << 21
#: The id half of an item-buffer key (the depth is the high half).
ID_MASK = np.int64(0xFFFFFFFF)
# index of the high 32-bit half of an int64 viewed as two int32
_HIGH = 1 if sys.byteorder == "little" else 0


def _covers(A, B, X, rhs):
    """Edge test with a fill rule: ``A X > rhs``, or on the edge (``A X == rhs``) when the edge
    is this polygon's to own (``A > 0``, or ``A == 0`` and ``B >= 0``: a padding edge of zero
    length, 0 >= 0 everywhere, never excludes).  A polygon sharing the edge
    has ``-A``, ``-B``, ``-rhs``: a pixel centre exactly on it goes to one of the two, decided by
    the geometry, not by which depth rounds nearer."""
    ax = A * X
    return (ax > rhs) | ((ax == rhs) & ((A > 0) | ((A == 0) & (B >= 0))))


def _edge_functions(px, py):
    """Edge functions of convex polygons in either winding.

    ``px``, ``py`` are lists of K arrays (M,) float32, the vertices in order.  Returns lists
    (a, b, c) of K arrays (M,) float32 and ``flat`` (M,) bool: ``a X + b Y + c >= 0`` for a
    point (X, Y) on the inner side of edge k (or on it).  ``c`` is computed from the edge's
    lexicographically first endpoint and its direction away from it, then negated as the
    polygon's winding needs, so two polygons sharing an edge evaluate exactly opposite values.
    ``flat`` marks polygons of zero area (they cover nothing; their coefficients are
    meaningless).  ``a`` is never -0.
    """
    K = len(px)
    area2 = None
    for k in range(K):  # summed left to right, as numpy sums a short row
        t = px[k] * py[(k + 1) % K] - px[(k + 1) % K] * py[k]
        area2 = t if area2 is None else area2 + t
    sgn = np.sign(area2).astype(np.float32)
    a_l, b_l, c_l = [], [], []
    for k in range(K):
        x0, y0, x1, y1 = px[k], py[k], px[(k + 1) % K], py[(k + 1) % K]
        dx, dy = x1 - x0, y1 - y0
        # first endpoint in (x, y) order: its x is the smaller one, its y that of the same end
        swap = (x1 < x0) | ((x1 == x0) & (y1 < y0))
        sx, sy = np.minimum(x0, x1), np.where(swap, y1, y0)
        a = (y0 - y1) * sgn
        a += np.float32(0)                                           # -0 -> +0
        a_l.append(a)
        b_l.append(dx * sgn)
        c_l.append((dy * sx - dx * sy) * sgn)
    return a_l, b_l, c_l, area2 == 0


#: Row-count classes of the rasteriser: polygons are rasterised in groups of similar height.
_ROW_CLASSES = (1, 2, 3, 4, 6, 8, 12, 16, 24, 32, 48, 64, 96, 128, 192, 256)
#: Span-length classes of the fragment stage: spans up to 8 pixels long are expanded by exact
#: length, longer ones padded up to the next class.
_SPAN_CLASSES = (1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 24, 32, 48, 64, 96, 128, 192, 256, 384, 512)
_EXACT_SPANS = 8


def _classes(bounds, top):
    """Class bounds up to ``top`` and a table: class of every size 0..top."""
    b = [x for x in bounds if x < top] + [top]
    return b, np.searchsorted(np.array(b), np.arange(top + 1)).astype(np.int8)


def rasterise(px, py, face_rows, pixel_base, depth, item, keys, R):
    """Write polygons into the item buffer (see :func:`_rasterise_quiet`); infinities and nans
    of edges parallel to the rows or of unbounded spans are expected, their warnings are off."""
    with np.errstate(divide="ignore", invalid="ignore"):
        _rasterise_quiet(px, py, face_rows, pixel_base, depth, item, keys, R)


def _rasterise_quiet(px, py, face_rows, pixel_base, depth, item, keys, R):
    """Write polygons into the item buffer, keeping the nearest fragment per pixel.

    Parameters
    ----------
    px, py : lists of K arrays (M,) float32
        Convex polygons in pixel coordinates of their face, padded by repeating a vertex.
    face_rows : (M,) int
        Rows of each polygon's face (R or R/2); columns are R for every face.
    pixel_base : (M,) int64
        Index in ``keys`` of pixel (0, 0) of the polygon's face for its receiver.
    depth : 3 arrays (M,) float32
        Reciprocal depth ``a px + b py + c`` per polygon.
    item : (M,) int32
        Id written to the item buffer.
    keys : (P,) int64
        Item buffer, updated in place: ``(depth bits << 32) | item``, smaller is nearer.
    R : int
        Pixels across a face.
    """
    j0, rows, i0, i1 = _pixel_range(px, py, face_rows, R)
    bounds, table = _classes(_ROW_CLASSES, R)
    cls = table[np.clip(rows, 0, R)]
    cls[(rows <= 0) | (i1 < i0)] = -1
    # one candidate pixel (one row, one column within SNAP of the x-range): a point test
    single = np.flatnonzero((rows == 1) & (i1 == i0))
    if single.size:
        cls[single] = -1
        _draw_points(i0[single], j0[single], [p[single] for p in px], [p[single] for p in py],
                     pixel_base[single], [d[single] for d in depth], item[single], keys, R)
    order = np.argsort(cls, kind="stable")                            # radix sort
    ends = np.cumsum(np.bincount(cls + 1, minlength=len(bounds) + 1))
    spans = []
    for ci in np.flatnonzero(np.diff(ends)):
        sel = order[ends[ci]:ends[ci + 1]]
        spans.append(_spans(bounds[ci], rows[sel], j0[sel], [p[sel] for p in px],
                            [p[sel] for p in py], pixel_base[sel], [d[sel] for d in depth],
                            item[sel], R))
    if not spans:
        return
    q0, dq, start, ids, n = (np.concatenate(s) for s in zip(*spans))
    if n.sum() <= FRAGMENTS_PER_CHUNK:
        _draw_spans(q0, dq, start, ids, n, keys, R)
        return
    ends = np.cumsum(n)
    lo = 0
    while lo < n.size:
        hi = int(np.searchsorted(ends, (ends[lo - 1] if lo else 0) + FRAGMENTS_PER_CHUNK, "right"))
        hi = max(hi, lo + 1)
        sl = slice(lo, hi)
        _draw_spans(q0[sl], dq[sl], start[sl], ids[sl], n[sl], keys, R)
        lo = hi


def _pixel_range(px, py, face_rows, R):
    """Candidate pixels of polygons: first row j0 (M,) int64, rows (M,) int64 (<= 0: none),
    first and last column i0, i1 (M,) float32 (i1 < i0: none).

    Rows are those whose centres lie in the polygon's y-range; columns those whose centres lie
    within ``SNAP`` of its x-range (rounding in the edge inequalities moves a boundary by far
    less than SNAP), both clamped to the face.
    """
    lo_y, hi_y = fold(np.minimum, py), fold(np.maximum, py)
    j0 = np.maximum(np.ceil(lo_y - np.float32(0.5)), 0).astype(np.int64)
    j1 = np.minimum(np.floor(hi_y - np.float32(0.5)), face_rows - 1).astype(np.int64)
    lo_x, hi_x = fold(np.minimum, px), fold(np.maximum, px)
    i0 = np.maximum(np.ceil(lo_x - np.float32(0.5 + SNAP)), 0)
    i1 = np.minimum(np.floor(hi_x - np.float32(0.5 - SNAP)), R - 1)
    return j0, j1 - j0 + 1, i0, i1


def can_cover(px, py, face_rows, R):
    """(M,) bool: polygons with a candidate pixel (:func:`_pixel_range`); the others are left
    out by :func:`rasterise` anyway."""
    with np.errstate(invalid="ignore"):
        _, rows, i0, i1 = _pixel_range(px, py, face_rows, R)
        return (rows > 0) & (i1 >= i0)


def fold(op, arrays):
    """``op`` folded over a list of arrays (faster than a reduction along a short axis)."""
    out = arrays[0]
    for a in arrays[1:]:
        out = op(out, a)
    return out


def _spans(height, rows, j0, px, py, pixel_base, depth, item, R):
    """Pixel spans covered by polygons of at most ``height`` rows, one per (polygon, pixel row).

    Pixel (i, j) is covered when its centre satisfies every edge function.  On row j each edge
    ``a X + b Y + c >= 0`` bounds X from one side at ``-(b Y + c) / a``; a polygon sharing the
    edge computes the same bound with both signs flipped, so the two spans meet without a gap.
    When a bound falls within ``SNAP`` of a pixel centre, that pixel is decided by the edge
    inequalities themselves (``a X >= -(b Y + c)``, exactly complementary between neighbours),
    not by the rounded quotient, so a centre lying on an edge is covered as a point test would.
    An edge parallel to the rows (``a = 0``) empties the rows outside it.

    The rows are laid out (height, S): row r of every polygon at once, no gathers.
    Returns (q0, dq, start, item, n) per span: reciprocal depth at the first pixel and its step
    along the row (float32), index of the first pixel in the item buffer, id, and length (> 0).
    """
    a, b, c, flat = _edge_functions(px, py)
    S = rows.size
    r = np.arange(height)[:, None]
    j = j0 + r
    Y = j.astype(np.float32) + np.float32(0.5)                         # (height, S)
    lo = hi = None
    rhs_l = []
    inf = np.float32(np.inf)
    zero = np.float32(0)
    # (called with division and invalid-value warnings off: see rasterise)
    for k in range(len(a)):
        A = a[k]
        rhs = (-b[k]) * Y + (-c[k])                                  # need A X >= rhs
        bound = rhs / A
        # a left edge (A > 0) bounds from below, a right edge (A < 0) from above; a level
        # edge (A = +0) gives +inf (row outside: empty), -inf or nan (no bound) from below
        # and nothing from above (nan and inf are ignored by fmax / fmin)
        l = bound + np.where(A < 0, -inf, zero)
        # a level edge through the row's centres (0 / 0): the row is inside when the edge is ours
        l = np.where((A == 0) & (rhs == 0) & (b[k] < 0), inf, l)
        h = bound + np.where(A >= 0, inf, zero)
        lo = l if lo is None else np.fmax(lo, l)
        hi = h if hi is None else np.fmin(hi, h)
        rhs_l.append(rhs)
    i_lo = np.maximum(_snap_to_pixels(lo, a, b, rhs_l, first=True), zero)
    i_hi = np.minimum(_snap_to_pixels(hi, a, b, rhs_l, first=False), np.float32(R - 1))
    n = i_hi - i_lo + 1
    ok = (n > 0) & (r < rows) & ~flat
    da, db, dc = depth
    idx = np.flatnonzero(ok)
    s = idx % S
    i_lo = i_lo.ravel()[idx]
    Yk = Y.ravel()[idx]
    dq = da[s]
    q0 = dq * (i_lo + np.float32(0.5)) + db[s] * Yk + dc[s]
    start = pixel_base[s] + j.ravel()[idx] * R + i_lo.astype(np.int64)
    return q0, dq, start, item[s], n.ravel()[idx].astype(np.int64)


def _snap_to_pixels(bound, A, B, rhs, first):
    """First (or last) pixel column whose centre lies inside, given the span bound on X.

    ``bound`` and ``rhs[k]`` are (height, S), ``A[k]``, ``B[k]`` (S,).  Columns whose centres
    are within ``SNAP`` of the bound are tested with the edge inequalities (all edges, with the
    fill rule of :func:`_covers`) instead of trusting the quotient's rounding.
    """
    t = bound - np.float32(0.5)
    col = np.ceil(t) if first else np.floor(t)
    near = np.round(t)
    check = np.flatnonzero(np.abs(t - near) < SNAP)                 # nan on an unbounded side
    if check.size:
        S = bound.shape[1]
        s = check % S
        nr = near.ravel()[check]
        X = nr + np.float32(0.5)
        inside = None
        for Ak, Bk, rk in zip(A, B, rhs):
            t_k = _covers(Ak[s], Bk[s], X, rk.ravel()[check])
            inside = t_k if inside is None else inside & t_k
        col.ravel()[check] = np.where(inside, nr, nr + (1 if first else -1))
    return col


def _fragment_keys(q, ids):
    """Item-buffer keys of fragments: reciprocal depths ``q`` (...) float32 and ids broadcasting
    against them (int32) packed as int64 ``((0x7F800000 - bits(q)) << 32) | id``, so the nearer
    fragment (the larger 1/w) has the smaller key; q is clamped to 1e-30 (positive bits)."""
    qbits = np.maximum(q, np.float32(1e-30)).view(np.int32)
    frag = np.empty(q.shape + (2,), dtype=np.int32)                   # (high, low) int64 halves
    np.subtract(np.int32(0x7F800000), qbits, out=frag[..., _HIGH])
    frag[..., 1 - _HIGH] = ids
    return frag.view(np.int64)[..., 0]


def empty_key(n):
    """Item-buffer key of a pixel that sees nothing: farther than any fragment, id ``n + 1``
    (fragments carry a patch id, or ``n`` for a back face)."""
    return (np.int64(0x7F800000) << 32) | np.int64(n + 1)


def _draw_points(i, j, px, py, pixel_base, depth, item, keys, R):
    """Depth-test polygons that can cover one pixel centre only, (i, j), into ``keys``.

    The pixel is covered when its centre satisfies every edge inequality ``a X >= -(b Y + c)``
    (on an edge: by the fill rule of :func:`_covers`)
    (as computed in :func:`_spans`, which decides a single candidate the same way), and its
    fragment carries the same depth and key as there.
    """
    a, b, c, flat = _edge_functions(px, py)
    X = i.astype(np.float32) + np.float32(0.5)
    Y = j.astype(np.float32) + np.float32(0.5)
    inside = ~flat
    for k in range(len(a)):
        inside &= _covers(a[k], b[k], X, (-b[k]) * Y + (-c[k]))
    sel = np.flatnonzero(inside)
    if not sel.size:
        return
    da, db, dc = depth
    X, Y = X[sel], Y[sel]
    q = da[sel] * X + db[sel] * Y + dc[sel]
    np.minimum.at(keys, pixel_base[sel] + j[sel] * R + i[sel].astype(np.int64), _fragment_keys(q, item[sel]))


def _draw_spans(q0, dq, start, ids, n, keys, R):
    """Depth-test the pixels of the spans into the item buffer ``keys`` (see :func:`rasterise`).

    Spans are grouped by length and expanded as (length, spans) grids, so the per-pixel work is
    broadcasting, not repeating.  The reciprocal depth of pixel ``start + o`` is ``q0 + dq o``
    in float32.
    """
    bounds, table = _classes(_SPAN_CLASSES, R)
    cls = table[n]
    order = np.argsort(cls, kind="stable")                            # radix sort
    counts = np.bincount(cls, minlength=len(bounds))
    q0, dq, start, ids = q0[order], dq[order], start[order], ids[order]
    lo = 0
    for ci in np.flatnonzero(counts):
        hi = lo + int(counts[ci])
        L = bounds[ci]
        o = np.arange(L)[:, None]
        q = q0[lo:hi] + dq[lo:hi] * o.astype(np.float32)             # (L, S)
        frag = _fragment_keys(q, ids[lo:hi])
        pix = start[lo:hi] + o
        if L > _EXACT_SPANS:  # padded class: keep the pixels inside the spans
            inside = o < n[order[lo:hi]]
            frag, pix = frag[inside], pix[inside]
        np.minimum.at(keys, pix.ravel(), frag.ravel())
        lo = hi
