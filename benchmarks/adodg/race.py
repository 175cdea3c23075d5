"""Who gets there in fewer solves: the best feasible drag against the flow + adjoint solves spent, an
``ffd optimize`` run beside SU2's own ``shape_optimization.py`` on the same case (the ADODG issues'
goal "fewer flow + adjoint solves than SU2's own optimiser on the same mesh").

    python -m benchmarks.adodg.race --case 3 --ffd out/adodg3h/case3 --su2 out/adodg3h/su2_twist \\
        --out docs/gallery/adodg_case3_race.png
    python -m benchmarks.adodg.race --case 2 --ffd out/adodg/case2 --su2 out/adodg/su2_case2 --out ...
    python -m benchmarks.adodg.race --case 1 --ffd out/adodg/case1_dense --su2 out/adodg/su2_case1_hh \\
        --baseline out/adodg/adodg_L2.su2 --out ...

Counting, the same for both tools: a design's drag is known when its flow has finished, so design k
stands at the solves finished before it plus its flow; its adjoints (if any) are counted after it.
ffd's ``history.csv`` has a row per finished evaluation with its ``flow_solves`` and ``adjoint_solves``;
SU2's run a row of ``history_project.csv`` per finished flow and a gradient file (``of_grad*.csv``) per
finished adjoint in ``DESIGNS/DSN_k/ADJOINT_*``, and SLSQP asks for a design's gradient before it moves
on, so design k's adjoints follow its flow. Feasible: ffd's ``violation`` (every constraint, the
geometric ones included) within the case's tolerance; SU2's designs by the case's own check
(:mod:`benchmarks.adodg.su2_side` (the add-material rule at every wall node), ``su2_side_case2``
(CL, CM, area), ``case3_su2_side`` (CL)), at the same tolerance (1e-6 chord for Case 1, 1e-4 else),
and only when its flow reached the configuration's residual (SU2's scripts take a flow stopped at
``ITER`` as a value; ffd counts it a failure).

Printed: per run its solves, its best feasible drag and the solves at which it was reached; per pair of
an ffd run and an SU2 run, the solves each needed to reach the other's best (``not reached in N`` when
it did not); the picture: every design (filled when feasible) and the best feasible so far, as steps,
against the solves.
"""

from __future__ import annotations

import argparse
import csv
import sys
from dataclasses import dataclass
from pathlib import Path

import matplotlib
import numpy as np

from benchmarks.adodg import case3_su2_side, su2_side, su2_side_case2

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402  (after the backend is chosen)

TOLERANCE = {1: 1e-6, 2: 1e-4, 3: 1e-4}
TITLES = {1: "ADODG Case 1: NACA 0012, M 0.85, Euler, material added only",
          2: "ADODG Case 2: RAE2822, RANS SA, M 0.734, CL 0.824, CM and area held",
          3: "ADODG Case 3: rectangular wing, twist only, M 0.5, CL 0.375"}


class RaceError(Exception):
    """A run folder that cannot be read (the message names the file)."""


@dataclass(frozen=True)
class Trace:
    """One run's designs in the order they were solved.

    ``solves`` (k,): the flow + adjoint solves finished when design k's drag was known (its flow
    included); ``objective`` (k,) the drag; ``feasible`` (k,) bool; ``total`` every solve the run
    finished (the last design's adjoints included); ``tool`` "ffd" or "SU2"; ``unconverged`` how many
    of its flows stopped short of the configuration's residual (counted infeasible)."""

    label: str
    solves: np.ndarray
    objective: np.ndarray
    feasible: np.ndarray
    total: int
    tool: str = "ffd"
    unconverged: int = 0


def trace_of(label: str, flows: list[int], adjoints: list[int], objective: list[float], feasible: list[bool],
             tool: str = "ffd", unconverged: int = 0) -> Trace:
    """A :class:`Trace` from each design's flow and adjoint solves, drag and feasibility (in order)."""
    flows_a, adj_a = np.asarray(flows, dtype=np.int64), np.asarray(adjoints, dtype=np.int64)
    before = np.concatenate([[0], np.cumsum(flows_a + adj_a)[:-1]])
    return Trace(label=label, solves=before + flows_a, objective=np.asarray(objective, dtype=float),
                 feasible=np.asarray(feasible, dtype=bool), total=int((flows_a + adj_a).sum()), tool=tool,
                 unconverged=unconverged)


def ffd_trace(run: Path, tolerance: float, label: str = "ffd") -> Trace:
    """The :class:`Trace` of an ``ffd optimize`` run folder (its ``history.csv``; failed rows carry no drag
    and are counted by their solves only)."""
    path = Path(run) / "history.csv"
    if not path.is_file():
        raise RaceError(f"{path}: no such file (an `ffd optimize` run folder holds its history.csv)")
    with open(path, newline="") as fh:
        rows = list(csv.DictReader(fh))
    rows.sort(key=lambda r: int(r["evaluation"]))
    flows = [int(float(r["flow_solves"] or 0)) for r in rows]
    adjoints = [int(float(r["adjoint_solves"] or 0)) for r in rows]
    failed = [bool(r.get("failed")) for r in rows]
    objective = [float("nan") if f else float(r["objective"]) for r, f in zip(rows, failed, strict=True)]
    feasible = [not f and float(r["violation"]) <= tolerance for r, f in zip(rows, failed, strict=True)]
    return trace_of(label, flows, adjoints, objective, feasible)


def su2_adjoints(folder: Path, n: int) -> list[int]:
    """The finished adjoints of SU2's designs 1..n (:func:`benchmarks.adodg.su2_side.finished_adjoints`)."""
    return [su2_side.finished_adjoints(Path(folder) / "DESIGNS" / f"DSN_{k + 1:03d}") for k in range(n)]


def su2_trace(case: int, folder: Path, label: str, baseline: Path | None = None) -> Trace:
    """The :class:`Trace` of SU2's ``shape_optimization.py`` run folder for ``case``, each design judged by
    the case's own report (``baseline``: the mesh of Case 1's rule)."""
    folder = Path(folder)
    if not (folder / "config.cfg").is_file():
        raise RaceError(f"{folder / 'config.cfg'}: no such file (a folder set up by the case's su2 side `setup`)")
    if case == 1:
        if baseline is None:
            raise RaceError("--baseline MESH is needed for Case 1 (the add-material rule is judged on its wall)")
        rows = su2_side.report(folder, baseline)["designs"]
        feasible = [r["rule_met"] for r in rows]
    elif case == 2:
        rows = su2_side_case2.report(folder)["designs"]
        feasible = [r["feasible"] for r in rows]
    else:
        rows = [{"CD": r["DRAG"], "CL": r["LIFT"]} for r in su2_side.project_rows(folder)]
        feasible = [abs(r["CL"] - case3_su2_side.CL_TARGET) <= case3_su2_side.CL_TOLERANCE for r in rows]
    converged = su2_side.flow_converged(folder, len(rows))
    feasible = [f and c for f, c in zip(feasible, converged, strict=True)]
    keep = [not r for r in su2_side.repeats(folder, len(rows))]      # a design SU2's restart made again: not counted
    pick = lambda xs: [x for x, k in zip(xs, keep, strict=True) if k]   # noqa: E731
    return trace_of(label, [1] * sum(keep), pick(su2_adjoints(folder, len(rows))), pick([r["CD"] for r in rows]),
                    pick(feasible), tool="SU2", unconverged=pick(converged).count(False))


def best_so_far(t: Trace) -> np.ndarray:
    """(k,) the lowest feasible drag among designs 1..k (inf before the first feasible one)."""
    return np.minimum.accumulate(np.where(t.feasible & np.isfinite(t.objective), t.objective, np.inf))


def best(t: Trace) -> tuple[float, int] | None:
    """(the best feasible drag, the solves at which it was known), None when no design is feasible."""
    b = best_so_far(t)
    if not len(b) or not np.isfinite(b[-1]):
        return None
    k = int(np.argmax(b == b[-1]))
    return float(b[-1]), int(t.solves[k])


def solves_to_reach(t: Trace, target: float) -> int | None:
    """The solves at which ``t`` first had a feasible design with drag <= ``target``; None if never."""
    hit = np.flatnonzero(best_so_far(t) <= target)
    return int(t.solves[hit[0]]) if len(hit) else None


def summary(traces: list[Trace], baseline: float | None = None) -> str:
    """Per run: solves and best feasible drag; per pair of runs of the two tools: the solves each took to
    reach the other's best."""
    lines = []
    for t in traces:
        b = best(t)
        cut = "" if b is None or baseline is None else f" ({100 * (1 - b[0] / baseline):.1f} % below {baseline:.6g})"
        stalled = f" ({t.unconverged} flows not converged: counted infeasible)" if t.unconverged else ""
        lines.append(f"{t.label}: {len(t.objective)} designs, {t.total} solves{stalled}; best feasible "
                     + ("none" if b is None else f"{b[0]:.6g} after {b[1]} solves{cut}"))
    for t in traces:
        for u in traces:
            if t.tool == u.tool or best(u) is None:
                continue
            n = solves_to_reach(t, best(u)[0])
            lines.append(f"{t.label} reaches {u.label}'s best ({best(u)[0]:.6g}): "
                         + (f"after {n} solves" if n is not None else f"not reached in {t.total} solves"))
    return "\n".join(lines)


def y_limits(traces: list[Trace], baseline: float | None = None, pad: float = 0.08) -> tuple[float, float]:
    """The drag range the picture shows: the feasible designs' and the baseline's, widened to every
    design within that range's own width of it, padded by ``pad``; a design further out (a flow that did
    not converge, say) is drawn at the edge."""
    vals = [t.objective[t.feasible & np.isfinite(t.objective)] for t in traces]
    vals.append(np.array([] if baseline is None else [baseline]))
    v = np.concatenate(vals)
    every = np.concatenate([t.objective[np.isfinite(t.objective)] for t in traces])
    if not len(v):
        v = every
    lo, hi = float(v.min()), float(v.max())
    span = hi - lo if hi > lo else max(abs(hi), 1e-12)
    near = every[(every >= lo - span) & (every <= hi + span)]
    lo, hi = min(lo, float(near.min(initial=lo))), max(hi, float(near.max(initial=hi)))
    return lo - pad * (hi - lo), hi + pad * (hi - lo)


def plot(traces: list[Trace], path: Path, title: str, baseline: float | None = None, scale: float = 1.0,
         unit: str = "CD") -> None:
    """Every design (filled when feasible) and the best feasible so far (steps) against the solves; a
    design outside :func:`y_limits` is drawn at the edge as a triangle pointing to where it lies."""
    fig, ax = plt.subplots(figsize=(8, 4.8))
    lo, hi = (scale * v for v in y_limits(traces, baseline))
    outside = 0
    for i, t in enumerate(traces):
        c = f"C{i}"
        y = scale * t.objective
        inside = (y >= lo) & (y <= hi)
        ax.plot(t.solves[t.feasible & inside], y[t.feasible & inside], "o", color=c, ms=5)
        ax.plot(t.solves[~t.feasible & inside], y[~t.feasible & inside], "o", mfc="none", mec=c, ms=5)
        for mask, edge, marker in ((y < lo, lo, "v"), (y > hi, hi, "^")):
            ax.plot(t.solves[mask], np.full(int(mask.sum()), edge), marker, mfc="none", mec=c, ms=7, clip_on=False)
            outside += int(mask.sum())
        b = best_so_far(t)
        ok = np.isfinite(b)
        xs = np.append(t.solves[ok], t.total)
        ax.step(xs, scale * np.append(b[ok], b[ok][-1]) if ok.any() else np.full(len(xs), np.nan), where="post",
                color=c, lw=1.6, label=f"{t.label} ({t.total} solves)")
    ax.plot([], [], "o", color="0.3", ms=5, label="a feasible design (line: the best so far)")
    ax.plot([], [], "o", mfc="none", mec="0.3", ms=5, label="an infeasible design")
    if outside:
        ax.plot([], [], "v", mfc="none", mec="0.3", ms=7, label=f"{outside} design(s) off the scale (infeasible)")
    if baseline is not None:
        ax.axhline(scale * baseline, color="0.5", lw=0.8, ls="--", label="baseline")
    ax.set_ylim(lo, hi)
    ax.set_xlabel("flow + adjoint solves")
    ax.set_ylabel(unit)
    ax.set_title(title, fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="upper right")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.adodg.race", description=__doc__.split("\n")[0])
    ap.add_argument("--case", type=int, choices=(1, 2, 3), required=True)
    ap.add_argument("--ffd", type=Path, action="append", default=[], metavar="RUN", help="an ffd run folder (repeat)")
    ap.add_argument("--su2", type=Path, action="append", default=[], metavar="FOLDER",
                    help="an SU2 shape_optimization.py folder (repeat)")
    ap.add_argument("--label", action="append", default=[],
                    help="labels, ffd runs first then SU2's (default: the folders' names)")
    ap.add_argument("--baseline", type=Path, help="Case 1: the optimisation mesh (the rule's baseline wall)")
    ap.add_argument("--out", type=Path, help="the picture (PNG); none without it")
    a = ap.parse_args(argv)
    if not a.ffd and not a.su2:
        ap.error("give at least one --ffd or --su2 folder")
    folders = [*a.ffd, *a.su2]
    if a.label and len(a.label) != len(folders):
        ap.error(f"{len(a.label)} --label for {len(folders)} folders")
    labels = a.label or [f"ffd {p.name}" for p in a.ffd] + [f"SU2 {p.name}" for p in a.su2]
    try:
        traces = [ffd_trace(p, TOLERANCE[a.case], lab) for p, lab in zip(a.ffd, labels, strict=False)]
        traces += [su2_trace(a.case, p, lab, a.baseline) for p, lab in zip(a.su2, labels[len(a.ffd):], strict=True)]
    except (RaceError, OSError, KeyError, ValueError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    empty = [t.label for t in traces if not len(t.objective)]
    if empty:
        print(f"error: no finished design in {', '.join(empty)}", file=sys.stderr)
        return 2
    baseline = float(traces[0].objective[0])
    print(summary(traces, baseline))
    if a.out is not None:
        a.out.parent.mkdir(parents=True, exist_ok=True)
        scale, unit = (1e4, "CD (counts)") if a.case == 2 else (1.0, "CD")
        plot(traces, a.out, TITLES[a.case], baseline, scale, unit)
        print(a.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
