"""ffd's own share of an ``ffd optimize`` iteration on SU2's NACA0012 case (target: <= 5 %).

ffd's part of an iteration is what :class:`ffdcli.optimize.problem.OptimizationProblem` times as
``ffd`` seconds: set the values, deform the surface, move the volume, run the quality gate, write the
mesh, evaluate the geometric constraints (one flow's worth), then chain one all-node dJ/dX per function
through the volume motion's transpose (``mesh_vjp``; three functions: DRAG, LIFT, MOMENT_Z). It is
measured here with a stub solver that returns a random dJ/dX of every mesh node (no SU2 needed), on
``configs/naca0012_optimize.yaml`` (5,233 points, 19 variables), at random designs within the bounds;
median of 5 evaluations after one warm-up (numba compiled, box cached).

The share itself is measured on a finished run (``--run FOLDER``; default ``out/naca0012_optimize``): the
ffd, optimiser and solver seconds of every evaluation of its ``history.csv``, as the run timed them
(a history written before ``optimizer_seconds`` existed counts it 0). Without a run the row says so.

The optimiser's QP (``method: SQP``) on a geometric rule stated at every surface point: 2,050 rows of
cubic B-spline weights on 32 variables, as ADODG Case 1's ``add_material`` with ``between: 7`` (2,050
items), a quarter of the rows on their bound and two violated, against the
same QP with one slack per row (target: under 1 s; the one-slack-per-row QP took about 20 s).

    python -m benchmarks.bench_optimize_ffd [--run out/naca0012_optimize]
"""

from __future__ import annotations

import csv
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from ffdcli.api import DesignModel
from ffdcli.io.formats import read_mesh
from ffdcli.optimize.problem import OptimizationProblem
from ffdcli.optimize.solvers.base import FlowResult, Sensitivity, Solver, SolverInfo
from ffdcli.optimize.store import EvaluationStore

TITLE = "ffd optimize: ffd's own share of an iteration on SU2's NACA0012 (benchmarks/bench_optimize_ffd.py)"
REPO = Path(__file__).resolve().parents[1]
DESIGN = REPO / "configs" / "naca0012_optimize.yaml"
RUN = REPO / "out" / "naca0012_optimize"
FUNCTIONS = ["DRAG", "LIFT", "MOMENT_Z"]


class StubSolver(Solver):
    """No flow: constant functions and a random dJ/dX at every mesh node (what a discrete adjoint gives)."""

    def __init__(self, n_points: int):
        self.n = n_points
        self.rng = np.random.default_rng(0)

    def check(self) -> SolverInfo:
        return SolverInfo(name="stub", adjoint="discrete")

    def flow(self, folder, mesh, start=None) -> FlowResult:
        return FlowResult(functions=dict.fromkeys(FUNCTIONS, 0.1), seconds=0.0)

    def adjoint(self, folder, mesh, function, start=None) -> Sensitivity:
        g = np.zeros((self.n, 3))
        g[:, :2] = self.rng.normal(size=(self.n, 2))
        return Sensitivity(ids=np.arange(self.n), values=g, seconds=0.0)


def ffd_seconds(repeats: int = 5) -> dict:
    """Median ffd seconds of one evaluation with its three gradient chains, and of its parts."""
    model = DesignModel.from_file(DESIGN)
    rng = np.random.default_rng(1)
    lo, hi = model.lower, model.upper
    with tempfile.TemporaryDirectory() as tmp:
        store = EvaluationStore(Path(tmp), "bench", resume=False)
        problem = OptimizationProblem(model, StubSolver(model.run.prep.mesh.n_points), store, FUNCTIONS,
                                      warm_start=False)
        times = []
        for k in range(repeats + 1):
            v = lo + (hi - lo) * (0.5 + 0.1 * (rng.random(model.n_vars) - 0.5))   # +-5 % of the range
            t0 = time.perf_counter()
            ev = problem.evaluate(v, gradient=True)
            wall = time.perf_counter() - t0
            problem.geometric(v)                       # the constraints' Jacobian SLSQP asks for
            if k:
                times.append((ev.seconds["ffd"], wall))
    ffd = float(np.median([t[0] for t in times]))
    return {"ffd": ffd, "wall": float(np.median([t[1] for t in times])), "points": int(model.run.prep.mesh.n_points),
            "variables": model.n_vars}


def run_seconds(run: Path) -> dict | None:
    """A finished run's totals from its ``history.csv``: solver and ffd seconds, iterations."""
    path = Path(run) / "history.csv"
    if not path.is_file():
        return None
    with open(path) as fh:
        rows = list(csv.DictReader(fh))
    def ffd(r):                       # ffd's geometry chain and its optimiser's own work
        return float(r["ffd_seconds"]) + float(r.get("optimizer_seconds") or 0.0)
    return {"solver": sum(float(r["solver_seconds"]) for r in rows), "ffd": sum(ffd(r) for r in rows),
            "ffd_first": ffd(rows[0]), "iterations": max(int(r["iteration"]) for r in rows)}


def rule_qp(rows: int = 1025, columns: int = 16, seed: int = 0):
    """The QP of one SQP iteration under a rule at every surface point: ``(point, B, equality, lower, upper)``
    with ``2 rows`` constraints of B-spline weights on ``2 columns`` variables (upper and lower rows)."""
    from scipy.interpolate import BSpline

    from ffdcli.optimize.sqp import Point
    rng = np.random.default_rng(seed)
    k = 3
    knots = np.r_[[0.0] * k, np.linspace(0.0, 1.0, columns - k + 1), [1.0] * k]
    W = BSpline.design_matrix(np.linspace(0.0, 1.0, rows), knots, k).toarray()
    A = np.zeros((2 * rows, 2 * columns))
    A[:rows, :columns], A[rows:, columns:] = W, W
    x = rng.uniform(0.0, 0.02, 2 * columns)
    c = A @ x
    c[rng.random(c.size) < 0.25] = 0.0
    c[:2] = -1e-3
    B = np.eye(2 * columns) + 0.1 * np.ones((2 * columns, 2 * columns))
    n = 2 * columns
    return Point(x=x, f=1.0, c=c, g=rng.normal(size=n), A=A), B, np.zeros(c.size, bool), x - 0.1, x + 0.1


def qp_seconds(quick: bool) -> list[dict]:
    """Rows: the SQP's QP on :func:`rule_qp` (min and max of 3), and the one-slack-per-row QP (not quick)."""
    from ffdcli.optimize import sqp
    p, B, eq, lo, hi = rule_qp()
    times = []
    for _ in range(4):                                  # the first loads scipy's LP solver: not timed
        t0 = time.perf_counter()
        sqp.solve_qp(p, B, eq, lo, hi, radius=0.01, mu=1.0)
        times.append(time.perf_counter() - t0)
    times = times[1:]
    rows = [{"case": f"the SQP's QP: {p.c.size} rule rows, {p.x.size} variables (min, max of 3)",
             "measured": f"{min(times):.3f} s, {max(times):.3f} s", "target": "< 1 s", "pyGeo reference": "",
             "met": max(times) < 1.0}]
    if not quick:
        dlo, dhi = np.maximum(lo - p.x, -0.01), np.minimum(hi - p.x, 0.01)
        t0 = time.perf_counter()
        sqp._qp_slacks(p, B, eq, np.ones(p.c.size, bool), dlo, dhi, 1.0, None)
        rows.append({"case": "the same QP with one slack per row (the formulation before)",
                     "measured": f"{time.perf_counter() - t0:.1f} s", "target": "", "pyGeo reference": ""})
    return rows


def max_thickness_to_chord(mesh_path: Path, marker: str = "airfoil") -> float:
    """The largest thickness over chord of a 2D airfoil mesh's wall (the chord line from the trailing
    edge, the wall point farthest aft, to the wall point farthest from it; thickness normal to it,
    upper minus lower at 2001 stations)."""
    mesh = read_mesh(mesh_path)
    p = mesh.points[mesh.marker_point_ids(marker), :2]
    te = p[np.argmax(p[:, 0])]
    le = p[np.argmax(np.linalg.norm(p - te, axis=1))]
    chord = float(np.linalg.norm(te - le))
    t = (te - le) / chord
    n = np.array([-t[1], t[0]])
    xi, eta = (p - le) @ t / chord, (p - le) @ n / chord
    stations = np.linspace(0.0, 1.0, 2001)
    up, lo = eta >= 0, eta < 0
    order_u, order_l = np.argsort(xi[up]), np.argsort(xi[lo])
    yu = np.interp(stations, xi[up][order_u], eta[up][order_u])
    yl = np.interp(stations, xi[lo][order_l], eta[lo][order_l])
    return float((yu - yl).max())


def best_row(run_folder: Path) -> dict | None:
    """The best design of a finished run: its functions and max t/c, from ``history.csv`` and the mesh."""
    hist = Path(run_folder) / "history.csv"
    best = Path(run_folder) / "best.su2"
    if not (hist.is_file() and best.is_file()):
        return None
    with open(hist) as fh:
        rows = list(csv.DictReader(fh))
    ok = [r for r in rows if not r["failed"]]
    flows = sum(int(r["flow_solves"]) for r in rows)
    adjoints = sum(int(r["adjoint_solves"]) for r in rows)
    feasible = [r for r in ok if float(r["violation"]) <= 1e-4]
    r = min(feasible or ok, key=lambda r: float(r["objective"]))
    return {"CD": float(r["objective"]), "CL": float(r["LIFT"]), "CMz": float(r.get("MOMENT_Z", "nan")),
            "t/c": max_thickness_to_chord(best), "violation": float(r["violation"]), "feasible": bool(feasible),
            "flows": flows, "adjoints": adjoints, "iterations": max(int(x["iteration"]) for x in rows),
            "solver_s": sum(float(x["solver_seconds"]) for x in rows),
            "ffd_s": sum(float(x["ffd_seconds"]) for x in rows)}


def run(quick: bool = False, run_folder: Path = RUN) -> list[dict]:
    r = ffd_seconds(3 if quick else 5)
    tot = run_seconds(run_folder)
    rows = qp_seconds(quick)
    rows += [{"case": f"ffd per iteration: deform + volume + gate + mesh write + constraints + 3 chains "
                     f"({r['points']} points, {r['variables']} variables)", "measured": f"{r['ffd']:.3f} s",
             "target": "", "pyGeo reference": ""}]
    if tot is None:
        rows.append({"case": f"the run: no finished run in {run_folder}", "measured": "", "target": "",
                     "pyGeo reference": ""})
    else:
        per = tot["solver"] / max(tot["iterations"], 1)
        share = tot["ffd"] / (tot["ffd"] + tot["solver"])
        rest = (tot["ffd"] - tot["ffd_first"]) / (tot["ffd"] - tot["ffd_first"] + tot["solver"])
        rows.append({"case": f"the run's solver seconds per iteration ({tot['iterations']} iterations, every "
                             "flow and adjoint)", "measured": f"{per:.1f} s", "target": "", "pyGeo reference": ""})
        rows.append({"case": f"ffd's share of the run (its {tot['ffd']:.1f} s, geometry and optimiser, of "
                             f"{tot['ffd'] + tot['solver']:.0f} s; "
                             f"without the first evaluation, which compiles numba's kernels: {100 * rest:.2f} %)",
                     "measured": f"{100 * share:.2f} %", "target": "<= 5 %", "pyGeo reference": "",
                     "met": share <= 0.05})
    best = best_row(run_folder)
    if best is not None:
        kind = "feasible " if best["feasible"] else "(infeasible) "
        case = (f"the run's best {kind}design: CD, CL, CMz, max t/c; {best['flows']} flows + "
                f"{best['adjoints']} adjoints, {best['iterations']} iterations")
        measured = f"{best['CD']:.6f}, {best['CL']:.6f}, {best['CMz']:.6f}, {best['t/c']:.5f}"
        rows.append({"case": case, "measured": measured, "target": "feasible, CD <= 0.003018, <= 43 solves",
                     "pyGeo reference": "",
                     "met": best["feasible"] and best["CD"] <= 0.003018 and best["flows"] + best["adjoints"] <= 43})
    return rows


if __name__ == "__main__":
    folder = Path(sys.argv[sys.argv.index("--run") + 1]) if "--run" in sys.argv else RUN
    for row in run("--quick" in sys.argv, folder):
        print(json.dumps(row))
