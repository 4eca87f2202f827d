"""Solvers against a direct dense solve, the furnace closed form, and their error handling."""
import numpy as np
import pytest

from hemicube_radiosity.core.solve.residual import energy_balance
from hemicube_radiosity.core.solve.solvers import solve
from hemicube_radiosity.core.util.sparse import CSR


def random_reciprocal_system(n=60, seed=1, leak=0.1):
    """A random enclosure-like F with reciprocity A_i F_ij = A_j F_ji and row sums 1 - leak."""
    rng = np.random.default_rng(seed)
    A = rng.uniform(0.5, 2.0, n)
    G = rng.uniform(0, 1, (n, n)) * (rng.uniform(0, 1, (n, n)) < 0.3)
    G = G + G.T
    np.fill_diagonal(G, 0)
    # symmetric G = A_i F_ij; scale rows via Sinkhorn-like iterations to row sums of F = 1 - leak
    for _ in range(200):
        F = G / A[:, None]
        s = F.sum(1) / (1 - leak)
        d = 1 / np.sqrt(s)
        G = G * d[:, None] * d[None, :]
    F = G / A[:, None]
    rho = rng.uniform(0.1, 0.9, (n, 3))
    S = rng.uniform(0, 1, (n, 3)) * (rng.uniform(0, 1, (n, 1)) < 0.2)
    return F, A, rho, S


@pytest.mark.parametrize("method", ["gauss_seidel", "jacobi", "progressive"])
def test_solvers_match_dense_direct_solve(method):
    F, A, rho, S = random_reciprocal_system()
    exact = np.stack([np.linalg.solve(np.eye(len(A)) - rho[:, k:k + 1] * F, S[:, k]) for k in range(3)], 1)
    sol = solve(CSR.from_dense(F), rho, S, method, tol=1e-9, max_iterations=2000, areas=A)
    assert sol.converged
    np.testing.assert_allclose(sol.B, exact, rtol=1e-5, atol=1e-7 * exact.max())
    assert sol.residual < 1e-6
    # float32 storage of F limits how exactly energy balances
    assert sol.energy["imbalance"] < 1e-5


def test_gauss_seidel_needs_fewer_sweeps_than_jacobi():
    F, A, rho, S = random_reciprocal_system()
    Fc = CSR.from_dense(F)
    gs = solve(Fc, rho, S, "gauss_seidel", tol=1e-6)
    ja = solve(Fc, rho, S, "jacobi", tol=1e-6)
    assert gs.iterations < ja.iterations


def test_furnace_closed_form_any_matrix():
    # closed enclosure (rows sum to 1, reciprocal), uniform E and rho: B = E/(1-rho) exactly
    F, A, _, _ = random_reciprocal_system(leak=0.0)
    for r in (0.5, 0.9):
        rho = np.full((len(A), 3), r)
        S = np.ones((len(A), 3))
        sol = solve(CSR.from_dense(F), rho, S, tol=1e-8, max_iterations=5000, areas=A)
        np.testing.assert_allclose(sol.B, 1 / (1 - r), rtol=1e-5)
        assert sum(sol.energy["escaped"]) == pytest.approx(0, abs=1e-3 * sum(sol.energy["emitted"]))


def test_energy_balance_with_rows_left_out_uses_reciprocity():
    F, A, rho, S = random_reciprocal_system()
    rho[:5] = 0.0  # emitters that reflect nothing: their rows are not needed for B
    Fc = CSR.from_dense(F)
    full = solve(Fc, rho, S, tol=1e-9, max_iterations=2000, areas=A)
    Fcut = F.copy()
    Fcut[:5] = 0
    part = solve(CSR.from_dense(Fcut), rho, S, tol=1e-9, max_iterations=2000, areas=A,
                 computed=np.arange(len(A)) >= 5)
    np.testing.assert_allclose(part.B, full.B, rtol=1e-6)
    assert part.energy["imbalance"] < 1e-5
    # without telling the balance which rows were left out it would be badly off
    wrong = energy_balance(CSR.from_dense(Fcut), rho, S, part.B, A)
    assert wrong["imbalance"] > 1e-2


@pytest.mark.parametrize("rho_value, message", [(1.0, r"\[0, 1\)"), (-0.1, r"\[0, 1\)")])
def test_rejects_reflectivity_outside_unit_interval(rho_value, message):
    F, A, rho, S = random_reciprocal_system(n=10)
    rho[3, 1] = rho_value
    with pytest.raises(ValueError, match=message) as e:
        solve(CSR.from_dense(F), rho, S)
    assert "patch 3 band G" in str(e.value)


def test_rejects_rows_that_would_diverge_and_negative_source():
    F, A, rho, S = random_reciprocal_system(n=10)
    F2 = F.copy()
    F2[2] *= 1.5 / F2[2].sum()
    rho[:] = 0.8
    with pytest.raises(ValueError, match="patch 2.*diverge"):
        solve(CSR.from_dense(F2), rho, S)
    S[4, 0] = -1
    with pytest.raises(ValueError, match="negative"):
        solve(CSR.from_dense(F), rho, S)
    with pytest.raises(ValueError, match="unknown solver"):
        solve(CSR.from_dense(F), rho, np.abs(S), method="newton")


def test_not_converged_is_reported_not_hidden():
    F, A, rho, S = random_reciprocal_system()
    sol = solve(CSR.from_dense(F), rho, S, "jacobi", tol=1e-12, max_iterations=2)
    assert not sol.converged and sol.iterations == 2 and sol.residual > 1e-6


def test_cancel_stops_the_solve():
    from hemicube_radiosity.core.runtime.progress import Cancelled

    F, A, rho, S = random_reciprocal_system()
    with pytest.raises(Cancelled):
        solve(CSR.from_dense(F), rho, S, tol=1e-12, cancelled=lambda: True)


# ---- reflectivity near 1: stop on an error bound, accelerate, never hang ----

def _closed_box_F():
    from hemicube_radiosity.core.form_factors.hemicube import hemicube_form_factors
    from hemicube_radiosity.core.mesh.subdivide import build_patches
    from hemicube_radiosity.core.builtin_scenes import closed_box

    ps = build_patches(closed_box((1.0, 1.3, 0.8)), 0.2)
    return hemicube_form_factors(ps, 32), ps.areas


@pytest.fixture(scope="module")
def box_F():
    return _closed_box_F()


def _exact(F, rho, S):
    D = F.to_dense()
    return np.stack([np.linalg.solve(np.eye(len(D)) - rho[:, k:k + 1] * D, S[:, k]) for k in range(3)], 1)


@pytest.mark.parametrize("method", ["gauss_seidel", "jacobi", "progressive"])
@pytest.mark.parametrize("r", [0.99, 0.999])
def test_closed_box_near_unit_reflectivity_reaches_the_furnace_value(box_F, method, r):
    F, A = box_F
    n = F.shape[0]
    rho, S = np.full((n, 3), r), np.ones((n, 3))
    sol = solve(F, rho, S, method, tol=1e-4, max_iterations=400, areas=A)
    assert sol.converged, (sol.iterations, sol.error_bound)
    np.testing.assert_allclose(sol.B, 1 / (1 - r), rtol=1e-2)
    # the bound holds, and is what 'converged' means
    true = np.abs(sol.B - _exact(F, rho, S)).max() / np.abs(sol.B).max()
    assert true <= sol.error_bound <= 1e-4
    assert sol.error_bound == pytest.approx(sol.residual * sol.extra["amplification"])
    assert sol.extra["amplification"] <= 1 / (1 - sol.extra["gain"]) * (1 + 1e-9)


@pytest.mark.parametrize("method", ["gauss_seidel", "jacobi", "progressive"])
def test_uneven_light_near_unit_reflectivity(box_F, method):
    # one wall lit: the slow mode is not the source itself (jacobi and progressive cannot be
    # exact after one step); the solve still gets there, and the bound holds
    F, A = box_F
    n = F.shape[0]
    rho = np.full((n, 3), 0.99)
    rho[:, 2] = 0.95
    S = np.zeros((n, 3))
    S[: n // 5] = 1.0
    sol = solve(F, rho, S, method, tol=1e-4, max_iterations=2000, areas=A)
    exact = _exact(F, rho, S)
    true = np.abs(sol.B - exact).max() / np.abs(sol.B).max()
    assert sol.converged and true <= sol.error_bound <= 1e-4


@pytest.mark.parametrize("method", ["gauss_seidel", "jacobi", "progressive"])
def test_capped_run_reports_a_bound_that_brackets_the_error(box_F, method):
    F, A = box_F
    n = F.shape[0]
    rho = np.full((n, 3), 0.99)
    S = np.zeros((n, 3))
    S[: n // 5] = 1.0
    sol = solve(F, rho, S, method, tol=1e-6, max_iterations=3, areas=A)
    assert not sol.converged
    true = np.abs(sol.B - _exact(F, rho, S)).max() / np.abs(sol.B).max()
    assert np.isfinite(sol.error_bound) and sol.residual > 0
    assert true <= sol.error_bound <= 10 * true


def test_gauss_seidel_over_relaxes_near_unit_reflectivity(box_F):
    F, A = box_F
    n = F.shape[0]
    rho, S = np.full((n, 3), 0.999), np.ones((n, 3))
    sol = solve(F, rho, S, "gauss_seidel", tol=1e-4, max_iterations=1000)
    assert sol.converged and sol.extra["omega"] > 1.8
    assert sol.iterations < 400          # plain Gauss-Seidel needs ~4600 sweeps for this


def test_a_few_patches_near_unit_reflectivity_do_not_loosen_the_bound(box_F):
    """Metal at rho 0.999 among walls of 0.7 (the grey-white room: 200 sweeps, residual 1.2e-5,
    'not converged' by 1 / (1 - gamma) = 1000): the amplification bound still holds, near the
    true norm of (I - rho F)^-1, and the solve stops by it."""
    from hemicube_radiosity.core.solve.residual import amplification

    F, A = box_F
    n = F.shape[0]
    rho = np.full((n, 3), 0.7)
    rho[:, 2] = 0.5
    rho[::17] = 0.999                                   # every 17th patch is metal
    S = np.zeros((n, 3))
    S[: n // 5] = 1.0
    D = F.to_dense()
    true_norm = max(np.abs(np.linalg.inv(np.eye(n) - rho[:, k:k + 1] * D)).sum(1).max() for k in range(3))
    kappa = amplification(F, rho)
    gamma = float((rho.max(1) * F.row_sums()).max())
    assert 1 / (1 - gamma) > 500
    assert true_norm <= kappa <= 1.2 * true_norm, (true_norm, kappa)
    assert true_norm < 5
    for method in ("gauss_seidel", "jacobi", "progressive"):
        sol = solve(F, rho, S, method, tol=1e-4, max_iterations=200, areas=A)
        true = np.abs(sol.B - _exact(F, rho, S)).max() / np.abs(sol.B).max()
        assert sol.converged and true <= sol.error_bound <= 1e-4, (method, sol.iterations)
        assert sol.error_bound == pytest.approx(sol.residual * kappa)
