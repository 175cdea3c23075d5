"""ffd's SQP with move limits (ffdcli.optimize.sqp): known optima, the QP against scipy, failures."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.optimize as so

from ffdcli.optimize import sqp
from ffdcli.optimize.sqp import (
    ETA,
    Filter,
    Point,
    bfgs_update,
    least_distance,
    minimize_sqp,
    solve_qp,
    verdict,
    violation,
)


def problem(f, g, c, A):
    """``evaluate`` of analytic functions, counting the calls."""
    calls = {"values": 0, "gradients": 0}

    def evaluate(x, gradient):
        calls["gradients" if gradient else "values"] += 1
        return Point(x=x.copy(), f=float(f(x)), c=np.atleast_1d(c(x)).astype(float),
                     g=g(x) if gradient else None, A=A(x) if gradient else None)
    return evaluate, calls


def hs071():
    """Hock and Schittkowski's problem 71: f* = 17.0140173 at (1, 4.7429994, 3.8211503, 1.3794082)."""
    return problem(lambda x: x[0] * x[3] * x[:3].sum() + x[2],
                   lambda x: np.array([x[3] * (2 * x[0] + x[1] + x[2]), x[0] * x[3], x[0] * x[3] + 1,
                                       x[0] * x[:3].sum()]),
                   lambda x: np.array([x.prod() - 25.0, x @ x - 40.0]),
                   lambda x: np.array([[x[1] * x[2] * x[3], x[0] * x[2] * x[3], x[0] * x[1] * x[3],
                                        x[0] * x[1] * x[2]], 2 * x]))


@pytest.mark.parametrize("radius", [0.05, 0.3, 1.0])
def test_hs071_reaches_its_known_optimum_from_any_first_move_limit(radius):
    evaluate, _ = hs071()
    r = minimize_sqp(evaluate, np.array([1.0, 5, 5, 1]), np.ones(4), np.full(4, 5.0), np.array([False, True]),
                     radius=radius, iterations=100, tolerance=1e-9)
    assert r.status == "converged", r.message
    assert r.point.f == pytest.approx(17.0140173, abs=1e-6)
    np.testing.assert_allclose(r.point.x, [1.0, 4.7429994, 3.8211503, 1.3794082], atol=1e-5)


def rosenbrock_in_disc():
    return problem(lambda x: (1 - x[0]) ** 2 + 100 * (x[1] - x[0] ** 2) ** 2,
                   lambda x: np.array([-2 * (1 - x[0]) - 400 * x[0] * (x[1] - x[0] ** 2), 200 * (x[1] - x[0] ** 2)]),
                   lambda x: 1.5 - x @ x, lambda x: -2 * x[None, :])


def test_constrained_rosenbrock_matches_scipys_slsqp():
    evaluate, calls = rosenbrock_in_disc()
    r = minimize_sqp(evaluate, np.array([-1.2, 1.0]), np.full(2, -5.0), np.full(2, 5.0), np.array([False]),
                     radius=0.2, iterations=200, tolerance=1e-9)
    ref = so.minimize(lambda x: (1 - x[0]) ** 2 + 100 * (x[1] - x[0] ** 2) ** 2, [-1.2, 1.0], method="SLSQP",
                      constraints=[{"type": "ineq", "fun": lambda x: 1.5 - x @ x}], options={"ftol": 1e-14})
    assert r.status == "converged"
    np.testing.assert_allclose(r.point.x, ref.x, atol=1e-5)
    assert calls["gradients"] == r.iterations + 1          # gradients only at accepted designs
    assert calls["values"] == r.trials


def test_equality_constraint_with_failed_designs():
    """min x + y on the circle x^2 + y^2 = 2: (-1, -1). The first two trial designs fail (a solver that
    diverges): the move limit shrinks and the run still gets there."""
    f, g, c, A = (lambda x: x.sum(), lambda x: np.ones(2), lambda x: np.array([x @ x - 2.0]),
                  lambda x: 2 * x[None, :])
    failed = []

    def evaluate(x, gradient):
        if not gradient and len(failed) < 2:
            failed.append(x.copy())
            return None
        return Point(x=x.copy(), f=f(x), c=c(x), g=g(x) if gradient else None, A=A(x) if gradient else None)

    r = minimize_sqp(evaluate, np.array([1.0, 0.5]), np.full(2, -5.0), np.full(2, 5.0), np.array([True]),
                     radius=1.0, iterations=100, tolerance=1e-9)
    assert r.status == "converged"
    np.testing.assert_allclose(r.point.x, [-1.0, -1.0], atol=1e-6)
    assert abs(r.point.c[0]) < 1e-8
    # each failure cut the move limit to a quarter of the failed step
    x0 = np.array([1.0, 0.5])
    assert np.abs(failed[1] - x0).max() <= 0.25 * np.abs(failed[0] - x0).max() + 1e-12


def test_iterations_are_accepted_steps_and_the_limit_holds():
    evaluate, calls = hs071()
    seen = []
    r = minimize_sqp(evaluate, np.array([1.0, 5, 5, 1]), np.ones(4), np.full(4, 5.0), np.array([False, True]),
                     radius=0.05, iterations=3, tolerance=1e-9, callback=seen.append)
    assert r.status == "iterations" and r.iterations == 3 == len(seen)
    assert calls["gradients"] == 4
    assert r.trials >= 3
    # a step never exceeds the move limit, which at most doubles per accepted step
    xs = [np.array([1.0, 5, 5, 1])] + [p.x for p in seen]
    assert all(np.abs(b - a).max() <= 0.05 * 2 ** k + 1e-12 for k, (a, b) in enumerate(zip(xs, xs[1:])))


@pytest.mark.parametrize("radius", [0.05, 0.3])
def test_scipy_minimize_with_the_callable_method_takes_the_same_steps(radius):
    """``scipy.optimize.minimize(method=sqp.method)``: the driver's one call path gives the same accepted
    designs, trials and result as :func:`minimize_sqp` itself (inequalities first, whatever the order)."""
    evaluate, _ = hs071()
    seen = []
    r = minimize_sqp(evaluate, np.array([1.0, 5, 5, 1]), np.ones(4), np.full(4, 5.0), np.array([False, True]),
                     radius=radius, iterations=100, tolerance=1e-9, callback=lambda p: seen.append(p.x))
    f, g, c, A = (lambda x: x[0] * x[3] * x[:3].sum() + x[2],
                  lambda x: np.array([x[3] * (2 * x[0] + x[1] + x[2]), x[0] * x[3], x[0] * x[3] + 1,
                                      x[0] * x[:3].sum()]),
                  lambda x: np.array([x.prod() - 25.0, x @ x - 40.0]),
                  lambda x: np.array([[x[1] * x[2] * x[3], x[0] * x[2] * x[3], x[0] * x[1] * x[3],
                                       x[0] * x[1] * x[2]], 2 * x]))
    steps = []
    res = so.minimize(f, np.array([1.0, 5, 5, 1]), jac=g, method=sqp.method, bounds=[(1, 5)] * 4,
                      constraints=[{"type": "eq", "fun": lambda x: c(x)[1:], "jac": lambda x: A(x)[1:]},
                                   {"type": "ineq", "fun": lambda x: c(x)[:1], "jac": lambda x: A(x)[:1]}],
                      callback=steps.append, options={"radius": radius, "maxiter": 100, "tol": 1e-9})
    assert res.outcome == r.status == "converged" and res.success
    assert res.nit == r.iterations and res.nfev == r.trials
    np.testing.assert_array_equal(res.x, r.point.x)
    assert len(steps) == len(seen) and all(np.array_equal(a, b) for a, b in zip(steps, seen, strict=True))


def test_scipy_face_a_nan_objective_is_a_failed_design():
    """Through scipy's face a failed design is a NaN value (or gradient): the trial is refused, the move
    limit cut to a quarter, and the run still reaches (-1, -1) on the circle."""
    failed = []

    def f(x):
        if len(failed) < 2 and not np.allclose(x, [1.0, 0.5]):
            failed.append(x.copy())
            return float("nan")
        return float(x.sum())

    res = so.minimize(f, np.array([1.0, 0.5]), jac=lambda x: np.ones(2), method=sqp.method,
                      bounds=so.Bounds(-5.0, 5.0),
                      constraints=[{"type": "eq", "fun": lambda x: x @ x - 2.0, "jac": lambda x: 2 * x[None, :]}],
                      options={"radius": 1.0, "maxiter": 100, "tol": 1e-9})
    assert res.outcome == "converged" and len(failed) == 2
    np.testing.assert_allclose(res.x, [-1.0, -1.0], atol=1e-6)
    x0 = np.array([1.0, 0.5])
    assert np.abs(failed[1] - x0).max() <= 0.25 * np.abs(failed[0] - x0).max() + 1e-12
    with pytest.raises(ValueError, match="jac"):
        so.minimize(f, x0, method=sqp.method)


def test_least_distance_matches_a_general_solver():
    rng = np.random.default_rng(3)
    for _ in range(20):
        G = rng.normal(size=(7, 4))
        h = G @ rng.normal(size=4) - rng.uniform(0.0, 1.0, size=7)       # feasible
        x, u = least_distance(G, h)
        ref = so.minimize(lambda z: 0.5 * z @ z, np.zeros(4), jac=lambda z: z, method="SLSQP",
                          constraints=[{"type": "ineq", "fun": lambda z, G=G, h=h: G @ z - h,
                                        "jac": lambda z, G=G: G}],
                          options={"ftol": 1e-15, "maxiter": 500})
        np.testing.assert_allclose(x, ref.x, atol=1e-7)
        assert np.all(G @ x - h >= -1e-9) and np.all(u >= 0)
        np.testing.assert_allclose(G.T @ u, x, atol=1e-9)      # stationarity: x = G^T u
        assert abs(u @ (G @ x - h)) < 1e-9                    # complementarity


def test_qp_step_respects_the_move_limit_and_bounds_and_meets_a_reachable_constraint():
    p = Point(x=np.array([0.0, 0.9]), f=0.0, c=np.array([-0.05]), g=np.array([1.0, -1.0]),
              A=np.array([[1.0, 2.0]]))
    step = solve_qp(p, np.eye(2), np.array([False]), np.array([-1.0, -1.0]), np.array([1.0, 1.0]),
                    radius=0.2, mu=1.0)
    assert np.all(np.abs(step.d) <= 0.2 + 1e-12)
    assert p.x[1] + step.d[1] <= 1.0 + 1e-12                  # the bound, closer than the move limit
    assert violation(p.c + p.A @ step.d, np.array([False])) < 1e-10
    assert step.lam[0] > 0 and step.mu >= 1.5 * step.lam[0]


def test_an_unreachable_linearisation_is_reduced_as_far_as_the_move_limit_allows():
    p = Point(x=np.zeros(2), f=0.0, c=np.array([-1.0]), g=np.array([0.0, 1.0]), A=np.array([[1.0, 0.0]]))
    step = solve_qp(p, np.eye(2), np.array([False]), np.full(2, -5.0), np.full(2, 5.0), radius=0.1, mu=1e-3)
    assert step.d[0] >= 0.9 * 0.1 - 1e-9                     # nine tenths of what 0.1 can remove, at least


def test_filter_and_bfgs():
    filt = Filter((), cap=1.0).add(0.5, 2.0).add(0.1, 3.0)
    assert filt.acceptable(0.05, 3.5)                          # less violation than every pair
    assert filt.acceptable(0.6, 1.0)                           # lower objective than every pair
    assert not filt.acceptable(0.3, 3.2)                       # worse than (0.1, 3.0) in both
    assert not filt.acceptable(1.1, -10.0)                     # above the cap
    assert len(Filter((), 1.0).add(0.5, 2.0).add(0.4, 1.0).pairs) == 1     # a dominated pair goes
    rng = np.random.default_rng(0)
    B = np.eye(3)
    for _ in range(30):
        B = bfgs_update(B, rng.normal(size=3), rng.normal(size=3))         # even with s.y < 0
        assert np.all(np.linalg.eigvalsh(B) > 0)


def _rule_qp(mu_scale: float, seed: int):
    """A QP shaped like a rule at every surface node: 2 x 120 rows of B-spline weights on 2 x 8 moves,
    some rows on their bound, two violated; ``mu`` at ``mu_scale`` times 1 (small: many slacks used)."""
    from scipy.interpolate import BSpline
    rng = np.random.default_rng(seed)
    nc, k = 8, 3
    knots = np.r_[[0.0] * k, np.linspace(0.0, 1.0, nc - k + 1), [1.0] * k]
    W = BSpline.design_matrix(np.linspace(0.0, 1.0, 120), knots, k).toarray()
    A = np.zeros((240, 2 * nc))
    A[:120, :nc], A[120:, nc:] = W, W
    x = rng.uniform(0.0, 0.02, 2 * nc)
    c = np.maximum(A @ x - 0.004, 0.0)
    c[:2] = -1e-3
    p = Point(x=x, f=1.0, c=c, g=rng.normal(size=2 * nc), A=A)
    B = np.eye(2 * nc) + 0.1 * np.ones((2 * nc, 2 * nc))
    return p, B, np.zeros(240, bool), np.full(2 * nc, -0.01), np.full(2 * nc, 0.01), mu_scale


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("mu_scale,cap", [(1.0, None), (0.03, None), (1.0, 2e-4)])
def test_slacks_where_the_step_needs_them_give_the_one_slack_per_row_qp(seed, mu_scale, cap):
    """The QP with slacks on the violated rows only (added where a multiplier exceeds a slack's cost) is
    the elastic QP with one slack per row: the same step, slacks and multipliers."""
    p, B, eq, dlo, dhi, mu = _rule_qp(mu_scale, seed)
    d, t, lam = sqp._qp(p, B, eq, dlo, dhi, mu, cap)
    d_ref, t_ref, lam_ref, _ = sqp._qp_slacks(p, B, eq, np.ones(p.c.size, bool), dlo, dhi, mu, cap)
    np.testing.assert_allclose(d, d_ref, atol=1e-9)
    np.testing.assert_allclose(t, t_ref, atol=1e-9)
    np.testing.assert_allclose(lam, lam_ref, atol=1e-7 * max(1.0, np.abs(lam_ref).max()))
    if mu_scale < 1.0:
        assert np.count_nonzero(t > 1e-12) > 2          # slacks beyond the two violated rows were needed


def test_an_equality_keeps_both_slacks_and_its_signed_multiplier():
    p, B, eq, dlo, dhi, mu = _rule_qp(1.0, 4)
    eq = eq.copy()
    eq[5] = True
    c = p.c.copy()
    c[5] = 0.01                                       # an equality off its value
    p = Point(x=p.x, f=p.f, c=c, g=p.g, A=p.A)
    d, t, lam = sqp._qp(p, B, eq, dlo, dhi, mu)
    d_ref, t_ref, lam_ref, _ = sqp._qp_slacks(p, B, eq, np.ones(p.c.size, bool), dlo, dhi, mu, None)
    np.testing.assert_allclose(d, d_ref, atol=1e-9)
    np.testing.assert_allclose(lam, lam_ref, atol=1e-7)


def test_every_trial_gets_a_verdict_and_the_accepted_ones_are_the_iterates():
    evaluate, _ = hs071()
    seen, verdicts = [], []
    r = minimize_sqp(evaluate, np.array([1.0, 5, 5, 1]), np.ones(4), np.full(4, 5.0), np.array([False, True]),
                     radius=0.3, iterations=6, tolerance=1e-9, callback=seen.append,
                     on_trial=lambda x, v: verdicts.append((x.copy(), v)))
    assert len(verdicts) == r.trials
    accepted = [x for x, v in verdicts if v.startswith("accepted")]
    assert len(accepted) == r.iterations and all(np.array_equal(a, p.x) for a, p in zip(accepted, seen))


def test_verdict_words():
    assert verdict(False, -np.inf, True, 1.0).startswith("failed")
    assert verdict(True, -np.inf, True, 1.0).startswith("refused by the filter")
    assert verdict(True, 0.5 * ETA, True, 2e-3) == (f"rejected: {0.5 * ETA:.3g} of the predicted objective "
                                                    f"decrease 0.002 (accepted from {ETA})")
    assert verdict(True, 1.0, False, 0.5).startswith("accepted: 1 of the predicted violation decrease 0.5")
