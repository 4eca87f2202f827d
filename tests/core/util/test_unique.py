"""core.util.unique.unique_rows returns what np.unique(axis=0) returns, on the kinds of rows the
bake keys on: small and huge integer ranges (the packed key and the lexsort), negative values,
bools, floats with ties and signed zeros, one column and many."""
import numpy as np
import pytest

from hemicube_radiosity.core.util.unique import run_positions, unique_ints, unique_rows


def _cases():
    rng = np.random.default_rng(7)
    yield rng.integers(0, 5, (2000, 2))                              # many ties, packed key
    yield rng.integers(-3, 3, (500, 5))                              # negatives
    yield rng.integers(-2 ** 40, 2 ** 40, (300, 3))                  # ranges too wide to pack
    yield np.concatenate([rng.integers(0, 2 ** 62, (50, 1)), rng.integers(0, 3, (50, 1))], 1)
    yield rng.integers(0, 4, (400, 1)).astype(np.int32)              # one column, int32
    yield rng.random((300, 3)) > 0.5                                 # bools
    f = np.round(rng.normal(size=(600, 3)), 1)
    f[::7] = -0.0 * f[::7]                                           # signed zeros among ties
    yield f
    yield np.repeat(rng.normal(size=(20, 4)), 5, axis=0)[rng.permutation(100)]
    yield np.zeros((1, 3), np.int64)


@pytest.mark.parametrize("case", list(range(9)))
def test_unique_rows_is_numpys_unique_along_rows(case):
    a = list(_cases())[case]
    want, inv, cnt = np.unique(a, axis=0, return_inverse=True, return_counts=True)
    got, ginv, gcnt = unique_rows(a, return_inverse=True, return_counts=True)
    assert got.dtype == want.dtype and got.shape == want.shape
    assert np.array_equal(got, want)
    assert np.array_equal(ginv, np.asarray(inv).reshape(-1)) and ginv.ndim == 1
    assert np.array_equal(gcnt, cnt)
    assert np.array_equal(got[ginv], a)
    assert np.array_equal(unique_rows(a), want)
    only_inv = unique_rows(a, return_inverse=True)
    assert len(only_inv) == 2 and np.array_equal(only_inv[1], ginv)


def test_unique_rows_of_nothing():
    a = np.zeros((0, 2), np.int64)
    got, inv, cnt = unique_rows(a, return_inverse=True, return_counts=True)
    assert got.shape == (0, 2) and inv.shape == (0,) and cnt.shape == (0,)


def _int_cases():
    rng = np.random.default_rng(11)
    yield rng.integers(0, 50, 5000)
    yield rng.integers(-7, 7, 300).astype(np.int32)
    yield rng.integers(0, 2 ** 61, 1000)                             # too wide to pack: NumPy's
    yield rng.integers(0, 3, (40, 7))                                # flattened, as NumPy does
    yield np.array([5])
    yield rng.random(100) > 0.3
    yield rng.integers(0, 2 ** 20, 4096).astype(np.uint32)
    # a gather chunk's keys: rows ascending, each row's columns in no order, repeats in a row
    yield np.repeat(np.arange(300), 64) * 5000 + rng.integers(0, 900, 300 * 64)
    yield np.arange(10_000)[::-1].copy()                           # one run, descending


@pytest.mark.parametrize("grouped", [False, True])
@pytest.mark.parametrize("case", list(range(9)))
def test_unique_ints_is_numpys_unique(case, grouped):
    x = list(_int_cases())[case]
    want = np.unique(x, return_index=True, return_inverse=True, return_counts=True)
    got = unique_ints(x, return_index=True, return_inverse=True, return_counts=True, grouped=grouped)
    assert got[0].dtype == want[0].dtype
    for g, w in zip(got, want):
        assert np.array_equal(g, np.asarray(w).reshape(-1))
    assert np.array_equal(unique_ints(x, grouped=grouped), want[0])
    assert np.array_equal(unique_ints(x, return_inverse=True, grouped=grouped)[1], np.asarray(want[2]).reshape(-1))


def test_run_positions_walk_each_run_from_zero():
    np.testing.assert_array_equal(run_positions([3, 0, 1, 2]), [0, 1, 2, 0, 0, 1])
    assert run_positions(np.zeros(0, np.int32)).size == 0
    counts = np.random.default_rng(3).integers(0, 6, 200)
    want = np.concatenate([np.arange(c) for c in counts])
    np.testing.assert_array_equal(run_positions(counts.astype(np.int32)), want)
