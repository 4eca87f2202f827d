"""What a solve finds of F and rho alone (gamma, kappa, the pockets: ``solvers._setup``) is kept
on F for the next solves of the same F and reflectivity (a relight solves a source's two signed
parts, and coloured glossy passes, with one F): the same solution, bit for bit, as with nothing
kept, and found again for another source, made again for another reflectivity (by value: an
array changed in place is another reflectivity)."""
from __future__ import annotations

import numpy as np

from hemicube_radiosity.core.solve import solvers
from hemicube_radiosity.core.solve.solvers import solve
from hemicube_radiosity.core.util.sparse import CSR
from tests.core.solve.test_solve import random_reciprocal_system


def _fresh(F):
    F.__dict__.pop("_derived", None)
    return F


def test_setup_is_kept_per_reflectivity(monkeypatch):
    Fd, _, rho, S = random_reciprocal_system(80, seed=3)
    F = CSR.from_dense(Fd)
    calls = []
    real = solvers.amplification
    monkeypatch.setattr(solvers, "amplification", lambda *a, **k: calls.append(1) or real(*a, **k))
    _fresh(F)
    first = solve(F, rho, S)
    assert len(calls) == 1
    again = solve(F, rho, 2.0 * S)                     # another source: kept
    assert len(calls) == 1
    np.testing.assert_array_equal(again.B, solve(_fresh(F), rho, 2.0 * S).B)
    assert len(calls) == 2
    darker = np.array(rho, copy=True)
    darker[0] *= 0.5                                   # another reflectivity: made again
    got = solve(F, darker, S)
    assert len(calls) == 3
    ref = solve(_fresh(F), darker, S)
    np.testing.assert_array_equal(got.B, ref.B)
    assert got.extra == ref.extra and got.extra["amplification"] != first.extra["amplification"]
    darker[1] *= 0.5                                   # the same array changed in place
    got = solve(F, darker, S)
    assert len(calls) == 5
    np.testing.assert_array_equal(got.B, solve(_fresh(F), darker, S).B)
