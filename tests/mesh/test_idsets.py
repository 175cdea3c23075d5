"""ffdcli.mesh.idsets: the id-set helpers equal NumPy's set routines (sorted, each id once)."""

import numpy as np
import pytest

from ffdcli.mesh.idsets import setdiff_ids, union_ids, unique_ids


@pytest.mark.parametrize("dtype", [np.int32, np.int64, np.uint32])
@pytest.mark.parametrize("n", [0, 1, 2, 7, 1000])
def test_unique_union_setdiff_equal_numpy(dtype, n):
    rng = np.random.default_rng(n)
    a = rng.integers(0, max(n // 2, 1), (n, 3)).astype(dtype)
    b = rng.integers(0, max(n, 1), n).astype(dtype)
    a0, b0 = a.copy(), b.copy()
    for got, want in ((unique_ids(a), np.unique(a)), (unique_ids(a, b), np.unique(np.concatenate([a.ravel(), b]))),
                      (union_ids(a.ravel(), b), np.union1d(a, b)), (setdiff_ids(b, a), np.setdiff1d(b, a)),
                      (setdiff_ids(a, b[:0]), np.unique(a))):
        np.testing.assert_array_equal(got, want)
        assert got.dtype == want.dtype
    np.testing.assert_array_equal(a, a0)          # the inputs are never reordered
    np.testing.assert_array_equal(b, b0)


def test_empty_inputs():
    assert unique_ids().dtype == np.int64 and unique_ids().size == 0
    assert unique_ids(np.zeros(0)).dtype == np.int64
    np.testing.assert_array_equal(unique_ids(np.array([5, 5, -1, 3])), [-1, 3, 5])
