"""The optimiser loop: scipy's SLSQP, ffd's SQP with move limits (:mod:`ffdcli.optimize.sqp`) or scipy's
trust-constr, on scaled variables, functions and constraints.

What the optimiser sees (every scale applied to a value and its gradient alike):

* variables ``x = (v - v0) / r``, ``r`` each variable's bound range (upper - lower) when both bounds are
  finite, else 1 (a degree, a mesh unit, a factor); bounds scaled the same way;
* objective ``s_f * J``: ``s_f`` the ``optimize.scale`` given, else chosen from the baseline gradient
  so that a first steepest-descent step moves the most sensitive variable by ``optimize.step`` (0.1)
  of its bound range: ``s_f = step / max |r * dJ/dv|``;
* each bound of an aerodynamic function ``s (value - lower) >= 0`` or ``s (upper - value) >= 0``,
  ``s = 1 / max(|bound|, |baseline|)`` unless the function's ``scale`` is given; ``lower == upper``
  is an equality; each geometric constraint (``constraints:``, exact Jacobian) the same with
  ``s = 1 / max(|bound|, 1)``.

Constraint screening (``optimize.screen``, default 0.3): an aerodynamic constraint whose scaled margin
at the design (the smallest ``s (value - lower)``, ``s (upper - value)``) is above ``screen`` is inactive
there; its adjoint is not run again and SLSQP's linearisation uses its latest adjoint gradient (the
"temporary deletion" of far-from-active constraints of structural optimisation). The objective's
adjoint and every constraint within ``screen`` of its bound are computed at every iterate; ``screen:
null`` computes every adjoint at every iterate.

Failures: an evaluation that failed (solver, NaN, not converged, gate) is answered with the last good
design's (the last accepted iterate's) scaled objective plus ``max(1, |value|)`` and its constraints,
which SLSQP's line search rejects: it shortens the step toward the last good design (a factor 0.1 to
0.5 per try). After ``max_failures`` failures the run stops (:class:`StopRun`, exit 1). A line search
that spends more than ``line_search`` evaluations (its full step included) without an accepted step
ends the run with that reason instead of spending solves. ``method: SQP`` is told of a failure instead
(a NaN objective): it refuses the trial and shrinks its move limit.

Every method is one ``scipy.optimize.minimize`` call with the same objective, gradient, constraints and
callback; ffd's SQP is given as a callable method (:func:`ffdcli.optimize.sqp.method`).

Iterations are scipy's: SLSQP counts one when an iteration's full step has been evaluated; the steps
back of its line search and the accepted design (whose gradients are asked) belong to it. SQP counts
an accepted step; its rejected trials (each one flow) belong to the iteration they precede, and more
than ``line_search`` of them in a row end the run like a collapsed line search.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.optimize as so

from ffdcli.design.optimize import OptimizeSettings
from ffdcli.optimize import kkt, sqp
from ffdcli.optimize.problem import OptimizationProblem
from ffdcli.optimize.store import Evaluation


class StopRun(Exception):
    """The run ends early: ``status`` (``failures``, ``line_search``, ``baseline``) and the reason in words."""

    def __init__(self, status: str, reason: str):
        self.status = status
        self.reason = reason
        super().__init__(reason)


@dataclass(frozen=True)
class Side:
    """One scaled constraint: ``scale * sign * (value - bound)`` (>= 0, or = 0 when ``equality``)."""

    name: str
    kind: str              # "function" (the solver's, with an adjoint) or "geometric"
    index: int             # into the geometric constraints (kind geometric)
    bound: float
    sign: float
    scale: float
    equality: bool = False


@dataclass(frozen=True)
class Outcome:
    """How the optimiser ended: ``status`` (converged, iterations, line_search, failures, stopped), the
    reason in words and the iterations done."""

    status: str
    message: str
    iterations: int


def constraint_sides(settings: OptimizeSettings, baseline: Evaluation, names: list[str], lower, upper) -> list[Side]:
    """The scaled constraints of a run: each bound of each aerodynamic function, then each geometric one."""
    sides = []
    for f in settings.functions:
        f0 = abs(baseline.functions.get(f.name, 0.0))
        for bound, sign in ((f.lower, 1.0), (f.upper, -1.0)):
            if bound is None or (sign < 0 and f.lower == f.upper):
                continue
            scale = f.scale or 1.0 / max(abs(bound), f0, 1e-12)
            sides.append(Side(f.name, "function", -1, bound, sign, scale, equality=f.lower == f.upper))
    for i, name in enumerate(names):
        lo, hi = float(lower[i]), float(upper[i])
        for bound, sign in ((lo, 1.0), (hi, -1.0)):
            if not np.isfinite(bound) or (sign < 0 and lo == hi):
                continue
            sides.append(Side(name, "geometric", i, bound, sign, 1.0 / max(abs(bound), 1.0), equality=lo == hi))
    return sides


def violation(ev: Evaluation, sides: list[Side]) -> float:
    """The worst violation of ``ev`` in the constraints' own units (0: feasible; inf: failed)."""
    if ev.failed is not None:
        return float("inf")
    worst = 0.0
    for s in sides:
        value = ev.functions[s.name] if s.kind == "function" else ev.constraints[s.index]
        gap = s.sign * (value - s.bound)
        worst = max(worst, abs(gap) if s.equality else -gap)
    return worst


class Driver:
    """Runs scipy's optimiser over a :class:`OptimizationProblem` (see the module docstring)."""

    def __init__(self, problem: OptimizationProblem, settings: OptimizeSettings, chosen: list[int]):
        self.problem = problem
        self.settings = settings
        self.chosen = np.asarray(chosen, dtype=int)
        model = problem.model
        self.v0 = model.values.copy()
        lo, hi = model.lower[self.chosen], model.upper[self.chosen]
        finite = np.isfinite(lo) & np.isfinite(hi) & (hi > lo)
        self.r = np.where(finite, hi - lo, 1.0)
        self.bounds = list(zip((lo - self.v0[self.chosen]) / self.r, (hi - self.v0[self.chosen]) / self.r,
                               strict=True))
        self.failures = 0
        self.iterations = 0
        self.since_accept: set[str] = set()          # the evaluations since the last accepted design
        self.trial_next = True                       # the next new design is an iteration's full step
        self.anchor: Evaluation | None = None
        self.sides: list[Side] = []
        self.f_scale = 1.0
        self.latest: dict[str, np.ndarray] = {}      # the latest adjoint gradient of each function
        self.refuse_failed = settings.method == "SQP"   # a failed design: refused (SQP) or penalised
        self.verdicts: dict[int, str] = {}           # method SQP: each trial's verdict, by evaluation index

    # -- the variables -------------------------------------------------------------------------
    def values_of(self, x: np.ndarray) -> np.ndarray:
        """The full design vector (n_vars,) of scaled variables ``x``."""
        v = self.v0.copy()
        v[self.chosen] = self.v0[self.chosen] + self.r * np.asarray(x, dtype=float)
        return v

    def start(self) -> Evaluation:
        """Evaluate the baseline with gradients and choose the scales; StopRun when it fails."""
        base = self.problem.evaluate(self.v0, gradient=True)
        if base.failed is not None:
            raise StopRun("baseline", f"the baseline design failed: {base.failed}" + (f" (log: {base.log})"
                                                                                      if base.log else ""))
        self.anchor = base
        self.latest.update(base.gradients)
        model = self.problem.model
        names = model.constraint_names if model.constraints else []
        lower = model.constraint_lower if model.constraints else []
        upper = model.constraint_upper if model.constraints else []
        self.sides = constraint_sides(self.settings, base, names, lower, upper)
        g = self.r * base.gradients[self.settings.objective][self.chosen]
        if self.settings.scale is not None:
            self.f_scale = self.settings.scale
        elif np.abs(g).max(initial=0.0) > 0:
            self.f_scale = self.settings.step / float(np.abs(g).max())
        else:
            self.f_scale = 1.0 / max(abs(base.functions[self.settings.objective]), 1e-12)
        return base

    # -- evaluations with the failure rules ------------------------------------------------------
    def needed(self, ev: Evaluation) -> list[str]:
        """The functions whose adjoint runs at ``ev``: the objective, and each constraint function with no
        gradient yet or within ``screen`` (scaled) of a bound."""
        out = [self.settings.objective]
        for f in self.settings.functions:
            sides = [s for s in self.sides if s.kind == "function" and s.name == f.name]
            margin = min((0.0 if s.equality else s.scale * s.sign * (ev.functions[f.name] - s.bound)
                          for s in sides), default=0.0)
            if f.name not in self.latest or self.settings.screen is None or margin <= self.settings.screen:
                out.append(f.name)
        return out

    def _get(self, x: np.ndarray, gradient: bool) -> Evaluation:
        before = self.problem.counts["evaluations"] + self.problem.counts["reused"]
        # scipy counts an iteration once its full step is evaluated: label that step with it
        self.problem.iteration = self.iterations + (1 if self.trial_next and not gradient else 0)
        ev = self.problem.evaluate(self.values_of(x))
        if gradient and ev.failed is None:
            ev = self.problem.evaluate(self.values_of(x), gradient=True, functions=self.needed(ev))
        fresh = self.problem.counts["evaluations"] + self.problem.counts["reused"] > before
        if fresh:
            self.since_accept.add(ev.key)
            if ev.failed is not None:
                self.failures += 1
                if self.failures > self.settings.max_failures:
                    raise StopRun("failures", f"{self.failures} failed evaluations (max_failures "
                                              f"{self.settings.max_failures}); the last: {ev.failed}")
            if len(self.since_accept) > self.settings.line_search:
                raise StopRun("line_search", f"line search collapsed: {len(self.since_accept)} evaluations "
                                             f"in iteration {self.iterations} without an accepted step")
        if gradient and ev.failed is None:
            self.since_accept = set()
            self.trial_next = True
            self.anchor = ev
            self.latest.update(ev.gradients)
        return ev

    def gradient(self, ev: Evaluation, name: str) -> np.ndarray:
        """dJ/dv (n_vars,) of function ``name`` at ``ev``: its own, or (screened) the latest computed."""
        return ev.gradients[name] if name in ev.gradients else self.latest[name]

    def _response(self, x: np.ndarray, gradient: bool) -> Evaluation:
        ev = self._get(x, gradient)
        return ev if ev.failed is None else self.anchor

    def objective(self, x):
        """The scaled objective; a failed design: NaN for ``method: SQP`` (:func:`ffdcli.optimize.sqp.method`
        refuses the trial), else the last good design's objective plus a penalty (scipy's methods back off)."""
        ev = self._get(x, False)
        if ev.failed is not None and self.refuse_failed:
            return float("nan")
        f = self.f_scale * (ev if ev.failed is None else self.anchor).functions[self.settings.objective]
        return f if ev.failed is None else f + max(1.0, abs(f))

    def objective_grad(self, x):
        """The scaled objective's gradient; a failed design: NaN (``method: SQP``) or the last good one's."""
        ev = self._get(x, True)
        if ev.failed is not None:
            if self.refuse_failed:
                return np.full(len(self.chosen), np.nan)
            ev = self.anchor
        return self.f_scale * self.r * self.gradient(ev, self.settings.objective)[self.chosen]

    def _sides(self, x, equality: bool, jac: bool):
        sides = [s for s in self.sides if s.equality == equality]
        if not sides:
            return np.zeros((0, len(self.chosen))) if jac else np.zeros(0)
        ev = self._response(x, jac and any(s.kind == "function" for s in sides))
        return self._scaled(ev, sides, jac, lambda name: self.gradient(ev, name))

    def _scaled(self, ev: Evaluation, sides: list[Side], jac: bool, gradient) -> np.ndarray:
        """The scaled constraints ``sides`` at ``ev``: values (k,), or with ``jac`` their Jacobian (k, n_chosen)
        in the scaled variables (a function's gradient from ``gradient(name)``, a geometric one exact)."""
        geo, J = self.problem.geometric(ev.values) if any(s.kind == "geometric" for s in sides) else (None, None)
        if jac:
            rows = [s.scale * s.sign * self.r * (gradient(s.name) if s.kind == "function" else J[s.index])[self.chosen]
                    for s in sides]
            return np.array(rows).reshape(len(sides), self.chosen.size)
        return np.array([s.scale * s.sign * ((ev.functions[s.name] if s.kind == "function" else geo[s.index]) - s.bound)
                         for s in sides])

    def optimality(self, ev: Evaluation) -> dict | None:
        """First-order optimality at ``ev`` (:func:`ffdcli.optimize.kkt.first_order` on the scaled problem
        the optimiser saw), from what the evaluations hold (no solve: a screened constraint's gradient is the
        one of the latest evaluation up to ``ev`` that has it, as the optimiser's linearisation used):
        ``{"objective", "residual", "active": [...], "at_bounds": [...]}``, each entry with
        ``d_objective_d_bound``, the objective's change per unit of that bound (its price: loosen the bound
        by delta and the optimum's objective falls by about ``|price| * delta``). None when ``ev`` has no
        gradient of the objective, or a constraint function has none yet."""
        name = self.settings.objective
        if ev is None or ev.failed is not None or name not in ev.gradients:
            return None
        earlier = sorted((e for e in self.problem.store.all() if e.index <= ev.index and e.failed is None),
                         key=lambda e: e.index)
        grads = {}
        for s in self.sides:
            if s.kind == "function" and s.name not in grads:
                found = next((e.gradients[s.name] for e in reversed(earlier) if s.name in e.gradients), None)
                if found is None:
                    return None
                grads[s.name] = found
        chosen, r = self.chosen, self.r
        c = self._scaled(ev, self.sides, False, grads.get)
        A = self._scaled(ev, self.sides, True, grads.get)
        lower, upper = (np.array(b, dtype=float) for b in zip(*self.bounds, strict=True))
        first = kkt.first_order(self.f_scale * r * ev.gradients[name][chosen], c, A,
                                np.array([s.equality for s in self.sides], dtype=bool),
                                (ev.values[chosen] - self.v0[chosen]) / r, lower, upper, tol=kkt.ACTIVE)
        names = self.problem.model.names
        active = [{"name": s.name, "kind": s.kind, "bound": s.bound, "equality": s.equality,
                   "side": "equal" if s.equality else ("lower" if s.sign > 0 else "upper"),
                   "d_objective_d_bound": float(s.sign * first.multipliers[i] * s.scale / self.f_scale)}
                  for i, s in enumerate(self.sides) if first.active[i]]
        at_bounds = [{"variable": names[v], "side": side, "bound": float(self.v0[v] + r[k] * b[k]),
                      "d_objective_d_bound": float(sign * z[k] / (r[k] * self.f_scale))}
                     for side, sign, z, b in (("lower", 1.0, first.lower, lower), ("upper", -1.0, first.upper, upper))
                     for k, v in enumerate(chosen) if z[k] > 0.0]
        return {"objective": name, "residual": first.residual, "active": active, "at_bounds": at_bounds}

    def judged(self, x: np.ndarray, verdict: str) -> None:
        """``method: SQP``'s verdict on the trial at ``x`` (scaled), kept for ``history.csv``'s ``trial``."""
        ev = self.problem.store.find(self.values_of(x))
        if ev is not None:
            self.verdicts[ev.index] = verdict
            if ev.index in self.problem.solved:          # said as it happens; a replayed trial is not
                self.problem.report(ev, "trial")

    def accepted(self, *args) -> None:
        """scipy's callback: SLSQP calls it once an iteration's full step is evaluated (its line search
        follows), trust-constr after each iteration, SQP after each accepted step (the next trial is
        already the next iteration's full step)."""
        self.iterations += 1
        self.trial_next = self.refuse_failed

    # -- the run -----------------------------------------------------------------------------------
    def run(self) -> Outcome:
        """Start (the baseline) and run the optimiser, one ``scipy.optimize.minimize`` call for every
        method (ffd's SQP as a callable method); StopRun propagates to the caller."""
        self.start()
        x0 = np.zeros(len(self.chosen))
        method = self.settings.method
        cons = []
        if any(not s.equality for s in self.sides):
            cons.append({"type": "ineq", "fun": lambda x: self._sides(x, False, False),
                         "jac": lambda x: self._sides(x, False, True)})
        if any(s.equality for s in self.sides):
            cons.append({"type": "eq", "fun": lambda x: self._sides(x, True, False),
                         "jac": lambda x: self._sides(x, True, True)})
        bounds = self.bounds
        tol, iterations = self.settings.tolerance, self.settings.iterations
        if method == "SQP":
            options = {"radius": self.settings.move_limit, "maxiter": iterations, "tol": tol,
                       "on_trial": self.judged}
        elif method == "trust-constr":
            cons = [so.NonlinearConstraint(c["fun"], 0.0, np.inf if c["type"] == "ineq" else 0.0, jac=c["jac"])
                    for c in cons]
            bounds = so.Bounds(*np.array(self.bounds).T)
            options = {"maxiter": max(iterations, 1), "gtol": tol, "xtol": tol}
        else:
            options = {"maxiter": iterations, "ftol": tol}
        res = so.minimize(self.objective, x0, jac=self.objective_grad, method=METHODS.get(method, method),
                          bounds=bounds, constraints=cons, callback=self.accepted, options=options)
        return Outcome(status=outcome(method, res), message=str(res.message), iterations=self.iterations)


#: ``optimize.method`` -> what ``scipy.optimize.minimize`` is given (ffd's own SQP is a callable method).
METHODS = {"SQP": sqp.method}


def outcome(method: str, res) -> str:
    """converged, iterations or stopped, from ``scipy.optimize.minimize``'s result for ``method``."""
    if method == "SQP":
        return res.outcome
    if method == "trust-constr":
        return "converged" if res.status in (1, 2) else "iterations"
    return "converged" if res.status == 0 else ("iterations" if res.status == 9 else "stopped")
