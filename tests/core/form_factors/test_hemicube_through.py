"""Hemi-cube form factors through see-through patches (core/form_factors/hemicube.py), against
closed forms: floor patches under a down-facing plane of transmittance 0.3 (with its back) and a
lid over it see the plane at 0.7 of its form factor and the lid behind it at 0.3 of what the
plane covers, for patches and for clusters (rows still sum to 1 at most); and a scene whose
receivers see no see-through patch gives the F it gave without one, bit for bit."""
from __future__ import annotations

import numpy as np
import pytest

from hemicube_radiosity.core.form_factors.hemicube import hemicube_form_factors
from hemicube_radiosity.core.light.transmit import Transmit
from hemicube_radiosity.core.mesh.backs import offset
from hemicube_radiosity.core.mesh.clusters import make_clusters
from hemicube_radiosity.core.mesh.patches import MeshInput
from hemicube_radiosity.core.mesh.subdivide import build_patches
from tests.core.output.test_gather import _rectangle_above

T, TOL = 0.3, 0.012            # transmittance; the hemi-cube's error at resolution 64 (measured 0.009)


def _grid(n, half, z, down=False):
    xs = np.linspace(-half, half, n + 1)
    X, Y = np.meshgrid(xs, xs, indexing="xy")
    v = np.stack([X.ravel(), Y.ravel(), np.full(X.size, float(z))], 1)
    i = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    f = np.stack([i[:-1, :-1], i[:-1, 1:], i[1:, 1:], i[1:, :-1]], -1).reshape(-1, 4)
    return v, (f[:, ::-1] if down else f)


def _patches(transmit=Transmit(np.full(4, T)), veil_z=1.0):
    """A 4 x 4 m floor of 0.1 m faces; a 2 x 2 m plane of 2 x 2 faces ``veil_z`` over it facing
    down, with its back a hair above; a 6 x 6 m lid facing down 2 m up."""
    floor = MeshInput.from_faces(*_grid(40, 2.0, 0.0), rho=(0.5,) * 3, name="floor")
    v, f = _grid(2, 1.0, veil_z, down=True)
    veil = MeshInput.from_faces(v, f, rho=(0.3,) * 3, name="veil")
    veil.transmit = transmit
    back = MeshInput(v + [0, 0, offset(v)], veil.face_offsets, veil.face_indices.reshape(-1, 4)[:, ::-1].ravel(),
                     veil.face_rho, veil.face_emission, "veil (back)", back_of=1, back_faces=np.arange(4))
    lid = MeshInput.from_faces(*_grid(1, 3.0, 2.0, down=True), rho=(0.5,) * 3, name="lid")
    return build_patches([floor, veil, back, lid], None)


def _rows(F, rows, cols_of):
    """(len(rows), k) sums of F's rows over each group of columns in ``cols_of`` (k lists)."""
    D = np.zeros((len(rows), F.shape[1]))
    for j, r in enumerate(rows):
        D[j, F.indices[F.indptr[r]:F.indptr[r + 1]]] = F.data[F.indptr[r]:F.indptr[r + 1]]
    return np.stack([D[:, c].sum(axis=1) for c in cols_of], 1)


def _expected(centres):
    x, y = centres[:, 0], centres[:, 1]
    Fv = _rectangle_above(-1 - x, 1 - x, -1 - y, 1 - y, 1.0)
    Fl = _rectangle_above(-3 - x, 3 - x, -3 - y, 3 - y, 2.0)
    return (1 - T) * Fv, Fl - (1 - T) * Fv, 1 - Fl


def test_floor_patches_see_the_lid_through_a_plane_of_transmittance_0_3():
    P = _patches()
    F = hemicube_form_factors(P, 64)
    floor = np.flatnonzero((P.owner == 0) & (np.abs(P.centers[:, :2]).max(axis=1) < 1.6))[::7]
    got = _rows(F, floor, [np.flatnonzero(P.owner == k) for k in (1, 2, 3)])
    Fv, Fl, sky = _expected(P.centers[floor])
    assert np.abs(got[:, 0] - Fv).max() < TOL                  # the plane, 0.7 of it
    assert not got[:, 1].any()                                 # its back faces away
    assert np.abs(got[:, 2] - Fl).max() < TOL                  # the lid, 0.3 of it behind the plane
    assert np.abs(F.sky[floor] - sky).max() < TOL
    assert np.mean(T * Fv > 2 * TOL) > 0.5                     # (opaque: 0.3 Fv / 0.7 off)
    assert np.allclose(F.meta["passes"], np.isin(P.owner, (1, 2)) * T)
    assert (F.row_sums() + F.sky).max() < 1 + 1e-6


def test_clusters_pass_their_mean_transmittance():
    """The plane's four faces one cluster, its back's another (every other patch its own): the
    floor's rows read the same closed forms over clusters."""
    P = _patches(Transmit(np.array([0.1, 0.5, 0.3, 0.3])))         # mean 0.3 (equal areas)
    of = np.arange(len(P))
    for k in (1, 2):
        on = np.flatnonzero(P.owner == k)
        of[on] = on[0]
    of = np.unique(of, return_inverse=True)[1].reshape(-1)
    C = make_clusters(P, of)
    F = hemicube_form_factors(P, 64, clusters=C)
    floor = np.flatnonzero((P.owner == 0) & (np.abs(P.centers[:, :2]).max(axis=1) < 1.6))[::7]
    got = _rows(F, of[floor], [[of[P.owner == k][0]] for k in (1, 2, 3)])
    Fv, Fl, sky = _expected(P.centers[floor])
    assert np.abs(got[:, 0] - Fv).max() < TOL and not got[:, 1].any()
    assert np.abs(got[:, 2] - Fl).max() < TOL
    assert np.abs(F.sky[of[floor]] - sky).max() < TOL


def test_receivers_that_see_no_see_through_patch_get_the_same_f_bit_for_bit():
    """The plane under the floor (no receiver that sees it is asked for): the floor's and the
    lid's rows as without see-through faces."""
    a, b = _patches(veil_z=-1.0), _patches(transmit=None, veil_z=-1.0)
    assert a.see_through is not None and b.see_through is None
    recv = np.flatnonzero(np.isin(a.owner, (0, 3)))
    Fa, Fb = (hemicube_form_factors(p, 32, receivers=recv) for p in (a, b))
    for x, y in ((Fa.indptr, Fb.indptr), (Fa.indices, Fb.indices), (Fa.data, Fb.data), (Fa.sky, Fb.sky)):
        assert np.array_equal(x, y)


def test_the_furnace_holds_with_a_half_transparent_panel_inside():
    """A closed room (rho 0.9, emission 1) with a panel of transmittance 0.5 inside whose solid
    half is made as the walls are (reflectance 0.45 and emission 0.5 over its area, as Cycles'
    albedo carries the alpha): the light is E / (1 - rho) = 10 everywhere, the panel's mean 5,
    however the panel stands. The solve reads the panel over its solid half (F's rows would
    otherwise sum past 1: rho x row sum up to 1.044 here, which the solver refuses); with the
    panel opaque to the form factors the walls read 6.9 on average, 6.4 at least."""
    from hemicube_radiosity.core.builtin_scenes import closed_box
    from hemicube_radiosity.core.pipeline import BakeSettings, bake

    rho, t = 0.9, 0.5
    room = closed_box(size=(2.0, 2.0, 2.0), rho=(rho,) * 3, emission=(1.0,) * 3)
    pv = np.array([[0.4, 0.4, 1.0], [1.6, 0.4, 1.0], [1.6, 1.6, 1.0], [0.4, 1.6, 1.0]])
    panel = MeshInput.from_faces(pv, [[0, 1, 2, 3]], rho=(rho * (1 - t),) * 3, emission=(1 - t,) * 3,
                                 name="panel")
    panel.transmit = Transmit(np.array([t]))
    r = bake(room + [panel], BakeSettings(patch_size=0.25, element_size=None, method="hemicube", resolution=32))
    B, P = r.patch_radiosity[:, 0], r.patches
    assert len(P.object_names) == 3 and r.form_factors.meta["passes"].max() == t   # the panel, its back
    np.testing.assert_allclose(B[P.owner == 0], 10.0, rtol=1e-3)
    np.testing.assert_allclose(B[P.owner > 0], 5.0, rtol=1e-3)
    assert abs(r.solution.energy["imbalance"]) < 1e-3
