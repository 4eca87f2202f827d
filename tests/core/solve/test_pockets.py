"""Pockets (patches that trap light, :mod:`hemicube_radiosity.core.solve.pockets`): solved as
one dense block inside Gauss-Seidel, with the block splitting's error bound; checked against a
dense ``numpy.linalg.solve`` of the same system.

The scene: the open Cornell box with two plates of reflectance 0.999 standing 1 cm apart facing
each other (a sofa's gap between cushions) and a closed cube of 0.999 glowing faintly inside
(every row of its inside sees only the cube: ``||(I - rho F)^-1||_inf`` is 1000 there exactly,
as in the grey-white room)."""
import numpy as np
import pytest

from hemicube_radiosity.core.builtin_scenes import box, cornell_box, quad
from hemicube_radiosity.core.solve import pockets as pk
from hemicube_radiosity.core.solve import solvers
from hemicube_radiosity.core.solve.residual import amplification, energy_balance, gain
from hemicube_radiosity.core.solve.solvers import solve
from hemicube_radiosity.core.util.sparse import CSR

WHITE = (0.999,) * 3


def _pocket_scene(gap=0.01):
    from hemicube_radiosity.core.form_factors.hemicube import hemicube_form_factors
    from hemicube_radiosity.core.mesh.subdivide import build_patches

    a = quad([(0.3, 1.4, 0.05), (0.9, 1.4, 0.05), (0.9, 1.4, 0.65), (0.3, 1.4, 0.65)], WHITE, name="PlateA")
    b = quad([(0.3, 1.4 - gap, 0.05), (0.3, 1.4 - gap, 0.65), (0.9, 1.4 - gap, 0.65), (0.9, 1.4 - gap, 0.05)],
             WHITE, name="PlateB")
    cube = box((1.5, 1.5, 1.5), (1.7, 1.7, 1.7), WHITE, emission=(1e-3,) * 3, inward=True, name="Closed")
    ps = build_patches(cornell_box() + [a, b, cube], 0.2)
    F = hemicube_form_factors(ps, 32)
    return F, ps.rho, ps.emission, ps.areas


@pytest.fixture(scope="module")
def scene():
    F, rho, S, A = _pocket_scene()
    D = F.to_dense()
    exact = np.stack([np.linalg.solve(np.eye(len(D)) - rho[:, k:k + 1] * D, S[:, k]) for k in range(3)], 1)
    return F, rho, S, A, D, exact


def _true(sol, exact):
    return np.abs(sol.B - exact).max() / np.abs(sol.B).max()


def test_the_scene_has_pockets_the_plain_bound_cannot_see_past(scene):
    F, rho, S, A, D, exact = scene
    n = len(D)
    kappa = amplification(F, rho)
    true_norm = max(np.linalg.solve(np.eye(n) - rho[:, k:k + 1] * D, np.ones(n)).max() for k in range(3))
    assert true_norm == pytest.approx(1000, rel=1e-3)       # the closed cube: 1 / (1 - 0.999)
    assert true_norm <= kappa * (1 + 1e-9)
    p = pk.find_pockets(F, rho, gain(F, rho), kappa)
    assert p is not None
    plates_and_cube = np.flatnonzero(rho[:, 0] > 0.99)
    assert set(p.rows) <= set(plates_and_cube) and len(p.rows) >= 0.9 * len(plates_and_cube)
    assert p.kappa < 10


def test_block_splitting_pieces_against_dense_algebra(scene):
    """D^-1, G = D^-1 N and kappa_G against dense matrices: (I - T)^-1 = (I - G)^-1 D^-1,
    kappa_G >= ||(I - G)^-1||_inf, the block step is the exact B_P given the rest."""
    F, rho, S, A, D, exact = scene
    n = len(D)
    p = pk.find_pockets(F, rho, gain(F, rho), amplification(F, rho))
    P = p.rows
    rm = rho.max(axis=1)
    Dm = np.eye(n)
    Dm[np.ix_(P, P)] -= rm[P, None] * D[np.ix_(P, P)]
    N = Dm - (np.eye(n) - rm[:, None] * D)
    assert N.min() >= 0
    G = np.linalg.solve(Dm, N)
    np.testing.assert_allclose(G.sum(axis=1).max(), p.gain, rtol=1e-9)
    v = np.random.default_rng(0).uniform(size=n)
    np.testing.assert_allclose(p.gain_product(F, rm, v), G @ v, rtol=1e-9, atol=1e-12)
    true_norm = np.abs(np.linalg.inv(np.eye(n) - G)).sum(axis=1).max()
    assert true_norm <= p.kappa <= 2 * true_norm, (true_norm, p.kappa)
    r = np.random.default_rng(1).normal(size=(n, 3))
    for k in range(3):
        Dk = np.eye(n)
        Dk[np.ix_(P, P)] -= rho[P, k:k + 1] * D[np.ix_(P, P)]
        np.testing.assert_allclose(p.precondition(r)[:, k], np.linalg.solve(Dk, r[:, k]), rtol=1e-9, atol=1e-12)
    # the block step: B_P from the exact B elsewhere is the exact B_P
    BT = np.ascontiguousarray(exact.T).copy()
    BT[:, P] = 0.0
    got = p.solve_block(np.ascontiguousarray(rho.T), np.ascontiguousarray(S.T), BT)
    np.testing.assert_allclose(got, exact[P].T, rtol=1e-9, atol=1e-12 * exact.max())


def test_pockets_give_the_dense_solution_in_few_sweeps(scene):
    F, rho, S, A, D, exact = scene
    sol = solve(F, rho, S, tol=1e-6, max_iterations=200, areas=A)
    assert sol.converged and sol.extra["pockets"] > 0
    assert _true(sol, exact) <= sol.error_bound <= 1e-6
    np.testing.assert_allclose(sol.B, exact, rtol=0, atol=1e-6 * exact.max())
    assert sol.iterations <= 20
    # the balance is the form factors' (hemi-cube F is not exactly reciprocal), the same as B*'s
    assert sol.energy["imbalance"] == pytest.approx(energy_balance(F, rho, S, exact, A)["imbalance"], abs=1e-5)


def test_without_pockets_the_same_scene_does_not_converge_in_2000_sweeps(scene, monkeypatch):
    F, rho, S, A, D, exact = scene
    with_p = solve(F, rho, S, tol=1e-4, max_iterations=2000)
    monkeypatch.setattr(solvers, "find_pockets", lambda *a, **k: None)
    F.__dict__.pop("_derived", None)       # what F keeps of its solves (the pockets found) forgotten
    without = solve(F, rho, S, tol=1e-4, max_iterations=2000)
    F.__dict__.pop("_derived", None)       # ... and so is this solve's lack of them (F is shared)
    assert with_p.converged and with_p.iterations <= 10
    assert not without.converged and without.iterations == 2000     # its bound: 1000 x the residual
    assert _true(with_p, exact) <= with_p.error_bound <= 1e-4
    assert 1e-4 < _true(without, exact) <= without.error_bound      # truly short of B*: slow, not loose


@pytest.mark.parametrize("cap", [1, 2, 3, 4, 6, 8])
def test_capped_pocket_solve_reports_a_bound_that_holds(scene, cap):
    """Stopped early: the reported bound is at least the true error (and not far above it)."""
    F, rho, S, A, D, exact = scene
    sol = solve(F, rho, S, tol=1e-12, max_iterations=cap)
    assert not sol.converged and sol.iterations == cap
    true = _true(sol, exact)
    assert true <= sol.error_bound <= 10 * true, (true, sol.error_bound)
    assert sol.error_bound < sol.residual * sol.extra["amplification"]


def test_open_scenes_and_uniform_rooms_have_no_pockets():
    from tests.core.solve.test_solve import _closed_box_F, random_reciprocal_system

    F, A, rho, S = random_reciprocal_system()
    Fc = CSR.from_dense(F)
    assert pk.find_pockets(Fc, rho, gain(Fc, rho), amplification(Fc, rho)) is None
    Fb, _ = _closed_box_F()
    rho = np.full((Fb.shape[0], 3), 0.999)    # one slow mode over the whole room: over-relaxation's
    assert pk.find_pockets(Fb, rho, gain(Fb, rho), amplification(Fb, rho)) is None
    sol = solve(Fb, rho, np.ones_like(rho), tol=1e-4, max_iterations=1000)
    assert "pockets" not in sol.extra and sol.extra["omega"] > 1.8
