"""How far a radiosity B is from the answer: the gain of rho F, the error bound, residuals, one
checked Jacobi step and the power bookkeeping, with F stored sparse (:mod:`.solvers` uses them).

With ``T = rho F`` and ``gamma = max_i rho_i * rowsum_i`` (< 1, checked), the error of any B obeys
``max|B - B*| <= max|B - S - T B| / (1 - gamma)``, and ``<= kappa max|B - S - T B|`` with the
often far smaller kappa of :func:`amplification` (from the norms of T's powers): :func:`error_bound`. Inputs that would make an
iteration diverge are refused by :func:`check_inputs` with one line (:class:`SolveError`).
"""
from __future__ import annotations

import numpy as np

from ..runtime.errors import RadiosityError
from ..util.sparse import CSR


class SolveError(RadiosityError, ValueError):
    """The equation cannot be solved as given (a reflectivity of 1 or more, a non-finite value):
    a user-facing problem of the scene, one line."""


def check_inputs(F: CSR, rho, source):
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


#: Powers of ``rho F`` whose norms :func:`amplification` tries
POWERS = 8


def amplification(F: CSR, rho, powers=POWERS, pockets=None, slack=0.0) -> float:
    """kappa >= ``||(I - rho F)^-1||_inf``: how much a residual can grow into the error. From
    ``(I - T)^-1 = (I + T + ... + T^(k-1)) (I - T^k)^-1`` and ``g_k = ||T^k||_inf = max(T^k 1)``
    (T = rho F >= 0, each band's below the one of its patches' largest band): the least
    ``(1 + g_1 + ... + g_(k-1)) / (1 - g_k)`` over k <= ``powers`` (k = 1: 1 / (1 - gamma)).
    A few patches of rho near 1 (metal, whose light the bake spreads as diffuse) among duller
    ones make gamma near 1 while ``T^2`` is not: in a room of rho 0.7 with a block of 0.999,
    1 / (1 - gamma) is 1000, kappa 4.6 (k = 8), 1 / (1 - spectral radius) 3.6. At most ``powers``
    products with F (fewer once ``1 + g_1 + ...`` alone reaches the least so far over
    ``1 + slack``: no later k can do better by more than that).

    With ``pockets`` (:class:`.pockets.Pockets`) the same for ``G = D^-1 N`` in place of T
    (the block splitting of :mod:`.pockets`): then kappa bounds ``||(I - G)^-1||_inf``, and
    the error is at most kappa times ``max|D^-1 r|``."""
    rm = np.asarray(rho, dtype=np.float64).max(axis=1, initial=0.0)
    v, total, best = np.ones(len(rm)), 1.0, np.inf
    for _ in range(powers):
        v = rm * matvec(F, v) if pockets is None else pockets.gain_product(F, rm, v)
        g = float(v.max(initial=0.0))
        if g < 1.0:
            best = min(best, total / (1.0 - g))
        total += g
        if total * (1.0 + slack) >= best:
            break
    return float(best)


def error_bound(residual_value: float, kappa: float) -> float:
    """Bound on ``max|B - B*| / max|B|`` from the relative residual and :func:`amplification`."""
    return float(residual_value * kappa)


def column_indices(F) -> np.ndarray:
    """F's column indices as the platform's index type, kept on F (a relight solves the same F
    again): ``take`` converts int32 indices on every call. The sweeps' blocks are views of it."""
    if F.indices.dtype == np.intp:
        return F.indices
    return F.memo("indices64", lambda: F.indices.astype(np.intp))


def matvec(F, x) -> np.ndarray:
    """``F.matvec(x)``, the same sums bit for bit (float32 entries times float64 values, each
    non-empty row summed by one ``reduceat``), with F's index arrays kept on F."""
    x = np.asarray(x, dtype=np.float64)
    one = x.ndim == 1
    xt = np.ascontiguousarray((x[:, None] if one else x).T)
    nonempty, starts = F.memo("row-starts", lambda: (
        np.flatnonzero(np.diff(F.indptr)), F.indptr[:-1][np.diff(F.indptr) > 0]))
    out = np.zeros((F.shape[0], xt.shape[0]))
    if starts.size:
        cols, data = column_indices(F), F.data
        for k in range(xt.shape[0]):
            # 'wrap': the columns are in range (the same values), without take's bounds check
            out[nonempty, k] = np.add.reduceat(data * xt[k].take(cols, mode="wrap"), starts)
    return out[:, 0] if one else out


def residual_vector(F, rho, S, B):
    return S + rho * matvec(F, B) - B


def better_of_step(F, rho, S, B, kappa, pockets=None):
    """The better of B and one Jacobi step from it, ``B + r``, by the error bound; returns
    (B, its residual vector, its bound). The step's residual ``rho F r`` has lost the parts
    of r that ``(I - rho F)^-1`` barely amplifies and the bound counts as if amplified by
    ``kappa`` (:func:`amplification`): after over-relaxed sweeps that makes the bound ~10-100x
    tighter, and it is close to the true error. Two products with F.

    With ``pockets`` the step is a block-Jacobi one, ``B + D^-1 r``, and the bounds are
    ``kappa max|D^-1 r|`` (kappa then of G: :mod:`.pockets`)."""
    r = residual_vector(F, rho, S, B)
    if pockets is None:
        d, Bj = r, B + r
        rj = dj = rho * matvec(F, r)
    else:
        d = pockets.precondition(r)
        Bj = B + d
        rj = r - d + rho * matvec(F, d)
        dj = pockets.precondition(rj)
    s0, sj = np.abs(B).max(), np.abs(Bj).max()
    b0 = np.abs(d).max() * kappa / s0 if s0 > 0 else (0.0 if not d.any() else np.inf)
    bj = np.abs(dj).max() * kappa / sj if sj > 0 else (0.0 if not dj.any() else np.inf)
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
