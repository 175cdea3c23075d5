"""The results table of ADODG Case 1 (docs/adodg-case1.md) from the run folders, finished or still running.

One row per run: ffd's (``ffd optimize`` folders: ``history.csv``; the ``--json`` summary for the wall
time when given) and SU2's (``benchmarks.adodg.su2_side`` folders), with the CD reached on the
optimisation level, the reduction from that level's baseline, the flow and adjoint solves, the time and
ffd's share of it, and, where an evaluation on the finest level exists (``benchmarks.adodg.evaluate``'s
``evaluation.json``), the CD there, its reduction and the add-material rule at every node there.

    python -m benchmarks.adodg.results --baseline out/adodg/adodg_L2.su2 \\
        --ffd "ffd 8=out/adodg/case1_v8" --json-of "ffd 8=case1_v8.json" --eval "ffd 8=out/adodg/eval/case1_v8" \\
        --su2 "SU2 FFD 16=out/adodg/su2_ffd"
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
from pathlib import Path

from benchmarks.adodg.evaluate import BASELINE_CD, TOLERANCE
from benchmarks.adodg.plots import pair
from benchmarks.adodg.su2_side import report

HEAD = ("| run | variables | L2 CD | L2 reduction | flow + adjoint solves | wall (s) | SU2 (s) | ffd (s, share) | "
        "L3 CD | L3 reduction | rule on L3 (worst margin, chords) | state |")


def ffd_row(label: str, run: Path, summary: Path | None, evaluation: Path | None) -> str:
    """A table row of an ffd run (finished when ``summary``, its ``--json`` output, is given)."""
    if not (run / "history.csv").is_file():
        return f"| {label} | - | - | - | - | - | - | - | - | - | - | not run yet ({run} has no history.csv) |"
    with open(run / "history.csv", newline="") as fh:
        rows = [r for r in csv.DictReader(fh)]
    ok = [r for r in rows if not r.get("failed")]
    feasible = [r for r in ok if float(r["violation"]) <= 1e-4]
    if not feasible:
        return f"| {label} | - | - | - | - | - | - | - | - | - | - | no feasible evaluation yet |"
    best = min(feasible, key=lambda r: float(r["objective"]))
    flows = sum(int(r["flow_solves"]) for r in rows)
    adjoints = sum(int(r["adjoint_solves"]) for r in rows)
    solver = sum(float(r["solver_seconds"]) for r in rows)
    # ffd's geometry chain and its optimiser's own work (a history without optimizer_seconds: 0)
    ffd = sum(float(r["ffd_seconds"]) + float(r.get("optimizer_seconds") or 0.0) for r in rows)
    wall, state, n_vars = "-", f"running ({len(rows)} evaluations)", None
    text = summary.read_text().strip() if summary is not None and summary.is_file() else ""
    s = json.loads(text) if text else {}      # the --json summary is written when the run ends
    if s and "seconds" not in s:              # stopped (Ctrl-C, SIGTERM): its message says so
        state = f"stopped after {len(rows)} evaluations ({s.get('error', 'no summary').split(';')[0]})"
    elif s:
        wall = f"{s['seconds']['wall']:.0f}"
        state = f"{s['status']}: {s['iterations']} iterations"
        flows, adjoints = s["flow_solves"], s["adjoint_solves"]
        solver, ffd = s["seconds"]["solver"], s["seconds"]["ffd"] + s["seconds"].get("optimizer", 0.0)
        n_vars = len(s.get("variables") or []) or None
    cd = float(best["objective"])
    cells = [label, str(n_vars or "-"), f"{cd:.6f}", f"{100 * (1 - cd / BASELINE_CD['L2']):.1f} %",
             f"{flows} + {adjoints}", wall, f"{solver:.0f}", f"{ffd:.1f} ({100 * ffd / max(solver + ffd, 1e-9):.2f} %)"]
    cells += l3_cells(evaluation, int(best["evaluation"]))
    cells.append(state)
    return "| " + " | ".join(cells) + " |"


def l3_cells(evaluation: Path | None, index: int | None) -> list[str]:
    """CD on L3, its reduction and the rule's worst margin there, from ``evaluation.json`` (or dashes)."""
    path = None if evaluation is None else evaluation / "evaluation.json"
    if path is None or not path.is_file():
        return ["-", "-", "-"]
    e = json.loads(path.read_text())
    stale = index is not None and e["evaluation"] != index
    margin = min(e["rule"]["upper"], e["rule"]["lower"])
    rule = f"{margin:+.1e} ({'met' if margin >= -TOLERANCE else 'broken'})"
    if "cd" not in e:
        return ["(not solved)", "-", rule]
    note = f" (of evaluation {e['evaluation']})" if stale else ""
    return [f"{e['cd']:.6f}{note}", f"{100 * e['reduction']:.1f} %", rule]


def su2_row(label: str, run: Path, baseline: Path) -> str:
    """A table row of an SU2 run: its best design by SU2's own constraints (and the rule's margin there)."""
    rep = report(run, baseline)
    best = rep["best_su2"]
    n_vars = len([d for d in (run / "config.cfg").read_text().split("DEFINITION_DV=", 1)[1].splitlines()[0].split(";")])
    if best is None:
        return f"| {label} | {n_vars} | - | - | - | - | - | - | - | - | - | no design yet |"
    m = best["rule"]
    margin = min(m["upper"], m["lower"])
    state = (f"finished (exit {rep['rc']})" if rep["finished"] else f"running ({len(rep['designs'])} designs)")
    cells = [label, str(n_vars), f"{best['CD']:.6f} ({best['design']})",
             f"{100 * (1 - best['CD'] / BASELINE_CD['L2']):.1f} %",
             f"{rep['flow_solves']} + {rep['adjoint_solves']}", f"{rep['wall']:.0f}", "-", "-", "-", "-",
             f"L2: {margin:+.1e} ({'met' if margin >= -TOLERANCE else 'broken'})", state]
    return "| " + " | ".join(cells) + " |"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.adodg.results", description=__doc__.split("\n")[0])
    ap.add_argument("--baseline", type=Path, required=True, help="the optimisation level's baseline mesh")
    ap.add_argument("--ffd", type=pair, action="append", default=[], help="LABEL=FOLDER of an ffd optimize run")
    ap.add_argument("--json-of", type=pair, action="append", default=[], help="LABEL=FILE: the run's --json summary")
    ap.add_argument("--eval", type=pair, action="append", default=[], help="LABEL=FOLDER of its evaluation on L3")
    ap.add_argument("--su2", type=pair, action="append", default=[], help="LABEL=FOLDER of an SU2 run (su2_side)")
    args = ap.parse_args(argv)
    summaries, evals = dict(args.json_of), dict(args.eval)
    print(HEAD)
    print("|" + "---|" * HEAD.count(" | ") + "---|")
    for label, run in args.ffd:
        print(ffd_row(label, run, summaries.get(label), evals.get(label)))
    for label, run in args.su2:
        print(su2_row(label, run, args.baseline))
    return 0


if __name__ == "__main__":
    sys.exit(main())
