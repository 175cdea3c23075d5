"""2D airfoil fitting: the ``shape`` values that morph the mesh airfoil into a target airfoil.

The deformed surface is ``X = X0 + B (P' - P0)`` and a ``shape`` change moves the upper (k = l-1)
and lower (k = 0) control points along the thickness axis only, so each surface point's thickness
coordinate is linear in the shape values ``a`` while its chordwise coordinate stays put:

    eta_s(a) = eta0_s + sum_v B[s, row(v)] a_v.

(``--rows all`` moves every thickness row, not only the upper and lower ones: with l = 5 and a
cubic in thickness, the outer rows have no influence on points half-way up the box, such as the
leading and trailing edges, so the edge-rows-only fit is poor there.)

The target airfoil (Selig or Lednicer file) is placed on the mesh airfoil's chord line (same
leading and trailing edge), split at its leading edge into an upper and a lower branch, and
interpolated at each surface point's chordwise position on the point's own side. The fit solves
the Tikhonov-regularised linear least-squares problem

    min_a |W (A a - (eta_T - eta0))|^2 + s (lam |a|^2 + mu |D a|^2),   s = |W A|_F^2 / n_vars,

with W the thickness component of the target's unit normal at each point (so that the residual is
the linearised normal distance, not the vertical one that blows up at the leading edge) and D the
differences between neighbouring rows of each lattice column. Moving all rows leaves directions that
barely move the surface; without ``mu`` the least-squares answer uses them and folds the lattice
(rows cross by up to 0.7 chord for NACA0012 -> S1223). ``mu = 0.1`` prefers moving whole columns
together, which is what camber needs: 12 x 5 then fits within 0.21 % chord (0.04 % unsmoothed) with an
unfolded lattice; ``lam = 1e-6`` only pins what nothing else determines.
Deviations are reported in chord units, as the
distance of each deformed surface point to the target polyline. The workflow of ``ffd fit`` (files in,
the fitted design file out) is :mod:`ffdcli.app.fit`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ffdcli.errors import InputError

REG = 1e-6
SMOOTH = 0.1


@dataclass
class FitProblem:
    """The linear model of one airfoil fit, in chord units."""

    A: np.ndarray          # (S, n_cols) d eta / d (value of each moved control point), weighted
    rhs: np.ndarray        # (S,) weighted target minus original thickness coordinate
    weight: np.ndarray     # (S,) |n_eta| of the target at each point: vertical -> normal distance
    columns: list          # (i, k) control point of each column
    chord: float
    n: int
    l: int
    xi: np.ndarray         # (S,) chordwise position of each surface point (chords)
    eta: np.ndarray        # (S,) original thickness position (chords)
    target: np.ndarray     # (K, 2) the placed target polyline (xi, eta), Selig order


def place_target(coords: np.ndarray):
    """(xi, eta) in chord units of an airfoil (K, 2), leading edge at 0, trailing edge at (1, 0).

    Returns the placed polyline (K, 2) and its upper and lower branches, each (xi, eta) sorted by xi."""
    c = np.asarray(coords, dtype=np.float64)
    te_t = 0.5 * (c[0] + c[-1])
    i_le = int(np.argmax(np.hypot(*(c - te_t).T)))
    le_t = c[i_le]
    d_t = te_t - le_t
    L = np.hypot(*d_t)
    e1 = d_t / L
    e2 = np.array([-e1[1], e1[0]])
    xi = (c - le_t) @ e1 / L
    eta = (c - le_t) @ e2 / L
    upper = (xi[: i_le + 1][::-1], eta[: i_le + 1][::-1])
    lower = (xi[i_le:], eta[i_le:])
    if np.mean(upper[1]) < np.mean(lower[1]):      # a file running the other way round
        upper, lower = lower, upper
        eta = -eta
    return np.c_[xi, eta], _monotone(*upper), _monotone(*lower)


def _monotone(xi: np.ndarray, eta: np.ndarray):
    o = np.argsort(xi, kind="stable")
    xi, eta = xi[o], eta[o]
    keep = np.r_[True, np.diff(xi) > 0]
    return xi[keep], eta[keep]


def distance_to_polyline(p: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """Distance (S,) from points (S, 2) to the polyline (K, 2) (vectorised over all segments)."""
    a, b = poly[:-1], poly[1:]
    ab = b - a
    L2 = np.maximum(np.einsum("kd,kd->k", ab, ab), 1e-300)
    out = np.full(len(p), np.inf)
    for lo in range(0, len(p), 2048):          # bounded memory: 2048 x K pairs at a time
        q = p[lo:lo + 2048, None, :]
        t = np.clip(np.einsum("skd,kd->sk", q - a, ab) / L2, 0.0, 1.0)
        d = np.linalg.norm(q - (a + t[..., None] * ab), axis=2)
        out[lo:lo + 2048] = d.min(axis=1)
    return out


def build_problem(run, target: np.ndarray, rows: str = "all") -> FitProblem:
    """The linear least-squares model for the 2D design ``run`` (``ffdcli.app.pipeline.DesignRun``).

    ``rows="edge"``: the upper (k = l-1) and lower (k = 0) rows move, as the design file's
    ``shape: {upper, lower}``; ``rows="all"``: every thickness row (``shape: {rows}``)."""
    box, emb, surf = run.box, run.prep.embedding, run.prep.surface
    if box.dim != 2:
        raise InputError("ffd fit works on 2D airfoil meshes; this design's mesh is 3D",
                         path=run.design.path)
    n, _, l = box.shape
    ca, ta = box.axes.chord, box.axes.thickness
    le = box.le_points[0][[ca, ta]]
    te = box.te_points[0][[ca, ta]]
    chord = float(np.hypot(*(te - le)))
    e1 = (te - le) / chord
    e2 = np.array([-e1[1], e1[0]])
    if e2[1] < 0:              # thickness direction must be "up" (+ mesh thickness axis)
        e2 = -e2
    X = surf.points[:, [ca, ta]]
    xi = (X - le) @ e1 / chord
    eta = (X - le) @ e2 / chord
    poly, (xu, yu), (xl, yl) = place_target(target)
    upper_side = eta >= 0
    eta_t = np.where(upper_side, np.interp(xi, xu, yu), np.interp(xi, xl, yl))
    slope = np.where(upper_side, np.interp(xi, xu, np.gradient(yu, xu)), np.interp(xi, xl, np.gradient(yl, xl)))
    weight = 1.0 / np.sqrt(1.0 + slope ** 2)
    cols = [(i, l - 1) for i in range(n)] + [(i, 0) for i in range(n)] if rows == "edge" else \
        [(i, k) for k in range(l) for i in range(n)]
    A = np.zeros((len(X), len(cols)))
    for c, (i, k) in enumerate(cols):
        dP = np.zeros((n, l, 2))
        dP[i, k, 1] = 1.0       # the core's 2D coordinates are (chord axis, thickness axis)
        d = emb.displace(dP)
        A[:, c] = (d @ e2) / chord
    return FitProblem(A=A * weight[:, None], rhs=(eta_t - eta) * weight, weight=weight, columns=cols,
                      chord=chord, n=n, l=l, xi=xi, eta=eta, target=poly)


def smoothing_matrix(problem: FitProblem) -> np.ndarray:
    """Differences between neighbouring thickness rows of each lattice column (a row per pair)."""
    where = {c: j for j, c in enumerate(problem.columns)}
    rows = []
    for i in range(problem.n):
        ks = sorted(k for (ii, k) in problem.columns if ii == i)
        for k0, k1 in zip(ks[:-1], ks[1:]):
            r = np.zeros(len(problem.columns))
            r[where[(i, k1)]] = 1.0
            r[where[(i, k0)]] = -1.0
            rows.append(r)
    return np.array(rows).reshape(-1, len(problem.columns))


def solve(problem: FitProblem, reg: float = REG, smooth: float = SMOOTH):
    """Values (one per column, mesh units) and the deviation before/after in chord units.

    The deviation is the distance of each surface point to the target polyline."""
    A, r = problem.A, problem.rhs
    scale = float(np.sum(A * A)) / A.shape[1]
    D = smoothing_matrix(problem)
    M = A.T @ A + scale * (reg * np.eye(A.shape[1]) + smooth * D.T @ D)
    a = np.linalg.solve(M, A.T @ r)
    moved = (A / problem.weight[:, None]) @ a
    d0 = distance_to_polyline(np.c_[problem.xi, problem.eta], problem.target)
    d1 = distance_to_polyline(np.c_[problem.xi, problem.eta + moved], problem.target)
    stats = {"before": {"rms": float(np.sqrt(np.mean(d0 ** 2))), "max": float(d0.max())},
             "after": {"rms": float(np.sqrt(np.mean(d1 ** 2))), "max": float(d1.max())}}
    return a * problem.chord, stats


def shape_spec(problem: FitProblem, values: np.ndarray) -> dict:
    """The ``shape`` change of the fitted values."""
    n, l = problem.n, problem.l
    grid = np.zeros((l, n))
    for (i, k), v in zip(problem.columns, values):
        grid[k, i] = v
    if len(problem.columns) == 2 * n:
        return {"upper": grid[l - 1].tolist(), "lower": grid[0].tolist(), "sections": "all"}
    return {"rows": grid.tolist(), "sections": "all"}
