# SPDX-License-Identifier: GPL-3.0-or-later
"""Pockets: the few patches that trap light, solved exactly as one dense block.

A white sofa (reflectance clipped to 0.999) has gaps between its cushions whose patches see
almost only each other: light bounces there ~1000 times before it leaves. Gauss-Seidel needs as
many sweeps for those modes (the grey-white room: 642 sweeps), and the error bound
``kappa max|r|`` of :func:`.residual.amplification` is 1000x the residual there, whatever the
rest of the room does (``||(I - T)^-1||_inf`` is 1000 there, exactly).

The pocket set P is the rows whose light survives ``SURVIVAL_POWERS`` bounces mostly
(``(T^k 1)_i >= LIMIT``, T = rho F with each patch's largest band), at most ``MOST`` rows and a
quarter of the scene (a closed room of rho 0.99 is one slow mode everywhere, which
over-relaxation handles: no pockets there). With ``D`` the block diagonal of ``I - T`` over P
(identity elsewhere) and ``N = D - (I - T) >= 0``:

* the sweeps solve P exactly at the end of every sweep, ``B_P = D_PP^-1 (S_P + T_PR B_R)``
  (a block Gauss-Seidel step: the slow modes of the pockets are gone in one);
* the error obeys ``e = (I - G)^-1 D^-1 r`` with ``G = D^-1 N >= 0`` (``D^-1 >= 0``: I - T_PP
  is an M-matrix), so ``max|e| <= kappa_G max|D^-1 r|`` with kappa_G from the norms of G's
  powers as for T (:func:`.residual.amplification`); light that leaves a pocket meets the
  duller room, and kappa_G is ~9 in the grey-white room where kappa is 1000.

Shapes: F (N, N) :class:`~..util.sparse.CSR`; rho (N, 3); P (m,); the dense blocks (m, m);
radiosities band-major (bands, N) in the sweeps, (N, bands) elsewhere. Units: radiance.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .residual import amplification, matvec

#: Bounces of the survival test that picks the pockets
SURVIVAL_POWERS = 8
#: A row is in a pocket when at least this much of its light is left after those bounces
LIMIT = 0.5
#: At most this many rows are solved densely (three inverses of MOST x MOST)
MOST = 1024
#: ... and at most this share of the rows (a uniformly bright closed room is no pocket)
SHARE = 0.25
#: Powers of G that :func:`.residual.amplification` tries (light leaves a pocket over tens of
#: bounces), stopping once no later power can lower kappa by more than ``SLACK`` (the
#: grey-white room: kappa 9.09 after ~25 powers, 9.03 after 48)
POWERS = 48
SLACK = 0.02


@dataclass
class Pockets:
    """The rows P (m,) solved as one dense block: ``fpp`` (m, m) F among them (float64 of F's
    float32 entries), ``inv`` (bands, m, m) ``(I - rho_b F_PP)^-1`` per band, ``inv_max``
    (m, m) the same at each row's largest band (for the gain of G, an upper bound of every
    band's), and the CSR slice of P's rows (``cols``, ``vals``, ``starts``) for ``(F B)_P``;
    ``gain`` ``||G||_inf`` and ``kappa`` >= ``||(I - G)^-1||_inf`` (:func:`.residual.amplification`)."""

    rows: np.ndarray
    fpp: np.ndarray
    inv: np.ndarray
    inv_max: np.ndarray
    cols: np.ndarray
    vals: np.ndarray
    starts: np.ndarray
    gain: float = 1.0
    kappa: float = np.inf

    def gather(self, BT):
        """(bands, m) ``(F B)_P - F_PP B_P``: what P gathers from the rest, BT (bands, N)."""
        acc = np.zeros((BT.shape[0], len(self.rows)))
        nonempty = self.starts[:-1] < self.starts[1:]
        if nonempty.any():
            sums = np.add.reduceat(BT.take(self.cols, axis=1) * self.vals, self.starts[:-1][nonempty], axis=1)
            acc[:, nonempty] = sums
        return acc - BT[:, self.rows] @ self.fpp.T

    def solve_block(self, rhoT, ST, BT):
        """(bands, m) the exact B_P given B elsewhere: ``(I - T_PP)^-1 (S_P + T_PR B_R)``."""
        rhs = ST[:, self.rows] + rhoT[:, self.rows] * self.gather(BT)
        return np.einsum("bij,bj->bi", self.inv, rhs)

    def precondition(self, r):
        """``D^-1 r`` for r (N, bands): r with its P rows times ``(I - T_PP)^-1`` per band."""
        out = np.array(r, dtype=np.float64, copy=True)
        out[self.rows] = np.einsum("bij,jb->ib", self.inv, out[self.rows])
        return out

    def gain_product(self, F, rm, v):
        """``G v`` (N,) at each row's largest band rm (N,): ``D^-1 (T v - T_PP v_P)``."""
        y = rm * matvec(F, v)
        y[self.rows] = self.inv_max @ (y[self.rows] - rm[self.rows] * (self.fpp @ v[self.rows]))
        return y


def survival(F, rm, powers=SURVIVAL_POWERS):
    """(N,) ``T^k 1`` for k = ``powers``: the share of a row's light left after k bounces at its
    largest band rm (N,). ``powers`` products with F."""
    v = np.ones(F.shape[0])
    for _ in range(powers):
        v = rm * matvec(F, v)
    return v


def find_pockets(F, rho, gamma, kappa, limit=LIMIT, most=MOST, share=SHARE):
    """:class:`Pockets` of F and rho (N, 3), or None: where no row keeps ``limit`` of its light
    after :data:`SURVIVAL_POWERS` bounces (none can when ``gamma``, ``max rho rowsum``, to that
    power is below it, or when ``kappa`` is below ``1 + SURVIVAL_POWERS * limit``: such a row's
    ``T^k 1`` is at least ``limit`` for every k up to there, and their sum at most kappa; no
    product with F then), where they are more than ``share`` of the rows
    (the ``most`` that keep the most when there are more), or where their kappa is not below
    ``kappa``, the one without them. Kept on F per rho (a relight solves the same system
    again)."""
    if not (gamma ** SURVIVAL_POWERS >= limit and kappa >= 1 + SURVIVAL_POWERS * limit):
        return None
    rho = np.asarray(rho, dtype=np.float64)
    key = ("pockets", rho.shape, hash(rho.tobytes()), limit, most, share)
    pockets = F.memo(key, lambda: _make(F, rho, limit, most, share))
    return pockets if pockets is not None and pockets.kappa < kappa else None


def _make(F, rho, limit, most, share):
    """:class:`Pockets` (or None) of :func:`find_pockets`, before comparing kappas."""
    n = F.shape[0]
    rm = rho.max(axis=1, initial=0.0)
    v = survival(F, rm)
    rows = np.flatnonzero(v >= limit)
    if rows.size == 0 or rows.size > share * n:
        return None
    if rows.size > most:
        rows = np.sort(rows[np.argsort(-v[rows], kind="stable")[:most]])
    m = rows.size
    at = np.full(n, -1, dtype=np.int64)
    at[rows] = np.arange(m)
    starts = F.indptr[rows].astype(np.int64)
    ends = F.indptr[rows + 1].astype(np.int64)
    counts = ends - starts
    seg = np.zeros(m + 1, dtype=np.int64)
    np.cumsum(counts, out=seg[1:])
    take = np.repeat(starts - seg[:-1], counts) + np.arange(seg[-1])     # P's entries of F
    cols = F.indices[take].astype(np.intp)
    vals = F.data[take].astype(np.float64)
    local = np.repeat(np.arange(m), counts)
    inside = at[cols] >= 0
    fpp = np.zeros((m, m))
    fpp[local[inside], at[cols[inside]]] = vals[inside]
    eye = np.eye(m)
    inv = np.stack([np.linalg.inv(eye - rho[rows, b][:, None] * fpp) for b in range(rho.shape[1])])
    inv_max = np.linalg.inv(eye - rm[rows][:, None] * fpp)
    pockets = Pockets(rows, fpp, inv, inv_max, cols, vals, seg)
    pockets.gain = float(pockets.gain_product(F, rm, np.ones(n)).max(initial=0.0))
    pockets.kappa = amplification(F, rho, POWERS, pockets, SLACK)
    return pockets
