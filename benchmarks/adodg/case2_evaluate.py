"""An ADODG Case 2 optimum evaluated on the finer C-mesh of the same section, with the run's own lattice.

The optimum of ``ffd optimize configs/adodg/case2.yaml`` (SU2's RAE2822 RANS mesh, 13,937 points, first
cell 1e-5 chord) is applied to ``rae2822_s1`` (ffd's C-mesh of the same section, 74,593 points, first
cell 1e-6 chord) and solved there, as :mod:`benchmarks.adodg.evaluate` does for Case 1:

* **the lattice**: the run's automatic lattice is written to a Plot3D file (``ffd box --export-plot3d``)
  and the evaluation's design files name it as ``box.file`` (an automatic box fitted to the finer mesh
  would take its extent from that mesh's wall, a different lattice). Checked by rebuilding the run's own
  mesh of that evaluation from the file: ``lattice_error``, the largest wall-node difference (0 to
  rounding);
* **the shape on the finer mesh**: the two walls share almost no node (the finer wall is a spline
  through the run mesh's 192 wall nodes), so the deformed finer wall is compared with the optimum by
  its displacement: at each finer wall node, the displacement of the run's wall (the evaluation's mesh
  minus the baseline, a cubic spline along the run wall's arc length) at the node's place on the run's
  wall, against the finer mesh's own displacement (``shape_error``, within the interpolation's own error
  bound ``shape_tolerance``, :func:`interpolation_bound`);
  at the nodes the walls share (``common_nodes``) exactly. ``section_gap``: how far the finer baseline
  wall lies from the run's wall (the spline between the nodes);
* **the boundary layer** of the deformed finer mesh: ``ffd deform``'s report (first cell after / before,
  the off-wall angle's change, the quality gate: an inverted cell is refused) and ``ffd check`` of the
  written mesh (first-cell heights, off-wall angles, the worst scaled Jacobian);
* **the area** of the deformed finer section over its baseline's (the constraint is area >= 1);
* **SU2_CFD** (:mod:`benchmarks.adodg.case2_solve`, ``case2.cfg``'s numerics): the undeformed finer mesh
  (the baseline on that level, in ``WORK/baseline/{alpha,cl}``, reused when already solved) and the
  design (``WORK/eNNNN/{alpha,cl}``, warm-started from the baseline's solution), each at alpha 2.79 and
  in SU2's fixed-CL mode at CL 0.824; CD, CL, CM(c/4) nose-up positive, iterations, residual, converged
  (and by which criterion), CPU seconds; the drag reduction at CL 0.824 beside the run's.

    python -m benchmarks.adodg.case2_evaluate --design configs/adodg/case2.yaml --run out/adodg/case2 \\
        --mesh out/adodg/rae2822_s1.su2 --work out/adodg/case2_s1 [--evaluation N] [--no-solve]

Without ``--evaluation`` the run's best evaluation by ffd's rule (the lowest CD among the finished
evaluations within the feasibility tolerance, else the least violating: ``best.yaml``'s rule, read from
``history.csv`` so that a run still going is read as it stands). Writes ``WORK/eNNNN/evaluation.json``.
Run it without an outer ``nice``: SU2 is started under ``nice -n 10`` here.
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
from pathlib import Path

import numpy as np
from scipy.interpolate import CubicSpline
from scipy.spatial import cKDTree

from benchmarks.adodg.case2_meshes import wall_loop
from benchmarks.adodg.case2_solve import SolveError, reuse_or_solve
from benchmarks.adodg.evaluate import design_data, export_lattice, ffd, load_yaml, run_mesh_of, write_yaml
from ffdcli.io.formats import read_mesh
from ffdcli.testing.naca import polygon_area

#: the floor of the shape check's tolerance (chords): rounding, where the run's displacement is a field
#: the spline reproduces exactly (see :func:`interpolation_bound`)
SHAPE_FLOOR = 1e-10
MATCH = 1e-10              # two walls share a node within this distance (chords)
#: the run mesh's baseline CD at CL 0.824 (SU2's fixed-CL mode on rae2822_su2, docs/adodg-case2.md)
RUN_BASELINE_CL_CD = {"rae2822_su2": 0.020935}


class EvaluationError(Exception):
    """A missing run, mesh or evaluation: one line for the user."""


def history_rows(run: Path) -> list[dict]:
    """The finished rows of the run's ``history.csv``. Raises EvaluationError when there is none."""
    path = Path(run) / "history.csv"
    if not path.is_file():
        raise EvaluationError(f"--run {run}: no history.csv there; give the folder of an `ffd optimize` run "
                              "(its optimize.folder)")
    with open(path, newline="") as fh:
        rows = [r for r in csv.DictReader(fh) if not r.get("failed")]
    if not rows:
        raise EvaluationError(f"{path}: no finished evaluation yet")
    return rows


def pick_row(run: Path, feasibility: float, evaluation: int | None = None) -> dict:
    """The history row of evaluation ``evaluation``, or the run's best by ffd's rule (the lowest
    objective within ``feasibility``, else the least violating), with ``values`` (every design value,
    ``ffd vars`` order) from its ``result.json`` and ``feasible``. Raises EvaluationError."""
    rows = history_rows(run)
    if evaluation is not None:
        hit = [r for r in rows if int(r["evaluation"]) == evaluation]
        if not hit:
            done = ", ".join(r["evaluation"] for r in rows)
            raise EvaluationError(f"--evaluation {evaluation}: not a finished evaluation of {run} "
                                  f"(finished: {done})")
        row = hit[0]
    else:
        ok = [r for r in rows if float(r["violation"]) <= feasibility]
        row = (min(ok, key=lambda r: (float(r["objective"]), int(r["evaluation"]))) if ok else
               min(rows, key=lambda r: (float(r["violation"]), float(r["objective"]))))
    folder = Path(run) / row["folder"]
    if not (folder / "result.json").is_file():
        raise EvaluationError(f"{folder}: no result.json; the evaluation's files are needed")
    values = [float(v) for v in json.loads((folder / "result.json").read_text())["values"]]
    return {**row, "values": values, "feasible": float(row["violation"]) <= feasibility}


def marker_named(mesh, name: str) -> str:
    """The marker of ``mesh`` called ``name`` in any case (SU2's mesh says AIRFOIL, ffd's C-meshes airfoil)."""
    hit = [m for m in mesh.markers if m.lower() == name.lower()]
    if not hit:
        raise EvaluationError(f"the mesh has no marker {name!r} (markers: {', '.join(mesh.markers)})")
    return hit[0]


def wall(mesh_path: Path, marker: str) -> tuple[np.ndarray, np.ndarray]:
    """(ids (n,), xy (n, 2)) of the wall loop of ``marker`` (any case) in Selig order."""
    mesh = read_mesh(mesh_path)
    ids = wall_loop(mesh, marker_named(mesh, marker))
    return ids, mesh.points[ids, :2]


def project(points: np.ndarray, loop: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Nearest points of ``points`` (m, 2) on the closed polyline ``loop`` (n, 2; the last segment
    returns to the first node): (segment k (m,), fraction t in [0, 1] along it (m,), distance (m,))."""
    a = loop
    ab = np.roll(loop, -1, axis=0) - a
    rel = points[:, None, :] - a[None, :, :]                              # (m, n, 2)
    t = np.clip(np.einsum("mnj,nj->mn", rel, ab) / np.einsum("nj,nj->n", ab, ab)[None], 0.0, 1.0)
    d2 = np.einsum("mnj,mnj->mn", rel - t[..., None] * ab[None], rel - t[..., None] * ab[None])
    k = np.argmin(d2, axis=1)
    rows = np.arange(len(points))
    return k, t[rows, k], np.sqrt(d2[rows, k])


def wall_spline(loop: np.ndarray, values: np.ndarray) -> tuple[CubicSpline, np.ndarray]:
    """The cubic spline (not-a-knot) through ``values`` (n, k) at the nodes of the closed wall ``loop``
    (n, 2), in the loop's cumulative chord length from the first node round to it again (the
    parameter ffd's C-meshes resample a section in, :func:`ffdcli.testing.cmesh.cmesh`); and that
    parameter at the nodes (n + 1,)."""
    closed = np.vstack([loop, loop[:1]])
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(closed, axis=0), axis=1))])
    return CubicSpline(s, np.vstack([values, values[:1]]), axis=0), s


def locate(points: np.ndarray, loop: np.ndarray, newton: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """The parameter (m,) of the nearest point to each of ``points`` (m, 2) on the section's spline
    through the closed wall ``loop`` (n, 2) (:func:`wall_spline`), and the distance (m,) to it: the
    polyline's nearest point refined by Newton steps on the squared distance."""
    curve, s = wall_spline(loop, loop)
    k, t, _ = project(points, loop)
    u = s[k] + t * np.diff(s)[k]
    d1, d2 = curve.derivative(1), curve.derivative(2)
    for _ in range(newton):
        r, c1 = curve(u) - points, d1(u)
        hess = np.einsum("mj,mj->m", c1, c1) + np.einsum("mj,mj->m", r, d2(u))
        u = np.clip(u - np.einsum("mj,mj->m", r, c1) / np.where(hess > 0, hess, 1.0), 0.0, s[-1])
    return u, np.linalg.norm(curve(u) - points, axis=1)


def interpolation_bound(loop: np.ndarray, disp: np.ndarray) -> float:
    """The shape check's tolerance (chords): how well the run's displacement ``disp`` (n, 2), known at
    its wall nodes ``loop`` (n, 2) only, is known between them. The spline through every other node
    misses the nodes left out by ``e2`` (measured); the spline through all of them, at half that
    spacing, misses by about ``e2 / 8`` (third order: the FFD's cubic B-spline has jumps in its third
    derivative at the knots); the tolerance is ``e2 / 4``, not below :data:`SHAPE_FLOOR`."""
    closed = np.vstack([loop, loop[:1]])
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(closed, axis=0), axis=1))])
    even, odd = np.arange(0, len(loop), 2), np.arange(1, len(loop), 2)
    half = CubicSpline(np.append(s[even], s[-1]), np.vstack([disp[even], disp[:1]]), axis=0)
    e2 = float(np.linalg.norm(half(s[odd]) - disp[odd], axis=1).max())
    return max(e2 / 4.0, SHAPE_FLOOR)


def shape_check(base_run: np.ndarray, des_run: np.ndarray, base_fine: np.ndarray, des_fine: np.ndarray) -> dict:
    """The deformed finer wall against the run's optimum (module docstring): the walls' loops (n, 2),
    (m, 2) before and after. Each finer node is located on the section's spline through the run's wall
    nodes (``section_gap``: the largest distance from it) and the run's displacement, splined the same
    way, is read there: ``shape_error`` is the largest difference from the finer node's own
    displacement, judged against :func:`interpolation_bound`; ``common_error`` the largest at the nodes
    the walls share (exact there)."""
    u, gap = locate(base_fine, base_run)
    expect = wall_spline(base_run, des_run - base_run)[0](u)
    err = np.linalg.norm((des_fine - base_fine) - expect, axis=1)
    tol = interpolation_bound(base_run, des_run - base_run)
    dist, near = cKDTree(base_run).query(base_fine)
    shared = dist <= MATCH
    common = np.linalg.norm(des_fine[shared] - des_run[near[shared]], axis=1)
    return {"shape_error": float(err.max()), "shape_tolerance": tol, "shape_ok": bool(err.max() <= tol),
            "worst_at": base_fine[int(np.argmax(err))].tolist(),
            "common_nodes": int(shared.sum()), "common_error": float(common.max()) if common.size else None,
            "section_gap": float(gap.max()), "wall_nodes": int(len(base_fine)),
            "max_displacement": float(np.linalg.norm(des_fine - base_fine, axis=1).max())}


def gate(q: dict) -> dict:
    """The quality gate's figures of ``ffd deform``'s or ``ffd check``'s JSON (the worst-cell lists left
    out): cells, inverted, the worst scaled Jacobian before and after, the worst orthogonality (degrees)
    before and after, passed or not, and the wall layer (first cells, off-wall angles) when present."""
    orth = q.get("orthogonality") or {}
    return {"cells": q.get("cells"), "inverted": q.get("inverted"), "min_before": q.get("min_before"),
            "min_after": q.get("min_after"), "orthogonality_before": orth.get("min_before"),
            "orthogonality_after": orth.get("min_after"), "ok": q.get("ok"), "wall_layer": q.get("wall_layer")}


def area_ratio(base: np.ndarray, design: np.ndarray) -> float:
    """Area enclosed by the wall loop ``design`` (n, 2) over the baseline's ``base`` (n, 2)."""
    return polygon_area(design) / polygon_area(base)


def fine_design(design: Path, mesh: Path, marker: str, values: list[float], names: list[str], box_file: Path,
                output: Path) -> dict:
    """The design file's data on the finer ``mesh`` with the lattice of ``box_file`` and ``values``."""
    data = design_data(design, mesh, values=values, names=names, box_file=box_file, output=output)
    data["surface"] = marker
    return data


def check_inputs(design: Path, run: Path, mesh: Path) -> None:
    """Raise EvaluationError for a missing design file, run or mesh (before anything is written)."""
    if not Path(design).is_file():
        raise EvaluationError(f"--design {design}: no such file")
    if not Path(mesh).is_file():
        raise EvaluationError(f"--mesh {mesh}: no such file; build it with "
                              "`python -m benchmarks.adodg.case2_meshes --out out/adodg`")
    history_rows(run)


def evaluate(design: Path, run: Path, mesh: Path, work: Path, *, evaluation: int | None = None,
             run_solve: bool = True, iterations: int = 3000, multigrid: int | None = None,
             cfl: float | None = None) -> dict:
    """Evaluate an evaluation of the run on ``mesh``; see the module docstring. Returns the summary,
    also written to ``WORK/eNNNN/evaluation.json``."""
    design, run, mesh = Path(design), Path(run), Path(mesh).resolve()
    check_inputs(design, run, mesh)
    data = load_yaml(design)
    run_mesh = (design.parent / data["mesh"]).resolve()
    if not run_mesh.is_file():
        raise EvaluationError(f"{design}: its mesh {run_mesh} does not exist")
    row = pick_row(run, float((data.get("optimize") or {}).get("feasibility", 1e-4)), evaluation)
    n = int(row["evaluation"])
    marker = marker_named(read_mesh(mesh), data.get("surface", "airfoil"))
    names = [v["name"] for v in ffd("vars", str(design))["variables"]]
    folder = Path(work) / f"e{n:04d}"
    folder.mkdir(parents=True, exist_ok=True)
    cache = str(Path(work) / "cache")
    xyz = export_lattice(design, run_mesh, folder)
    base_row = pick_row(run, 1e-4, 1) if any(int(r["evaluation"]) == 1 for r in history_rows(run)) else None
    out: dict = {"design": str(design), "run": str(run), "evaluation": n, "feasible": row["feasible"],
                 "violation": float(row["violation"]), "run_mesh": str(run_mesh), "mesh": str(mesh),
                 "lattice_file": str(xyz), "values": dict(zip(names, row["values"], strict=True)),
                 "run_result": {"cd": float(row["objective"]), "cl": float(row["LIFT"]),
                                "cm": -float(row["MOMENT_Z"]), "area_ratio": float(row.get("k0.volume") or "nan")}}

    # the run's own mesh rebuilt from the lattice file: the evaluation's wall to rounding?
    own = folder / "run_mesh_rebuilt.su2"
    ffd("deform", str(write_yaml(folder / "design_run_mesh.yaml",
                                 design_data(design, run_mesh, values=row["values"], names=names, box_file=xyz,
                                             output=own))), "--cache-dir", cache)
    run_marker = data.get("surface", "airfoil")
    ids_run, base_run = wall(run_mesh, run_marker)
    run_best, out["run_mesh_rebuilt"] = run_mesh_of(design, run, row["folder"], row["values"], names, folder)
    des_run = read_mesh(run_best).points[ids_run, :2]
    out["lattice_error"] = float(np.abs(read_mesh(own).points[ids_run, :2] - des_run).max())

    # the finer mesh with the same lattice
    fine = folder / "mesh.su2"
    rep = ffd("deform", str(write_yaml(folder / "design_fine.yaml",
                                       fine_design(design, mesh, marker, row["values"], names, xyz, fine))),
              "--cache-dir", cache)
    ids_f, base_f = wall(mesh, marker)
    des_f = read_mesh(fine).points[ids_f, :2]
    out.update(shape_check(base_run, des_run, base_f, des_f))
    out["deform"] = {"quality": gate(rep.get("quality") or {}), "wall_layer": rep.get("wall_layer"),
                     "max_displacement": rep.get("max_displacement"), "seconds": rep.get("seconds")}
    out["check"] = gate(ffd("check", str(fine)))
    out["area_ratio"] = area_ratio(base_f, des_f)
    out["area_ratio_run_mesh"] = area_ratio(base_run, des_run)

    if run_solve:
        kw = {"iterations": iterations, "multigrid": multigrid, "cfl": cfl}
        # the two alpha solves first: a sitting stopped before the fixed-CL ones still compares the pair
        b_alpha = reuse_or_solve(mesh, "alpha", Path(work) / "baseline" / "alpha", **kw)
        d_alpha = reuse_or_solve(fine.resolve(), "alpha", folder / "alpha",
                                 restart=Path(work) / "baseline" / "alpha" / "restart_flow.dat", **kw)
        b_cl = reuse_or_solve(mesh, "cl", Path(work) / "baseline" / "cl",
                              restart=Path(work) / "baseline" / "alpha" / "restart_flow.dat", **kw)
        # the design's fixed-CL solve starts from its alpha solution, unless that solve diverged (its restart,
        # written every 50 iterations, then holds the diverged state): then from the baseline's alpha solution
        start = folder / "alpha" if finished(d_alpha) else Path(work) / "baseline" / "alpha"
        d_cl = reuse_or_solve(fine.resolve(), "cl", folder / "cl", restart=start / "restart_flow.dat", **kw)
        out["baseline"] = {"alpha": b_alpha, "cl": b_cl}
        out["solves"] = {"alpha": d_alpha, "cl": d_cl}
        out["reduction"] = {c: 1.0 - out["solves"][c]["cd"] / out["baseline"][c]["cd"] for c in ("alpha", "cl")
                            if finished(out["solves"][c]) and finished(out["baseline"][c])}
    out["reduction_run"] = {}
    if base_row is not None:
        out["reduction_run"]["alpha"] = 1.0 - float(row["objective"]) / float(base_row["objective"])
    if run_mesh.stem in RUN_BASELINE_CL_CD:
        out["reduction_run"]["cl"] = 1.0 - float(row["objective"]) / RUN_BASELINE_CL_CD[run_mesh.stem]
    (folder / "evaluation.json").write_text(json.dumps(out, indent=1))
    return out


def finished(solve: dict) -> bool:
    """Whether a solve ended without diverging (SU2's exit code 0, a finite residual): its coefficients are
    its last iteration's, converged or not by the criterion."""
    return solve["rc"] == 0 and bool(np.isfinite(solve["residual"]))


def solve_line(label: str, s: dict) -> str:
    """One solve as a line of text."""
    return (f"  {label:<22} CD {1e4 * s['cd']:7.1f} counts  CL {s['cl']:.5f}  CM(c/4) {s['cm']:+.5f}  "
            f"alpha {'?' if s['alpha'] is None else format(s['alpha'], '.4f')}  {s['iterations']} it, "
            f"rms[Rho] {s['residual']:.2f}, "
            f"{'converged' if s['converged'] else 'NOT converged'} ({s['criterion']}), {s['cpu']:.0f} s CPU")


def summary(out: dict) -> str:
    """Plain-text lines of an evaluation."""
    r, d = out["run_result"], out["deform"]
    wl = d.get("wall_layer") or {}
    lines = [f"evaluation {out['evaluation']} of {out['run']} ({'feasible' if out['feasible'] else 'INFEASIBLE'}, "
             f"worst violation {out['violation']:.1e}): CD {1e4 * r['cd']:.1f} counts, CL {r['cl']:.5f}, "
             f"CM(c/4) {r['cm']:+.5f}, area ratio {r['area_ratio']:.5f} on the run's mesh",
             f"lattice: the run's mesh rebuilt from {Path(out['lattice_file']).name} to {out['lattice_error']:.1e}",
             f"finer wall ({out['wall_nodes']} nodes): displacement equal to the optimum's to {out['shape_error']:.1e} "
             f"(tolerance {out['shape_tolerance']:.1e}; {out['common_nodes']} shared nodes); the finer baseline "
             f"within {out['section_gap']:.1e} of the run's wall",
             f"area ratio on the finer mesh {out['area_ratio']:.6f} (run's mesh {out['area_ratio_run_mesh']:.6f})"]
    q = d["quality"]
    lines.append(f"quality gate: {q['cells']} cells, {q['inverted']} inverted, worst scaled Jacobian "
                 f"{q['min_before']:.4f} -> {q['min_after']:.4f}, worst orthogonality "
                 f"{q['orthogonality_before']:.2f} -> "
                 f"{q['orthogonality_after']:.2f} deg: {'passed' if q['ok'] else 'FAILED'}")
    if wl:
        lines.append(f"boundary layer: first cell after / before {wl.get('ratio_min', float('nan')):.4f} to "
                     f"{wl.get('ratio_max', float('nan')):.4f} at {wl.get('n_wall')} wall nodes, off-wall angle "
                     f"changed by up to {wl.get('angle_change', float('nan')):.2f} deg")
    cwl = (out.get("check") or {}).get("wall_layer") or {}
    if cwl:
        lines.append(f"ffd check: first cell {cwl['height_min']:.3g} to {cwl['height_max']:.3g}, off-wall angle up "
                     f"to {cwl['angle_max']:.2f} deg")
    red = out.get("reduction_run", {})
    lines.append("run's mesh: drag reduction " + ", ".join(f"{100 * v:.1f} % at {k}" for k, v in red.items()))
    if "solves" in out:
        for cond in ("alpha", "cl"):
            lines.append(solve_line(f"baseline, {cond}", out["baseline"][cond]))
            lines.append(solve_line(f"evaluation {out['evaluation']}, {cond}", out["solves"][cond]))
        lines.append("finer mesh: drag reduction " + ", ".join(f"{100 * v:.1f} % at {k}"
                                                               for k, v in out["reduction"].items()))
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.adodg.case2_evaluate", description=__doc__.split("\n")[0])
    ap.add_argument("--design", type=Path, required=True, help="the run's design file (configs/adodg/case2.yaml)")
    ap.add_argument("--run", type=Path, required=True, help="the run's folder (optimize.folder: history.csv, evals/)")
    ap.add_argument("--mesh", type=Path, required=True, help="the finer mesh (out/adodg/rae2822_s1.su2)")
    ap.add_argument("--work", type=Path, required=True, help="where to write (baseline/ and eNNNN/)")
    ap.add_argument("--evaluation", type=int, help="this evaluation of the run instead of its best")
    ap.add_argument("--iterations", type=int, default=3000, help="SU2's ITER for each solve (default 3000)")
    ap.add_argument("--multigrid", type=int, help="SU2's MGLEVEL for the solves instead of case2.cfg's 3")
    ap.add_argument("--cfl", type=float, help="a fixed CFL for the solves instead of case2.cfg's adapted one")
    ap.add_argument("--no-solve", action="store_true", help="the lattice, shape, boundary-layer and area checks only")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    try:
        out = evaluate(args.design, args.run, args.mesh, args.work, evaluation=args.evaluation,
                       run_solve=not args.no_solve, iterations=args.iterations, multigrid=args.multigrid,
                       cfl=args.cfl)
    except (EvaluationError, SolveError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    print(json.dumps(out, indent=1) if args.json else summary(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
