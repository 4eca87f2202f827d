"""Fast paths that must give NumPy's own values bit for bit: core.util.geometry.cross3 against
np.cross, and core.util.sparse.summed_entries (which leaves out the entries of weight 0 before
its sort) against NumPy's unique and bincount over every entry, zeros included."""
import numpy as np
import pytest

from hemicube_radiosity.core.util.geometry import cross3
from hemicube_radiosity.core.util.sparse import nonzero_entries, summed_entries


def _vectors(rng, shape):
    v = rng.normal(size=shape) * 10.0 ** rng.integers(-6, 6, shape)
    v[rng.random(shape) < 0.1] = 0.0
    v[rng.random(shape) < 0.05] = -0.0
    return v


@pytest.mark.parametrize("shapes", [((500, 3), (500, 3)), ((40, 7, 3), (40, 7, 3)), ((40, 7, 3), (40, 1, 3)),
                                    ((300, 3), (3,)), ((3,), (3,)), ((0, 3), (0, 3))])
def test_cross3_is_numpys_cross_bit_for_bit(shapes):
    rng = np.random.default_rng(3)
    a, b = _vectors(rng, shapes[0]), _vectors(rng, shapes[1])
    want, got = np.cross(a, b), cross3(a, b)
    assert got.shape == want.shape and got.dtype == want.dtype
    # the same bits, signed zeros included
    assert np.array_equal(got.view(np.int64), want.view(np.int64))


def _numpy_rows(rows, ids, weights, width, m):
    """summed_entries' rows by np.unique and bincount over every entry (zeros too)."""
    k = ids.shape[1]
    key, inv = np.unique(np.repeat(rows, k) * width + ids.ravel(), return_inverse=True)
    summed = np.bincount(inv.reshape(-1), weights=weights.ravel(), minlength=key.size)
    key, summed = key[summed != 0], summed[summed != 0]
    return np.bincount(key // width, minlength=m), (key % width).astype(np.int32), summed.astype(np.float32)


@pytest.mark.parametrize("seed", range(4))
def test_summed_entries_with_zero_weights_is_numpys_sum_bit_for_bit(seed):
    rng = np.random.default_rng(seed)
    m, width, h = 50, 40, 3000
    rows = np.sort(rng.integers(0, m, h))
    ids = rng.integers(0, width, (h, 4))
    w = rng.random((h, 4)) * 10.0 ** rng.integers(-8, 2, (h, 4))
    w[:, 3] = 0.0                                          # a triangle's fourth corner
    w[rng.random((h, 4)) < 0.1] = 0.0
    w[rng.random((h, 4)) < 0.02] *= -1.0                   # signed values, -0.0 among the zeros
    only_zero = rows == rows[0]
    w[only_zero] = 0.0                                     # a row whose every entry is 0
    want = _numpy_rows(rows, ids, w, width, m)
    got = summed_entries(rows, ids, w, width, m)
    assert want[0][rows[0]] == 0
    for g, e in zip(got, want):
        assert g.dtype == e.dtype and np.array_equal(g, e)


def test_summed_entries_all_zero_and_nonzero_entries():
    rows, ids = np.array([0, 0, 2]), np.array([[1, 2], [1, 3], [0, 0]])
    counts, cols, vals = summed_entries(rows, ids, np.zeros((3, 2)), 4, 3)
    assert np.array_equal(counts, [0, 0, 0]) and cols.size == 0 and vals.dtype == np.float32
    key, w = np.arange(5), np.array([0.0, 1.0, -0.0, 2.0, 0.0])
    k2, w2 = nonzero_entries(key, w)
    assert np.array_equal(k2, [1, 3]) and np.array_equal(w2, [1.0, 2.0])
    k3, w3 = nonzero_entries(key, w + 1.0)
    assert k3 is key                                       # nothing left out: the same arrays


def test_outside_decides_as_numpys_max_and_min():
    """mesh.contact_lines.outside (the contact cut's test of a piece against a line, on Python
    floats) against NumPy's max and min of the same values: NaN, infinities, signed zeros."""
    from hemicube_radiosity.core.mesh.contact_lines import outside
    rng = np.random.default_rng(5)
    specials = [np.nan, np.inf, -np.inf, 0.0, -0.0, 1e-300]
    for _ in range(4000):
        v = rng.normal(size=int(rng.integers(3, 7)))
        for i in np.flatnonzero(rng.random(v.size) < 0.15):
            v[i] = specials[int(rng.integers(len(specials)))]
        lo, hi = (float(x) for x in rng.normal(size=2))
        with np.errstate(invalid="ignore"):
            want = bool(v.max() <= lo or v.min() >= hi)
        assert outside(v.tolist(), lo, hi) == want, (v, lo, hi)
