"""``ffd optimize --check-gradient``: the adjoint gradient of each function beside central finite
differences of the solver, the first thing a careful user runs.

The step of variable i is ``step * (upper_i - lower_i)`` when both bounds are finite, else ``step``
(default 1e-3, SPEC). ``relative = |adjoint - fd| / max(|fd|, 1e-12)``.

The two flows of a variable's central difference give every function of the run at once (each function
only adds its adjoint at the baseline), and the design file's geometric ``constraints:`` too (their
values at the two ends are computed with the deformed meshes): one row per geometric constraint and
variable follows the functions' rows, its ``function`` the constraint's name (``k0.volume``, as
``ffd constraints`` and ``history.csv`` name it) and its ``adjoint`` the exact Jacobian's entry.
"""

from __future__ import annotations

import numpy as np

from ffdcli.optimize.driver import StopRun
from ffdcli.optimize.problem import OptimizationProblem


def variable_steps(lower: np.ndarray, upper: np.ndarray, step: float) -> np.ndarray:
    """(n,) the finite-difference step of each variable: ``step`` of its bound range, or ``step``."""
    finite = np.isfinite(lower) & np.isfinite(upper) & (upper > lower)
    return np.where(finite, step * (upper - lower), step)


def gradient_check(problem: OptimizationProblem, which: list[int], step: float) -> list[dict]:
    """One row ``{"function", "variable", "adjoint", "finite_difference", "relative", "step"}`` per function
    of the run, then per geometric constraint, and variable index in ``which``; StopRun when an
    evaluation fails (with its reason)."""
    model = problem.model
    v0 = model.values.copy()
    base = problem.evaluate(v0, gradient=True)
    if base.failed is not None:
        raise StopRun("baseline", f"the baseline design failed: {base.failed}")
    h = variable_steps(model.lower, model.upper, step)
    names = list(model.constraint_names) if model.constraints else []
    jacobian = problem.geometric(v0)[1] if names else None
    rows = []
    for i in which:
        ends = []
        for sign in (1.0, -1.0):
            v = v0.copy()
            v[i] += sign * h[i]
            ev = problem.evaluate(v)
            if ev.failed is not None:
                raise StopRun("failures", f"the evaluation at {model.names[i]} {sign * h[i]:+g} failed: {ev.failed}")
            ends.append(ev)
        pairs = [(f, (ends[0].functions[f] - ends[1].functions[f]) / (2.0 * h[i]), float(base.gradients[f][i]))
                 for f in problem.functions]
        pairs += [(name, (ends[0].constraints[k] - ends[1].constraints[k]) / (2.0 * h[i]), float(jacobian[k, i]))
                  for k, name in enumerate(names)]
        for f, fd, adj in pairs:
            rows.append({"function": f, "variable": model.names[i], "adjoint": adj, "finite_difference": float(fd),
                         "relative": abs(adj - fd) / max(abs(fd), 1e-12), "step": float(h[i])})
    return rows
