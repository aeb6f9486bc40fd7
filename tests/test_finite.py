"""all_finite: the bad-data screens' test — a compiled loop for small arrays, a vectorised compiled sum
for large contiguous float64 ones, numpy's for the rest."""

import numpy as np
import pytest

from flowtact.finite import COMPILED_MAX, all_finite


@pytest.mark.parametrize("size", [1, 7, COMPILED_MAX, COMPILED_MAX + 1, 50_000])
@pytest.mark.parametrize("dtype", [np.float64, np.float32, np.float16])
@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_one_bad_value_anywhere_is_found(size, dtype, bad):
    rng = np.random.default_rng(size)
    a = rng.normal(0.0, 1e3, size).astype(dtype)
    assert all_finite(a)
    for i in {0, size // 2, size - 1}:
        b = a.copy()
        b[i] = bad
        assert not all_finite(b), (i, b[i])


def test_shapes_views_and_read_only_arrays():
    a = np.arange(60.0).reshape(3, 4, 5)
    a.flags.writeable = False
    assert all_finite(a) and all_finite(a[:, ::2, 1:]) and all_finite(a[0, 0, :0])
    assert all_finite(np.empty((0, 3))) and all_finite(np.array(np.finfo(np.float64).max))
    b = a.copy()
    b[2, 3, 4] = np.nan
    assert not all_finite(b[:, ::3]) and all_finite(b[:, ::2])  # the NaN is in column 3 only
    assert not all_finite(np.array(np.inf))


def test_large_views_and_the_vectorised_path_agree_with_numpy():
    """Wide arrays take the compiled sum of x·0 when contiguous, numpy's test when strided; a bad
    value is found by both, and a bad value outside a view is not."""
    a = np.random.default_rng(3).normal(0.0, 1e300, (500, 200))  # values near overflow stay finite
    assert all_finite(a) and all_finite(a[:, ::2])
    for bad in (np.nan, np.inf, -np.inf):
        b = a.copy()
        b[499, 199] = bad
        assert not all_finite(b) and not all_finite(b[:, 1::2]) and all_finite(b[:, ::2])
