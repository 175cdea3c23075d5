"""SU2's own optimiser on ADODG Case 2 (RAE2822, RANS SA), beside ``ffd optimize``: same mesh, same flow.

``shape_optimization.py`` (SU2 8.1's script: SLSQP, discrete adjoint ``SU2_CFD_AD`` with the SA model
differentiated, mesh moved by ``SU2_DEF``'s linear elasticity) on SU2's RAE2822 RANS mesh (the mesh
``configs/adodg/case2.cfg`` names, 13,937 points), starting from SU2's own RAE2822 RANS design case
(``TestCases/optimization_rans/steady_rae2822/turb_SA_RAE2822.cfg``: ``OPT_OBJECTIVE= DRAG * 0.001``, a
lift constraint scaled by 0.001, SLSQP) with Case 2's problem and ``case2.cfg``'s flow in place of
that case's (M 0.729, alpha 2.31, ``LIFT > 0.723``, 38 Hicks-Henne bumps, continuous adjoint):

* **the box**: SU2's FFD box (``FFD_SETTING`` embedded by ``SU2_DEF``) on ffd's 24-variable lattice's
  rectangle (ffd's automatic 13 x 2 lattice on this mesh spans x -0.02001 ... 1.02001 and y -0.0778 ...
  0.0844, margins 0.02 chord; rounded outward here), Bezier degree (12, 1): 13 x 2 control points;
  the 24 ``FFD_CONTROL_POINT_2D`` variables move the control points of the 12 columns ahead of the
  trailing edge in y (the trailing-edge column stays put, as in ffd's file), bounds +-0.05 chord as
  ffd's. The bases differ (SU2: one Bezier curve of degree 12 along the chord; ffd: a cubic B-spline),
  the count, extent and bounds are the same.
* **the constraints**: ``LIFT = 0.824`` (an equality, as ffd's file), ``MOMENT_Z < 0.092`` (CM(c/4) >=
  -0.092 in SU2's sign, positive nose-down, as ffd's file) and ``AIRFOIL_AREA > A0`` (SU2_GEO's area of
  the baseline, measured at setup), each scaled by 0.001 as SU2's RAE2822 case scales its lift. alpha
  2.79 deg held, as ffd's run (SU2's example holds alpha too).
* **the flow**: ``case2.cfg`` (JST, SA, 3-level W multigrid, M 0.734, Re 6.5e6, rms[Rho] 1e-8), with one
  change: the CFL fixed at 50 (``CFL_ADAPT= NO``) instead of adapted from 10 to 50. SU2's script runs
  the flow and the adjoint from one configuration, and SU2_CFD_AD started at CFL 10 with adaptation
  does not converge on this mesh (``ffdcli/optimize/solvers/su2_settings.py``), while at a fixed 50 the
  cold flow reaches -8 in about 240 iterations and the DRAG adjoint in about 350. Every design's flow
  starts cold (``RESTART_SOL= NO``, as SU2's script sets it), converged to -8 as ffd's cold flow; each
  adjoint to rms[Rho_adj] 1e-8 (``CONV_FIELD= (RMS_DENSITY, RMS_ADJ_DENSITY)``: each program ignores
  the other's field). At most 30 SLSQP iterations, as ffd's file.

    python -m benchmarks.adodg.case2_meshes --out out/adodg
    python -m benchmarks.adodg.su2_side_case2 setup --mesh out/adodg/rae2822_su2.su2 --folder out/adodg/su2_case2
    nice -n 5 python -m benchmarks.adodg.su2_side_case2 run out/adodg/su2_case2       # hours; nice -n 5
    nice -n 5 python -m benchmarks.adodg.su2_side_case2 run out/adodg/su2_case2 --resume   # the next piece
    python -m benchmarks.adodg.su2_side_case2 report out/adodg/su2_case2

``setup`` writes ``config.cfg`` and ``mesh_ffd.su2`` (the mesh with SU2's box embedded by ``SU2_DEF``)
and ``baseline_geometry.json`` (SU2_GEO's functions of the baseline); ``run`` starts SU2's script there
(``optimizer.log``; ``run.json`` with the wall time when it ends; ``--resume`` goes on from SU2's own
``project.pkl``, :func:`benchmarks.adodg.su2_side.run`); ``report`` reads
``history_project.csv`` and the ``DESIGNS`` folders: flow and adjoint solves, CD, CL, CMz, area, each
design's constraints at the case's tolerance (1e-4), the best feasible design.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from benchmarks.adodg.su2_side import (
    designs,
    dispatch,
    ffd_definition,
    finished_adjoints,
    flow_converged,
    geometry,
    project_rows,
    repeated_line,
    repeats,
    run_program,
    run_state,
    side_parser,
    su2_bin,
)
from ffdcli.optimize.solvers.su2 import read_config, with_keys

ROOT = Path(__file__).resolve().parents[2]
CONFIG = ROOT / "configs" / "adodg" / "case2.cfg"
MARKER = "AIRFOIL"                        # SU2's RAE2822 RANS mesh's wall marker
ITERATIONS = 30
BOUND = 0.05                              # chords, as configs/adodg/case2.yaml
BOX = (-0.0201, 1.0201, -0.0779, 0.0845)  # ffd's 13 x 2 lattice on SU2's mesh, rounded outward to 1e-4
FFD_COLUMNS, FFD_FREE = 13, 12            # Bezier degree 12: 13 columns, the trailing-edge one fixed
TARGET_CL, MAX_CMZ = 0.824, 0.092         # CL = 0.824; CM(c/4) >= -0.092 is SU2's CMz <= 0.092
SCALE = 0.001                             # SU2's RAE2822 RANS design case's scale of DRAG and LIFT
CFL = 50.0                                # fixed, for the flow and SU2_CFD_AD alike (module docstring)
TOLERANCE = 1e-4                          # the case's constraint tolerance (CL, CM, area)


def ffd_variables(free: int = FFD_FREE) -> str:
    """``DEFINITION_DV``: the control points of the ``free`` columns ahead of the trailing edge, upper
    row (j = 1) then lower (j = 0), as ffd's variable order (``c0.shape.upper[0..11]``, then lower),
    each moving in y by its value in chords."""
    return "; ".join(f"( 19, 1.0 | {MARKER} | BOX, {i}, {j}, 0.0, 1.0 )" for j in (1, 0) for i in range(free))


def constraints(area: float) -> str:
    """``OPT_CONSTRAINT``: the lift equality, the moment bound and the area of the baseline (SU2_GEO's)."""
    return (f"( LIFT = {TARGET_CL:g} ) * {SCALE:g}; ( MOMENT_Z < {MAX_CMZ:g} ) * {SCALE:g}; "
            f"( AIRFOIL_AREA > {area:.7g} ) * {SCALE:g}")


def config_keys(mesh_name: str, area: float) -> dict[str, str]:
    """The keys added to (or replaced in) ``case2.cfg`` for SU2's optimiser on Case 2."""
    return {
        "MESH_FILENAME": mesh_name,
        "CFL_NUMBER": f"{CFL:g}", "CFL_ADAPT": "NO",
        "RESTART_SOL": "NO",
        "CONV_FIELD": "(RMS_DENSITY, RMS_ADJ_DENSITY)", "CONV_RESIDUAL_MINVAL": "-8",
        "OUTPUT_FILES": "(RESTART, SURFACE_CSV)",
        "DV_MARKER": f"( {MARKER} )",
        "GEO_MARKER": f"( {MARKER} )", "GEO_DESCRIPTION": "AIRFOIL", "GEO_MODE": "FUNCTION",
        "DEFORM_LINEAR_SOLVER_ITER": "500", "DEFORM_NONLINEAR_ITER": "1", "DEFORM_CONSOLE_OUTPUT": "YES",
        "DEFORM_LINEAR_SOLVER_ERROR": "1E-14", "DEFORM_STIFFNESS_TYPE": "INVERSE_VOLUME",
        "DV_KIND": "FFD_SETTING", "DV_PARAM": "( 1.0 )", "DV_VALUE": "0.0",
        "FFD_DEFINITION": ffd_definition(BOX), "FFD_DEGREE": f"({FFD_COLUMNS - 1}, 1, 0)",
        "FFD_CONTINUITY": "USER_INPUT", "FFD_TOLERANCE": "1E-10", "FFD_ITERATIONS": "500",
        "OPT_OBJECTIVE": f"DRAG * {SCALE:g}",
        "OPT_CONSTRAINT": constraints(area),
        "OPT_BOUND_UPPER": f"{BOUND:g}", "OPT_BOUND_LOWER": f"{-BOUND:g}",
        "OPT_ITERATIONS": str(ITERATIONS), "OPT_ACCURACY": "1E-10",
        "DEFINITION_DV": ffd_variables(),
    }


def setup(mesh: Path, folder: Path) -> Path:
    """Write ``folder/config.cfg``, ``mesh.su2``, ``mesh_ffd.su2`` (SU2's box embedded) and the baseline's
    SU2_GEO functions (``baseline_geometry.json``)."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "mesh.su2").write_bytes(Path(mesh).read_bytes())
    geo = geometry(folder, "mesh.su2", CONFIG, MARKER)
    keys = config_keys("mesh.su2", geo["AIRFOIL_AREA"])
    box = with_keys(read_config(CONFIG), {**keys, "MESH_OUT_FILENAME": "mesh_ffd.su2"})
    (folder / "box.cfg").write_text(box)
    run_program([str(su2_bin() / "SU2_DEF"), "box.cfg"], folder, "box.log")
    keys["MESH_FILENAME"] = "mesh_ffd.su2"
    head = ("% SU2's shape_optimization.py on ADODG Case 2 (benchmarks/adodg/su2_side_case2.py): case2.cfg with\n"
            "% the optimiser's keys below and the CFL fixed at 50 for the flow and SU2_CFD_AD alike (the\n"
            "% comments of case2.cfg that follow describe ffd's run, which adapts the flow's CFL).\n")
    (folder / "config.cfg").write_text(head + with_keys(read_config(CONFIG), keys))
    (folder / "baseline_geometry.json").write_text(json.dumps(geo, indent=1))
    return folder / "config.cfg"


def feasible(row: dict[str, float], area0: float, tol: float = TOLERANCE) -> bool:
    """Case 2's constraints at the tolerance: |CL - 0.824| <= tol, CMz <= 0.092 + tol, area >= A0 - tol."""
    return (abs(row["LIFT"] - TARGET_CL) <= tol and row["MOMENT_Z"] <= MAX_CMZ + tol
            and row.get("AIRFOIL_AREA", float("nan")) >= area0 - tol)


def report(folder: Path) -> dict:
    """What a (finished or running) run reached: solves, each design's CD, CL, CMz (SU2's sign), area and
    constraints, the best feasible design, the wall time."""
    folder = Path(folder)
    area0 = json.loads((folder / "baseline_geometry.json").read_text())["AIRFOIL_AREA"]
    table = project_rows(folder)
    again = repeats(folder, len(table))
    adjoints = sum(finished_adjoints(dsn) for k, dsn in enumerate(designs(folder))
                   if not (k < len(again) and again[k]))
    converged = flow_converged(folder, len(table))
    rows = [{"design": f"DSN_{k + 1:03d}", "CD": r["DRAG"], "CL": r["LIFT"], "CMz": r["MOMENT_Z"],
             "area": r.get("AIRFOIL_AREA", float("nan")), "converged": converged[k],
             "feasible": converged[k] and feasible(r, area0), "repeat": again[k]} for k, r in enumerate(table)]
    ok = [r for r in rows if r["feasible"]]
    state, wall = run_state(folder)
    return {"folder": str(folder), "finished": state is not None, "rc": None if state is None else state["rc"],
            "flow_solves": len(table) - sum(again), "adjoint_solves": adjoints, "repeated_designs": sum(again),
            "designs": rows, "wall": wall,
            "baseline_CD": rows[0]["CD"] if rows else None, "baseline_area": area0,
            "best": min(ok, key=lambda r: r["CD"]) if ok else None}


def summary(rep: dict) -> str:
    """Plain-text lines of a report."""
    lines = [f"{rep['folder']}: {'finished (exit ' + str(rep['rc']) + ')' if rep['finished'] else 'RUNNING'}, "
             f"{rep['flow_solves']} flow + {rep['adjoint_solves']} adjoint solves, {rep['wall']:.0f} s wall"
             + repeated_line(rep)]
    for r in rep["designs"]:
        lines.append(f"  {r['design']}: CD {r['CD']:.6f}  CL {r['CL']:.5f}  CMz {r['CMz']:+.5f}  area {r['area']:.7f}  "
                     f"{'feasible' if r['feasible'] else 'infeasible'}"
                     f"{'  (a repeat: not counted)' if r.get('repeat') else ''}"
                     f"{'' if r.get('converged', True) else ' (FLOW NOT CONVERGED: no result)'}")
    b0, best = rep["baseline_CD"], rep["best"]
    lines.append("best feasible: " + ("none" if best is None else
                 f"{best['design']} CD {best['CD']:.6f} ({100 * (1 - best['CD'] / b0):.1f} % below {b0:.6f})"))
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap, _, _ = side_parser("python -m benchmarks.adodg.su2_side_case2", __doc__.split("\n")[0],
                           "write config.cfg and the mesh with SU2's box into FOLDER",
                           "solves, CD, CL, CMz, area and the constraints of a run")
    return dispatch(ap.parse_args(argv), lambda a: setup(a.mesh, a.folder), lambda a: report(a.folder), summary)


if __name__ == "__main__":
    sys.exit(main())
