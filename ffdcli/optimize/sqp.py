"""Sequential quadratic programming with move limits (a trust region on each step): ``method: SQP``.

Why a second SQP beside scipy's SLSQP: SLSQP's only control of a step is its line search along the
full quasi-Newton step. In a transonic flow that full step is often far outside where the linearised
lift holds (a step predicted to keep CL gains nothing and SU2 answers with a shock 0.1 lower), so the
line search keeps a tenth of it and the iterates creep along the constraint from the infeasible side.
Move limits, the aerodynamicist's usual cure (SNOPT's major step limit, DOT's move limits), bound each
step where the linear model is trusted, and the ratio of the achieved to the predicted decrease grows
or shrinks that region.

One iteration, at an accepted design ``x`` with objective ``f``, gradient ``g``, constraints ``c`` (>= 0,
or = 0 for equalities) and their Jacobian ``A``, and a BFGS model ``B`` of the Lagrangian's Hessian:

1. the elastic QP: minimise ``g.d + d.B.d / 2 + mu * sum(t + t^2 / 2)`` over ``d`` and slacks ``t >= 0``
   with ``c + A d + t >= 0`` (equalities: ``c + A d + t+ - t- = 0``), the bounds and ``|d_i| <= radius``
   (the slacks make it feasible whatever the radius), solved exactly as a least-distance program by
   non-negative least squares (Lawson and Hanson; SLSQP's own QP solver);
2. the trial ``x + d`` is evaluated (values only: one flow);
3. Fletcher and Leyffer's filter decides (no penalty parameter to tune): the trial must not be dominated
   by an earlier design's (violation, objective) pair nor exceed a violation cap; a step the QP
   predicts to lower the objective (an objective step) must then achieve at least ``ETA`` of that
   decrease; a feasibility step, at least ``ETA`` of its predicted decrease of the violation, and
   adds the current design to the filter. Accepted: the gradients are computed there (the adjoints),
   ``B`` takes a damped (Powell) BFGS update with the QP's multipliers, and the radius doubles when
   the step reached it with a good ratio (above ``GROW_AT``); a poor ratio (below ``SHRINK_AT``) halves
   it. Rejected, the radius becomes half the step's length; failed (the solver, the gate), a quarter.

The filter accepts a step that buys much drag for a little lift only while the violation stays below
the cap and below every earlier design's; feasibility steps then bring the design back, within the
move limit where the linearised lift holds.

The slacks' penalty ``mu`` stays above 1.5 times the multipliers of the constraints the step meets;
when the step still leaves its linearised constraints violated, the QP is solved again with the
slacks' sum capped so that it removes nine tenths of what a step within the move limit can remove.
An iteration counts an accepted step: like an SLSQP iteration (a full step, the steps back of its line
search, one gradient), it may spend several flows and spends one set of adjoints.

Pure: the functions of the problem come from ``evaluate(x, gradient)``, which returns a :class:`Point`
or None (the design failed); nothing here knows of solvers or files.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import scipy.optimize as so

#: Accept a trial when its achieved / predicted decrease (of the objective or the violation) >= ETA.
ETA = 0.1
#: Grow the radius (x2) when the ratio is above GROW_AT and the step reached the radius.
GROW_AT = 0.75
#: Shrink the radius (to half the step) when the ratio is below SHRINK_AT.
SHRINK_AT = 0.25
#: The largest radius (scaled variables: a fraction of each variable's bound range).
MAX_RADIUS = 1.0
#: The filter's margins: a new pair must have a violation BETA times smaller, or an objective lower
#: by GAMMA times its violation, than every pair.
BETA, GAMMA = 0.99, 1e-4
#: A step is an objective step (judged by its objective's decrease) when the QP predicts a decrease
#: of at least KAPPA * violation^2; else a feasibility step (judged by its violation's decrease).
KAPPA = 1e-4
#: No design is accepted with a violation above MAX_VIOLATION_GROWTH times the first design's, nor
#: above MIN_VIOLATION_CAP (scaled constraints: 5 % of a bound) when the first design is feasible.
MAX_VIOLATION_GROWTH, MIN_VIOLATION_CAP = 1.25, 0.05


@dataclass(frozen=True)
class Point:
    """A design with its functions: ``x`` (n,), objective ``f``, constraints ``c`` (m,) (>= 0, or = 0 where
    ``equality``); with gradients ``g`` (n,) and ``A`` (m, n) when asked (else None)."""

    x: np.ndarray
    f: float
    c: np.ndarray
    g: np.ndarray | None = None
    A: np.ndarray | None = None


@dataclass(frozen=True)
class Step:
    """The QP's answer: step ``d`` (n,), multipliers ``lam`` (m,) (>= 0 for inequalities) and the slacks'
    penalty ``mu`` for the next QP (at least 1.5 times the multipliers of the rows the step meets)."""

    d: np.ndarray
    lam: np.ndarray
    mu: float


@dataclass(frozen=True)
class Result:
    """How the run ended: the last accepted :class:`Point`, ``status`` (converged, iterations, stopped),
    the reason, the accepted iterations and the trials (flows) spent."""

    point: Point
    status: str
    message: str
    iterations: int
    trials: int


def violation(c: np.ndarray, equality: np.ndarray) -> float:
    """The l1 violation of constraints ``c`` (m,): ``sum(max(0, -c))`` over inequalities, ``sum(|c|)``
    over equalities."""
    c = np.asarray(c, dtype=float)
    return float(np.sum(np.where(equality, np.abs(c), np.maximum(-c, 0.0))))


def least_distance(G: np.ndarray, h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The least-distance program ``min |x|^2 / 2`` subject to ``G x >= h`` by non-negative least squares
    (Lawson and Hanson's LDP, the QP solver inside SLSQP): ``(x (n,), multipliers (k,) >= 0)``.

    Parameters
    ----------
    G : (k, n) ndarray
    h : (k,) ndarray

    Raises ``ValueError`` when the constraints are inconsistent.
    """
    k, n = G.shape
    if k == 0:
        return np.zeros(n), np.zeros(0)
    norm = np.maximum(np.linalg.norm(G, axis=1), 1e-300)      # rows scaled: same set, better conditioned
    E = np.vstack([(G / norm[:, None]).T, (h / norm)[None, :]])
    f = np.zeros(n + 1)
    f[n] = 1.0
    u, _ = so.nnls(E, f, maxiter=50 * (n + k + 1))
    r = E @ u - f
    if abs(r[n]) < 1e-12:
        raise ValueError("the QP's constraints are inconsistent")
    return -r[:n] / r[n], u / (-r[n] * norm)


def _qp(p: Point, B: np.ndarray, equality: np.ndarray, dlo: np.ndarray, dhi: np.ndarray, mu: float,
        cap: float | None = None):
    """The elastic QP for one ``mu``, the slacks' sum at most ``cap`` when given: (d (n,), slacks
    (m + ne,), multipliers of the m rows).

    Slacks are given at first only to the equalities and to the rows violated at ``p`` (``c < 0``); a row
    without one holds as ``c + A d >= 0``, which ``d = 0`` meets, so the QP stays feasible. That is the
    elastic QP's own solution as long as no such row's multiplier exceeds what its slack would cost
    (``mu``, plus the cap's multiplier): then the slack would stay zero. A row whose multiplier does
    is given its slack and the QP solved again. The answer is the one-slack-per-row QP's (unique:
    strictly convex), at the cost of a QP with as many slacks as the step uses: with thousands of
    geometric rows (a rule at every surface node) one slack per row made each QP a least-squares
    problem thousands of columns wide.
    """
    soft = np.asarray(equality, dtype=bool) | (p.c < 0.0)
    while True:
        d, t, lam, kappa = _qp_slacks(p, B, equality, soft, dlo, dhi, mu, cap)
        cost = mu + kappa
        if not np.any(~soft & (lam > cost * (1.0 + 1e-9))):
            return d, t, lam
        soft = soft | (lam > 0.5 * cost)     # with the rows near it: a slack that stays zero changes nothing


def _qp_slacks(p: Point, B: np.ndarray, equality: np.ndarray, soft: np.ndarray, dlo: np.ndarray,
               dhi: np.ndarray, mu: float, cap: float | None):
    """The QP of :func:`_qp` with slacks on the rows ``soft`` (m,) only (``soft`` all true: one per row):
    (d (n,), slacks (m + ne,) zero on the other rows, multipliers (m,), the cap's multiplier)."""
    n, m = p.x.size, p.c.size
    eq = np.flatnonzero(equality)
    ne = eq.size
    rows = np.flatnonzero(soft)
    ns = rows.size
    nt = ns + ne                             # a slack per soft row, a second (t-) per equality
    S = np.zeros((m, nt))
    S[rows, np.arange(ns)] = 1.0
    S[eq, ns + np.arange(ne)] = -1.0
    M = np.hstack([p.A if m else np.zeros((0, n)), S])
    # the rows G z >= h: constraints (equalities both ways), step bounds, slacks >= 0
    Iz = np.eye(n + nt)
    G = np.vstack([M, -M[eq], Iz[:n], -Iz[:n], Iz[n:]])
    h = np.concatenate([-p.c, p.c[eq], dlo, -dhi, np.zeros(nt)])
    if cap is not None:
        G = np.vstack([G, np.concatenate([np.zeros(n), -np.ones(nt)])])
        h = np.append(h, -cap)
    # z^T H z / 2 + q^T z with H = diag(B, mu I): the slacks cost mu (t + t^2 / 2), exact-penalty-like
    # for the small slacks of scaled constraints, and strictly convex (a tiny curvature instead puts the
    # least-distance centre at t = -mu / eps and ruins the conditioning)
    H = np.zeros((n + nt, n + nt))
    H[:n, :n] = B
    H[n:, n:] = mu * np.eye(nt)
    q = np.concatenate([p.g, np.full(nt, mu)])
    L = np.linalg.cholesky(H)
    Li_q = np.linalg.solve(L, q)
    Gt = np.linalg.solve(L, G.T).T              # G L^-T
    x, u = least_distance(Gt, h + Gt @ Li_q)
    z = np.linalg.solve(L.T, x - Li_q)
    lam = u[:m].copy()
    lam[eq] -= u[m:m + ne]
    t = np.zeros(m + ne)
    t[rows] = z[n:n + ns]
    t[m:] = z[n + ns:]
    return np.clip(z[:n], dlo, dhi), t, lam, (float(u[-1]) if cap is not None else 0.0)


def least_violation(p: Point, equality: np.ndarray, dlo: np.ndarray, dhi: np.ndarray) -> float:
    """The smallest l1 violation of the linearised constraints ``c + A d`` over the steps ``dlo <= d <= dhi``
    (a linear program)."""
    n, m = p.x.size, p.c.size
    if m == 0:
        return 0.0
    eq = np.flatnonzero(equality)
    ne = eq.size
    S = np.zeros((m, m + ne))
    S[np.arange(m), np.arange(m)] = 1.0
    S[eq, m + np.arange(ne)] = -1.0
    M = np.hstack([p.A, S])
    ineq = np.flatnonzero(~equality)
    res = so.linprog(np.concatenate([np.zeros(n), np.ones(m + ne)]),
                     A_ub=-M[ineq] if ineq.size else None, b_ub=p.c[ineq] if ineq.size else None,
                     A_eq=M[eq] if ne else None, b_eq=-p.c[eq] if ne else None,
                     bounds=list(zip(dlo, dhi, strict=True)) + [(0.0, None)] * (m + ne), method="highs")
    return float(res.fun) if res.status == 0 else 0.0


def solve_qp(p: Point, B: np.ndarray, equality: np.ndarray, lower: np.ndarray, upper: np.ndarray,
             radius: float, mu: float) -> Step:
    """The elastic QP at ``p`` (see the module docstring). When the step leaves its linearised
    constraints violated, it is solved again with the slacks' sum capped so that it removes at least
    nine tenths of the violation a step within the move limit can remove (:func:`least_violation`;
    the spirit of Byrd, Nocedal and Waltz's steering, without raising the penalty).

    Parameters
    ----------
    p : Point
        With gradients.
    B : (n, n) ndarray
        Positive definite model of the Lagrangian's Hessian.
    equality : (m,) bool ndarray
    lower, upper : (n,) ndarray
        Bounds on the variables (not on the step); ``p.x`` is within them.
    radius : float
        Move limit: ``|d_i| <= radius``.
    mu : float
        Penalty of the slacks.
    """
    dlo = np.minimum(np.maximum(lower - p.x, -radius), 0.0)
    dhi = np.maximum(np.minimum(upper - p.x, radius), 0.0)
    A = p.A if p.c.size else np.zeros((0, p.x.size))
    d, t, lam = _qp(p, B, equality, dlo, dhi, mu)
    v0 = violation(p.c, equality)
    viol = violation(p.c + A @ d, equality)
    if viol > 1e-12:
        target = v0 - 0.9 * (v0 - least_violation(p, equality, dlo, dhi))
        if viol > target + 1e-12:
            try:
                d, t, lam = _qp(p, B, equality, dlo, dhi, mu, cap=target + 1e-12)
            except ValueError:                   # numerically inconsistent: keep the uncapped step
                pass
    # the penalty: above the multipliers of the rows the step meets (1.5x)
    met = t[:p.c.size] <= 1e-12 * max(1.0, mu)
    mu = max(mu, 1.5 * float(np.abs(lam[met]).max(initial=0.0)))
    return Step(d=d, lam=lam, mu=mu)


def bfgs_update(B: np.ndarray, s: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Powell's damped BFGS update of ``B`` (n, n) with step ``s`` and gradient change ``y`` (n,): stays
    positive definite (``y`` is blended with ``B s`` when ``s.y < 0.2 s.B.s``)."""
    Bs = B @ s
    sBs = float(s @ Bs)
    if sBs <= 0.0:
        return B
    sy = float(s @ y)
    if sy < 0.2 * sBs:
        theta = 0.8 * sBs / (sBs - sy)
        y = theta * y + (1.0 - theta) * Bs
        sy = float(s @ y)
    return B + np.outer(y, y) / sy - np.outer(Bs, Bs) / sBs


def lagrangian_gradient(p: Point, lam: np.ndarray) -> np.ndarray:
    """``g - A^T lam`` (n,) at ``p`` (with gradients)."""
    return p.g - (p.A.T @ lam if p.c.size else 0.0)


@dataclass(frozen=True)
class Filter:
    """Fletcher and Leyffer's filter: pairs (violation, objective) of earlier designs. A design is
    acceptable when its violation is at most ``MAX_VIOLATION_GROWTH`` times the first design's (and
    :data:`MIN_VIOLATION_CAP`) and, against every pair, it has a violation ``BETA`` times smaller or
    an objective ``GAMMA`` times its violation lower."""

    pairs: tuple[tuple[float, float], ...]
    cap: float

    def acceptable(self, h: float, f: float, also: tuple[float, float] | None = None) -> bool:
        if h > self.cap:
            return False
        return all(h <= BETA * hj or f <= fj - GAMMA * h for hj, fj in self.pairs + ((also,) if also else ()))

    def add(self, h: float, f: float) -> Filter:
        """With (h, f) added and the pairs it dominates removed."""
        kept = tuple((hj, fj) for hj, fj in self.pairs if not (h <= hj and f <= fj))
        return Filter(kept + ((h, f),), self.cap)


def minimize_sqp(evaluate: Callable[[np.ndarray, bool], Point | None], x0: np.ndarray, lower: np.ndarray,
                 upper: np.ndarray, equality: np.ndarray, *, radius: float, iterations: int,
                 tolerance: float, callback: Callable[[Point], None] | None = None,
                 on_trial: Callable[[np.ndarray, str], None] | None = None) -> Result:
    """Minimise with move limits (see the module docstring).

    Parameters
    ----------
    evaluate : callable
        ``evaluate(x, gradient)`` -> :class:`Point` (with ``g``, ``A`` when ``gradient``), or None when
        the design failed. Called with ``gradient=True`` at ``x0`` and at each accepted trial only.
    x0 : (n,) ndarray
        A design within the bounds (the baseline: it must not fail).
    lower, upper : (n,) ndarray
        Variable bounds (may be infinite).
    equality : (m,) bool ndarray
        Which constraints are equalities.
    radius : float
        The first move limit (per variable, in the variables' units).
    iterations : int
        Accepted steps at most.
    tolerance : float
        Converged when the QP's step (max norm) or its predicted decrease is below it at a design
        whose linearised constraints the step meets; also the smallest move limit.
    callback : callable, optional
        Called with each accepted point.
    on_trial : callable, optional
        Called with each trial's ``x`` and the verdict in words (:func:`verdict`), once it is judged.
    """
    equality = np.asarray(equality, dtype=bool)
    p = evaluate(np.asarray(x0, dtype=float), True)
    if p is None:
        return Result(point=None, status="stopped", message="the first design failed", iterations=0, trials=0)
    B = np.eye(p.x.size)
    mu = 1.0
    filt = Filter((), max(MAX_VIOLATION_GROWTH * violation(p.c, equality), MIN_VIOLATION_CAP))
    done = trials = 0
    while done < iterations:
        step = solve_qp(p, B, equality, lower, upper, radius, mu)
        mu = step.mu
        A = p.A if p.c.size else np.zeros((0, p.x.size))
        size = float(np.abs(step.d).max(initial=0.0))
        h_p = violation(p.c, equality)
        h_lin = violation(p.c + A @ step.d, equality)
        pred_f = -float(p.g @ step.d + 0.5 * step.d @ B @ step.d)
        if h_lin <= max(tolerance, 1e-12) and h_p <= max(tolerance, 1e-12) and (
                size <= tolerance or abs(pred_f) <= tolerance * max(1.0, abs(p.f))):
            return Result(p, "converged", f"the step ({size:.3g}) or its predicted decrease "
                          f"({pred_f:.3g}) is below the tolerance at a feasible design", done, trials)
        trials += 1
        q = evaluate(p.x + step.d, False)
        ratio = -np.inf
        f_type = pred_f > 0.0 and pred_f >= KAPPA * h_p ** 2
        if q is not None:
            h_q = violation(q.c, equality)
            if filt.acceptable(h_q, q.f, also=(h_p, p.f)):
                if f_type:
                    ratio = (p.f - q.f) / pred_f
                else:
                    ratio = (h_p - h_q) / (h_p - h_lin) if h_p > h_lin else (1.0 if h_q <= h_p else -np.inf)
        if on_trial is not None:
            on_trial(p.x + step.d, verdict(q is not None, ratio, f_type, pred_f if f_type else h_p - h_lin))
        if ratio >= ETA:
            q = evaluate(q.x, True)
        else:
            q = None
        if q is None:
            radius = (0.25 if ratio == -np.inf else 0.5) * size
            if radius < tolerance:
                return Result(p, "stopped", f"the move limit shrank to {radius:.3g}, below the tolerance: "
                              "no step near the design is accepted", done, trials)
            continue
        if not f_type:
            filt = filt.add(h_p, p.f)
        y = lagrangian_gradient(q, step.lam) - lagrangian_gradient(p, step.lam)
        B = bfgs_update(B, step.d, y)
        p = q
        done += 1
        if callback is not None:
            callback(p)
        if ratio > GROW_AT and size >= 0.9 * radius:
            radius = min(2.0 * radius, MAX_RADIUS)
        elif ratio < SHRINK_AT:
            radius = 0.5 * size
    return Result(p, "iterations", f"{iterations} iterations reached", done, trials)


def verdict(evaluated: bool, ratio: float, f_type: bool, predicted: float) -> str:
    """A trial's verdict in words: ``failed``, ``refused by the filter``, or ``accepted`` / ``rejected``
    with the ratio of the achieved to the ``predicted`` decrease (of the objective for an objective step,
    of the violation for a feasibility step) beside :data:`ETA`."""
    if not evaluated:
        return "failed: the move limit shrinks to a quarter of the step"
    if ratio == -np.inf:
        return "refused by the filter: dominated, or above the violation cap"
    what = "objective" if f_type else "violation"
    word = "accepted" if ratio >= ETA else "rejected"
    return f"{word}: {ratio:.3g} of the predicted {what} decrease {predicted:.3g} (accepted from {ETA})"


def method(fun: Callable, x0: np.ndarray, args=(), jac: Callable | None = None, bounds=None, constraints=(),
           callback: Callable | None = None, *, radius: float = 0.1, maxiter: int = 100, tol: float = 1e-6,
           on_trial: Callable | None = None, **unused) -> so.OptimizeResult:
    """:func:`minimize_sqp` behind scipy's face: ``scipy.optimize.minimize(fun, x0, jac=jac,
    method=sqp.method, bounds=bounds, constraints=constraints, callback=callback,
    options={"radius": r, "maxiter": n, "tol": t})``, so a driver has one call path for every method.

    Parameters
    ----------
    fun, jac : callable
        ``fun(x, *args)`` -> float and ``jac(x, *args)`` -> (n,) (required). A value or gradient that is
        not finite marks a failed design (a flow that diverged, a mesh refused): the trial is refused
        and the move limit shrinks to a quarter of the step.
    bounds : sequence of (lo, hi) or scipy.optimize.Bounds, optional
        The variables' bounds (``None`` or infinite: unbounded).
    constraints : sequence of dict
        scipy's ``{"type": "ineq" | "eq", "fun": c(x) >= 0 | = 0, "jac": dc/dx, "args": ...}``;
        inequalities come before equalities in :class:`Point`'s ``c``, each in the order given.
    callback : callable, optional
        ``callback(x)`` after each accepted step.
    radius, maxiter, tol, on_trial
        :func:`minimize_sqp`'s first move limit, iterations, tolerance and trial verdicts.

    Returns
    -------
    scipy.optimize.OptimizeResult
        ``x``, ``fun``, ``outcome`` (converged, iterations, stopped), ``message``, ``success``,
        ``nit`` (accepted steps), ``nfev`` (trials).
    """
    if jac is None or not callable(jac):
        raise ValueError("method SQP needs the gradient: pass jac as a callable")
    x0 = np.asarray(x0, dtype=float)
    n = x0.size
    if bounds is None:
        lower, upper = np.full(n, -np.inf), np.full(n, np.inf)
    elif isinstance(bounds, so.Bounds):
        lower, upper = np.broadcast_to(bounds.lb, n).astype(float), np.broadcast_to(bounds.ub, n).astype(float)
    else:
        lower, upper = (np.array([np.nan if b is None else b for b in side], dtype=float)
                        for side in zip(*bounds, strict=True))
        lower, upper = np.nan_to_num(lower, nan=-np.inf), np.nan_to_num(upper, nan=np.inf)
    cons = [c for c in constraints if c["type"] == "ineq"] + [c for c in constraints if c["type"] == "eq"]
    sizes: list[int] = []           # each constraint's length, learnt at the first design

    def evaluate(x, gradient):
        f = float(fun(x, *args))
        if not np.isfinite(f):
            return None
        parts = [np.atleast_1d(np.asarray(k["fun"](x, *k.get("args", ())), dtype=float)) for k in cons]
        sizes[:] = [q.size for q in parts]
        c = np.concatenate(parts or [np.zeros(0)])
        if not gradient:
            return Point(x=np.asarray(x, float).copy(), f=f, c=c)
        g = np.asarray(jac(x, *args), dtype=float)
        if not np.isfinite(g).all():
            return None
        A = np.vstack([np.atleast_2d(k["jac"](x, *k.get("args", ()))) for k in cons] or [np.zeros((0, n))])
        return Point(x=np.asarray(x, float).copy(), f=f, c=c, g=g, A=A)

    # minimize_sqp's first call is evaluate(x0, True): made here (it tells the constraints' lengths), replayed
    first = [evaluate(x0, True)]
    equality = np.concatenate([np.full(size, k["type"] == "eq") for size, k in zip(sizes, cons, strict=False)]
                              or [np.zeros(0, dtype=bool)])

    def replay(x, gradient):
        return first.pop() if first else evaluate(x, gradient)

    res = minimize_sqp(replay, x0, lower, upper, equality, radius=radius, iterations=maxiter, tolerance=tol,
                       callback=None if callback is None else (lambda q: callback(q.x.copy())),
                       on_trial=on_trial)
    p = res.point
    return so.OptimizeResult(x=None if p is None else p.x, fun=None if p is None else p.f, outcome=res.status,
                             message=res.message, success=res.status == "converged", nit=res.iterations,
                             nfev=res.trials)
