"""First-order optimality (:mod:`ffdcli.optimize.kkt`) against problems whose optimum and multipliers are
known in closed form, and the prices ``ffd optimize`` reports against the optimum's change when a bound
moves (central differences of two converged runs with the analytic stand-in solver)."""

from __future__ import annotations

import numpy as np
import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st
from test_optimize import solver_for, write_case

from ffdcli.cli.optimize import held_by
from ffdcli.optimize.kkt import first_order
from ffdcli.optimize.workflow import run_optimize

INF = np.inf


@given(st.integers(0, 2**32 - 1), st.integers(2, 6))
@settings(max_examples=30, deadline=None)
def test_projection_onto_a_half_space_has_the_closed_form_multiplier(seed, n):
    # min |x - a|^2 / 2 subject to w.x >= b, with a outside: x* = a + lam w, lam = (b - w.a) / |w|^2
    rng = np.random.default_rng(seed)
    w = rng.normal(size=n)
    a = rng.normal(size=n)
    b = w @ a + rng.uniform(0.1, 2.0)
    lam = (b - w @ a) / (w @ w)
    x = a + lam * w
    out = first_order(x - a, [w @ x - b], w[None, :], [False], x, np.full(n, -INF), np.full(n, INF))
    assert out.residual < 1e-5
    assert out.active.tolist() == [True]
    assert out.multipliers[0] == pytest.approx(lam, rel=1e-4)


def test_an_equality_can_have_a_negative_multiplier():
    # min x0 + x1 subject to x0 - x1 = 0 ... and x0 >= 1 (bound): x* = (1, 1)
    # g = (1, 1) = lam (1, -1) + z (1, 0): lam = -1, z = 2
    out = first_order([1.0, 1.0], [0.0], [[1.0, -1.0]], [True], [1.0, 1.0], [1.0, -INF], [INF, INF])
    assert out.residual < 1e-5
    assert out.multipliers[0] == pytest.approx(-1.0, rel=1e-4)
    assert out.lower.tolist() == pytest.approx([2.0, 0.0], rel=1e-4)


def test_box_bounds_take_the_gradient_at_the_clipped_point():
    # min |x - a|^2 / 2 over a box: x* = clip(a), the bounds' multipliers |x* - a|
    a = np.array([-2.0, 0.3, 5.0])
    lo, hi = np.array([-1.0, -1.0, -1.0]), np.array([1.0, 1.0, 1.0])
    x = np.clip(a, lo, hi)
    out = first_order(x - a, np.zeros(0), np.zeros((0, 3)), np.zeros(0, bool), x, lo, hi)
    assert out.residual < 1e-5
    assert out.lower.tolist() == pytest.approx([1.0, 0.0, 0.0], rel=1e-4)
    assert out.upper.tolist() == pytest.approx([0.0, 0.0, 4.0], rel=1e-4)


def test_a_point_no_constraint_holds_has_residual_one():
    # the gradient points along the active constraint's normal: a multiplier >= 0 cannot cancel it
    out = first_order([-1.0, 0.0], [0.0], [[1.0, 0.0]], [False], [0.0, 0.0], [-INF, -INF], [INF, INF])
    assert out.residual == pytest.approx(1.0)
    assert out.multipliers[0] == 0.0
    # an inactive constraint is left out however well it would fit
    out = first_order([1.0, 0.0], [0.5], [[1.0, 0.0]], [False], [0.0, 0.0], [-INF, -INF], [INF, INF])
    assert out.residual == pytest.approx(1.0) and not out.active[0]
    # a zero gradient is a stationary point
    assert first_order([0.0, 0.0], [0.5], [[1.0, 0.0]], [False], [0.0, 0.0], [-INF, -INF], [INF, INF]).residual == 0


@given(st.integers(0, 2**32 - 1))
@settings(max_examples=30, deadline=None)
def test_multipliers_of_a_built_kkt_point_are_recovered(seed):
    # g made from chosen multipliers on independent active rows and bounds: they come back exactly
    rng = np.random.default_rng(seed)
    n, m = 6, 4
    A = np.zeros((m, n))                       # the rows leave x4, x5 to the bounds
    A[:, :4] = np.linalg.qr(rng.normal(size=(4, 4)))[0] * rng.uniform(0.5, 2.0, size=(m, 1))   # well posed
    lam = np.array([rng.uniform(0.1, 2), rng.uniform(0.1, 2), 0.0, rng.normal()])
    c = np.array([0.0, 0.0, 0.7, 0.0])         # rows 0, 1 active, row 2 inactive, row 3 an equality
    equality = np.array([False, False, False, True])
    lo, hi = np.full(n, -1.0), np.full(n, 1.0)
    x = rng.uniform(-0.5, 0.5, size=n)
    x[4], x[5] = -1.0, 1.0
    z4, z5 = rng.uniform(0.1, 1), rng.uniform(0.1, 1)
    g = A.T @ lam
    g[4] += z4
    g[5] -= z5
    out = first_order(g, c, A, equality, x, lo, hi)
    assert out.residual < 1e-5
    assert out.multipliers == pytest.approx(lam, rel=1e-4, abs=1e-5)
    assert out.lower[4] == pytest.approx(z4, rel=1e-3) and out.upper[5] == pytest.approx(z5, rel=1e-3)


def _converged(tmp_path, lift=0.1, width=0.03):
    path = write_case(tmp_path, iterations=80, tolerance=1e-10, functions=[{"name": "LIFT", "lower": lift}])
    design = yaml.safe_load(path.read_text())
    design["bounds"]["c1.shape"] = [-width, width]
    path.write_text(yaml.safe_dump(design, sort_keys=False))
    out = run_optimize(path, solver=solver_for(path))
    assert out["status"] == "converged", out["message"]
    return out


def test_the_reported_prices_are_the_optimum_s_change_when_a_bound_moves(tmp_path):
    # the analytic case: min DRAG = mean(y^2) with LIFT >= L, the shape variables within +-w; at the
    # optimum LIFT and some shape bounds are active: dDRAG*/dL and dDRAG*/dw by four more converged runs
    L, w, h = 0.1, 0.03, 0.002
    runs = {}
    for key, lift, width in (("mid", L, w), ("L-", L - h, w), ("L+", L + h, w), ("w-", L, w - h), ("w+", L, w + h)):
        (tmp_path / key).mkdir()
        runs[key] = _converged(tmp_path / key, lift, width)
    opt = runs["mid"]["optimality"]
    assert opt is not None and opt["objective"] == "DRAG"
    assert opt["residual"] < 1e-3
    best = {k: r["objective"]["best"] for k, r in runs.items()}
    # LIFT's lower bound: a positive price (raising it costs drag)
    lift = next(a for a in opt["active"] if a["name"] == "LIFT")
    assert lift["side"] == "lower" and lift["bound"] == L
    fd = (best["L+"] - best["L-"]) / (2 * h)
    assert fd > 0
    assert lift["d_objective_d_bound"] == pytest.approx(fd, rel=0.02)
    # the shape bounds: widening by dw moves every upper bound up and every lower bound down by dw
    shape = [b for b in opt["at_bounds"] if b["variable"].startswith("c1.shape")]
    assert shape, "the case is meant to end with shape variables on their bounds"
    price = sum(b["d_objective_d_bound"] * (1.0 if b["side"] == "upper" else -1.0) for b in shape)
    fd = (best["w+"] - best["w-"]) / (2 * h)
    assert fd < 0
    assert price == pytest.approx(fd, rel=0.02)
    line = held_by(opt)
    assert "LIFT >= 0.1 (dDRAG/dbound" in line and "residual" in line


def test_the_summary_line_groups_a_geometric_constraint_s_items():
    opt = {"objective": "DRAG", "residual": 0.002,
           "active": [{"name": f"k0.add_material[{i}]", "kind": "geometric", "bound": 0.0, "equality": False,
                       "side": "lower", "d_objective_d_bound": p} for i, p in enumerate([0.1, 0.4, 0.0])]
           + [{"name": "LIFT", "kind": "function", "bound": 0.824, "equality": True, "side": "equal",
               "d_objective_d_bound": 0.012}],
           "at_bounds": [{"variable": "c0.shape.upper[15]", "side": "upper", "bound": 0.1,
                          "d_objective_d_bound": -0.02}]}
    line = held_by(opt)
    assert "k0.add_material: 2 items (largest dDRAG/dbound 0.4)" in line
    one = held_by({**opt, "active": opt["active"][:1]})
    assert "k0.add_material[0] >= 0 (dDRAG/dbound 0.1)" in one
    assert "LIFT = 0.824 (dDRAG/dbound 0.012)" in line
    assert "c0.shape.upper[15] at its upper bound 0.1 (dDRAG/dbound -0.02)" in line
    assert yaml.safe_dump(opt)                 # plain data: the --json summary carries it


def test_opposite_items_get_the_least_multipliers_with_their_net():
    # a point held in place by two items, +y >= 0 and -y >= 0 (a sharp edge's two sides): any pair
    # (l + d, l) fits g = (0, d); the report gives (d, 0), not an arbitrary large pair
    for d in (0.7, -0.7):
        out = first_order([0.0, d], [0.0, 0.0], [[0.0, 1.0], [0.0, -1.0]], [False, False], [0.0, 0.0],
                          [-INF, -INF], [INF, INF])
        assert out.residual < 1e-5
        assert out.multipliers == pytest.approx([max(d, 0.0), max(-d, 0.0)], abs=1e-5)
