"""benchmarks/adodg/lifting_line.py against Glauert's closed forms: the incidence that gives the elliptic
load has one mode and e = 1; the best twist meets its lift and beats every other twist of its basis."""

from __future__ import annotations

import math

import numpy as np
import pytest

from benchmarks.adodg.lifting_line import (
    best_twist,
    case3,
    coefficients,
    efficiency,
    lifting_line,
    twist_basis,
)


@pytest.mark.parametrize("s, slope", [(3.0, 2 * math.pi), (5.0, 7.255), (1.5, 5.0)])
def test_the_elliptic_incidence_has_one_mode_and_e_one(s, slope):
    ll = lifting_line(s, 1.0, slope, 30)
    a1 = 0.02
    alpha = a1 * (1.0 + 4 * (2 * s) / slope * np.sqrt(1 - (ll.y / s) ** 2))   # sum A_n sin(n t)(4b/(ac) + n/sin t)
    A = coefficients(ll, alpha)
    assert A[0] == pytest.approx(a1, rel=1e-12) and np.abs(A[1:]).max() < 1e-13
    assert efficiency(ll, A) == pytest.approx(1.0, abs=1e-12)


def test_a_rectangular_wings_lift_slope_is_glauerts():
    ll = lifting_line(3.0, 1.0, 2 * math.pi, 40)
    A = coefficients(ll, np.full(len(ll.y), 0.01))
    cl_alpha = math.pi * ll.aspect_ratio * A[0] / 0.01
    e = efficiency(ll, A)
    assert 0.94 < e < 0.98                            # AR 6: Glauert's delta about 0.04-0.05
    tau = 0.17                                        # AR 6, a = 2 pi: Glauert's tau (Anderson fig. 5.20) 0.15-0.2
    assert cl_alpha == pytest.approx(2 * math.pi / (1 + 2 / ll.aspect_ratio * (1 + tau)), rel=0.02)


def test_the_best_twist_meets_its_lift_and_no_other_twist_of_the_basis_does_better():
    rng = np.random.default_rng(4)
    ll = lifting_line(3.0, 1.0, 7.255, 40)
    basis = twist_basis(ll.y, 3.06, 5)
    a0, t, A = best_twist(ll, basis, 0.375)
    assert math.pi * ll.aspect_ratio * A[0] == pytest.approx(0.375, rel=1e-12) and t[0] == 0.0
    best = efficiency(ll, A)
    for _ in range(20):
        tt = t + np.concatenate([[0.0], rng.normal(0, 0.01, len(t) - 1)])
        Ar = coefficients(ll, np.full(len(ll.y), a0) + basis @ tt)
        Ar = Ar * (A[0] / Ar[0])                          # the same lift (A scales with the incidence)
        assert efficiency(ll, Ar) <= best + 1e-12


def test_case3s_nine_sections_can_reach_the_ellipse_in_lifting_line_theory():
    r = case3(9)
    assert r["CL"] == pytest.approx(0.375)
    assert 0.95 < r["e_untwisted"] < 0.97 and r["e_best"] > 0.9999
    assert r["twist_deg"][0] == 0.0 and r["twist_deg"][-1] < r["twist_deg"][4] < 0.0   # washout
