"""The lattice map (ffdcli.lattice.lattice): compiled kernels against the NumPy tensor products, finite
differences, exact end interpolation, linear precision, affine invariance and input checks."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from lattice_cases import curved_patch, wing_grid, wing_lattice
from numba import njit

from ffdcli.errors import InputError
from ffdcli.lattice.lattice import (
    Lattice,
    derivatives,
    derivatives_reference,
    eval_point_fixed_nb,
    eval_point_nb,
    evaluate,
    evaluate_reference,
    fixed_widths,
    kernel_args,
    padded_rows,
)
from ffdcli.lattice.spline import clamped_knots
from ffdcli.settings import MAX_DEGREE

# Compiled vs NumPy reference: same sums in a different order on coordinates of order 1-5 (mesh
# units), so they agree to a few ulps of the coordinates; 1e-13 relative to the lattice size
# (~5 here) is ~100 ulps and far below any indexing error (order of a control-point spacing).
KERNEL_TOL = 1e-13

CASES = {
    "3d-wing": lambda: wing_lattice((8, 6, 2), (3, 3, 1)),
    "3d-wing-deg3": lambda: wing_lattice((7, 6, 5), 3),
    "3d-mixed": lambda: Lattice(wing_grid((6, 4, 4)), (5, 1, 2), knots=(
        np.array([0, 0, 0, 0, 0, 0, 1, 1, 1, 1, 1, 1.0]), clamped_knots(4, 1),
        np.array([0, 0, 0, 0.3, 1, 1, 1]))),
    "2d-gdim2": lambda: curved_patch((6, 5), (3, 2), gdim=2),
    "2d-gdim3": lambda: curved_patch((5, 4), (4, 1), gdim=3),
}


def random_params(rng, pdim, n, margin=0.0):
    u = rng.uniform(margin, 1.0 - margin, (n, pdim))
    # include the corners and faces (parameters exactly 0 or 1) unless a margin is asked for
    if margin == 0.0:
        corners = np.array(np.meshgrid(*[[0.0, 1.0]] * pdim, indexing="ij")).reshape(pdim, -1).T
        u = np.vstack([u, corners])
        u[: n // 10, 0] = rng.choice([0.0, 1.0], n // 10)
    return u


@pytest.mark.parametrize("case", sorted(CASES))
def test_compiled_evaluate_and_derivatives_match_reference(case):
    lat = CASES[case]()
    rng = np.random.default_rng(1)
    u = random_params(rng, lat.pdim, 500)
    X = evaluate(lat, u)
    assert X.shape == (u.shape[0], lat.gdim)
    np.testing.assert_allclose(X, evaluate_reference(lat, u), rtol=0, atol=KERNEL_TOL * lat.size)
    J = derivatives(lat, u)
    assert J.shape == (u.shape[0], lat.gdim, lat.pdim)
    Jref = derivatives_reference(lat, u)
    np.testing.assert_allclose(J, Jref, rtol=0, atol=KERNEL_TOL * np.abs(Jref).max())


@pytest.mark.parametrize("case", sorted(CASES))
def test_derivatives_match_central_differences(case):
    lat = CASES[case]()
    rng = np.random.default_rng(2)
    h = 1e-5
    u = random_params(rng, lat.pdim, 200, margin=h)
    J = derivatives(lat, u)
    for a in range(lat.pdim):
        e = np.zeros(lat.pdim)
        e[a] = h
        fd = (evaluate(lat, u + e) - evaluate(lat, u - e)) / (2 * h)
        # error of the central difference: truncation h^2/6 |V'''| (V''' of these lattices is below
        # ~1e3 x size: third derivatives of quintics over spans of 1/2) plus round-off eps |V| / h
        # ~ 2e-11 x size: 1e-7 x size bounds both; a wrong derivative is off by O(size).
        np.testing.assert_allclose(J[:, :, a], fd, rtol=0, atol=1e-7 * lat.size)


@pytest.mark.parametrize("case", sorted(CASES))
def test_corners_interpolate_control_points(case):
    lat = CASES[case]()
    pdim = lat.pdim
    idx = np.array(np.meshgrid(*[[0, 1]] * pdim, indexing="ij")).reshape(pdim, -1).T
    X = evaluate(lat, idx.astype(float))
    cp = lat.control_points
    expect = np.array([cp[tuple(np.where(c, -1, 0))] for c in idx])
    # clamped knots: the corner values are exactly the corner control points (one basis value is 1)
    np.testing.assert_array_equal(X, expect)


def greville(knots, degree):
    n = knots.size - degree - 1
    return np.array([knots[i + 1: i + degree + 1].mean() for i in range(n)])


@pytest.mark.parametrize("case", sorted(CASES))
def test_linear_precision(case):
    """Control points at the Greville abscissae of an affine map reproduce that map exactly."""
    lat = CASES[case]()
    rng = np.random.default_rng(3)
    grids = np.meshgrid(*[greville(k, p) for k, p in zip(lat.knots, lat.degree, strict=True)], indexing="ij")
    G = np.stack(grids, axis=-1)
    A = rng.normal(size=(lat.gdim, lat.pdim))
    b = rng.normal(size=lat.gdim)
    affine = Lattice(G @ A.T + b, lat.degree, lat.knots)
    u = random_params(rng, lat.pdim, 300)
    # exact up to rounding of sums of a few dozen terms of order 1
    np.testing.assert_allclose(evaluate(affine, u), u @ A.T + b, rtol=0, atol=1e-13 * 10)
    np.testing.assert_allclose(derivatives(affine, u), np.broadcast_to(A, (u.shape[0], *A.shape)),
                               rtol=0, atol=1e-12)


@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), case=st.sampled_from(sorted(CASES)))
def test_affine_invariance(seed, case):
    """evaluate with A @ P + b equals A @ X + b (partition of unity): what design changes rely on."""
    lat = CASES[case]()
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(lat.gdim, lat.gdim))
    b = rng.normal(size=lat.gdim) * 10
    moved = lat.with_control_points(lat.control_points @ A.T + b)
    u = random_params(rng, lat.pdim, 100)
    X = evaluate(lat, u)
    scale = lat.size * np.abs(A).max() + np.abs(b).max()
    np.testing.assert_allclose(evaluate(moved, u), X @ A.T + b, rtol=0, atol=1e-13 * scale)


def test_lattice_properties_and_read_only():
    lat = wing_lattice()
    assert lat.pdim == 3 and lat.gdim == 3 and lat.shape == (8, 6, 2) and lat.n_ctrl == 96
    assert lat.degree == (3, 3, 1)
    pts = lat.control_points.reshape(-1, 3)
    assert lat.size == pytest.approx(np.linalg.norm(pts.max(0) - pts.min(0)), rel=1e-15)
    with pytest.raises(ValueError):
        lat.control_points[0, 0, 0, 0] = 1.0
    assert Lattice(wing_grid((4, 4, 4)), 2).degree == (2, 2, 2)
    with pytest.raises(ValueError, match="control points of shape"):
        lat.with_control_points(np.zeros((8, 6, 3, 3)))


@pytest.mark.parametrize("cp,degree,msg", [
    (np.zeros((4, 3)), 1, "must have shape"),
    (np.zeros((2, 2, 2, 2, 3)), 1, "must have shape"),
    (np.zeros((4, 4, 4, 2)), 1, "3D lattice needs 3 coordinates per control point, got 2"),
    (np.zeros((4, 4, 1)), 1, "2D lattice needs 2 or 3 coordinates per control point, got 1"),
    (np.zeros((4, 4, 4)), 1, "2D lattice needs 2 or 3 coordinates per control point, got 4"),
    (np.full((4, 4, 4, 3), np.nan), 1, "NaN"),
    (wing_grid((4, 4, 4)), (3, 3), "degree needs 3 integers"),
    (wing_grid((4, 4, 4)), (3, 3, 1.5), "degree needs 3 integers"),
    (wing_grid((4, 4, 4)), (4, 3, 3), "needs more than 4 control points"),
    (wing_grid((4, 4, 2)), (3, 3, 2), "needs more than 2 control points"),
    (wing_grid((8, 8, 8)), 6, "not supported"),
    (wing_grid((4, 4, 4)), 0, "not supported"),
])
def test_lattice_rejects_bad_input(cp, degree, msg):
    with pytest.raises(InputError, match=msg):
        Lattice(cp, degree)


def test_lattice_rejects_bad_knots():
    with pytest.raises(InputError, match="2 knot vectors"):
        Lattice(np.zeros((4, 4, 2)), 1, knots=(clamped_knots(4, 1),))
    with pytest.raises(InputError, match="invalid knot vector"):
        Lattice(np.zeros((4, 4, 2)), 1, knots=(clamped_knots(4, 1), clamped_knots(5, 1)))


def test_evaluate_rejects_bad_params():
    lat = wing_lattice()
    for bad in (np.zeros((3, 2)), np.zeros(3), np.zeros((3, 4))):
        with pytest.raises(ValueError, match=r"params must have shape \(N, 3\)"):
            evaluate(lat, bad)
    for bad in ([[0.5, 0.5, 1.0 + 1e-9]], [[-1e-9, 0.5, 0.5]], [[np.nan, 0.5, 0.5]]):
        with pytest.raises(ValueError, match="must lie in"):
            evaluate(lat, bad)
        with pytest.raises(ValueError, match="must lie in"):
            derivatives(lat, bad)
    assert evaluate(lat, np.zeros((0, 3))).shape == (0, 3)


@njit
def _both_kernels(P, k0, k1, k2, p0, p1, p2, R, n1, n2, w0, w1, w2, U, gen, fix):
    W = np.zeros((8, MAX_DEGREE + 1))
    for i in range(U.shape[0]):
        u2 = U[i, 2] if U.shape[1] == 3 else 0.0
        a = eval_point_nb(P, k0, k1, k2, p0, p1, p2, U[i, 0], U[i, 1], u2, W)
        b = eval_point_fixed_nb(R, n1, n2, k0, k1, k2, U[i, 0], U[i, 1], u2, w0, w1, w2)
        for j in range(12):
            gen[i, j] = a[j]
            fix[i, j] = b[j]


FIXED_CASES = dict(CASES, **{
    "3d-linear": lambda: wing_lattice((3, 2, 2), 1),
    "3d-quadratic-cubic-linear": lambda: wing_lattice((5, 7, 3), (2, 3, 1)),
    "3d-deg4-knots": lambda: Lattice(wing_grid((7, 5, 3)), (4, 2, 2), knots=(
        np.array([0, 0, 0, 0, 0, 0.4, 0.4, 1, 1, 1, 1, 1.0]), np.array([0, 0, 0, 0.25, 0.5, 1, 1, 1.0]),
        clamped_knots(3, 2))),
    "2d-linear-gdim2": lambda: curved_patch((4, 3), (1, 1), gdim=2),
})


@pytest.mark.parametrize("case", sorted(FIXED_CASES))
def test_fixed_degree_kernel_is_the_generic_one_bit_for_bit(case):
    # the Newton embedding's kernel (unrolled for the lattice's degrees, 4-wide vector tensor product)
    # against the generic one: the same 12 floats, bit for bit, inside, on faces and corners and at
    # repeated knots
    lat = FIXED_CASES[case]()
    rng = np.random.default_rng(3)
    U = random_params(rng, lat.pdim, 400)
    breaks = np.unique(np.concatenate(lat.knots))
    U[-len(breaks):, -1] = breaks                      # parameters exactly at (repeated) knots
    P, k0, k1, k2, p0, p1, p2 = kernel_args(lat)
    gen = np.empty((len(U), 12))
    fix = np.empty((len(U), 12))
    _both_kernels(P, k0, k1, k2, p0, p1, p2, padded_rows(P), np.int64(P.shape[1]), np.int64(P.shape[2]),
                  *fixed_widths((p0, p1, p2)), np.ascontiguousarray(U), gen, fix)
    np.testing.assert_array_equal(fix, gen)
    np.testing.assert_allclose(fix[:, :lat.gdim], evaluate_reference(lat, U), rtol=0, atol=KERNEL_TOL * lat.size)


def test_padded_rows_and_fixed_widths():
    lat = wing_lattice((4, 3, 2), (3, 2, 1))
    P, *_, p0, p1, p2 = kernel_args(lat)
    R = padded_rows(P).reshape(-1, 4)
    np.testing.assert_array_equal(R[:, :3], lat.control_points.reshape(-1, 3))
    assert not R[:, 3].any()
    assert fixed_widths((p0, p1, p2)) == ((0.0,) * 4, (0.0,) * 3, (0.0,) * 2)
