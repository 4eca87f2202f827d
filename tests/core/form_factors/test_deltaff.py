"""Delta form factors: exact per pixel, symmetric, summing to one, tending to eq. (3)."""
import numpy as np
import pytest

from hemicube_radiosity.core.form_factors.deltaff import delta_form_factors


def point_to_polygon(polys):
    """Form factor from the origin (normal +Z) to convex polygons (M, K, 3) above the horizon.

    Independent of the module: the contour integral F = 1/(2 pi) |sum_k angle_k n . unit(r_k x r_k+1)|.
    """
    r = polys
    rn = np.roll(polys, -1, axis=1)
    cross = np.cross(r, rn)
    angle = np.arctan2(np.linalg.norm(cross, axis=2), np.einsum("mki,mki->mk", r, rn))
    return np.abs(np.sum(angle * cross[..., 2] / np.linalg.norm(cross, axis=2), axis=1)) / (2 * np.pi)


def pixel_squares(R):
    """Every pixel of the top face and of the +X side face as a polygon (table layout)."""
    e = -1 + 2 * np.arange(R + 1) / R
    h = e[R // 2:]
    row, col = np.meshgrid(np.arange(R), np.arange(R), indexing="ij")
    x0, x1, y0, y1 = e[col], e[col + 1], e[row], e[row + 1]
    one = np.ones_like(x0)
    top = np.stack([np.stack(p, -1) for p in ((x0, y0, one), (x1, y0, one), (x1, y1, one), (x0, y1, one))], 2)
    row, col = np.meshgrid(np.arange(R // 2), np.arange(R), indexing="ij")
    s0, s1, z0, z1 = e[col], e[col + 1], h[row], h[row + 1]
    one = np.ones_like(s0)
    side = np.stack([np.stack(p, -1) for p in ((one, s0, z0), (one, s1, z0), (one, s1, z1), (one, s0, z1))], 2)
    return top, side


@pytest.mark.parametrize("R", [2, 4, 10, 64, 128, 1000])
def test_tables_sum_to_one(R):
    top, side = delta_form_factors(R)
    assert top.shape == (R, R) and side.shape == (R // 2, R)
    assert top.dtype == np.float64 and side.dtype == np.float64
    assert abs(top.sum() + 4 * side.sum() - 1.0) < 1e-12
    assert np.all(top > 0) and np.all(side > 0)


@pytest.mark.parametrize("R", [2, 6, 32, 100])
def test_symmetry_built_tables_match_direct_evaluation_of_every_pixel(R):
    top, side = delta_form_factors(R)
    ptop, pside = pixel_squares(R)
    direct_top = point_to_polygon(ptop.reshape(-1, 4, 3)).reshape(R, R)
    direct_side = point_to_polygon(pside.reshape(-1, 4, 3)).reshape(R // 2, R)
    np.testing.assert_allclose(top, direct_top, rtol=1e-9, atol=0)
    np.testing.assert_allclose(side, direct_side, rtol=1e-9, atol=0)
    # the symmetries the construction relies on hold on the result
    np.testing.assert_array_equal(top, top.T)
    np.testing.assert_array_equal(top, top[::-1])
    np.testing.assert_array_equal(side, side[:, ::-1])


def centre_point_tables(R):
    """Cohen & Greenberg eq. (3) at the pixel centres."""
    c = -1 + (np.arange(R) + 0.5) * 2 / R
    z = (np.arange(R // 2) + 0.5) * 2 / R
    dA = (2 / R) ** 2
    top = dA / (np.pi * (c[None, :] ** 2 + c[:, None] ** 2 + 1) ** 2)
    side = z[:, None] * dA / (np.pi * (c[None, :] ** 2 + z[:, None] ** 2 + 1) ** 2)
    return top, side


def test_converges_to_the_centre_point_formula():
    errors = []
    for R in (16, 64, 512):
        top, side = delta_form_factors(R)
        ctop, cside = centre_point_tables(R)
        errors.append(max(np.abs(top / ctop - 1).max(), np.abs(side / cside - 1).max()))
    # midpoint rule: relative error O(1/R^2)
    assert errors[0] > errors[1] > errors[2]
    assert errors[1] / errors[2] > 50
    assert errors[2] < 2e-5
    # the centre-point tables themselves do not sum to one at low resolution
    ctop, cside = centre_point_tables(16)
    assert abs(ctop.sum() + 4 * cside.sum() - 1) > 1e-4


def test_cached_read_only_and_validated():
    a = delta_form_factors(64)
    assert delta_form_factors(64)[0] is a[0]
    with pytest.raises(ValueError):
        a[0][0, 0] = 1.0
    for bad in (0, 3, 63, -4, 2.5):
        with pytest.raises(ValueError, match="even integer"):
            delta_form_factors(bad)
