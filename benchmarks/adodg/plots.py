"""The pictures of ADODG Case 1 (docs/adodg-case1.md), drawn from the run folders.

* ``adodg_case1_sections.png``: each run's best section over the baseline at true scale, and the
  thickness-wise move of each surface from the baseline (exaggerated: material added is above zero
  on both panels' second row);
* ``adodg_case1_cp.png``: -Cp on the surface before (the baseline) and after, on the optimisation
  level (the runs' own ``surface_flow.csv``) and, where evaluated, on the finest level;
* ``adodg_case1_history.png``: CD of every evaluation of each run (ffd's ``history.csv``, SU2's
  ``history_project.csv``) against the flow solves done, with the best feasible CD so far.

    python -m benchmarks.adodg.plots --baseline out/adodg/adodg_L2.su2 --out docs/gallery \\
        --run "ffd 8=out/adodg/case1_v8" --run "ffd 16=out/adodg/case1" \\
        --su2 "SU2 FFD 16=out/adodg/su2_ffd" --eval "ffd 8=out/adodg/case1_v8_L3" \\
        --eval-baseline out/adodg/eval/baseline_L3
"""

from __future__ import annotations

import argparse
import csv
import sys
from pathlib import Path

import matplotlib
import numpy as np

from benchmarks.adodg.evaluate import best_row, wall_xy
from benchmarks.adodg.su2_side import design_mesh, designs, project_rows, report

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402  (after the backend is chosen)

TITLE = "ADODG Case 1: NACA 0012 (sharp TE), Euler, M 0.85, alpha 0"


def pair(text: str) -> tuple[str, Path]:
    """``LABEL=FOLDER`` of the command line."""
    label, _, folder = text.partition("=")
    if not folder:
        raise argparse.ArgumentTypeError(f"{text!r}: expected LABEL=FOLDER")
    return label, Path(folder)


def ffd_best(run: Path) -> tuple[Path, float]:
    """(the best design's folder, its CD) of an ``ffd optimize`` run (ffd's feasibility 1e-4)."""
    row = best_row(run, 1e-4)
    return run / row["folder"], float(row["objective"])


def su2_best(run: Path, baseline: Path) -> tuple[Path, float] | None:
    """(the best design's DIRECT folder, its CD) of an SU2 run: the best meeting SU2's own constraints."""
    rep = report(run, baseline)
    best = rep["best_su2"]
    if best is None:
        return None
    return run / "DESIGNS" / best["design"] / "DIRECT", float(best["CD"])


def sections(baseline: Path, bests: list[tuple[str, Path, float]], path: Path) -> None:
    """Baseline and best sections at true scale (top) and each surface's move from the baseline (bottom)."""
    base = wall_xy(baseline)
    up, lo = base[:, 1] >= 0, base[:, 1] <= 0
    fig, (ax, bx) = plt.subplots(2, 1, figsize=(8, 6.4), gridspec_kw={"height_ratios": [1, 1.2]})
    for sel in (up, lo):
        o = np.argsort(base[sel, 0])
        ax.plot(base[sel, 0][o], base[sel, 1][o], "k-", lw=1.4, label="NACA 0012 (baseline)" if sel is up else None)
    for k, (label, mesh, cd) in enumerate(bests):
        xy = wall_xy(mesh)
        c = f"C{k}"
        for sel, sign in ((up, 1.0), (lo, -1.0)):
            o = np.argsort(base[sel, 0])
            ax.plot(xy[sel, 0][o], xy[sel, 1][o], c, lw=1.0, label=f"{label}: CD {cd:.5f}" if sign > 0 else None)
            bx.plot(base[sel, 0][o], sign * (xy[sel, 1][o] - base[sel, 1][o]), c, lw=1.0,
                    ls="-" if sign > 0 else "--")
    ax.set_aspect("equal")
    ax.set_ylim(-0.08, 0.15)
    ax.set_ylabel("y / c")
    ax.set_title(TITLE + ": best sections", fontsize=10)
    ax.legend(fontsize=7, loc="upper center", ncol=3)
    ax.grid(alpha=0.3)
    bx.axhline(0.0, color="k", lw=0.8)
    bx.set_xlabel("x / c")
    bx.set_ylabel("material added (chords)\nupper -, lower --")
    bx.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def surface_cp(folder: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(x, y, Cp) of SU2's ``surface_flow.csv`` in ``folder``."""
    d = np.genfromtxt(folder / "surface_flow.csv", delimiter=",", names=True)
    return d["x"], d["y"], d["Pressure_Coefficient"]


def cp_plot(panels: list[tuple[str, list[tuple[str, Path, str, str]]]], path: Path) -> None:
    """-Cp over the upper surface of each curve (label, folder, colour, line style) of each panel (the
    flow is symmetric: alpha 0 and symmetric designs, so the lower surface is the same curve)."""
    fig, axes = plt.subplots(1, len(panels), figsize=(6.2 * len(panels), 4.4), squeeze=False)
    for ax, (title, curves) in zip(axes[0], panels):
        for label, folder, color, ls in curves:
            x, y, cp = surface_cp(folder)
            up = y >= 0
            o = np.argsort(x[up])
            ax.plot(x[up][o], -cp[up][o], color=color, ls=ls, lw=1.5 if color == "k" else 1.1, label=label)
        ax.axhline(0.0, color="0.6", lw=0.5)
        ax.set_xlabel("x / c")
        ax.set_ylabel("-Cp (upper surface)")
        ax.set_title(title, fontsize=10)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    fig.suptitle(TITLE, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def ffd_history(run: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(cumulative flow solves, CD, feasible) of each finished evaluation of an ffd run."""
    with open(run / "history.csv", newline="") as fh:
        rows = [r for r in csv.DictReader(fh) if not r.get("failed")]
    flows = np.cumsum([int(r["flow_solves"]) for r in rows])
    cd = np.array([float(r["objective"]) for r in rows])
    return flows, cd, np.array([float(r["violation"]) <= 1e-4 for r in rows])


def su2_history(run: Path, baseline: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(flow solves, CD, feasible by SU2's own constraints) of each design of an SU2 run."""
    rep = report(run, baseline)
    rows = rep["designs"]
    return (np.arange(1, len(rows) + 1), np.array([r["CD"] for r in rows]),
            np.array([r["su2_constraints_met"] for r in rows]))


def history_plot(curves: list[tuple[str, np.ndarray, np.ndarray, np.ndarray]], path: Path) -> None:
    """CD of every evaluation (dots) and the best feasible so far (line) against the flow solves."""
    fig, ax = plt.subplots(figsize=(7.5, 4.6))
    for k, (label, flows, cd, ok) in enumerate(curves):
        c = f"C{k}"
        ax.plot(flows, cd, ".", color=c, ms=4, alpha=0.6)
        best = np.minimum.accumulate(np.where(ok, cd, np.inf))
        ax.step(flows, np.where(np.isfinite(best), best, np.nan), where="post", color=c, lw=1.3,
                label=f"{label}: {np.nanmin(np.where(ok, cd, np.nan)):.5f} in {flows[-1]} flows")
    ax.set_yscale("log")
    ax.set_xlabel("flow solves (each followed by an adjoint at an accepted step)")
    ax.set_ylabel("CD (dots: every evaluation; line: best feasible)")
    ax.set_title(TITLE + ": convergence on L2", fontsize=10)
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.adodg.plots", description=__doc__.split("\n")[0])
    ap.add_argument("--baseline", type=Path, required=True, help="the optimisation level's baseline mesh")
    ap.add_argument("--run", type=pair, action="append", default=[], help="LABEL=FOLDER of an ffd optimize run")
    ap.add_argument("--su2", type=pair, action="append", default=[], help="LABEL=FOLDER of an SU2 run (su2_side)")
    ap.add_argument("--eval", type=pair, action="append", default=[],
                    help="LABEL=FOLDER of an evaluation on the finest level (benchmarks.adodg.evaluate --work)")
    ap.add_argument("--eval-baseline", type=Path, help="the finest level's baseline solve (its surface_flow.csv)")
    ap.add_argument("--out", type=Path, required=True, help="folder for the PNGs")
    args = ap.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    bests, l2_cp, hist, l2_best = [], [], [], {}
    for k, (label, run) in enumerate(args.run):
        if not (run / "history.csv").is_file():
            continue
        folder, cd = ffd_best(run)
        bests.append((label, folder / "mesh.su2", cd))
        if not l2_cp:
            l2_cp.append(("baseline", run / "evals" / "0001", "k", "-"))
        l2_cp.append((f"{label} (CD {cd:.5f})", folder, f"C{k}", "-"))
        l2_best[label] = (folder, f"C{k}")
        hist.append((label, *ffd_history(run)))
    for k, (label, run) in enumerate(args.su2, start=len(args.run)):
        got = su2_best(run, args.baseline)
        if got is not None:
            folder, cd = got
            mesh = design_mesh(folder.parent)
            if mesh is not None:
                bests.append((label, mesh, cd))
            l2_cp.append((f"{label} (CD {cd:.5f})", folder, f"C{k}", "-"))
        if designs(run) and project_rows(run):
            hist.append((label, *su2_history(run, args.baseline)))
    sections(args.baseline, bests, args.out / "adodg_case1_sections.png")
    panels = [("L2 (the optimisation mesh)", l2_cp)]
    fine = [("baseline on L3", args.eval_baseline, "k", "-")] if args.eval_baseline else []
    for label, folder in args.eval:
        if (folder / "su2" / "surface_flow.csv").is_file() and label in l2_best:
            l2_folder, color = l2_best[label]
            fine += [(f"{label} on L2", l2_folder, color, ":"), (f"{label} on L3", folder / "su2", color, "-")]
    if fine:
        panels.append(("the same design on L2 (dotted) and on L3 (the finest mesh)", fine))
    cp_plot(panels, args.out / "adodg_case1_cp.png")
    history_plot(hist, args.out / "adodg_case1_history.png")
    for name in ("sections", "cp", "history"):
        print(args.out / f"adodg_case1_{name}.png")
    return 0


if __name__ == "__main__":
    sys.exit(main())
