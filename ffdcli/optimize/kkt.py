"""First-order optimality (the Karush-Kuhn-Tucker conditions) at a design: which constraints and bounds
hold it, and at what price.

At a local optimum of ``min f(x)`` subject to ``c(x) >= 0`` (or ``= 0``) and ``lower <= x <= upper``, the
objective's gradient is a combination of the active constraints' gradients and the active bounds'
normals (Nocedal and Wright, *Numerical Optimization*, 2nd ed., Theorem 12.1):

    g = A_a^T lam + z_lower - z_upper,    lam >= 0 for inequalities, z >= 0.

:func:`first_order` finds the multipliers that come closest to that (a bounded linear least-squares
problem) and returns the relative residual ``|g - A_a^T lam - z| / |g|``: near 0 at a KKT point, 1 where
no active constraint opposes the gradient (the optimiser stopped for another reason: iterations, a
failed flow). A multiplier is a price: tightening its constraint's bound by ``delta`` raises the
optimum's objective by about ``lam * delta`` (in the units the arrays are given in).

Pure: arrays in, a :class:`FirstOrder` out; :meth:`ffdcli.optimize.driver.Driver.optimality` gives it
the scaled quantities of a run's best design and turns the prices into each constraint's own units.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.optimize as so

#: The tolerance of "active" for a run's report: a scaled constraint (a function's ``s (value - bound)``
#: with ``s`` about 1 / |bound|, a geometric one in its units for bounds below 1) or a scaled variable
#: (a fraction of its bound range) within 1e-4 of its bound.
ACTIVE = 1e-4
#: The ridge on the multipliers, relative to the largest active gradient's norm: the least multipliers
#: among nearly equally good fits (items whose gradients are nearly opposite, such as the upper and lower
#: items beside a sharp trailing edge, otherwise share large multipliers of small net). Its bias: about
#: RIDGE**2 relative on the residual and the multipliers (1e-6: a report's precision).
RIDGE = 1e-3


@dataclass(frozen=True)
class FirstOrder:
    """The first-order optimality of a design.

    Attributes
    ----------
    residual : float
        ``|g - A^T lam - z_lower + z_upper| / |g|`` (2-norms) with the best multipliers: 0 at a KKT point;
        0 when ``g`` is 0.
    multipliers : (m,) ndarray
        Of the constraints: >= 0 for an active inequality, of either sign for an equality, 0 for an
        inactive row.
    lower, upper : (n,) ndarray
        Of the variables' active lower and upper bounds (>= 0; 0 where the bound is not active).
    active : (m,) bool ndarray
        The rows taken as active (every equality; an inequality within ``tol`` of its bound).
    """

    residual: float
    multipliers: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    active: np.ndarray


def first_order(g: np.ndarray, c: np.ndarray, A: np.ndarray, equality: np.ndarray, x: np.ndarray,
                lower: np.ndarray, upper: np.ndarray, tol: float = 1e-6) -> FirstOrder:
    """The multipliers that best satisfy ``g = A_a^T lam + z_lower - z_upper`` at a design, and how well.

    Parameters
    ----------
    g : (n,) ndarray
        The objective's gradient.
    c : (m,) ndarray
        The constraints' values (``>= 0``, or ``= 0`` where ``equality``).
    A : (m, n) ndarray
        Their Jacobian.
    equality : (m,) bool ndarray
    x : (n,) ndarray
        The design, with ``lower <= x <= upper`` (infinite bounds allowed).
    lower, upper : (n,) ndarray
    tol : float
        An inequality with ``c <= tol`` is active, a variable within ``tol`` of a bound is on it (the
        arrays' own units: scaled ones, where the optimiser's tolerance applies).

    Returns
    -------
    FirstOrder
    """
    g = np.asarray(g, dtype=float)
    c = np.asarray(c, dtype=float).reshape(-1)
    n, m = g.size, c.size
    A = np.asarray(A, dtype=float).reshape(m, n)
    equality = np.asarray(equality, dtype=bool).reshape(m)
    x, lower, upper = (np.asarray(a, dtype=float).reshape(n) for a in (x, lower, upper))
    active = equality | (c <= tol)
    at_lower = np.isfinite(lower) & (x - lower <= tol)
    at_upper = np.isfinite(upper) & (upper - x <= tol) & ~at_lower
    rows = np.flatnonzero(active)
    il, iu = np.flatnonzero(at_lower), np.flatnonzero(at_upper)
    # the columns: each active constraint's gradient, +e_i for a lower bound, -e_i for an upper one
    M = np.hstack([A[rows].T, np.eye(n)[:, il], -np.eye(n)[:, iu]])
    lo = np.concatenate([np.where(equality[rows], -np.inf, 0.0), np.zeros(il.size + iu.size)])
    scale = float(np.linalg.norm(g))
    lam, z_lo, z_up = np.zeros(m), np.zeros(n), np.zeros(n)
    if scale == 0.0:
        return FirstOrder(0.0, lam, z_lo, z_up, active)
    if M.shape[1] == 0:
        return FirstOrder(1.0, lam, z_lo, z_up, active)
    # a small ridge picks the least multipliers among (nearly) equally good fits: items whose gradients are
    # (nearly) opposite would otherwise share large multipliers with a small net, and their prices would
    # mean nothing (measured: 1,180 dCD/chord on each side beside Case 1's trailing edge without it, 3.1
    # and 2.5 with it, the residual and every other price the same to three digits)
    ridge = RIDGE * float(np.linalg.norm(M, axis=0).max())
    K = np.vstack([M, ridge * np.eye(M.shape[1])])
    y = so.lsq_linear(K, np.concatenate([g, np.zeros(M.shape[1])]), bounds=(lo, np.full(lo.size, np.inf)),
                      method="bvls", tol=1e-14).x
    residual = float(np.linalg.norm(M @ y - g)) / scale
    lam[rows] = y[:rows.size]
    z_lo[il] = y[rows.size:rows.size + il.size]
    z_up[iu] = y[rows.size + il.size:]
    return FirstOrder(residual, lam, z_lo, z_up, active)
