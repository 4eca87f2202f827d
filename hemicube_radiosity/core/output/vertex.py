"""Patch radiosities to vertex radiosities, as in the paper (section "Rendering", fig. 8).

- A vertex interior to a surface takes the mean of the patches around it.
- A vertex on the surface's boundary is extrapolated from the adjacent interior vertices through
  its adjacent patches. The paper draws the line from the interior vertex through the patch
  average on to the boundary; we fit the same samples (adjacent patch centres with their
  radiosities, adjacent interior vertices with theirs) with a plane in the least-squares sense and
  evaluate it at the vertex. On a regular grid along an edge that is the paper's rule; unlike a
  single line it stays exact for linear variation at corners and next to them.
  Without an adjacent interior vertex the boundary vertex takes the patch mean.
  The fit reaches no further than the paper's line could: within its samples' range widened by
  its width on either side (:func:`_sample_bounds`), where an ill-conditioned fit (samples that
  nearly line up, or on the faces of a fold) would shoot far past every sample.
- A "surface" is what shares vertices: patches that do not share a vertex never mix, so callers
  split vertices at hard edges and material borders (see :mod:`.patches`).
Extrapolated values are clamped at 0 too (radiosity is never negative).
"""
from __future__ import annotations

import numpy as np

from ..runtime.cache import Memo, array_key, cache_key, cached, geometry_key
from ..mesh.patches import PatchSet
from ..util.unique import unique_ints, unique_rows

__all__ = ["vertex_radiosity", "frames", "exposure", "boundary_vertices", "BURIED", "fill_buried"]


def _incidence(polys):
    """(patch, vertex, corner) for every valid corner."""
    valid = polys >= 0
    p, c = np.nonzero(valid)
    return p, polys[p, c], c


def boundary_vertices(polys, n_verts) -> np.ndarray:
    """(V,) bool: vertex lies on an edge used by exactly one patch."""
    tri = polys[:, 3] < 0
    a = polys
    b = np.where(tri[:, None], polys[:, [1, 2, 0, 0]], polys[:, [1, 2, 3, 0]])
    valid = np.ones(polys.shape, bool)
    valid[tri, 3] = False
    e = np.sort(np.stack([a[valid], b[valid]], axis=1), axis=1)
    uniq, counts = unique_rows(e, return_counts=True)
    on = np.zeros(n_verts, bool)
    on[uniq[counts == 1].ravel()] = True
    return on


def exposure(F, areas=None) -> np.ndarray:
    """(N,) how much of each patch's hemisphere sees front faces or the sky: row sum + sky.

    A patch whose centre lies under a block standing on it sees only back faces (exposure 0):
    its value says nothing about the exposed rest of the patch. An empty row is either a row
    that was not computed (a patch that reflects nothing, e.g. a lamp) or a patch buried in a
    solid, which sees nothing. With ``areas`` they are told apart by reciprocity: others see a
    lamp (its row sum from the computed rows, ``sum_j A_j F_ji / A_i``, is what it would see),
    while a buried patch is seen only through the odd pixel leaking past the solid's edges
    (measured up to 1.2% of its hemisphere beside a block sunk 10 cm while pixels were sampled
    at their centres, none since: :data:`.pixels.SAMPLE_X`): below ``BURIED`` it counts as
    buried (0), else as exposed (1).
    Without ``areas`` every empty row counts as exposed. (Counting them all as exposed gave a
    floor patch wholly under a block the weight of an open one: the vertices it shares with
    open floor took half its zero.)"""
    rs = F.row_sums()
    sky = np.zeros_like(rs) if F.sky is None else np.asarray(F.sky, float)
    e = np.clip(rs + sky, 0.0, 1.0)
    empty = np.diff(F.indptr) == 0
    if areas is None or not empty.any():
        return np.where(empty, 1.0, e)
    areas = np.asarray(areas, dtype=np.float64)
    w = F.data.astype(np.float64) * areas[F.row_ids()]
    seen = np.bincount(F.indices, weights=w, minlength=F.shape[1])[:F.shape[0]] / np.maximum(areas, 1e-300)
    return np.where(empty, (seen >= BURIED).astype(np.float64), e)


#: An empty row whose reciprocal row sum is below this is a buried patch (:func:`exposure`).
BURIED = 0.05


def _boundary_interior_pairs(polys, boundary, interior):
    """(K, 2) unique pairs (boundary vertex, interior vertex) that share a patch."""
    k = polys.shape[1]
    pv = polys[:, :, None].repeat(k, 2).ravel()
    qv = polys[:, None, :].repeat(k, 1).ravel()
    ok = (pv >= 0) & (qv >= 0) & (pv != qv)
    pv, qv = pv[ok], qv[ok]
    ok = boundary[pv] & interior[qv]
    return unique_rows(np.stack([pv[ok], qv[ok]], 1))


_TOPOLOGY = Memo(8)      # polys -> (boundary, pairs): a relight reuses the patches'


def _topology(polys, V, cnt):
    """(boundary (V,) bool, pairs (K, 2)) of :func:`vertex_radiosity`: geometry only, so kept
    for the last few patch arrays (the same ``polys`` object, as a relight's cached patches are)."""
    def make():
        boundary = boundary_vertices(polys, V) & (cnt > 0)
        return boundary, _boundary_interior_pairs(polys, boundary, ~boundary & (cnt > 0))
    return _TOPOLOGY.of((polys,), make)


def vertex_radiosity(patches: PatchSet, B, extrapolate=True, weights=None, cache=None) -> np.ndarray:
    """(V, 3) radiosity per patch vertex from (N, 3) patch radiosities ``B``.

    ``weights`` (N,) weigh each patch in its vertices' averages and fits (e.g. :func:`exposure`,
    so a patch buried under a block does not darken the vertices it shares with lit ones); a
    vertex whose patches all weigh 0 takes their plain mean. ``extrapolate=False`` gives
    averages everywhere (for comparison). Vertices no patch uses get 0.

    ``cache`` (a :class:`.cache.FormFactorCache`): what depends only on the geometry and the
    weights (the incidences, the fits' samples and their 4 x 4 normal matrices factored,
    :func:`_fits`) is kept there, so a relight only sums its values into the fits and solves
    them by substitution, the same arithmetic as without a cache, bit for bit. (Folding the
    fits into one sparse matrix instead moved vertices whose samples lie nearly on a line, where
    the fit is ill-conditioned, by up to 2e-7 of the scene's largest value; the factors, with
    partial pivoting as LAPACK's, differ from LAPACK's solve by 2e-15 of the largest value on
    the dense Cornell room, whose worst fit's condition number is 3e12.)
    """
    B = np.asarray(B, dtype=np.float64)
    fit = _kept_fits(patches, weights, extrapolate, cache)
    avg, sparse = _weighted_means(fit[:5], B)
    if len(fit) == 5:
        return avg
    return _fitted(fit[5:], B, avg, sparse)


def _kept_fits(patches: PatchSet, weights, extrapolate, cache):
    """:func:`_fits` of ``patches`` with ``weights`` (N,) (or None), kept in ``cache`` (a
    :class:`.cache.FormFactorCache`, or None: made every time) by geometry and weights."""
    if cache is None:
        return _fits(patches, weights, extrapolate)
    wkey = b"" if weights is None else array_key(np.asarray(weights, dtype=np.float64))
    key = cache_key(geometry_key(patches) + wkey, ("vertex-fits-lu", weights is None, bool(extrapolate)))
    return cached(cache, key, lambda: _fits(patches, weights, extrapolate))


def _weighted_means(incidence, B):
    """(avg (V, k), sparse): at every vertex the weighted mean of its patches' ``B`` (N, k)
    (radiosity, or any per-patch field), from :func:`_fits`' ``incidence`` (patch p, vertex v,
    weight wp (I,), weight sums (V,), V); ``sparse``: most rows of ``B`` are 0, and only the
    rest were summed."""
    p, v, wp, safe, V = incidence
    Bt = np.ascontiguousarray(B.T)              # a band's values contiguous: B[p, k], taken faster
    # a field that is 0 on most patches (an emission field: only the lamps glow) sums only the
    # rest: a sum in order that skips terms of 0 is the same sum, bit for bit (it starts at +0,
    # so no partial sum is -0, and s + 0 = s)
    live = _nonzero_rows(Bt)
    sparse = live is not None and 4 * np.count_nonzero(live) < len(live)
    if sparse:                                  # the live patches' incidences (p is sorted)
        lp = np.flatnonzero(live)
        a, b = np.searchsorted(p, lp), np.searchsorted(p, lp, side="right")
        n = b - a
        i = np.repeat(a - np.cumsum(n) + n, n) + np.arange(int(n.sum()))
        p, v, wp = p[i], v[i], wp[i]
    avg = np.stack([np.bincount(v, weights=wp * Bt[k].take(p), minlength=V) for k in range(B.shape[1])], 1) / safe[:, None]
    return avg, sparse


def _fitted(fits, B, avg, sparse):
    """(V, k): ``avg`` (V, k) with each boundary vertex given its plane fit's value there,
    within its samples' bounds (:func:`_sample_bounds`): the fit of its patches' ``B`` (N, k) at
    their centres and its interior neighbours' ``avg``. ``fits``: :func:`_fits`' (patches
    sampled, interior vertices sampled (S,), each sample's fit (S,), the fitted vertices (T,),
    the samples' weighted [1, dx, dy, dz] (S, 4) (world units), normal matrices (T, 4, 4) and
    their factors); ``sparse``: only B's rows not 0 count (:func:`_weighted_means`)."""
    pp, iv, slot, targets, Xw, M, lu = fits
    sb = np.concatenate([B.take(pp, axis=0), avg.take(iv, axis=0)])
    lo, hi = _sample_bounds(sb, slot, targets.size)
    if sparse:
        i = np.flatnonzero(_nonzero_rows(np.ascontiguousarray(sb.T)))
        sb, slot, Xw = sb[i], slot[i], Xw[i]
    rhs = _fit_sums(Xw, sb, slot, targets.size)
    out = avg.copy()
    # a fit whose samples are all 0 (most of an emission field: only the lamps glow) is 0: solved
    # only where some sample is not (each 4 x 4 system is solved alone: the same values)
    flat = rhs.reshape(targets.size, -1)
    some = flat[:, 0] != 0                      # rhs.any(axis=1), a column at a time
    for c in range(1, flat.shape[1]):
        some |= flat[:, c] != 0
    if some.all():
        out[targets] = np.clip(_fit_solve(M, lu, rhs)[:, 0, :], lo, hi)
    else:
        out[targets] = 0.0
        if some.any():
            lu_some = None if lu is None else (lu[0][some], lu[1][some])
            out[targets[some]] = np.clip(_fit_solve(None if lu else M[some], lu_some, rhs[some])[:, 0, :],
                                         lo[some], hi[some])
    return out


def _fit_sums(Xw, sb, slot, T):
    """(T, 4, k) the normal equations' right-hand sides: per fit, ``sum_s Xw[s] sb[s]`` over its
    samples (``slot`` (S,)), from their weighted [1, dx, dy, dz] ``Xw`` (S, 4) and values
    ``sb`` (S, k). Per entry the samples are summed in order (as np.add.at sums them, bit for
    bit), every entry in one bincount (its samples come in the same order as in a bincount of
    its own), the terms made as (4, k, S)."""
    k = sb.shape[1]
    terms = (np.ascontiguousarray(Xw.T)[:, None, :] * np.ascontiguousarray(sb.T)[None, :, :]).reshape(-1)
    bins = (np.arange(4 * k)[:, None] + slot[None, :] * (4 * k)).reshape(-1)
    return np.bincount(bins, weights=terms, minlength=T * 4 * k).reshape(T, 4, k)


def _sample_bounds(sb, slot, T):
    """(lo, hi) (T, bands): how far each fit may reach, from its samples ``sb`` (S, bands)
    (``slot`` (S,): the fit of each): their range widened by its own width on either side, and
    not below 0. The paper's line from an interior vertex through a patch's centre reaches at
    most that far (the boundary vertex lies as far beyond the centre as the interior vertex
    before it); a plane fitted to samples that nearly line up, or to four samples on the faces
    of a fold (a window frame's moulding, patches turning 90 degrees at the vertex), solved
    exactly and ill-conditioned, reached 70 from samples under 0.1."""
    k = sb.shape[1]
    lo = np.full((T, k), np.inf)
    hi = np.full((T, k), -np.inf)
    np.minimum.at(lo, slot, sb)
    np.maximum.at(hi, slot, sb)
    width = hi - lo
    return np.maximum(lo - width, 0.0), hi + width


def _nonzero_rows(Bt):
    """(N,) bool: the rows of B not all 0, from Bt = B.T (bands, N) contiguous, a band at a time
    (faster than ``B.any(axis=1)`` over its short rows); None without bands."""
    if Bt.ndim != 2 or Bt.shape[0] == 0:
        return None
    live = Bt[0] != 0
    for band in Bt[1:]:
        live |= band != 0
    return live


def _lu(M):
    """(LU (T, n, n), pivot rows (T, n)) of a stack of matrices, by Gaussian elimination with
    partial pivoting (as LAPACK's getrf: the unit lower factor below the diagonal, the upper on
    and above), or None when a pivot is 0 (singular: :func:`_fit_solve` lets LAPACK say so).
    The fits' matrices depend on the geometry only: factored once, a relight substitutes
    (LAPACK's batched solve was slower, the more so on a busy machine: OpenBLAS's threads, not
    the arithmetic)."""
    A = np.array(M, dtype=np.float64)
    T, n, _ = A.shape
    perm = np.tile(np.arange(n), (T, 1))
    at = np.arange(T)
    for k in range(n):
        piv = k + np.abs(A[:, k:, k]).argmax(axis=1)        # rows k and piv change places
        row, pk = A[at, piv], perm[at, piv]                   # (copies: fancy indexing)
        A[at, piv], perm[at, piv] = A[:, k], perm[:, k]
        A[:, k], perm[:, k] = row, pk
        if not A[:, k, k].all():
            return None
        A[:, k + 1:, k] /= A[:, k, k][:, None]
        A[:, k + 1:, k + 1:] -= A[:, k + 1:, k, None] * A[:, k, None, k + 1:]
    return A, perm


def _fit_solve(M, lu, rhs):
    """(T, n, k) solutions of the systems ``M`` (T, n, n) for ``rhs`` (T, n, k), by substitution
    in their factors ``lu`` (:func:`_lu`), or by LAPACK without them."""
    if lu is None:
        return np.linalg.solve(M, rhs)
    A, perm = lu
    T, n = perm.shape
    k = rhs.shape[2]
    # P b (np.take_along_axis(rhs, perm[:, :, None], axis=1), by one take of rows), and the
    # substitutions on (n, k, T) and (n, n, T) copies: a system's values are its last axis, each
    # step one contiguous product per row (on (T, k) rows the (T, 1) factors were broadcast along
    # the short axis); the same operations on every value, bit for bit
    rows = (np.arange(T)[:, None] * n + perm).reshape(-1)
    x = np.ascontiguousarray(rhs.reshape(T * n, k).take(rows, axis=0).reshape(T, n, k).transpose(1, 2, 0))
    a = np.ascontiguousarray(A.transpose(1, 2, 0))
    for i in range(1, n):                      # L y = P b, L unit lower
        for j in range(i):
            x[i] -= a[i, j] * x[j]
    for i in range(n - 1, -1, -1):             # U x = y
        for j in range(i + 1, n):
            x[i] -= a[i, j] * x[j]
        x[i] /= a[i, i]
    return x.transpose(2, 0, 1)


def frames(patches: PatchSet, weights=None, cache=None):
    """:func:`.emitters.vertex_frames` ``(points, normals, rho)`` with ``weights``, its points and
    normals (geometry and weights only) kept in ``cache`` with the means' weights: a relight
    only averages the new reflectivity to the vertices, as vertex_frames does (bit for bit)."""
    from ..light.emitters import vertex_frames, vertex_weights
    if cache is None:
        return vertex_frames(patches, weights=weights)
    # the weights hashed once per array (a relight's are its cached elements' own)
    wkey = b"" if weights is None else array_key(np.asarray(weights, dtype=np.float64))

    def make():
        x, n, _ = vertex_frames(patches, weights=weights)
        return (x, n) + vertex_weights(patches, weights)
    key = cache_key(geometry_key(patches) + wkey, ("vertex-frames", weights is None))
    x, n, p, v, w, total = cached(cache, key, make)
    rho = np.ascontiguousarray(patches.rho.T)
    V = len(patches.verts)
    return x, n, np.stack([np.bincount(v, weights=w * rho[k].take(p), minlength=V) for k in range(rho.shape[0])], 1) / total


def _fits(patches: PatchSet, weights, extrapolate=True):
    """What :func:`vertex_radiosity` needs of the geometry and weights: (incidence patch p,
    vertex v, weight wp, weight sum per vertex, V) and, where boundary vertices are fitted,
    (patches sampled, interior vertices sampled, each sample's fit, the fitted vertices,
    the samples' weighted [1, dx, dy, dz] (S, 4), the fits' normal matrices (T, 4, 4))."""
    polys = patches.polys
    V = len(patches.verts)
    p, v, _ = _incidence(polys)
    cnt = np.bincount(v, minlength=V).astype(np.float64)
    w = np.ones(len(patches)) if weights is None else np.asarray(weights, dtype=np.float64)
    wsum = np.bincount(v, weights=w[p], minlength=V)
    plain = wsum <= 1e-6 * np.maximum(cnt, 1)
    wp = np.where(plain[v], 1.0, w[p])                          # per incidence
    safe = np.maximum(np.bincount(v, weights=wp, minlength=V), 1e-300)
    if not extrapolate:
        return p, v, wp, safe, V
    boundary, pairs = _topology(polys, V, cnt)
    if pairs.size == 0:
        return p, v, wp, safe, V
    bv, iv = pairs[:, 0], pairs[:, 1]
    has = np.zeros(V, bool)
    has[bv] = True
    # samples per boundary vertex: its patches (centre, B) and its interior neighbours (position, avg)
    pb = boundary[v] & has[v] & (wp > 0)
    sv = np.concatenate([v[pb], bv])
    sx = np.concatenate([patches.centers[p[pb]], patches.verts[iv]])
    sw = np.concatenate([wp[pb], np.ones(bv.size)])
    order = unique_ints(sv, return_inverse=True)
    targets, slot = order[0], order[1].reshape(-1)
    d = sx - patches.verts[sv]                                # offsets from the vertex
    X = np.concatenate([np.ones((len(sv), 1)), d], axis=1)     # (S, 4): [1, dx, dy, dz]
    M = np.zeros((targets.size, 4, 4))
    np.add.at(M, slot, sw[:, None, None] * X[:, :, None] * X[:, None, :])
    # samples on a surface leave the gradient along the normal free: a tiny ridge term fixes it
    scale = np.einsum("ij,ij->i", d, d)
    lam = 1e-9 * np.bincount(slot, weights=scale, minlength=targets.size) / np.bincount(slot, minlength=targets.size)
    lam = np.maximum(lam, 1e-30)
    M[:, 1:, 1:] += lam[:, None, None] * np.eye(3)
    return p, v, wp, safe, V, p[pb], iv, slot, targets, sw[:, None] * X, M, _lu(M)


def fill_buried(patches: PatchSet, values, weights, rings=16, cache=None) -> np.ndarray:
    """(V, k) ``values`` (per vertex, from :func:`vertex_radiosity` with ``weights``) where every
    vertex whose patches all weigh nothing (buried: under a block, below a floor a block is
    sunk into) takes the mean of its neighbours' (through a patch, or at the same place) that
    do not, ring by ring inward, ``rings`` at most (further in, they keep theirs).

    For what is read by the final gather's rays, not for output: a block's side sunk into a
    floor ends in patches below the floor that see nothing (0); the elements across the floor
    line took 0 at their buried corners, and rays from the floor beside the block, which land
    on the side within millimetres of the floor, read their bilinear mix: the open floor's
    limit on the outline 17% dark. The buried floor under a block is read by no ray.

    Which vertex takes which neighbours' values, ring by ring, depends on the geometry and
    ``weights`` only (:func:`_fill_rings`): kept in ``cache`` (a :class:`.cache.FormFactorCache`)
    when given, so a relight only averages its values (the same sums, bit for bit)."""
    values = np.asarray(values, dtype=np.float64)
    if cache is None:
        steps = _fill_rings(patches, weights, rings)
    else:
        wkey = array_key(np.asarray(weights, dtype=np.float64))
        steps = cached(cache, cache_key(geometry_key(patches) + wkey, ("fill-rings", rings)),
                       lambda: _fill_rings(patches, weights, rings))
    if not steps:
        return values
    out = values.copy()
    V = len(patches.verts)
    for a, b, got, n in steps:
        for c in range(values.shape[1]):
            out[got, c] = np.bincount(a, weights=out[b, c], minlength=V)[got] / n
    return out


def _fill_rings(patches: PatchSet, weights, rings=16) -> list:
    """The rings of :func:`fill_buried`: per ring (vertex a, neighbour b it reads (e,), the
    vertices filled (V,) bool, how many neighbours each reads); [] when nothing is buried."""
    polys = patches.polys
    V = len(patches.verts)
    p, v, _ = _incidence(polys)
    cnt = np.bincount(v, minlength=V)
    wsum = np.bincount(v, weights=np.asarray(weights, dtype=np.float64)[p], minlength=V)
    buried = (cnt > 0) & (wsum <= 1e-6 * np.maximum(cnt, 1))
    if not buried.any():
        return []
    k = polys.shape[1]
    touch = buried[np.maximum(polys, 0)].any(axis=1)          # patches with a buried corner
    sub = polys[touch]
    a = np.repeat(sub, k, axis=1).ravel()
    b = np.tile(sub, (1, k)).ravel()
    ok = (a >= 0) & (b >= 0) & (a != b) & buried[np.maximum(a, 0)]
    a, b = a[ok], b[ok]
    # and vertices at one place (a vertex parted by a floor a block is sunk into: its copy
    # below the floor takes the one above)
    place = unique_rows(patches.verts, return_inverse=True)[1].reshape(-1)
    order = np.argsort(place, kind="stable")
    same = np.flatnonzero(place[order][1:] == place[order][:-1])
    if same.size:
        x, y = order[same], order[same + 1]
        a, b = np.concatenate([a, x, y]), np.concatenate([b, y, x])
        keep = buried[a]
        a, b = a[keep], b[keep]
    steps = []
    known = ~buried
    for _ in range(rings):
        use = ~known[a] & known[b]
        if not use.any():
            break
        n = np.bincount(a[use], minlength=V)
        got = n > 0
        steps.append((a[use], b[use], got, n[got]))
        known |= got
    return steps
