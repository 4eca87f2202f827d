"""Gauss-Seidel sweeps over blocks of rows, over-relaxed (SOR), with the relaxation factor found
from the sweeps themselves (Young's optimum): the paper's solver at NumPy speed.

Shapes: F (N, N) :class:`~..util.sparse.CSR`; rho, S (N, 3); the sweeps work band-major on
(3, N) float64 radiosities, gathering from a float32 copy.
"""
from __future__ import annotations

import numpy as np

from .residual import better_of_step, column_indices


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
    cols64 = column_indices(F)                        # a block's columns: a view of them
    for b0, b1 in bounds:
        if ("b", b0, b1) not in memo:
            s, e = ip[b0], ip[b1]
            counts = np.diff(ip[b0:b1 + 1])
            nonempty = np.flatnonzero(counts)
            starts = (ip[b0:b1][nonempty] - s).astype(np.int64)
            memo["b", b0, b1] = (b0, b1, cols64[s:e], dv[s:e], starts, nonempty)
        blocks.append(memo["b", b0, b1])
    return blocks


def _sor_sweep(blocks, rhoT, ST, BT, B32, w, pockets=None):
    """One over-relaxed block Gauss-Seidel sweep, in place; returns the largest change of a value.

    ``blocks`` from :func:`_gs_blocks`; rhoT, ST (bands, N) reflectivity and source, band-major
    as BT, the (bands, N) float64 radiosities, updated block by block (a block's values are
    computed as (bands, rows), the same arithmetic per value as row-major, without transposes);
    B32 the copy the gathers read (a float32 copy of BT, kept up to date, or BT itself); w the
    relaxation factor (1 = plain Gauss-Seidel).

    Every value changes once a sweep, so the largest change is taken once, from a copy of BT
    before it (the same differences as block by block), and the gathers' columns are intp
    views (:func:`column_indices`), read without take's bounds check.

    ``pockets`` (:class:`.pockets.Pockets`): their rows are then solved exactly from the rest,
    over-relaxed by w as the rows (block SOR: each step lowers the error's energy)."""
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
    if pockets is not None:
        P = pockets.rows
        new = pockets.solve_block(rhoT, ST, BT)
        if w != 1.0:
            old = BT[:, P]
            new = old + w * (new - old)
        BT[:, P] = new
        if B32 is not BT:
            B32[:, P] = new
    return float(np.abs(BT - before).max(initial=0.0))


class _Relaxation:
    """The relaxation factor ``w`` of :func:`gauss_seidel` and the row blocks that go with it.

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


def gauss_seidel(F, rho, S, tol, max_it, ticker, gamma, kappa=None, block=None, omega=None, pockets=None):
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
    (``|r| <= ((omega - 1) / omega + gamma) max|change|``, times ``kappa`` for the error:
    :func:`.residual.amplification`, None: ``1 / (1 - gamma)``), and the exact residual (one product
    with F) confirms it before stopping; if the float32 copy of B that the sweeps read limits the
    residual, the sweeps go on in float64.

    ``pockets`` (:class:`.pockets.Pockets`): rows that trap light, solved exactly at the end of
    every sweep; gamma and kappa are then those of the block splitting (``G = D^-1 N``), and
    the bound is ``kappa max|D^-1 r|``. Returns B, sweeps, converged, omega."""
    kappa = 1.0 / (1.0 - gamma) if kappa is None else kappa
    relax = _Relaxation(F, rho.max(axis=1), block or max(1, min(256, F.shape[0] // 32)), omega)
    BT = np.ascontiguousarray(S.T).copy()   # (bands, N): contiguous gathers per band
    B32 = BT.astype(np.float32)             # what the gathers read (half the memory traffic)
    rhoT, ST = np.ascontiguousarray(rho.T), np.ascontiguousarray(S.T)
    calib = 0.2          # exact bound / cheap bound, learnt at each exact check
    it, converged = 0, False
    for it in range(1, max_it + 1):
        w = relax.w
        change = _sor_sweep(relax.blocks, rhoT, ST, BT, B32, w, pockets)
        ticker.tick(it, max_it)
        scale = np.abs(BT).max()
        if scale == 0:
            converged = True
            break
        cheap = ((w - 1.0) / w + gamma) * change * kappa / scale
        if cheap * calib <= tol:
            Bc, _, exact = better_of_step(F, rho, S, BT.T, kappa, pockets)
            if exact <= tol:
                BT = np.ascontiguousarray(Bc.T)
                converged = True
                break
            if cheap <= tol and B32 is not BT:
                B32 = BT                    # the float32 copy is the floor: read float64 from now on
            calib = max(exact / max(cheap, 1e-300), 1e-3) * 1.1
        relax.observe(change)
    return np.ascontiguousarray(BT.T), it, converged, relax.w
