"""The boundary-layer report of every design of an ADODG Case 2 run: at each wall node of each
evaluation's mesh, the first cell's height after / before (the run's baseline mesh, evaluation 1) and
the change of the off-wall angle, as ``ffd deform`` reports them for one design
(:func:`ffdcli.quality.wall_layer.wall_layer_report`).

    python -m benchmarks.adodg.case2_layers --run out/adodg/case2 [--all] [--marker airfoil]

The accepted designs by default (those whose adjoints were solved: the iterates), every finished one
with ``--all``. One markdown row per design: evaluation, CD (counts), CL, the first-cell ratio's min
and max, the largest off-wall angle change, the nodes measured, and whether every first cell stayed
within ``volume.first_cell``'s default 1 %.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from benchmarks.adodg.case2_evaluate import EvaluationError, history_rows, marker_named
from ffdcli.io.formats import read_mesh
from ffdcli.quality.wall_layer import wall_layer_report

HEAD = ("| evaluation | CD (counts) | CL | first cell after / before, min | max | off-wall angle change, max (°) "
        "| wall nodes | within 1 % |\n|---:|---:|---:|---:|---:|---:|---:|---|")


def layer_rows(run: Path, accepted_only: bool = True, marker: str = "airfoil") -> list[dict]:
    """One dict per finished evaluation (accepted ones only by default): its figures against the run's
    first evaluation's mesh."""
    rows = [r for r in history_rows(run) if not r.get("failed")]
    if not rows:
        raise EvaluationError(f"{run / 'history.csv'}: no finished evaluation")
    rows.sort(key=lambda r: int(r["evaluation"]))
    base_path = run / rows[0]["folder"] / "mesh.su2"
    if not base_path.is_file():
        raise EvaluationError(f"{base_path}: no such file (the run's first evaluation's mesh)")
    base = read_mesh(base_path)
    name = marker_named(base, marker)
    out = []
    for r in rows:
        if accepted_only and int(float(r["adjoint_solves"] or 0)) == 0:
            continue
        path = run / r["folder"] / "mesh.su2"
        if not path.is_file():
            raise EvaluationError(f"{path}: no such file")
        design = read_mesh(path)
        if design.points.shape != base.points.shape:
            raise EvaluationError(f"{path}: {len(design.points)} points, the baseline has {len(base.points)}")
        rep = wall_layer_report(base, [name], points_after=design.points, points_before=base.points)
        if rep is None:
            raise EvaluationError(f"{base_path}: no boundary layer on {name!r} (an Euler mesh?)")
        out.append({"evaluation": int(r["evaluation"]), "cd_counts": 1e4 * float(r["objective"]),
                    "cl": float(r["LIFT"]), "ratio_min": rep.ratio_min, "ratio_max": rep.ratio_max,
                    "angle_change": rep.angle_change, "n_wall": rep.n_wall, "ok": rep.ok})
    return out


def table(rows: list[dict]) -> str:
    """The rows as markdown."""
    lines = [HEAD]
    for r in rows:
        lines.append(f"| {r['evaluation']} | {r['cd_counts']:.1f} | {r['cl']:.5f} | {r['ratio_min']:.6f} | "
                     f"{r['ratio_max']:.6f} | {r['angle_change']:.3f} | {r['n_wall']} | {'yes' if r['ok'] else 'NO'} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.adodg.case2_layers", description=__doc__.split("\n")[0])
    ap.add_argument("--run", type=Path, required=True, help="the ffd optimize run folder (history.csv, evals/)")
    ap.add_argument("--all", action="store_true", help="every finished evaluation, the trials too")
    ap.add_argument("--marker", default="airfoil", help="the wall marker (default airfoil)")
    a = ap.parse_args(argv)
    try:
        rows = layer_rows(a.run, accepted_only=not a.all, marker=a.marker)
    except (EvaluationError, OSError, ValueError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    print(table(rows))
    lo, hi = min(r["ratio_min"] for r in rows), max(r["ratio_max"] for r in rows)
    print(f"\n{len(rows)} designs: first cell after / before {lo:.7f} to {hi:.7f}; off-wall angle changed by up "
          f"to {max(r['angle_change'] for r in rows):.3f} deg; "
          f"{sum(not r['ok'] for r in rows)} outside 1 %")
    return 0


if __name__ == "__main__":
    sys.exit(main())
