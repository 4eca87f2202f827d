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
(1 - lambda) / (1 - gamma), lambda the spectral radius of T). The solvers use the smaller kappa
of :func:`.residual.amplification` in place of 1 / (1 - gamma), from the norms of T's powers:
a few metal patches at rho 0.999 make 1 / (1 - gamma) 1000, while the light they pass on meets
duller surfaces at the next bounce. Where light is trapped instead (the grey-white room's white
sofa, rho 0.999, whose gaps between cushions keep it for ~1000 bounces: ``||(I - T)^-1||`` is 1000
there, 200 sweeps left a bound of 1.2e-2 and plain Gauss-Seidel needed 642 to reach 1e-4),
Gauss-Seidel solves those pockets as one dense block and bounds the error by the block
splitting (:mod:`.pockets`: 14 sweeps, kappa 9). Inputs that could make the
iteration diverge (reflectivity outside [0, 1), a row of F summing past 1 such that
rho * rowsum >= 1, negative or non-finite sources) are rejected with a clear error.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import hashlib

import numpy as np

from ..runtime.cache import Memo
from ..runtime.progress import Ticker
from ..util.sparse import CSR
from .gauss_seidel import gauss_seidel
from .pockets import find_pockets
from .residual import (amplification, check_inputs, energy_balance, error_bound, gain, matvec, residual,
                       residual_vector)

__all__ = ["Solution", "solve", "SOLVERS"]

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


def _jacobi(F, rho, S, tol, max_it, ticker, kappa):
    """Jacobi iteration ``B += alpha r`` on the residual ``r = S + rho F B - B``, with the step
    alpha per band that minimises the next residual (alpha = 1 is plain Jacobi). The residual
    of a Jacobi sweep is dominated by the slowest mode of ``rho F``, for which the best step
    is ``1 / (1 - lambda)``: the minimal-residual step takes it, so a closed room at rho = 0.999
    needs a few sweeps instead of thousands. One product with F per sweep, as plain Jacobi;
    the residual is carried along and recomputed every 32 sweeps and before stopping."""
    B = S.copy()
    r = residual_vector(F, rho, S, B)
    it, converged = 0, False
    for it in range(1, max_it + 1):
        ticker.tick(it, max_it)
        Tr = rho * F.matvec(r)
        # B + r (a plain Jacobi step) has residual rho F r: stop there when its bound allows
        scale = np.abs(B + r).max()
        if scale == 0 or np.abs(Tr).max() * kappa <= tol * scale:
            B = B + r
            r = residual_vector(F, rho, S, B)          # the carried residual drifts: confirm
            if scale == 0 or np.abs(r).max() * kappa <= tol * np.abs(B).max():
                converged = True
                break
            continue
        d = r - Tr                                   # (I - rho F) r
        dd = (d * d).sum(axis=0)
        with np.errstate(invalid="ignore", divide="ignore"):
            alpha = (r * d).sum(axis=0) / dd
        alpha = np.where(np.isfinite(alpha) & (alpha > 0), np.minimum(alpha, kappa), 1.0)
        B = B + alpha * r
        r = r - alpha * d
        if it % 32 == 0:
            r = residual_vector(F, rho, S, B)
    return B, it, converged


def _progressive(F, rho, S, tol, max_it, ticker, areas, kappa):
    """Southwell iteration ("shooting"): the patch with the most unshot power distributes it.

    Uses the columns of F (F transposed), so it converges to the same B as the gathering solvers
    even when F is not exactly reciprocal. B includes the unshot radiosity u, and the residual
    of B is ``rho F u`` (so ``max|error| <= (kappa - 1) max|u|``: ``(I - T)^-1 T = (I - T)^-1 - I``,
    non-negative, of norm kappa - 1).

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
    limit = tol / max(kappa - 1.0, 1e-300)
    while shots < max_shots:
        scale = np.abs(B).max()
        if scale == 0 or np.abs(unshot).max() <= limit * scale or (shots and shots % n == 0):
            res = residual_vector(F, rho, S, B)
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
            if scale == 0 or np.abs(Tr).max() * kappa <= tol * scale:
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


def _setup(F, rho, method):
    """(gamma, kappa, pockets) of F and rho (the source is not in them), kept on F for the last
    few reflectivities: a relight solves the same F and rho several times (a source's two signed
    parts, coloured glossy passes: eight solves of the staircase hall, each with eight products
    for kappa)."""
    def make():
        gamma, kappa = gain(F, rho), amplification(F, rho)
        return gamma, kappa, find_pockets(F, rho, gamma, kappa) if method == "gauss_seidel" else None
    key = (hashlib.sha256(np.ascontiguousarray(rho).tobytes()).digest(), rho.shape, method)   # by value
    return F.memo("solve-setups", lambda: Memo(4)).get(key, make)


def solve(F: CSR, rho, source, method="gauss_seidel", tol=1e-4, max_iterations=200, areas=None,
          progress=None, cancelled=None, computed=None) -> Solution:
    """Solve ``B = S + rho F B`` for all three bands.

    method: 'gauss_seidel' (the paper's, over-relaxed), 'jacobi' (with a minimal-residual step
    length), or 'progressive' (Southwell shooting, plus the ambient step every N shots).
    tol: the relative error target. The solve stops when ``max|B - B*| <= tol * max|B|`` is
    guaranteed by the bound ``residual * kappa`` (kappa <= ``1 / (1 - gamma)``, ``gamma = max rho
    * rowsum``: :func:`.residual.amplification`; see the module docstring), so at rho near 1 it iterates further than a step-size rule would.
    'gauss_seidel' solves pockets that trap light exactly (:mod:`.pockets`; ``extra['pockets']``
    their number of rows) and bounds the error by ``kappa_G max|D^-1 r|`` where that is tighter.
    max_iterations: sweeps (for 'progressive', ``max_iterations * N`` shots); a solve that
    reaches it returns ``converged=False`` with its residual and ``error_bound``, never hangs.
    ``areas`` (N,) enables the energy balance and area-weighted shooting order; ``computed`` is
    passed to :func:`energy_balance`. Raises ValueError on inputs that would diverge.
    """
    if method not in SOLVERS:
        raise ValueError(f"unknown solver {method!r}; choose one of {', '.join(SOLVERS)}")
    if not tol > 0:
        raise ValueError(f"tolerance must be > 0, got {tol}")
    rho, S = check_inputs(F, rho, source)
    ticker = Ticker(progress, cancelled)
    rid = F.row_ids()
    gamma, kappa, pockets = _setup(F, rho, method)
    extra = {"gain": gamma, "amplification": kappa}
    if pockets is not None:
        extra.update(pockets=len(pockets.rows), pocket_gain=pockets.gain, pocket_amplification=pockets.kappa)
    if method == "gauss_seidel":
        if pockets is None:
            B, it, conv, w = gauss_seidel(F, rho, S, tol, max_iterations, ticker, gamma, kappa)
        else:
            B, it, conv, w = gauss_seidel(F, rho, S, tol, max_iterations, ticker, pockets.gain, pockets.kappa,
                                          pockets=pockets)
        extra["omega"] = w
    elif method == "jacobi":
        B, it, conv = _jacobi(F, rho, S, tol, max_iterations, ticker, kappa)
    else:
        B, it, conv, more = _progressive(F, rho, S, tol, max_iterations, ticker, areas, kappa)
        extra.update(more)
    FB = matvec(F, B)                # once for the residual and the balance (a relight's solve is ms)
    res = residual(F, rho, S, B, rid, FB)
    bound = error_bound(res, kappa)
    if pockets is not None:          # the block splitting's bound, where it is the tighter
        scale = np.abs(B).max()
        d = np.abs(pockets.precondition(S + rho * FB - B)).max()
        bound = min(bound, error_bound(d / scale if scale > 0 else d, pockets.kappa))
    energy = energy_balance(F, rho, S, B, areas, rid, computed, FB) if areas is not None else {}
    return Solution(B, it, res, energy, method, bool(conv and bound <= tol), extra, bound)
