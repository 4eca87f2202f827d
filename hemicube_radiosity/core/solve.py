"""Radiosity solvers: B = S + rho * (F @ B), per colour band, with F stored sparse.

S is the source term in radiance units: the patches' emission, plus (when lamps or a world are
modelled) the first bounce of their direct light, ``rho * H_direct / pi``.

Every solver returns a :class:`Solution` with the same fields, so they can be swapped and
compared. Inputs that could make the iteration diverge (reflectivity outside [0, 1), a row of F
summing past 1 such that rho * rowsum >= 1, negative or non-finite sources) are rejected with
a clear error instead of diverging silently.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .progress import Ticker
from .sparse import CSR

__all__ = ["Solution", "solve", "residual", "energy_balance", "SOLVERS"]

SOLVERS = ("gauss_seidel", "jacobi", "progressive")


@dataclass
class Solution:
    """B (N,3) radiosities; iterations (sweeps, or shots for 'progressive'); residual
    ``max|B - S - rho F B| / max|B|``; energy balance (see :func:`energy_balance`)."""

    B: np.ndarray
    iterations: int
    residual: float
    energy: dict
    method: str
    converged: bool
    extra: dict = field(default_factory=dict)


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
            raise ValueError(f"{name} of patch {i} is not finite: {tuple(a[i])}")
    bad = (rho < 0) | (rho >= 1)
    if bad.any():
        i, b = (int(x[0]) for x in np.nonzero(bad))
        raise ValueError(f"reflectivity of patch {i} band {'RGB'[b]} is {rho[i, b]:g}; "
                         "it must be in [0, 1) (rho >= 1 creates energy and the solve diverges)")
    if (source < 0).any():
        i, b = (int(x[0]) for x in np.nonzero(source < 0))
        raise ValueError(f"source of patch {i} band {'RGB'[b]} is negative ({source[i, b]:g})")
    rs = F.row_sums()
    gain = rho * rs[:, None]
    if (gain >= 1).any():
        i = int(np.argmax(gain.max(axis=1)))
        raise ValueError(f"patch {i}: reflectivity x form-factor row sum = {gain[i].max():.4f} >= 1; "
                         "the form factors are inconsistent (row sum > 1) and the solve would diverge")
    return rho, source


def residual(F: CSR, rho, source, B, row_ids=None) -> float:
    """Relative residual ``max|B - S - rho F B| / max|B|`` (0 when B is all zero and S is too)."""
    r = B - source - rho * F.matvec(B, row_ids)
    scale = np.abs(B).max()
    return float(np.abs(r).max() / scale) if scale > 0 else float(np.abs(r).max())


def energy_balance(F: CSR, rho, source, B, areas, row_ids=None, computed=None) -> dict:
    """Power bookkeeping per band, in radiance x area units (multiply by pi for watts).

    emitted  = sum A_i S_i
    absorbed = sum A_i (1 - rho_i) H_i,   H = F @ B (incident radiance)
    escaped  = sum A_i B_i (1 - rowsum_i) (left through openings, or onto back faces)
    With reciprocity ``A_i F_ij = A_j F_ji`` and a converged B, emitted = absorbed + escaped;
    ``imbalance`` is the relative difference, a check on both the form factors and the solve.
    ``computed`` (N,) bool marks rows that were computed; rows left out (patches with rho = 0,
    whose radiosity needs no gathering) get their row sum and incident radiance by reciprocity
    from the computed rows: ``F_ji = A_i F_ij / A_j``.
    """
    areas = np.asarray(areas, dtype=np.float64)
    H = F.matvec(B, row_ids)
    rs = F.row_sums()
    if computed is not None and not np.all(computed):
        miss = ~np.asarray(computed, bool)
        # column sums of A_i F_ij over computed rows i, without forming the transpose
        # (only the entries in the left-out columns matter: few, e.g. the lights)
        sel = np.flatnonzero(miss[F.indices])
        rid = (F.row_ids() if row_ids is None else row_ids)[sel]
        col = F.indices[sel]
        w = F.data[sel].astype(np.float64) * (areas * computed)[rid]
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


def _segment_sums(vals, cols, x, starts, nonempty, nrows):
    """Row sums of ``vals * x[cols]`` per band; x is (bands, N) float32 (half the memory traffic
    of the gathers), sums accumulate in float64; rows given by CSR ``starts`` of the non-empty
    rows. Returns (nrows, bands)."""
    out = np.zeros((nrows, x.shape[0]))
    if starts.size:
        for k in range(x.shape[0]):
            out[nonempty, k] = np.add.reduceat(vals * x[k][cols], starts, dtype=np.float64)
    return out


def _gauss_seidel(F, rho, S, tol, max_it, ticker, block=None):
    """Gauss-Seidel sweeps over blocks of rows: each block is updated at once from the newest
    values of every block before it (block Gauss-Seidel, a Jacobi step inside a block). With
    ``block=1`` this is the paper's row-by-row Gauss-Seidel; larger blocks trade a little
    convergence per sweep for NumPy-speed sweeps (default: N/32 rows, at most 256). Converges
    whenever the row-wise method does (I - rho F is strictly diagonally dominant)."""
    n = F.shape[0]
    block = block or max(1, min(256, n // 32))
    B = S.copy()
    BT = np.ascontiguousarray(B.T)          # (bands, N): contiguous gathers per band
    B32 = BT.astype(np.float32)             # what the gathers read
    ip, ix = F.indptr, F.indices
    dv = np.asarray(F.data, dtype=np.float32)   # no copy: F is stored float32
    blocks = []
    for b0 in range(0, n, block):
        b1 = min(n, b0 + block)
        s, e = ip[b0], ip[b1]
        counts = np.diff(ip[b0:b1 + 1])
        nonempty = np.flatnonzero(counts)
        starts = (ip[b0:b1][nonempty] - s).astype(np.int64)
        blocks.append((b0, b1, ix[s:e], dv[s:e], starts, nonempty))
    it, converged = 0, False
    for it in range(1, max_it + 1):
        change = 0.0
        for b0, b1, cols, vals, starts, nonempty in blocks:
            acc = _segment_sums(vals, cols, B32, starts, nonempty, b1 - b0)
            new = S[b0:b1] + rho[b0:b1] * acc
            d = np.abs(new - BT[:, b0:b1].T).max(initial=0.0)
            if d > change:
                change = d
            BT[:, b0:b1] = new.T
            B32[:, b0:b1] = new.T
        scale = np.abs(BT).max()
        ticker.tick(it, max_it)
        if scale == 0 or change <= tol * scale:
            converged = True
            break
    return np.ascontiguousarray(BT.T), it, converged


def _jacobi(F, rho, S, tol, max_it, ticker, rid):
    B = S.copy()
    it, converged = 0, False
    for it in range(1, max_it + 1):
        new = S + rho * F.matvec(B, rid)
        change = np.abs(new - B).max()
        B = new
        scale = np.abs(B).max()
        ticker.tick(it, max_it)
        if scale == 0 or change <= tol * scale:
            converged = True
            break
    return B, it, converged


def _progressive(F, rho, S, tol, max_it, ticker, areas):
    """Southwell iteration ("shooting"): the patch with the most unshot power distributes it.

    Uses the columns of F (F transposed), so it converges to the same B as the gathering solvers
    even when F is not exactly reciprocal. ``extra['ambient']`` is Cohen et al. (1988)'s ambient
    term for previewing an unconverged solution; B itself never includes it.
    """
    n = F.shape[0]
    FT = F.transpose()
    ip, ix, dv = FT.indptr, FT.indices, FT.data.astype(np.float64)
    B = S.copy()
    unshot = S.copy()  # residual r = S + rho F B - B
    a = np.ones(n) if areas is None else np.asarray(areas, dtype=np.float64)
    power = a * np.abs(unshot).sum(axis=1)
    max_shots = max_it * n
    shots, converged = 0, False
    while shots < max_shots:
        scale = np.abs(B).max()
        i = int(np.argmax(power))
        # stop when no patch's unshot radiosity is above tol relative to the brightest patch
        if scale == 0 or np.abs(unshot).max() <= tol * scale:
            converged = True
            break
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
        if shots % n == 0:
            ticker.tick(shots, max_shots)
    rho_avg = (a[:, None] * rho).sum(0) / a.sum()
    ambient = (a[:, None] * unshot).sum(0) / a.sum() / np.maximum(1e-12, 1 - rho_avg)
    return B, shots, converged, {"ambient": ambient.tolist(), "sweeps": shots / max(n, 1)}


def solve(F: CSR, rho, source, method="gauss_seidel", tol=1e-4, max_iterations=200, areas=None,
          progress=None, cancelled=None, computed=None) -> Solution:
    """Solve ``B = S + rho F B`` for all three bands.

    method: 'gauss_seidel' (the paper's), 'jacobi', or 'progressive' (Southwell shooting).
    tol: stop when no radiosity changes by more than ``tol * max(B)`` in a sweep (for
    'progressive': when no unshot radiosity exceeds it). max_iterations: sweeps (for
    'progressive', ``max_iterations * N`` shots). ``areas`` (N,) enables the energy balance
    and area-weighted shooting order; ``computed`` is passed to :func:`energy_balance`.
    Raises ValueError on inputs that would diverge.
    """
    if method not in SOLVERS:
        raise ValueError(f"unknown solver {method!r}; choose one of {', '.join(SOLVERS)}")
    if not tol > 0:
        raise ValueError(f"tolerance must be > 0, got {tol}")
    rho, S = _check(F, rho, source)
    ticker = Ticker(progress, cancelled)
    rid = F.row_ids()
    extra = {}
    if method == "gauss_seidel":
        B, it, conv = _gauss_seidel(F, rho, S, tol, max_iterations, ticker)
    elif method == "jacobi":
        B, it, conv = _jacobi(F, rho, S, tol, max_iterations, ticker, rid)
    else:
        B, it, conv, extra = _progressive(F, rho, S, tol, max_iterations, ticker, areas)
    res = residual(F, rho, S, B, rid)
    energy = energy_balance(F, rho, S, B, areas, rid, computed) if areas is not None else {}
    return Solution(B, it, res, energy, method, conv, extra)
