"""What a run leaves beside its evaluations: ``history.csv`` (one row per evaluation), ``history.png``
(objective and worst violation per iteration) and the choice of the best design.

``history.csv`` columns (SPEC "Optimisation"): ``evaluation, iteration, norm`` (of the optimised
variables' values), ``objective``, each function the solver reported for the run, each geometric
constraint, ``violation`` (worst, in the constraints' own units), ``step`` (the distance in scaled
variables from the previous evaluation), ``solver_seconds``, ``ffd_seconds`` (the geometry chain: deform,
gate, write, chain rule), ``optimizer_seconds`` (the optimiser's work before it asked for the design: its
QP, the geometric constraints' values and Jacobian), ``flow_solves``,
``adjoint_solves``, ``folder``, ``failed`` (the reason, with the log's path), ``trial`` (``method: SQP``:
the verdict on the design as a trial step, accepted or rejected with the ratio of the achieved to the
predicted decrease, :func:`ffdcli.optimize.sqp.verdict`; empty for the baseline and other methods).
"""

from __future__ import annotations

import csv
import io
import os
from pathlib import Path

import numpy as np

from ffdcli.io.atomic import atomic_path, atomic_write
from ffdcli.optimize.store import Evaluation
from ffdcli.viz.plot import load_pyplot


def history_rows(evaluations: list[Evaluation], *, objective: str, functions: list[str], constraint_names: list[str],
                 violations: list[float], chosen: np.ndarray, r: np.ndarray, folder: Path,
                 verdicts: dict[int, str] | None = None) -> list[dict]:
    """One dict per evaluation, the columns of ``history.csv`` (``verdicts``: the trial column, by index)."""
    rows, prev = [], None
    for ev, worst in zip(evaluations, violations, strict=True):
        x = ev.values[chosen] / r
        row = {"evaluation": ev.index, "iteration": ev.iteration, "norm": float(np.linalg.norm(ev.values[chosen])),
               "objective": ev.functions.get(objective, float("nan"))}
        row.update({f: ev.functions.get(f, float("nan")) for f in functions if f != objective})
        row.update({c: (float(ev.constraints[i]) if ev.failed is None and i < len(ev.constraints) else float("nan"))
                    for i, c in enumerate(constraint_names)})
        row.update({"violation": worst, "step": 0.0 if prev is None else float(np.linalg.norm(x - prev)),
                    "solver_seconds": round(ev.seconds["solver"], 3), "ffd_seconds": round(ev.seconds["ffd"], 3),
                    "optimizer_seconds": round(ev.seconds.get("optimizer", 0.0), 3),
                    "flow_solves": ev.solves["flow"], "adjoint_solves": ev.solves["adjoint"],
                    "folder": os.path.relpath(ev.folder, folder),
                    "failed": "" if ev.failed is None else ev.failed + (f" (log: {ev.log})" if ev.log else ""),
                    "trial": (verdicts or {}).get(ev.index, "")})
        rows.append(row)
        prev = x
    return rows


def write_history(path: Path, rows: list[dict]) -> None:
    """``history.csv``, written whole (atomic)."""
    if not rows:
        return
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=list(rows[0]), lineterminator="\n")
    writer.writeheader()
    for row in rows:
        writer.writerow({k: (f"{v:.10g}" if isinstance(v, float) else v) for k, v in row.items()})
    with atomic_write(path, "w") as fh:
        fh.write(buf.getvalue())


def iterates(evaluations: list[Evaluation]) -> list[Evaluation]:
    """The designs the optimiser accepted, in order: the evaluations whose gradients were asked for."""
    return [ev for ev in evaluations if ev.gradients and ev.failed is None]


def write_picture(path: Path, evaluations: list[Evaluation], violations: dict[int, float], objective: str,
                  feasibility: float) -> None:
    """``history.png``: the objective (left) and the worst violation (right, log) of each iteration, every
    evaluation faint behind (failed ones as crosses)."""
    plt = load_pyplot()
    its = iterates(evaluations)
    fig, ax = plt.subplots(figsize=(7, 4), dpi=110)
    ok = [e for e in evaluations if e.failed is None]
    ax.plot([e.iteration for e in ok], [e.functions[objective] for e in ok], "o", color="0.75", ms=4,
            label="every evaluation")
    bad = [e for e in evaluations if e.failed is not None]
    if bad and its:
        ax.plot([e.iteration for e in bad], [its[0].functions[objective]] * len(bad), "x", color="red",
                label="failed evaluation")
    ax.plot(range(len(its)), [e.functions[objective] for e in its], "o-", color="C0", label=objective)
    ax.set_xlabel("iteration")
    ax.set_ylabel(objective, color="C0")
    ax2 = ax.twinx()
    worst = [max(violations[e.index], 1e-2 * feasibility) for e in its]     # 0 drawn at the plot's floor
    # the range set first (one value, or none, would give an empty range, which matplotlib warns about)
    ys = [e.functions[objective] for e in ok]
    if ys and min(ys) == max(ys):
        ax.set_ylim(ys[0] - (0.1 * abs(ys[0]) or 1.0), ys[0] + (0.1 * abs(ys[0]) or 1.0))
    ax2.set_yscale("log")
    ax2.set_ylim(min(worst + [feasibility]) / 3, max(worst + [feasibility]) * 3)
    ax2.semilogy(range(len(its)), worst, "s--", color="C3", ms=4, label="worst violation")
    ax2.axhline(feasibility, color="C3", lw=0.6, ls=":")
    ax2.set_ylabel("worst constraint violation", color="C3")
    lines = ax.get_legend_handles_labels()
    lines2 = ax2.get_legend_handles_labels()
    ax.legend(lines[0] + lines2[0], lines[1] + lines2[1], loc="best", fontsize=8)
    ax.set_title(f"{objective} and the worst violation per iteration ({len(evaluations)} evaluations)", fontsize=9)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png")
    plt.close(fig)


def best_evaluation(evaluations: list[Evaluation], violations: dict[int, float], objective: str,
                    feasibility: float) -> tuple[Evaluation | None, bool]:
    """(the best design, feasible?): the lowest objective among the feasible evaluations, else the one
    with the smallest violation (None when every evaluation failed)."""
    ok = [e for e in evaluations if e.failed is None]
    feasible = [e for e in ok if violations[e.index] <= feasibility]
    if feasible:
        return min(feasible, key=lambda e: (e.functions[objective], e.index)), True
    if ok:
        return min(ok, key=lambda e: (violations[e.index], e.functions[objective])), False
    return None, False
