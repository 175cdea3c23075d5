"""The pressure integration that reads SU2's CMz sign (benchmarks/adodg/moment_sign.py): on a thin
ellipse with loads whose answers are known, the lift, drag and the right-hand moment about +z through
the quarter chord (positive nose-down: a load aft of c/4 turns the nose down)."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.adodg.moment_sign import pressure_loads


def ellipse(n: int = 2001, thickness: float = 0.05) -> np.ndarray:
    """A closed counter-clockwise loop from the trailing edge (1, 0) over the upper side, chord 1."""
    t = np.linspace(0.0, 2.0 * np.pi, n)
    t[-1] = 0.0
    return np.column_stack([0.5 + 0.5 * np.cos(t), thickness * np.sin(t)])


def test_uniform_suction_and_pressure_lift_at_mid_chord_turns_the_nose_down():
    loop = ellipse()
    cp = np.where(loop[:, 1] > 0, -1.0, 1.0)
    cp[np.abs(loop[:, 1]) < 1e-12] = 0.0           # the two ends: a jump between the sides
    loads = pressure_loads(loop, cp, 0.0)
    assert loads.cl == pytest.approx(2.0, abs=2e-3)
    assert loads.cmz == pytest.approx(2.0 * (0.5 - 0.25), abs=2e-3)   # lift at mid-chord: +, nose-down
    assert abs(loads.cd) < 1e-9


@pytest.mark.parametrize("x0", [0.1, 0.15, 0.25, 0.4, 0.6, 0.85])
@pytest.mark.parametrize("alpha", [0.0, 2.79, -4.0])
def test_moment_is_lift_times_the_loads_arm_aft_of_the_quarter_chord(x0, alpha):
    loop = ellipse(thickness=0.001)                  # thin: the normal force is the y force
    suction = np.exp(-(((loop[:, 0] - x0) / 0.03) ** 2))
    cp = np.where(loop[:, 1] > 0, -suction, 0.0)
    body = pressure_loads(loop, cp, 0.0)               # at alpha 0: (cd, cl) = the body axes' (Fx, Fy)
    fx, fy = body.cd, body.cl
    assert fy > 0.05
    assert body.cmz / fy == pytest.approx(x0 - 0.25, abs=2e-3)    # sign: aft of c/4 nose-down (+)
    loads, a = pressure_loads(loop, cp, alpha), np.radians(alpha)
    assert loads.cl == pytest.approx(fy * np.cos(a) - fx * np.sin(a), abs=1e-12)   # wind axes: rotated by alpha
    assert loads.cd == pytest.approx(fx * np.cos(a) + fy * np.sin(a), abs=1e-12)
    assert loads.cmz == pytest.approx(body.cmz, abs=1e-12)       # a moment does not depend on alpha
