"""The pictures of ADODG Case 2 (docs/adodg-case2.md), drawn from an ``ffd optimize`` run's folder.

* ``adodg_case2_cp_cf.png``: -Cp and the skin friction's chordwise component Cf_x (below zero aft of
  the leading edge: the flow reversed; ahead of the stagnation point it runs forward) on the upper and
  lower surfaces, the baseline (evaluation 1) and a design (the run's best, or ``--evaluation N``),
  from SU2's ``surface_flow.csv`` of each evaluation (the run's mesh);
* ``adodg_case2_section.png``: the two sections (the thickness axis stretched) and the thickness-wise
  move of each surface (design minus baseline, in thousandths of the chord);
* ``adodg_case2_history.png``: CD, CL and CM(c/4) of every evaluation, the accepted iterates (those
  whose adjoints were solved) apart from the line search's trials, with the lift target and the
  moment bound.

    python -m benchmarks.adodg.case2_plots --run out/adodg/case2 --out docs/gallery [--evaluation N]

With ``--solve LABEL FOLDER MESH`` (repeated) only the -Cp and Cf_x picture is drawn, of any SU2 solves
(each folder holds SU2's ``surface_flow.csv`` and ``history.csv``, ``MESH`` the mesh it was solved on),
labelled with the CD and CL of the history's last row: the finer mesh's solves of
``case2_evaluate``, for one, into ``--name``::

    python -m benchmarks.adodg.case2_plots --out docs/gallery --name adodg_case2_cp_cf_fine.png \
        --solve baseline out/adodg/case2_s1/baseline/cl out/adodg/rae2822_s1.su2 \
        --solve "evaluation 34" out/adodg/case2_s1/e0034/cl out/adodg/case2_s1/e0034/mesh.su2
"""

from __future__ import annotations

import argparse
import csv
import sys
from pathlib import Path

import matplotlib
import numpy as np

from benchmarks.adodg.case2_evaluate import EvaluationError, marker_named, pick_row
from benchmarks.adodg.case2_meshes import wall_loop
from ffdcli.io.formats import read_mesh
from ffdcli.optimize.solvers.su2 import read_history

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402  (after the backend is chosen)

CASE = "ADODG Case 2: RAE2822, RANS SA, M 0.734, Re 6.5e6"
TITLE = CASE + ", alpha 2.79"
TARGET_CL, CM_BOUND = 0.824, -0.092


def surfaces(folder: Path, mesh_path: Path | None = None) -> dict[str, np.ndarray]:
    """SU2's ``surface_flow.csv`` of an evaluation ``folder`` split into the upper and lower surfaces
    along the wall loop of its mesh (``mesh_path``, default the folder's ``mesh.su2``): {'upper'|'lower':
    (k, 4) x, y, Cp, Cf_x}, the upper from the trailing edge to the leading edge, the lower from the
    leading edge to the trailing edge."""
    d = np.genfromtxt(folder / "surface_flow.csv", delimiter=",", names=True)
    mesh = read_mesh(mesh_path or folder / "mesh.su2")
    loop = wall_loop(mesh, marker_named(mesh, "airfoil"))
    row = np.full(len(mesh.points), -1, dtype=np.int64)
    row[d["PointID"].astype(np.int64)] = np.arange(len(d))
    if (row[loop] < 0).any():
        raise EvaluationError(f"{folder / 'surface_flow.csv'}: not every wall node of its mesh.su2 is in it")
    table = np.column_stack([d["x"], d["y"], d["Pressure_Coefficient"], d["Skin_Friction_Coefficient_x"]])[row[loop]]
    le = int(np.argmin(table[:, 0]))
    return {"upper": table[: le + 1], "lower": np.vstack([table[le:], table[:1]])}


def cp_cf_plot(curves: list[tuple[str, Path, str]], path: Path, meshes: list[Path | None] | None = None,
               title: str = TITLE) -> None:
    """-Cp (top) and Cf_x (bottom) on both surfaces (upper solid, lower dashed) of each curve
    (label, evaluation folder, colour), each on its folder's ``mesh.su2`` or on ``meshes[i]``."""
    fig, (ax, bx) = plt.subplots(2, 1, figsize=(8, 7.2), sharex=True, gridspec_kw={"height_ratios": [1.3, 1]})
    for (label, folder, color), mesh in zip(curves, meshes or [None] * len(curves), strict=True):
        s = surfaces(folder, mesh)
        for side, ls in (("upper", "-"), ("lower", "--")):
            t = s[side]
            ax.plot(t[:, 0], -t[:, 2], color=color, ls=ls, lw=1.3, label=f"{label}, {side}")
            bx.plot(t[:, 0], t[:, 3], color=color, ls=ls, lw=1.1)
    ax.axhline(0.0, color="0.6", lw=0.5)
    ax.set_ylabel("-Cp")
    ax.set_title(title + ": surface pressure and skin friction", fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, ncol=2)
    bx.axhline(0.0, color="0.3", lw=0.7)
    bx.set_ylim(-0.001, 0.007)
    bx.set_xlabel("x / c")
    bx.set_ylabel("Cf_x (chordwise component)")
    bx.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def section_plot(base: Path, design: Path, label: str, path: Path) -> None:
    """The baseline and design sections (top; y stretched 4 times against x) and the thickness-wise move
    of each surface, design minus baseline (bottom, in thousandths of the chord; the upper surface's
    positive up, the lower's positive down: material added is above zero for both)."""
    mesh = read_mesh(base)
    loop = wall_loop(mesh, marker_named(mesh, "airfoil"))
    b, d = mesh.points[loop, :2], read_mesh(design).points[loop, :2]
    le = int(np.argmin(b[:, 0]))
    sides = {"upper": np.arange(0, le + 1), "lower": np.append(np.arange(le, len(loop)), 0)}
    fig, (ax, bx) = plt.subplots(2, 1, figsize=(8, 6.4), sharex=True, gridspec_kw={"height_ratios": [1, 1]})
    for name, idx in sides.items():
        first = name == "upper"
        ax.plot(b[idx, 0], b[idx, 1], "k-", lw=1.3, label="baseline" if first else None)
        ax.plot(d[idx, 0], d[idx, 1], "C3-", lw=1.1, label=label if first else None)
        sign = 1.0 if first else -1.0
        bx.plot(b[idx, 0], 1e3 * sign * (d[idx, 1] - b[idx, 1]), "C3", ls="-" if first else "--", lw=1.2,
                label=f"{name} surface")
    ax.set_aspect(4.0)
    ax.set_ylabel("y / c (stretched x4)")
    ax.set_title(TITLE + ": the section", fontsize=10)
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    bx.axhline(0.0, color="k", lw=0.8)
    bx.set_xlabel("x / c")
    bx.set_ylabel("material added (0.001 c)")
    bx.legend(fontsize=8)
    bx.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def history(run: Path) -> dict[str, np.ndarray]:
    """Every finished evaluation of the run's ``history.csv`` (the last row of each): evaluation,
    CD (counts), CL, CM(c/4) (nose-up positive: SU2's MOMENT_Z negated), accepted (adjoints solved)."""
    with open(Path(run) / "history.csv", newline="") as fh:
        rows = {int(r["evaluation"]): r for r in csv.DictReader(fh) if not r.get("failed")}
    ev = np.array(sorted(rows))
    get = lambda key: np.array([float(rows[e][key]) for e in ev])  # noqa: E731
    return {"evaluation": ev, "cd": 1e4 * get("objective"), "cl": get("LIFT"), "cm": -get("MOMENT_Z"),
            "violation": get("violation"), "accepted": get("adjoint_solves") > 0}


def history_plot(run: Path, path: Path, feasibility: float = 1e-4) -> None:
    """CD, CL and CM(c/4) against the evaluation: accepted iterates (filled, joined) and trials (open)."""
    h = history(run)
    acc, feas = h["accepted"], h["violation"] <= feasibility
    fig, axes = plt.subplots(3, 1, figsize=(7.5, 7.5), sharex=True)
    for ax, key, label in zip(axes, ("cd", "cl", "cm"), ("CD (counts)", "CL", "CM(c/4)"), strict=True):
        ax.plot(h["evaluation"][acc], h[key][acc], "C0o-", ms=5, lw=1.0, label="accepted (adjoints solved)")
        ax.plot(h["evaluation"][~acc], h[key][~acc], "o", mfc="none", mec="C1", ms=6, label="trial (flow only)")
        ax.plot(h["evaluation"][feas], h[key][feas], "k*", ms=9, mfc="none", label="feasible (within 1e-4)")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    axes[1].axhline(TARGET_CL, color="C2", lw=1.0, ls="--", label="CL = 0.824")
    axes[2].axhline(CM_BOUND, color="C3", lw=1.0, ls="--", label="CM >= -0.092")
    axes[0].legend(fontsize=7, loc="upper right")
    for ax in axes[1:]:
        ax.legend(handles=ax.get_lines()[-1:], fontsize=7, loc="best")
    axes[0].set_title(TITLE + ": the run on SU2's mesh", fontsize=10)
    axes[-1].set_xlabel("evaluation")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def solve_label(label: str, folder: Path) -> str:
    """``label`` with the CD (counts) and CL of the last row of the solve's ``history.csv``."""
    path = folder / "history.csv"
    if not path.is_file():
        raise EvaluationError(f"{path}: no such file (a folder of an SU2 solve holds its history.csv)")
    h = read_history(path)
    if not h.get("CD") or not h.get("CL"):
        raise EvaluationError(f"{path}: no CD and CL columns with a row (SU2's HISTORY_OUTPUT must hold AERO_COEFF)")
    return f"{label}: CD {1e4 * h['CD'][-1]:.1f}, CL {h['CL'][-1]:.3f}"


def solves_plot(solves: list[list[str]], path: Path) -> None:
    """The -Cp and Cf_x picture of ``solves`` ([label, folder, mesh] each), the first in black."""
    for _, folder, mesh in solves:
        for f in (Path(folder) / "surface_flow.csv", Path(mesh)):
            if not f.is_file():
                raise EvaluationError(f"{f}: no such file")
    curves = [(solve_label(label, Path(folder)), Path(folder), "k" if i == 0 else f"C{2 + i}")
              for i, (label, folder, _) in enumerate(solves)]
    path.parent.mkdir(parents=True, exist_ok=True)
    cp_cf_plot(curves, path, [Path(mesh) for _, _, mesh in solves], title=CASE)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.adodg.case2_plots", description=__doc__.split("\n")[0])
    ap.add_argument("--run", type=Path, help="the run's folder (history.csv, evals/)")
    ap.add_argument("--out", type=Path, required=True, help="folder for the PNGs")
    ap.add_argument("--evaluation", type=int, help="the design drawn (default: the run's best by ffd's rule)")
    ap.add_argument("--solve", nargs=3, action="append", metavar=("LABEL", "FOLDER", "MESH"),
                    help="draw only -Cp and Cf_x of these SU2 solves (repeat: the first is the reference)")
    ap.add_argument("--name", default="adodg_case2_cp_cf.png", help="the picture's file name with --solve")
    args = ap.parse_args(argv)
    if args.solve:
        try:
            solves_plot(args.solve, args.out / args.name)
        except EvaluationError as e:
            print(f"error: {e}", file=sys.stderr)
            return 2
        print(args.out / args.name)
        return 0
    if args.run is None:
        ap.error("--run is required (or --solve)")
    try:
        row = pick_row(args.run, 1e-4, args.evaluation)
        base = pick_row(args.run, 1e-4, 1)
    except EvaluationError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    best, first = args.run / row["folder"], args.run / base["folder"]
    label = (f"evaluation {row['evaluation']}" + ("" if row["feasible"] else " (infeasible)"))
    args.out.mkdir(parents=True, exist_ok=True)
    cp_cf_plot([(f"baseline: CD {1e4 * float(base['objective']):.1f}, CL {float(base['LIFT']):.3f}", first, "k"),
                (f"{label}: CD {1e4 * float(row['objective']):.1f}, CL {float(row['LIFT']):.3f}", best, "C3")],
               args.out / "adodg_case2_cp_cf.png")
    section_plot(first / "mesh.su2", best / "mesh.su2", label, args.out / "adodg_case2_section.png")
    history_plot(args.run, args.out / "adodg_case2_history.png")
    for name in ("cp_cf", "section", "history"):
        print(args.out / f"adodg_case2_{name}.png")
    return 0


if __name__ == "__main__":
    sys.exit(main())
