"""The picture of an ADODG Case 3 run (docs/adodg-case3.md), drawn from an ``ffd optimize`` run's folder.

``adodg_case3_run.png`` (or ``--name``), three panels:

* the span load ``c·cl`` of the baseline (evaluation 1) and of a design (the run's best by ffd's rule, or
  ``--evaluation N``) strip by strip, against the ellipse of the design's lift
  (:func:`benchmarks.adodg.case3_report.report`: SU2's ``surface_flow.csv`` on the evaluation's mesh);
* the design's twist at the box's control sections, relative to the root section (the case's twist; the
  root's own twist is the change of the angle of attack, in the legend), against their span station
  (equally spaced from the symmetry plane to the wing's outermost point: ``case3_su2_side.stations``);
* the history: CD of every evaluation and ``e_load`` (the load's Trefftz efficiency) of each, the
  accepted iterates (adjoints solved) joined, the line search's trials apart.

    python -m benchmarks.adodg.case3_plots --run out/adodg3h/case3 --out docs/gallery --strips 0 [--evaluation N]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import matplotlib
import numpy as np

from benchmarks.adodg.case2_evaluate import EvaluationError, history_rows, pick_row
from benchmarks.adodg.case3_report import S_HALF, SEMISPAN, config_alpha, report
from benchmarks.adodg.case3_su2_side import stations, wing_box, wing_points
from ffdcli.errors import FfdError
from ffdcli.io.formats import read_mesh

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402  (after the backend is chosen)

TITLE = "ADODG Case 3: rectangular NACA 0012 wing, Euler, M 0.5, CL 0.375"
FEASIBILITY = 1e-4


def evaluation_report(folder: Path, n_strips: int) -> dict:
    """:func:`case3_report.report` of an evaluation folder (its ``mesh.su2``, its ``flow.cfg``'s angle)."""
    alpha = config_alpha(folder)
    if alpha is None:
        raise EvaluationError(f"{folder}: no flow.cfg with AOA")
    return report(folder, folder / "mesh.su2", cd0=None, n_strips=n_strips, alpha=alpha)


def run_history(run: Path, n_strips: int) -> dict[str, np.ndarray]:
    """Every finished evaluation of the run: evaluation, CD, CL, e_load, accepted (adjoints solved)."""
    rows = [r for r in history_rows(run) if not r.get("failed")]
    e_load = [evaluation_report(Path(run) / r["folder"], n_strips)["e_load"] for r in rows]
    return {"evaluation": np.array([int(r["evaluation"]) for r in rows]),
            "cd": np.array([float(r["objective"]) for r in rows]),
            "cl": np.array([float(r["LIFT"]) for r in rows]),
            "e_load": np.array(e_load),
            "accepted": np.array([int(r["adjoint_solves"]) > 0 for r in rows])}


def run_plot(run: Path, out: Path, *, evaluation: int | None, n_strips: int) -> dict:
    """Draw the three panels into ``out``; returns what was drawn (design, twists, stations, reports)."""
    best = pick_row(run, FEASIBILITY, evaluation)
    first = pick_row(run, FEASIBILITY, 1)
    base_r = evaluation_report(Path(run) / first["folder"], n_strips)
    best_r = evaluation_report(Path(run) / best["folder"], n_strips)
    twist = np.asarray(best["values"])
    y = stations(wing_box(wing_points(read_mesh(Path(run) / first["folder"] / "mesh.su2"))), len(twist))
    hist = run_history(run, n_strips)

    fig, (ax, bx, cx) = plt.subplots(3, 1, figsize=(7.5, 10.0))
    label = f"evaluation {best['evaluation']}" + ("" if best["feasible"] else " (infeasible)")
    for r, name, color in ((base_r, "baseline", "k"), (best_r, label, "C3")):
        ax.plot(r["eta"], r["ccl"], "o-", color=color, ms=3, lw=1.0,
                label=f"{name}: CL {r['CL']:.4f}, RMS {r['rms_pct']:.2f} %, e_load {r['e_load']:.4f}")
    eta = np.linspace(0.0, 1.0, 400)
    c0 = 4.0 * best_r["CL"] * S_HALF / (np.pi * SEMISPAN)          # the elliptic root load of the same lift
    ax.plot(eta, c0 * np.sqrt(1.0 - eta ** 2), "C0--", lw=1.2,
            label="ellipse of the design's lift")
    ax.set_xlabel("eta = y / 3")
    ax.set_ylabel("c cl")
    ax.set_title(TITLE + ": span load", fontsize=10)
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3)

    bx.plot(y / SEMISPAN, twist - twist[0], "C3o-", lw=1.2,
            label=f"{label}, relative to the root (root {twist[0]:+.3f} deg = the change of alpha)")
    bx.axhline(0.0, color="k", lw=0.7)
    bx.set_xlabel("control section's span station / 3")
    bx.set_ylabel("twist (deg)")
    bx.set_title("twist of the box's control sections (about the trailing edge)", fontsize=10)
    bx.legend(fontsize=7)
    bx.grid(alpha=0.3)

    acc = hist["accepted"]
    cx.plot(hist["evaluation"][acc], 1e4 * hist["cd"][acc], "C0o-", ms=4, lw=1.0, label="CD, accepted")
    cx.plot(hist["evaluation"][~acc], 1e4 * hist["cd"][~acc], "o", mfc="none", mec="C1", ms=6, label="CD, trial")
    cx.set_xlabel("evaluation")
    cx.set_ylabel("CD (counts)")
    cx.grid(alpha=0.3)
    ex = cx.twinx()
    ex.plot(hist["evaluation"], hist["e_load"], "C2s--", ms=4, lw=0.8, label="e_load")
    ex.set_ylabel("e_load")
    lines = cx.get_lines() + ex.get_lines()
    cx.legend(lines, [ln.get_label() for ln in lines], fontsize=7, loc="center right")
    cx.set_title("history", fontsize=10)
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return {"evaluation": int(best["evaluation"]), "twist": twist.tolist(), "stations": y.tolist(),
            "baseline": base_r, "design": best_r, "history": {k: v.tolist() for k, v in hist.items()}}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.adodg.case3_plots", description=__doc__.split("\n")[0])
    ap.add_argument("--run", type=Path, required=True, help="the run's folder (history.csv, evals/)")
    ap.add_argument("--out", type=Path, required=True, help="folder for the PNG")
    ap.add_argument("--name", default="adodg_case3_run.png")
    ap.add_argument("--evaluation", type=int, help="the design drawn (default: the run's best by ffd's rule)")
    ap.add_argument("--strips", type=int, default=24,
                    help="equal strips (default 24); 0: the wall's own spanwise rows (the hybrid family)")
    args = ap.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    try:
        drawn = run_plot(args.run, args.out / args.name, evaluation=args.evaluation, n_strips=args.strips)
    except (EvaluationError, FfdError) as e:          # a missing run, evaluation or evaluation file
        print(f"error: {e}", file=sys.stderr)
        return 2
    print(args.out / args.name)
    print(json.dumps({k: drawn[k] for k in ("evaluation", "twist", "stations")}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
