"""Radiosity solvers: B = S + rho * (F @ B), per colour band, with F stored sparse.

S is the source term in radiance units: the patches' emission, plus (when lamps or a world are
modelled) the first bounce of their direct light, ``rho * H_direct / pi``.

Every solver returns a :class:`Solution` with the same fields, so they can be swapped and
compared. All of them stop on a bound on the error, not on the size of the last step: with
``T = rho F`` and ``gamma = max_i rho_i * rowsum_i`` (< 1, checked), the error of any B obeys

    max|B - B*| <= max|B - S - T B| / (1 - gamma)

(``(I - T)^-1 = I + T + T^2 + ...`` has infinity norm <= 1 / (1 - gamma)). At rho near 1 the error
is ~1 / (1 - rho) times the residual, and a step-size rule stopped 1-10 % short of B*. The
bound is exact for a closed room of one reflectivity and conservative elsewhere (by about
(1 - lambda) / (1 - gamma), lambda the spectral radius of T). Inputs that could make the iteration diverge (reflectivity outside [0, 1), a row of F
summing past 1 such that rho * rowsum >= 1, negative or non-finite sources) are rejected with
a clear error instead of diverging silently.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..runtime.progress import Ticker
from ..runtime.errors import RadiosityError
from ..util.sparse import CSR


class SolveError(RadiosityError, ValueError):
    """The equation cannot be solved as given (a reflectivity of 1 or more, a non-finite value):
    a user-facing problem of the scene, one line."""

__all__ = ["Solution", "solve", "residual", "energy_balance", "gain", "error_bound", "SOLVERS"]

SOLVERS = ("gauss_seidel", "jacobi", "progressive")


@dataclass
class Solution:
    """B (N,3) radiosities; iterations (sweeps, or shots for 'progressive'); residual
    ``max|B - S - rho F B| / max|B|``; energy balance (see :func:`energy_balance`);
    ``error_bound`` = residual / (1 - gamma) bounds ``max|B - B*| / max|B|`` (the module
    docstring says why); ``converged`` is ``error_bound <= tol``."""

    B: np.ndarray
    iterations: int
    residual: float
    energy: dict
    method: str
    converged: bool
    extra: dict = field(default_factory=dict)
    error_bound: float = float("nan")


def _check(F: CSR, rho, source):
    n = F.shape[0]
    rho = np.asarray(rho, dtype=np.float64)
    source = np.asarray(source, dtype=np.float64)
    if F.shape[0] != F.shape[1]:
        raise ValueError(f"form-factor matrix must be square, got {F.shape}")
    for name, a in (("reflectivity", rho), ("source", source)):
        if a.shape != (n, 3):
            raise ValueError(f"{name} must have shape ({n}, 3), got {a.shape}")
        if not np.all(np.isfinite(a)):
            i = int(np.flatnonzero(~np.all(np.isfinite(a), axis=1))[0])
            raise SolveError(f"{name} of patch {i} is not finite: {tuple(a[i])}")
    bad = (rho < 0) | (rho >= 1)
    if bad.any():
        i, b = (int(x[0]) for x in np.nonzero(bad))
        raise SolveError(f"reflectivity of patch {i} band {'RGB'[b]} is {rho[i, b]:g}; "
                         "it must be in [0, 1) (rho >= 1 creates energy and the solve diverges)")
    if (source < 0).any():
        i, b = (int(x[0]) for x in np.nonzero(source < 0))
        raise SolveError(f"source of patch {i} band {'RGB'[b]} is negative ({source[i, b]:g})")
    rs = F.row_sums()
    gain = rho * rs[:, None]
    if (gain >= 1).any():
        i = int(np.argmax(gain.max(axis=1)))
        raise SolveError(f"patch {i}: reflectivity x form-factor row sum = {gain[i].max():.4f} >= 1; "
                         "the form factors are inconsistent (row sum > 1) and the solve would diverge")
    return rho, source


def gain(F: CSR, rho) -> float:
    """``gamma = max_i max_band rho_i * rowsum_i``, the infinity norm of ``rho F``."""
    rho = np.asarray(rho, dtype=np.float64)
    return float((rho.max(axis=1) * F.row_sums()).max(initial=0.0))


def error_bound(residual_value: float, gamma: float) -> float:
    """Bound on ``max|B - B*| / max|B|`` from the relative residual and :func:`gain`."""
    return float(residual_value / (1.0 - gamma))


def _indices(F) -> np.ndarray:
    """F's column indices as the platform's index type, kept on F (a relight solves the same F
    again): ``take`` converts int32 indices on every call. The sweeps' blocks are views of it."""
    if F.indices.dtype == np.intp:
        return F.indices
    return F.memo("indices64", lambda: F.indices.astype(np.intp))


def _matvec(F, x) -> np.ndarray:
    """``F.matvec(x)``, the same sums bit for bit (float32 entries times float64 values, each
    non-empty row summed by one ``reduceat``), with F's index arrays kept on F: 0.62 -> 0.36 ms
    for the dense Cornell room's 451 x 451 F (80k entries), three per solve."""
    x = np.asarray(x, dtype=np.float64)
    one = x.ndim == 1
    xt = np.ascontiguousarray((x[:, None] if one else x).T)
    nonempty, starts = F.memo("row-starts", lambda: (
        np.flatnonzero(np.diff(F.indptr)), F.indptr[:-1][np.diff(F.indptr) > 0]))
    out = np.zeros((F.shape[0], xt.shape[0]))
    if starts.size:
        cols, data = _indices(F), F.data
        for k in range(xt.shape[0]):
            # 'wrap': the columns are in range (the same values), without take's bounds check
            out[nonempty, k] = np.add.reduceat(data * xt[k].take(cols, mode="wrap"), starts)
    return out[:, 0] if one else out


def _residual_vec(F, rho, S, B):
    return S + rho * _matvec(F, B) - B


def _checked(F, rho, S, B, gamma):
    """The better of B and one Jacobi step from it, ``B + r``, by the error bound; returns
    (B, its residual vector, its bound). The step's residual ``rho F r`` has lost the parts
    of r that ``(I - rho F)^-1`` barely amplifies and the bound counts as if amplified by
    ``1 / (1 - gamma)``: after over-relaxed sweeps that makes the bound ~10-100x tighter, and
    it is close to the true error. Two products with F."""
    r = _residual_vec(F, rho, S, B)
    Bj = B + r
    rj = rho * _matvec(F, r)
    s0, sj = np.abs(B).max(), np.abs(Bj).max()
    b0 = np.abs(r).max() / (1.0 - gamma) / s0 if s0 > 0 else (0.0 if not r.any() else np.inf)
    bj = np.abs(rj).max() / (1.0 - gamma) / sj if sj > 0 else (0.0 if not rj.any() else np.inf)
    return (Bj, rj, bj) if bj <= b0 else (B, r, b0)


def residual(F: CSR, rho, source, B, row_ids=None, FB=None) -> float:
    """Relative residual ``max|B - S - rho F B| / max|B|`` (0 when B is all zero and S is too).
    ``FB``: ``F.matvec(B)`` when the caller has it."""
    r = B - source - rho * (F.matvec(B, row_ids) if FB is None else FB)
    scale = np.abs(B).max()
    return float(np.abs(r).max() / scale) if scale > 0 else float(np.abs(r).max())


def energy_balance(F: CSR, rho, source, B, areas, row_ids=None, computed=None, FB=None) -> dict:
    """Power bookkeeping per band, in radiance x area units (multiply by pi for watts).

    emitted  = sum A_i S_i
    absorbed = sum A_i (1 - rho_i) H_i,   H = F @ B (incident radiance)
    escaped  = sum A_i B_i (1 - rowsum_i) (left through openings, or onto back faces)
    With reciprocity ``A_i F_ij = A_j F_ji`` and a converged B, emitted = absorbed + escaped;
    ``imbalance`` is the relative difference, a check on both the form factors and the solve.
    ``computed`` (N,) bool marks rows that were computed; rows left out (patches with rho = 0,
    whose radiosity needs no gathering) get their row sum and incident radiance by reciprocity
    from the computed rows: ``F_ji = A_i F_ij / A_j``. ``FB``: ``F.matvec(B)`` when the caller
    has it.
    """
    areas = np.asarray(areas, dtype=np.float64)
    H = F.matvec(B, row_ids) if FB is None else FB
    rs = F.row_sums()
    if computed is not None and not np.all(computed):
        miss = ~np.asarray(computed, bool)
        # column sums of A_i F_ij over computed rows i, without forming the transpose
        # (only the entries in the left-out columns matter: few, e.g. the lights); which
        # entries those are is kept on F for the rows left out (a relight's are the same)
        rid, col, data = F.memo(("left-out-columns", np.packbits(miss).tobytes(), miss.size),
                                 lambda: _left_out_entries(F, miss))
        w = data * (areas * computed)[rid]
        n = F.shape[1]
        rs_recip = np.bincount(col, weights=w, minlength=n) / areas
        H_recip = np.stack([np.bincount(col, weights=w * B[rid, k], minlength=n)
                            for k in range(B.shape[1])], 1) / areas[:, None]
        rs = np.where(miss, rs_recip, rs)
        H = np.where(miss[:, None], H_recip, H)
    a = areas[:, None]
    emitted = (a * source).sum(axis=0)
    absorbed = (a * (1 - rho) * H).sum(axis=0)
    escaped = (a * B * (1 - rs[:, None])).sum(axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        imb = np.where(emitted > 0, np.abs(emitted - absorbed - escaped) / emitted, 0.0)
    return {"emitted": emitted.tolist(), "absorbed": absorbed.tolist(), "escaped": escaped.tolist(),
            "imbalance": float(np.max(imb))}


def _left_out_entries(F, miss):
    """(row (e,), column (e,), value (e,) float64) of F's entries in the columns ``miss`` (N,)
    bool, in F's order."""
    sel = np.flatnonzero(miss[F.indices])
    return F.row_ids()[sel], F.indices[sel], F.data[sel].astype(np.float64)


def _segment_sums(vals, cols, x, starts, nonempty, nrows):
    """Row sums of ``vals * x[cols]`` per band; x is (bands, N) float32 (half the memory traffic
    of the gathers), sums accumulate in float64; rows given by CSR ``starts`` of the non-empty
    rows. Returns (nrows, bands)."""
    out = np.zeros((nrows, x.shape[0]))
    if starts.size:   # every band at once: the same sums, bit for bit, a third of the calls
        out[nonempty] = np.add.reduceat(x.take(cols, axis=1, mode="wrap") * vals, starts, axis=1,
                                        dtype=np.float64).T
    return out


def _gs_blocks(F, rho_max, size, omega):
    """Row blocks for the block sweep, in order. With over-relaxation (omega > 1) a Jacobi step
    inside a block is safe only when the rows of a block barely see each other: the splitting
    converges when ``2 / omega - 1`` exceeds the coupling inside the blocks (Ostrowski-Reich for
    ``A = I - rho F``, symmetric up to a diagonal scaling by reciprocity). A block whose rows
    gather more than half that from the block itself is halved until they do not (patches of
    one flat face never see each other, so blocks along a face stay whole)."""
    n = F.shape[0]
    ip, ix = F.indptr, F.indices
    dv = np.asarray(F.data, dtype=np.float32)   # no copy: F is stored float32
    limit = None if omega <= 1.0 else 0.5 * (2.0 / omega - 1.0)
    bounds = []
    # F's part of it (each block's coupling, its slices) once per F: a relight solves again
    memo = F.memo("gs-blocks", dict)

    def coupling(b0, b1):
        """(b1 - b0,) what each row of the block gathers from the block itself, or None."""
        if ("c", b0, b1) not in memo:
            s, e = ip[b0], ip[b1]
            cols = ix[s:e]
            inside = (cols >= b0) & (cols < b1)
            c = None
            if inside.any():
                rows = np.repeat(np.arange(b1 - b0), np.diff(ip[b0:b1 + 1]))
                c = np.bincount(rows[inside], weights=dv[s:e][inside], minlength=b1 - b0)
            memo["c", b0, b1] = c
        return memo["c", b0, b1]

    def split(b0, b1):
        if limit is not None and b1 - b0 > 1:
            c = coupling(b0, b1)
            if c is not None and (c * rho_max[b0:b1]).max() > limit:
                mid = (b0 + b1) // 2
                split(b0, mid)
                split(mid, b1)
                return
        bounds.append((b0, b1))

    for b0 in range(0, n, size):
        split(b0, min(n, b0 + size))
    blocks = []
    cols64 = _indices(F)                        # a block's columns: a view of them
    for b0, b1 in bounds:
        if ("b", b0, b1) not in memo:
            s, e = ip[b0], ip[b1]
            counts = np.diff(ip[b0:b1 + 1])
            nonempty = np.flatnonzero(counts)
            starts = (ip[b0:b1][nonempty] - s).astype(np.int64)
            memo["b", b0, b1] = (b0, b1, cols64[s:e], dv[s:e], starts, nonempty)
        blocks.append(memo["b", b0, b1])
    return blocks


def _sor_sweep(blocks, rhoT, ST, BT, B32, w):
    """One over-relaxed block Gauss-Seidel sweep, in place; returns the largest change of a value.

    ``blocks`` from :func:`_gs_blocks`; rhoT, ST (bands, N) reflectivity and source, band-major
    as BT, the (bands, N) float64 radiosities, updated block by block (a block's values are
    computed as (bands, rows), the same arithmetic per value as row-major, without transposes);
    B32 the copy the gathers read (a float32 copy of BT, kept up to date, or BT itself); w the
    relaxation factor (1 = plain Gauss-Seidel).

    Every value changes once a sweep, so the largest change is taken once, from a copy of BT
    before it (the same differences as block by block), and the gathers' columns are intp
    views (:func:`_indices`), read without take's bounds check: 3.7 -> 2.6 ms for the six
    sweeps of the dense Cornell room's relight (451 unknowns in 33 blocks), the same values."""
    before = BT.copy()
    for b0, b1, cols, vals, starts, nonempty in blocks:
        if starts.size == b1 - b0:            # every row sees something: the sums are the rows
            acc = np.add.reduceat(B32.take(cols, axis=1, mode="wrap") * vals, starts, axis=1, dtype=np.float64)
        else:
            acc = _segment_sums(vals, cols, B32, starts, nonempty, b1 - b0).T
        new = ST[:, b0:b1] + rhoT[:, b0:b1] * acc
        if w != 1.0:
            old = BT[:, b0:b1]
            new = old + w * (new - old)
        BT[:, b0:b1] = new
        if B32 is not BT:
            B32[:, b0:b1] = new
    return float(np.abs(BT - before).max(initial=0.0))


class _Relaxation:
    """The relaxation factor ``w`` of :func:`_gauss_seidel` and the row blocks that go with it.

    Given ``omega``, w stays there. With ``omega`` None the first sweeps are plain Gauss-Seidel
    and :meth:`observe` picks Young's optimum from the ratio of their changes once it settles;
    then, should the changes grow past 1000 times the smallest since (SOR grows for a while
    first, then diverges if w is too large), w is halved towards 1 (and dropped to 1 below
    1.05). ``blocks`` are rebuilt at every change of w (:func:`_gs_blocks` depends on it).
    """

    def __init__(self, F, rho_max, size, omega):
        self.F, self.rho_max, self.size = F, rho_max, size
        self.adaptive = omega is None            # pick omega once, from the first sweeps
        self.w = 1.0 if self.adaptive else float(omega)
        self.blocks = _gs_blocks(F, rho_max, size, self.w)
        self.changes = []                        # absolute: their ratio is the convergence rate
        self.best = np.inf

    def _set(self, w):
        self.w = w
        self.blocks = _gs_blocks(self.F, self.rho_max, self.size, w)
        self.best = self.changes[-1]

    def observe(self, change):
        """Record the largest change of a sweep and adapt w from the record."""
        changes = self.changes
        changes.append(change)
        if not self.adaptive:
            return
        w = self.w
        if w == 1.0 and len(changes) >= 3 and changes[-2] > 0:
            q, qp = changes[-1] / changes[-2], changes[-2] / max(changes[-3], 1e-300)
            # the ratio settles on mu^2 after a few sweeps (from below: the first ones
            # are faster); near 1, omega needs it to a fraction of 1 - q
            if q < 1 and len(changes) >= 4 and (abs(q - qp) <= 0.1 * (1 - q) or len(changes) >= 12):
                w_new = min(1.95, 2.0 / (1.0 + np.sqrt(1.0 - q)))
                self.adaptive = w_new > 1.05
                if self.adaptive:
                    self._set(float(w_new))
        elif w > 1.0:
            self.best = min(self.best, changes[-1])
            if changes[-1] > 1e3 * self.best:   # diverging: relax less
                w = 1.0 + 0.5 * (w - 1.0)
                if w < 1.05:
                    w, self.adaptive = 1.0, False
                self._set(w)


def _gauss_seidel(F, rho, S, tol, max_it, ticker, gamma, block=None, omega=None):
    """Gauss-Seidel sweeps over blocks of rows, over-relaxed (SOR): each block is updated at
    once from the newest values of every block before it (block Gauss-Seidel, a Jacobi step
    inside a block). With ``block=1`` this is the paper's row-by-row Gauss-Seidel; larger blocks
    trade a little convergence per sweep for NumPy-speed sweeps (default: N/32 rows, at most
    256).

    ``omega`` None picks the relaxation factor from the sweeps themselves: the first sweeps are
    plain Gauss-Seidel, whose change shrinks by about mu^2 per sweep (mu the spectral radius of
    rho F), and then ``omega = 2 / (1 + sqrt(1 - mu^2))`` (Young's optimum). At rho = 0.99 in a
    closed room that is ~1.75 and cuts the sweeps ~9x; in an open room mu is small and omega
    stays near 1. Should the changes grow (the estimate was wrong), omega is halved towards 1
    (:class:`_Relaxation`).

    Stops when the error bound is below ``tol``: the change of a sweep bounds the residual
    (``|r| <= ((omega - 1) / omega + gamma) max|change|``), and the exact residual (one product
    with F) confirms it before stopping; if the float32 copy of B that the sweeps read limits the
    residual, the sweeps go on in float64. Returns B, sweeps, converged, omega."""
    relax = _Relaxation(F, rho.max(axis=1), block or max(1, min(256, F.shape[0] // 32)), omega)
    BT = np.ascontiguousarray(S.T).copy()   # (bands, N): contiguous gathers per band
    B32 = BT.astype(np.float32)             # what the gathers read (half the memory traffic)
    rhoT, ST = np.ascontiguousarray(rho.T), np.ascontiguousarray(S.T)
    calib = 0.2          # exact bound / cheap bound, learnt at each exact check
    it, converged = 0, False
    for it in range(1, max_it + 1):
        w = relax.w
        change = _sor_sweep(relax.blocks, rhoT, ST, BT, B32, w)
        ticker.tick(it, max_it)
        scale = np.abs(BT).max()
        if scale == 0:
            converged = True
            break
        cheap = ((w - 1.0) / w + gamma) * change / (1.0 - gamma) / scale
        if cheap * calib <= tol:
            Bc, _, exact = _checked(F, rho, S, BT.T, gamma)
            if exact <= tol:
                BT = np.ascontiguousarray(Bc.T)
                converged = True
                break
            if cheap <= tol and B32 is not BT:
                B32 = BT                    # the float32 copy is the floor: read float64 from now on
            calib = max(exact / max(cheap, 1e-300), 1e-3) * 1.1
        relax.observe(change)
    return np.ascontiguousarray(BT.T), it, converged, relax.w


def _jacobi(F, rho, S, tol, max_it, ticker, gamma):
    """Jacobi iteration ``B += alpha r`` on the residual ``r = S + rho F B - B``, with the step
    alpha per band that minimises the next residual (alpha = 1 is plain Jacobi). The residual
    of a Jacobi sweep is dominated by the slowest mode of ``rho F``, for which the best step
    is ``1 / (1 - lambda)``: the minimal-residual step takes it, so a closed room at rho = 0.999
    needs a few sweeps instead of thousands. One product with F per sweep, as plain Jacobi;
    the residual is carried along and recomputed every 32 sweeps and before stopping."""
    B = S.copy()
    r = _residual_vec(F, rho, S, B)
    it, converged = 0, False
    for it in range(1, max_it + 1):
        ticker.tick(it, max_it)
        Tr = rho * F.matvec(r)
        # B + r (a plain Jacobi step) has residual rho F r: stop there when its bound allows
        scale = np.abs(B + r).max()
        if scale == 0 or np.abs(Tr).max() / (1.0 - gamma) <= tol * scale:
            B = B + r
            r = _residual_vec(F, rho, S, B)          # the carried residual drifts: confirm
            if scale == 0 or np.abs(r).max() / (1.0 - gamma) <= tol * np.abs(B).max():
                converged = True
                break
            continue
        d = r - Tr                                   # (I - rho F) r
        dd = (d * d).sum(axis=0)
        with np.errstate(invalid="ignore", divide="ignore"):
            alpha = (r * d).sum(axis=0) / dd
        alpha = np.where(np.isfinite(alpha) & (alpha > 0), np.minimum(alpha, 1.0 / (1.0 - gamma)), 1.0)
        B = B + alpha * r
        r = r - alpha * d
        if it % 32 == 0:
            r = _residual_vec(F, rho, S, B)
    return B, it, converged


def _progressive(F, rho, S, tol, max_it, ticker, areas, gamma):
    """Southwell iteration ("shooting"): the patch with the most unshot power distributes it.

    Uses the columns of F (F transposed), so it converges to the same B as the gathering solvers
    even when F is not exactly reciprocal. B includes the unshot radiosity u, and the residual
    of B is ``rho F u`` (so ``max|error| <= gamma max|u| / (1 - gamma)``).

    Every N shots, Cohen et al. (1988)'s ambient term goes into B: a uniform radiosity c per
    band, with the c that leaves the least residual (``(I - rho F) 1 = 1 - rho rowsum``; in a
    closed room of one reflectivity this is the exact remainder ``u rho / (1 - rho)`` and
    finishes the solve; in an open scene c is small). Then B takes one Jacobi step,
    ``B += r``, ``u = r`` with r its exact residual, which keeps ``residual = rho F u`` and
    clears the float drift of u. ``extra['ambient']`` is the ambient term of what is left.
    """
    n = F.shape[0]
    FT = F.transpose()
    ip, ix, dv = FT.indptr, FT.indices, FT.data.astype(np.float64)
    B = S.copy()
    unshot = S.copy()
    a = np.ones(n) if areas is None else np.asarray(areas, dtype=np.float64)
    power = a * np.abs(unshot).sum(axis=1)
    leak = 1.0 - rho * F.row_sums()[:, None]          # (I - rho F) applied to a uniform 1
    max_shots = max_it * n
    shots, converged = 0, False
    limit = tol * (1.0 - gamma) / max(gamma, 1e-300)
    while shots < max_shots:
        scale = np.abs(B).max()
        if scale == 0 or np.abs(unshot).max() <= limit * scale or (shots and shots % n == 0):
            res = _residual_vec(F, rho, S, B)
            den = (a[:, None] * leak * leak).sum(axis=0)
            with np.errstate(invalid="ignore", divide="ignore"):
                c = (a[:, None] * res * leak).sum(axis=0) / den
            c = np.where(np.isfinite(c) & (c > 0), c, 0.0)
            B = B + c
            res = res - c * leak
            B = B + res                                   # a Jacobi step: residual rho F res
            unshot = res
            Tr = rho * F.matvec(res)
            scale = np.abs(B).max()
            if scale == 0 or np.abs(Tr).max() / (1.0 - gamma) <= tol * scale:
                converged = True
                unshot = np.zeros_like(B)
                break
            power = a * np.abs(unshot).sum(axis=1)
            ticker.tick(shots, max_shots)
        i = int(np.argmax(power))
        r = unshot[i].copy()
        unshot[i] = 0.0
        power[i] = 0.0
        s, e = ip[i], ip[i + 1]
        j = ix[s:e]
        d = rho[j] * (dv[s:e, None] * r[None, :])
        B[j] += d
        unshot[j] += d
        power[j] = a[j] * np.abs(unshot[j]).sum(axis=1)
        shots += 1
    rho_avg = (a[:, None] * rho).sum(0) / a.sum()
    ambient = (a[:, None] * unshot).sum(0) / a.sum() / np.maximum(1e-12, 1 - rho_avg)
    return B, shots, converged, {"ambient": ambient.tolist(), "sweeps": shots / max(n, 1)}


def solve(F: CSR, rho, source, method="gauss_seidel", tol=1e-4, max_iterations=200, areas=None,
          progress=None, cancelled=None, computed=None) -> Solution:
    """Solve ``B = S + rho F B`` for all three bands.

    method: 'gauss_seidel' (the paper's, over-relaxed), 'jacobi' (with a minimal-residual step
    length), or 'progressive' (Southwell shooting, plus the ambient step every N shots).
    tol: the relative error target. The solve stops when ``max|B - B*| <= tol * max|B|`` is
    guaranteed by the bound ``residual / (1 - gamma)`` (``gamma = max rho * rowsum``; see the
    module docstring), so at rho near 1 it iterates further than a step-size rule would.
    max_iterations: sweeps (for 'progressive', ``max_iterations * N`` shots); a solve that
    reaches it returns ``converged=False`` with its residual and ``error_bound``, never hangs.
    ``areas`` (N,) enables the energy balance and area-weighted shooting order; ``computed`` is
    passed to :func:`energy_balance`. Raises ValueError on inputs that would diverge.
    """
    if method not in SOLVERS:
        raise ValueError(f"unknown solver {method!r}; choose one of {', '.join(SOLVERS)}")
    if not tol > 0:
        raise ValueError(f"tolerance must be > 0, got {tol}")
    rho, S = _check(F, rho, source)
    ticker = Ticker(progress, cancelled)
    rid = F.row_ids()
    gamma = gain(F, rho)
    extra = {"gain": gamma}
    if method == "gauss_seidel":
        B, it, conv, w = _gauss_seidel(F, rho, S, tol, max_iterations, ticker, gamma)
        extra["omega"] = w
    elif method == "jacobi":
        B, it, conv = _jacobi(F, rho, S, tol, max_iterations, ticker, gamma)
    else:
        B, it, conv, more = _progressive(F, rho, S, tol, max_iterations, ticker, areas, gamma)
        extra.update(more)
    FB = _matvec(F, B)                # once for the residual and the balance (a relight's solve is ms)
    res = residual(F, rho, S, B, rid, FB)
    bound = error_bound(res, gamma)
    energy = energy_balance(F, rho, S, B, areas, rid, computed, FB) if areas is not None else {}
    return Solution(B, it, res, energy, method, bool(conv and bound <= tol), extra, bound)
