"""``ffd optimize`` beside SU2's own optimiser on SU2's NACA0012 case, and the adjoint chain.

One invocation runs, on this machine, with the mesh and flow of SU2's shape-design case
(``../shared/data/su2``: ``mesh_NACA0012_inv.su2``, ``inv_NACA0012_basic.cfg``; Euler, M 0.8, alpha
1.25 deg) and 8 optimiser iterations each:

* ``--peers``: SU2's ``shape_optimization.py`` (SLSQP) with (a) its 38 Hicks-Henne bumps and (b) SU2's
  own FFD box (the ``_v8`` mesh, 22 ``FFD_CONTROL_POINT_2D``), each with the discrete and the
  continuous adjoint, constrained as SU2's ``inv_NACA0012_adv`` (CL >= 0.328486, MOMENT_Z >= 0,
  t/c >= 0.12) and unconstrained (:mod:`benchmarks._optpeers`);
* ``--ffd``: (c) ``ffd optimize`` with ffd's automatic box, the same two adjoints, constrained and not
  (:mod:`benchmarks._optffd`; needs the ``optimize`` command, ``--ffd-path`` names a tree that has it);
* ``--chain``: (i) SU2's projection of a Hicks-Henne bump against dJ/dX read from its files; (ii) ``ffd
  grad`` of ffd's box against central differences of SU2 (:mod:`benchmarks._optchain`).

Every solver run lives in ``--root`` (default ``/work/scratch/optbench``, env ``FFD_OPTBENCH_ROOT``) in a
folder named by the hash of its config, inputs and command; a finished run (its ``result.json``) is
reused, so an interrupted benchmark continues where it stopped and the table is assembled from one
invocation's runs. Only one SU2 process of the benchmark runs at a time (a lock file in the root). The
table's columns: final CD, CL, CMz, t/c (SU2_GEO's ``AIRFOIL_THICKNESS``), the worst violation of the
constrained case's bounds (also shown for unconstrained runs), flow and adjoint solves (counted from
the runs' folders), wall seconds of the run alone (waiting for the slot excluded).

    python -m benchmarks.bench_optimize --peers --chain --ffd --write-doc
    python -m benchmarks.bench_optimize --chain --quick          # twist and one shape variable

Within ``python -m benchmarks`` (``run``) it only reports finished runs found in the root: the runs take
one to two hours on two cores and are started here, by hand.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import re
import sys
import time
from pathlib import Path

from benchmarks import _optchain, _optffd, _optpeers, _su2

TITLE = "ffd optimize beside SU2's shape_optimization.py on SU2's NACA0012 (benchmarks/bench_optimize.py)"
NOTES = ("Runs are started by `python -m benchmarks.bench_optimize --peers --ffd --chain`; `python -m "
         "benchmarks` reports the finished ones it finds.")
DOC = _su2.REPO / "docs" / "optimize.md"
BEGIN, END = "<!-- bench_optimize:begin -->", "<!-- bench_optimize:end -->"
ADJOINTS = ("discrete", "continuous")


def peer_rows(only_constrained: bool = False, run_missing: bool = True, adjoints=ADJOINTS) -> list[dict]:
    """The (a)/(b) rows: run (or reuse) each peer and read its folder."""
    rows = []
    for case in _optpeers.all_cases():
        if (only_constrained and not case.constrained) or case.adjoint not in adjoints:
            continue
        r = _optpeers.run_case(case, only_cached=not run_missing)
        if r is None:
            continue
        print(f"  {case.label}: {'reused' if r.get('cached') else 'ran'} {r['folder']}", flush=True)
        rows.append(_read_row(_optpeers.peer_row, case, r))
    return rows


def ffd_rows(ffd_path: Path, only_constrained: bool = False, run_missing: bool = True,
             adjoints=ADJOINTS) -> list[dict]:
    """The (c) rows, when the tree at ``ffd_path`` has ``ffd optimize`` (else none, with a message)."""
    if not _optffd.has_optimize(ffd_path):
        print(f"  (c) skipped: {ffd_path} has no `ffd optimize` yet", flush=True)
        return []
    rows = []
    for constrained in (True, False):
        if only_constrained and not constrained:
            continue
        for adjoint in adjoints:
            label = f"ffd-{adjoint[:4]}-{'con' if constrained else 'unc'}"
            r = _optffd.run_case(adjoint, constrained, ffd_path, only_cached=not run_missing)
            if r is None:
                folder = _optffd.run_folder(adjoint, constrained, ffd_path)
                part = _read_row(_optffd.partial_row, adjoint, constrained, folder) if folder.exists() else None
                if part is not None:
                    print(f"  {label}: unfinished run {folder}", flush=True)
                    rows.append(part)
                continue
            print(f"  {label}: {'reused' if r.get('cached') else 'ran'} {r['folder']}", flush=True)
            rows.append(_read_row(_optffd.ffd_row, adjoint, constrained, r))
            last = _read_row(_optffd.last_iterate_row, adjoint, constrained, r)
            if last is not None:
                rows.append(last)
    return rows


def _read_row(fn, *args) -> dict:
    """``fn(*args)``; a run whose folder cannot be read gives a row saying why (the others go on)."""
    try:
        return fn(*args)
    except Exception as exc:  # noqa: BLE001  (one unreadable run must not stop the remaining runs)
        r = args[-1] if isinstance(args[-1], dict) else {"folder": str(args[-1])}
        print(f"  cannot read {r.get('folder')}: {type(exc).__name__}: {exc}", flush=True)
        return {"run": r.get("label", "?"), "adjoint": "", "constrained": "con" in r.get("label", ""),
                "CD": float("nan"), "CL": float("nan"), "CMz": float("nan"), "tc": float("nan"),
                "worst_violation": float("nan"), "feasible": False, "flow": None, "adjoint_solves": None,
                "wall_s": r.get("wall_s", float("nan")), "error": f"{type(exc).__name__}: {exc}",
                "folder": r.get("folder")}


# ----------------------------------------------------------------------------------------------
# Tables
# ----------------------------------------------------------------------------------------------

def _f(x, fmt="{:.6f}") -> str:
    if x is None:
        return ""
    if isinstance(x, float) and x != x:
        return "n/a"
    return fmt.format(x)


def side_by_side_table(rows: list[dict]) -> str:
    """Markdown: one line per run, constrained runs first."""
    head = ("| run | adjoint | constrained | final CD | CL | CMz | t/c | worst violation | feasible | "
            "flow + adjoint solves | wall |\n|---|---|---|---|---|---|---|---|---|---|---|")
    lines, notes = [head], []
    for r in sorted(rows, key=lambda r: (not r["constrained"], r["run"], r["adjoint"])):
        feas = "yes" if r["feasible"] else "no"
        status = str(r.get("status") or "")
        run = r["run"]
        if status.startswith("unfinished"):
            notes.append(f"{run}, {r['adjoint']}: {status}.")
            run += f" [{len(notes)}]"
        lines.append(f"| {run} | {r['adjoint']} | {'yes' if r['constrained'] else 'no'} | "
                     f"{_f(r['CD'])} | {_f(r['CL'], '{:.4f}')} | {_f(r['CMz'], '{:.4f}')} | "
                     f"{_f(r['tc'], '{:.4f}')} | {_f(r['worst_violation'], '{:.2e}')} | {feas} | "
                     f"{r['flow']} + {r['adjoint_solves']} | {r['wall_s']:.0f} s |")
    return "\n".join(lines) + "".join(f"\n\n[{i}] {n}" for i, n in enumerate(notes, 1))


def projection_table(rows: list[dict]) -> str:
    lines = ["| adjoint | dJ/dX read from | SU2's gradient | SU2_DEF displacement . dJ/dX | relative |",
             "|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['adjoint']} | {r['dJdX']} | {r['SU2']:.15e} | {r['ffd']:.15e} | "
                     f"{r['relative']:.1e} |")
    return "\n".join(lines)


def gradient_table(rows: list[dict]) -> str:
    lines = ["| function | variable | step | central difference | discrete adjoint | rel. | "
             "continuous adjoint | rel. |", "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['function']} | `{r['variable']}` | {r['step']:g} | {r['fd']:.6e} | "
                     f"{r.get('discrete', float('nan')):.6e} | {r.get('discrete_rel', float('nan')):.1e} | "
                     f"{r.get('continuous', float('nan')):.6e} | {r.get('continuous_rel', float('nan')):.2f} |")
    return "\n".join(lines)


def machine_line() -> str:
    load = os.getloadavg()
    return (f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}, {platform.node() or 'this machine'} "
            f"({os.cpu_count()} cores, {platform.python_implementation()} {platform.python_version()}), "
            f"load average at the end {load[0]:.2f} / {load[1]:.2f} / {load[2]:.2f} (1 / 5 / 15 min)")


def write_doc(text: str) -> None:
    """Put ``text`` between the benchmark's markers in docs/optimize.md (appended when absent)."""
    block = f"{BEGIN}\n{text.rstrip()}\n{END}\n"
    old = DOC.read_text() if DOC.exists() else "# Optimisation with `ffd optimize`\n\n"
    if BEGIN in old and END in old:
        new = re.sub(re.escape(BEGIN) + r".*?" + re.escape(END) + r"\n?", lambda m: block, old, flags=re.S)
    else:
        new = old.rstrip() + "\n\n" + block
    tmp = DOC.with_suffix(".md.tmp")
    tmp.write_text(new)
    os.replace(tmp, DOC)


# ----------------------------------------------------------------------------------------------
# Entry points
# ----------------------------------------------------------------------------------------------

def run(quick: bool = False) -> list[dict]:
    """For ``python -m benchmarks``: the finished runs found in the root (no solver is started)."""
    if _su2.su2_bin() is None:
        return [{"case": "SU2 not found (SU2_RUN, PATH, ../shared/su2/bin): nothing to compare"}]
    rows = peer_rows(run_missing=False) + ffd_rows(_su2.REPO, run_missing=False)
    return [{"case": f"{r['run']}, {r['adjoint']}, {'constrained' if r['constrained'] else 'free'}",
             "measured": f"CD {r['CD']:.6f}, CL {r['CL']:.4f}, viol {r['worst_violation']:.1e}, "
                         f"{r['flow']}+{r['adjoint_solves']} solves, {r['wall_s']:.0f} s"} for r in rows]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.bench_optimize", description=__doc__.splitlines()[0])
    ap.add_argument("--peers", action="store_true", help="SU2's shape_optimization.py rows (a), (b)")
    ap.add_argument("--ffd", action="store_true", help="ffd optimize rows (c)")
    ap.add_argument("--chain", action="store_true", help="the chain checks (i), (ii)")
    ap.add_argument("--quick", action="store_true",
                    help="constrained rows only; chain (ii) with twist and one shape variable")
    ap.add_argument("--adjoint", action="append", choices=ADJOINTS,
                    help="--peers/--ffd: only this adjoint (repeatable; default both)")
    ap.add_argument("--ffd-path", type=Path, default=_su2.REPO, help="the ffd tree that has `ffd optimize`")
    ap.add_argument("--finished-only", action="store_true",
                    help="--peers/--ffd: only the runs already finished in the root (start no new run)")
    ap.add_argument("--write-doc", action="store_true", help="write the tables into docs/optimize.md")
    ap.add_argument("--json", type=Path, help="also write every row as JSON here")
    args = ap.parse_args(argv)
    if not (args.peers or args.ffd or args.chain):
        args.peers = args.ffd = args.chain = True
    if _su2.su2_bin() is None:
        print("SU2 not found (SU2_RUN, PATH, ../shared/su2/bin)", file=sys.stderr)
        return 2
    t0 = time.perf_counter()
    out: dict = {"command": "python -m benchmarks.bench_optimize " + " ".join(argv or sys.argv[1:])}
    sections = []
    rows = []
    if args.peers:
        rows += peer_rows(only_constrained=args.quick, run_missing=not args.finished_only,
                          adjoints=tuple(args.adjoint or ADJOINTS))
    if args.ffd:
        rows += ffd_rows(args.ffd_path, only_constrained=args.quick, run_missing=not args.finished_only,
                         adjoints=tuple(args.adjoint or ADJOINTS))
    if rows:
        out["side_by_side"] = rows
        sections.append("## Side by side with SU2's optimiser\n\n" + _side_intro() + side_by_side_table(rows))
    if args.chain:
        chain = _optchain.run_chain(quick=args.quick)
        out["chain"] = chain
        sections.append("## The chain SU2 adjoint -> ffd, checked\n\n" + _chain_text(chain))
    stamp = (f"Measured {machine_line()}; `{out['command'].strip()}` "
             f"({time.perf_counter() - t0:.0f} s for this invocation, runs reused from the cache included).")
    text = "\n\n".join(sections) + "\n\n" + stamp + "\n"
    print(text)
    if args.json:
        args.json.write_text(json.dumps(out, indent=1, default=str))
    if args.write_doc:
        write_doc(text)
    return 0


def _side_intro() -> str:
    return ("SU2's NACA0012 shape-design case (mesh `mesh_NACA0012_inv.su2`, 5,233 points; "
            "`inv_NACA0012_basic.cfg`: Euler, M 0.8, alpha 1.25 deg, residuals to 1e-13), 8 optimiser "
            "iterations for every run (SU2's script: scipy's SLSQP; ffd: its SQP with move limits, "
            "docs/optimize.md), from CD 0.021481. Constrained: CL >= 0.328486, CMz >= 0, t/c >= 0.12 "
            "(SU2: `OPT_CONSTRAINT= " + _optpeers.CONSTRAINTS + "`). The final design is the last one the "
            "optimiser evaluated (SU2's `history_project.csv`) or the best feasible one (ffd's `best.yaml`); "
            "t/c is SU2_GEO's `AIRFOIL_THICKNESS` of its mesh; the worst violation is against the "
            "constrained case's bounds, shown for the unconstrained runs too; solves are counted from the "
            "runs' folders (SU2: `DESIGNS/DSN_*/DIRECT` and `ADJOINT_*` with a history).\n\n")


def _chain_text(chain: dict) -> str:
    return ("(i) SU2's projection of its Hicks-Henne bump `( 1, 0.50 )` (upper side, mid-chord), for the "
            "drag adjoint at `OUTPUT_PRECISION= 16`: the displacement SU2_DEF makes for the bump "
            f"(value {_optchain.HH_STEP:g}, divided by it: the bump is linear in its value) dotted with dJ/dX "
            "from SU2's files, against SU2_DOT (continuous) and SU2_DOT_AD (discrete; its projection moves "
            "the volume nodes by SU2's elastic mesh motion, so the whole mesh's displacement is dotted "
            "with every node's dJ/dX):\n\n" + projection_table(chain["projection"]) +
            "\n\n(ii) ffd's automatic box (`box: {points: [8, 2]}`, twist about the trailing edge and 2 x 8 "
            "shape variables): `ffd grad --sens` of the adjoints' files (discrete: `restart_adj_cd.csv` / "
            "`restart_adj_cl.csv`, every node, through ffd's volume motion; continuous: -S n_hat of "
            "`surface_adjoint.csv`, wall nodes) against central differences of SU2_CFD solutions on meshes "
            "written by `ffd deform --set` (restarted from the baseline flow, residuals to 1e-13):\n\n"
            + gradient_table(chain["gradient"]))


if __name__ == "__main__":
    sys.exit(main())
