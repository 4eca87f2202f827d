"""A source negative in places (core/light/seen.py takes out of what a receiver gathers first the
part of a cluster's mean direct light it does not see) is solved as its positive part minus its
negative part (core/solve/stage.py ``_signed``): checked against a dense ``numpy.linalg.solve``
of the same system, and a source of one sign is solved once, as before, bit for bit."""
import numpy as np
import pytest

from hemicube_radiosity.core.builtin_scenes import cornell_box
from hemicube_radiosity.core.settings import BakeSettings
from hemicube_radiosity.core.solve import stage
from hemicube_radiosity.core.solve.residual import SolveError


@pytest.fixture(scope="module")
def system():
    from hemicube_radiosity.core.form_factors.hemicube import hemicube_form_factors
    from hemicube_radiosity.core.mesh.subdivide import build_patches

    ps = build_patches(cornell_box(), 0.25)
    F = hemicube_form_factors(ps, 32)
    D = F.to_dense()
    return F, ps.rho, ps.areas, D


def _run(F, rho, areas, solver="gauss_seidel"):
    s = BakeSettings(solver=solver, tolerance=1e-7, max_iterations=2000)
    computed = np.ones(len(areas), bool)
    return stage._signed(stage._solver(F, rho, None, s, areas, computed, None), F, rho, areas, computed)


def _signed_source(rho, S, F):
    """A source whose negative rows are what a receiver's first gather of its neighbour loses,
    at most what it gathers of it: rho_r F_rc S_c for the largest entry of each row."""
    D = F.to_dense()
    c = np.argmax(D, axis=1)
    take = np.zeros_like(S)
    rows = np.arange(0, len(S), 3)
    take[rows] = rho[rows] * D[rows, c[rows], None] * S[c[rows]]
    return S - take


@pytest.mark.parametrize("solver", ["gauss_seidel", "jacobi"])
def test_a_signed_source_against_dense_algebra(system, solver):
    F, rho, areas, D = system
    S0 = np.random.default_rng(0).uniform(0.0, 1.0, size=(len(areas), 3))
    S = _signed_source(rho, S0, F)
    assert (S < 0).any()
    exact = np.stack([np.linalg.solve(np.eye(len(D)) - rho[:, k:k + 1] * D, S[:, k]) for k in range(3)], 1)
    assert exact.min() >= -1e-12                 # taking out no more than the row gathers
    sol = _run(F, rho, areas, solver)(S)
    err = np.abs(sol.B - exact).max() / np.abs(exact).max()
    assert err < 1e-5
    assert sol.error_bound >= err                # the two solves' bounds hold for the difference
    assert sol.converged
    # the balance of the signed source: what it sends out, net, is absorbed or escapes (to the
    # hemi-cube's reciprocity, 0.9% here as for a positive source)
    np.testing.assert_allclose(sol.energy["emitted"], (areas[:, None] * S).sum(axis=0), rtol=1e-12)
    assert sol.energy["imbalance"] < 0.02


def test_the_solvers_themselves_refuse_a_negative_source(system):
    F, rho, areas, D = system
    S = -np.ones((len(areas), 3))
    s = BakeSettings(solver="gauss_seidel")
    with pytest.raises(SolveError):
        stage._solver(F, rho, None, s, areas, np.ones(len(areas), bool), None)(S)


def test_a_source_of_one_sign_is_solved_once_as_before(system):
    F, rho, areas, D = system
    S = np.random.default_rng(1).uniform(0.0, 1.0, size=(len(areas), 3))
    s = BakeSettings(solver="gauss_seidel", tolerance=1e-7, max_iterations=2000)
    computed = np.ones(len(areas), bool)
    plain = stage._solver(F, rho, None, s, areas, computed, None)(S)
    signed = _run(F, rho, areas)(S)
    assert np.array_equal(plain.B, signed.B) and plain.iterations == signed.iterations
