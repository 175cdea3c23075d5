"""One-dimensional B-splines (ffdcli.lattice.spline) against scipy.interpolate.BSpline and their own identities.

Tolerance 1e-13: both sides run the Cox–de Boor recurrence in float64 on values of order 1; the
rounding error of a degree-p recurrence is a few p ulps (~1e-15), so 1e-13 leaves a factor ~50 and still
catches any wrong knot index or coefficient (those give errors of order 1e-2 and up). Derivatives are
compared relative to the largest derivative value (they scale with p / knot spacing).
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.interpolate import BSpline

from ffdcli.lattice.spline import (
    basis,
    basis_compiled,
    basis_d1_row_nb,
    basis_d1_tuple,
    basis_derivs,
    basis_row_nb,
    check_knots,
    clamped_knots,
    degree_proto,
    find_span,
    find_span_count_nb,
    find_span_nb,
)

TOL = 1e-13


def random_knots(rng, n_ctrl, degree):
    """A clamped knot vector with random distinct interior knots at least 0.02 apart."""
    n_inner = n_ctrl - degree - 1
    while True:
        inner = np.sort(rng.uniform(0.02, 0.98, n_inner))
        if n_inner < 2 or np.min(np.diff(inner)) >= 0.02:
            break
    return np.concatenate([np.zeros(degree + 1), inner, np.ones(degree + 1)])


def params_with_knots(rng, knots, n=200):
    """Random parameters plus every knot (span boundaries) and both ends."""
    return np.concatenate([rng.uniform(0.0, 1.0, n), np.unique(knots), [0.0, 1.0]])


def dense(first, values, n_ctrl):
    out = np.zeros((first.size, n_ctrl))
    rows = np.arange(first.size)[:, None]
    out[rows, first[:, None] + np.arange(values.shape[1])[None, :]] = values
    return out


def scipy_basis(knots, degree, t, nu=0):
    """All basis functions (N, n_ctrl) and their nu-th derivative from scipy's BSpline."""
    n_ctrl = knots.size - degree - 1
    spl = BSpline(knots, np.eye(n_ctrl), degree, extrapolate=False)
    if nu:
        spl = spl.derivative(nu)
    return spl(t)


# ---------------------------------------------------------------------------------------------- knots

def test_clamped_knots_uniform_and_clamped():
    k = clamped_knots(7, 3)
    np.testing.assert_array_equal(k, [0, 0, 0, 0, 1 / 4, 2 / 4, 3 / 4, 1, 1, 1, 1])
    assert check_knots(k, 3, 7) is not None
    np.testing.assert_array_equal(clamped_knots(2, 1), [0, 0, 1, 1])


@pytest.mark.parametrize("n_ctrl,degree", [(3, 3), (2, 5), (0, 1)])
def test_clamped_knots_rejects_degree_not_below_points(n_ctrl, degree):
    with pytest.raises(ValueError, match="more control points than the degree"):
        clamped_knots(n_ctrl, degree)


@pytest.mark.parametrize("knots,degree,n_ctrl,msg", [
    ([0, 0, 0.5, 1, 1], 1, 4, "need 6 knots"),
    ([[0, 0, 1, 1]], 1, None, "one-dimensional"),
    ([0, 0, 0.7, 0.3, 1, 1], 1, None, "non-decreasing"),
    ([0, 0, 0.5, np.nan, 1, 1], 1, None, "finite"),
    ([0, 0.1, 0.5, 1, 1], 1, None, "clamped"),
    ([0, 0, 0.5, 0.5, 0.5, 1, 1], 2, None, "clamped on"),
    ([0, 0, 0, 0.5, 0.5, 0.5, 1, 1, 1], 2, None, "repeated more than the degree"),
])
def test_check_knots_rejects(knots, degree, n_ctrl, msg):
    with pytest.raises(ValueError, match=msg):
        check_knots(knots, degree, n_ctrl)


def test_find_span_contract_and_compiled_agree():
    rng = np.random.default_rng(0)
    for p in range(1, 6):
        k = random_knots(rng, p + 6, p)
        t = params_with_knots(rng, k)
        s = find_span(k, p, t)
        n = k.size - p - 1
        assert np.all((s >= p) & (s <= n - 1))
        inner = t < 1.0
        assert np.all(k[s[inner]] <= t[inner]) and np.all(t[inner] < k[s[inner] + 1])
        assert np.all(s[t == 1.0] == n - 1)
        np.testing.assert_array_equal([find_span_nb(k, p, x) for x in t], s)


@pytest.mark.parametrize("n_ctrl", [2, 4, 8, 20, 21, 40])
def test_branch_free_span_is_the_binary_search(n_ctrl):
    # the count of interior knots at or below t (up to 16 of them), the binary search beyond:
    # the same span everywhere, at repeated knots, at and beyond the ends
    rng = np.random.default_rng(n_ctrl)
    for p in range(0, 6):
        if n_ctrl <= p:
            continue
        k = clamped_knots(n_ctrl, p)                  # uniform interior knots, then moved a little
        k[p + 1: n_ctrl] += rng.uniform(-0.2, 0.2, n_ctrl - p - 1) / (n_ctrl - p)
        if n_ctrl - p - 1 >= 3:                       # a knot repeated p times
            k[p + 2: p + 2 + p] = k[p + 2]
            k = np.ascontiguousarray(np.sort(k))
        t = np.concatenate([params_with_knots(rng, k), [-0.5, 1.5]])
        np.testing.assert_array_equal([find_span_count_nb(k, p, x) for x in t],
                                      [find_span_nb(k, p, x) for x in t])


# ---------------------------------------------------------------------------------------------- values

@pytest.mark.parametrize("degree", [1, 2, 3, 4, 5])
def test_basis_matches_scipy(degree):
    rng = np.random.default_rng(degree)
    for n_ctrl in (degree + 1, degree + 2, degree + 7):
        for knots in (clamped_knots(n_ctrl, degree), random_knots(rng, n_ctrl, degree)):
            t = params_with_knots(rng, knots)
            first, values = basis(knots, degree, t)
            assert values.shape == (t.size, degree + 1)
            np.testing.assert_allclose(dense(first, values, n_ctrl), scipy_basis(knots, degree, t),
                                       rtol=0, atol=TOL)


@pytest.mark.parametrize("degree", [1, 2, 3, 4, 5])
def test_basis_derivatives_match_scipy(degree):
    rng = np.random.default_rng(10 + degree)
    n_ctrl = degree + 5
    for knots in (clamped_knots(n_ctrl, degree), random_knots(rng, n_ctrl, degree)):
        # derivatives of order >= 1 jump at knots (left/right limits differ): avoid the knots
        t = rng.uniform(0.0, 1.0, 300)
        nder = degree + 1
        first, ders = basis_derivs(knots, degree, t, nder)
        assert ders.shape == (nder + 1, t.size, degree + 1)
        for k in range(nder + 1):
            ref = scipy_basis(knots, degree, t, k) if k <= degree else np.zeros((t.size, n_ctrl))
            scale = max(1.0, np.abs(ref).max())
            np.testing.assert_allclose(dense(first, ders[k], n_ctrl), ref, rtol=0, atol=TOL * scale)


@settings(max_examples=40, deadline=None)
@given(degree=st.integers(1, 5), extra=st.integers(0, 8), seed=st.integers(0, 2**32 - 1))
def test_partition_of_unity_and_non_negative(degree, extra, seed):
    rng = np.random.default_rng(seed)
    knots = random_knots(rng, degree + 1 + extra, degree)
    t = params_with_knots(rng, knots, 50)
    first, values = basis(knots, degree, t)
    assert np.all(values >= 0.0)
    np.testing.assert_allclose(values.sum(axis=1), 1.0, rtol=0, atol=TOL)
    # the derivatives of a partition of unity sum to zero
    _, ders = basis_derivs(knots, degree, t, 2)
    scale = max(1.0, np.abs(ders[1:]).max())
    np.testing.assert_allclose(ders[1:].sum(axis=2), 0.0, rtol=0, atol=TOL * scale)
    np.testing.assert_allclose(ders[0], values, rtol=0, atol=0)
    assert np.all(first >= 0) and np.all(first + degree <= knots.size - degree - 2)


@settings(max_examples=30, deadline=None)
@given(degree=st.integers(1, 5), extra=st.integers(0, 8), seed=st.integers(0, 2**32 - 1))
def test_compiled_kernels_match_numpy(degree, extra, seed):
    rng = np.random.default_rng(seed)
    knots = random_knots(rng, degree + 1 + extra, degree)
    t = params_with_knots(rng, knots, 100)
    first, values = basis(knots, degree, t)
    cfirst, cvalues = basis_compiled(knots, degree, t)
    np.testing.assert_array_equal(cfirst, first)
    np.testing.assert_allclose(cvalues, values, rtol=0, atol=TOL)
    _, ders = basis_derivs(knots, degree, t, 1)
    W = np.empty((6, degree + 1))
    scale = max(1.0, np.abs(ders[1]).max())
    for i in range(0, t.size, 7):
        span = find_span_nb(knots, degree, t[i])
        basis_d1_row_nb(knots, degree, span, t[i], W, 0, 1, 2, 3)
        np.testing.assert_allclose(W[0], values[i], rtol=0, atol=TOL)
        np.testing.assert_allclose(W[1], ders[1, i], rtol=0, atol=TOL * scale)
        # the values-only kernel does the same operations: bit for bit
        basis_row_nb(knots, degree, span, t[i], W, 4, 2, 3)
        np.testing.assert_array_equal(W[4], W[0])
        np.testing.assert_array_equal(W[0], cvalues[i])
        # the unrolled fixed-degree kernel of the Newton embedding: the same operations, bit for bit
        N, D = basis_d1_tuple(knots, span, t[i], degree_proto(degree))
        np.testing.assert_array_equal(np.array(N), W[0])
        np.testing.assert_array_equal(np.array(D), W[1])


def test_degree_zero_compiled_basis_is_constant():
    # the dummy third axis of a 2D lattice: one basis function, value 1, derivative 0
    W = np.empty((4, 1))
    basis_d1_row_nb(np.array([0.0, 1.0]), 0, 0, 0.3, W, 0, 1, 2, 3)
    assert W[0, 0] == 1.0 and W[1, 0] == 0.0
    assert basis_d1_tuple(np.array([0.0, 1.0]), 0, 0.3, degree_proto(0)) == ((1.0,), (0.0,))


def test_basis_rejects_parameters_outside_range():
    k = clamped_knots(5, 2)
    for bad in (-1e-12, 1.0 + 1e-12, np.nan):
        with pytest.raises(ValueError, match="outside the knot range"):
            basis(k, 2, [0.5, bad])
        with pytest.raises(ValueError, match="outside the knot range"):
            basis_compiled(k, 2, [bad])
    with pytest.raises(ValueError, match="nder"):
        basis_derivs(k, 2, [0.5], -1)
