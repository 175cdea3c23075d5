"""SU2's own optimiser on ADODG Case 1, beside ``ffd optimize``: same mesh, same flow settings.

``shape_optimization.py`` (SU2 8.1's script: SLSQP, discrete adjoint ``SU2_CFD_AD``, mesh moved by
``SU2_DEF``'s linear elasticity) on the optimisation mesh L2 with ``configs/adodg/case1.cfg``'s flow
settings (JST, implicit Euler, multigrid, every flow and adjoint solve to an rms residual of 1e-12:
``CONV_FIELD= (RMS_DENSITY, RMS_ADJ_DENSITY)``, each program ignores the other's field) and the
optimiser settings of SU2's own ``inv_NACA0012_basic`` tutorial (objective ``DRAG * 0.001``, its
mesh-deformation keys), at most 30 SLSQP iterations like ffd's design files, with

* ``ffd``: SU2's FFD box (``FFD_SETTING`` embedded by ``SU2_DEF``): ffd's 16-variable lattice's
  rectangle (2 % of the chord around the airfoil: x -0.02 ... 1.02, y -0.08 ... 0.08), Bezier, degree
  (8, 1): 9 x 2 control points; the 16 ``FFD_CONTROL_POINT_2D`` variables move the control points of
  the 8 columns ahead of the trailing edge in y (the trailing-edge column stays put, as in ffd's
  file), bounds +-0.1 chord as ffd's. SU2 cannot state the add-material rule for it: the closest it
  can state are SU2_GEO's 2-D functions, ``AIRFOIL_THICKNESS`` (the maximum thickness) and
  ``AIRFOIL_AREA`` at least the baseline's (SU2_GEO in 2-D has no thickness at given stations: its
  functions are AREA, THICKNESS, CHORD, LE_RADIUS, TOC and ALPHA). Both are necessary, not sufficient.
* ``hh``: 18 Hicks-Henne bumps (``HICKS_HENNE``, 9 on each surface at x = 0.1 ... 0.9, SU2's bump
  width exponent), amplitudes bounded to [0, 0.1] chord. A Hicks-Henne bump is non-negative and
  SU2 moves the upper surface up and the lower down for a positive amplitude (checked with SU2_DEF),
  so these bounds state the add-material rule exactly (a sufficient condition: designs that add
  material with a bump of negative amplitude are excluded); no geometric constraint is needed.

    python -m benchmarks.adodg.su2_side setup ffd --mesh out/adodg/adodg_L2.su2 --folder out/adodg/su2_ffd
    python -m benchmarks.adodg.su2_side run out/adodg/su2_ffd          # hours on L2; nice -n 5
    python -m benchmarks.adodg.su2_side report out/adodg/su2_ffd --baseline out/adodg/adodg_L2.su2

``setup`` writes ``config.cfg`` and the mesh into the folder (for ``ffd`` it runs ``SU2_DEF`` to embed
the box: ``mesh_ffd.su2``); ``run`` starts SU2's script there (``optimizer.log``, ``run.json`` with the
wall time when it ends); ``report`` reads ``history_project.csv`` and the ``DESIGNS`` folders: flow and
adjoint solves, CD, SU2_GEO's functions, the best feasible design, and the add-material rule checked at
every wall node of that design's mesh (:mod:`benchmarks.adodg.surface`).
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from benchmarks.adodg.surface import add_material, wall_nodes
from ffdcli.io.formats import read_mesh
from ffdcli.optimize.solvers.base import find_program
from ffdcli.optimize.solvers.su2 import cauchy_only, config_value, read_config, read_history, with_keys

ROOT = Path(__file__).resolve().parents[2]
CONFIG = ROOT / "configs" / "adodg" / "case1.cfg"
SEARCH = (ROOT.parent / "shared" / "su2" / "bin",)
ITERATIONS = 30
BOUND = 0.1
BOX = (-0.02, 1.02, -0.08, 0.08)          # ffd's automatic 2-D lattice on these meshes (margin 0.02 chord)
FFD_COLUMNS, FFD_FREE = 9, 8              # Bezier degree 8: 9 columns, the trailing-edge one fixed
HH_STATIONS = tuple(round(0.1 * k, 1) for k in range(1, 10))
TOLERANCE = 1e-6                          # the case's constraint tolerance, chords


def su2_bin() -> Path:
    """The folder of SU2's programs and scripts (``SU2_RUN``, ``PATH``, ``../shared/su2/bin``)."""
    program = find_program("SU2_CFD", "SU2_RUN", SEARCH)
    if program is None:
        raise RuntimeError("SU2 not found: set SU2_RUN or put SU2_CFD on PATH")
    return Path(program).resolve().parent


def su2_env() -> dict:
    """Environment for SU2's programs and its Python scripts."""
    b = str(su2_bin())
    return {**os.environ, "SU2_RUN": b, "PATH": f"{b}:{os.environ.get('PATH', '')}", "PYTHONPATH": b,
            "OMP_NUM_THREADS": "1"}


def ffd_definition(box: tuple[float, float, float, float] = BOX) -> str:
    """``FFD_DEFINITION`` of the 2-D box: corners counter-clockwise from (x0, y0), z = 0."""
    x0, x1, y0, y1 = box
    corners = [(x0, y0), (x1, y0), (x1, y1), (x0, y1)]
    return "(BOX, " + ", ".join(f"{x:g}, {y:g}, 0.0" for x, y in corners) + ", " + ", ".join(["0.0"] * 12) + ")"


def ffd_variables() -> str:
    """``DEFINITION_DV``: the control points of the free columns, lower row then upper, moving in y."""
    return "; ".join(f"( 19, 1.0 | airfoil | BOX, {i}, {j}, 0.0, 1.0 )" for j in (0, 1) for i in range(FFD_FREE))


def hh_variables() -> str:
    """``DEFINITION_DV``: Hicks-Henne bumps, lower surface (0) then upper (1), at ``HH_STATIONS``."""
    return "; ".join(f"( 30, 1.0 | airfoil | {side}, {x:g} )" for side in (0, 1) for x in HH_STATIONS)


def config_keys(param: str, mesh_name: str, thickness: float, area: float) -> dict[str, str]:
    """The keys added to (or replaced in) ``case1.cfg`` for SU2's optimiser with ``param``."""
    keys = {
        "MESH_FILENAME": mesh_name,
        "CONV_FIELD": "(RMS_DENSITY, RMS_ADJ_DENSITY)",
        "OUTPUT_FILES": "(RESTART, SURFACE_CSV)",
        "DV_MARKER": "( airfoil )",
        "GEO_MARKER": "( airfoil )", "GEO_DESCRIPTION": "AIRFOIL", "GEO_MODE": "FUNCTION",
        "DEFORM_LINEAR_SOLVER_ITER": "500", "DEFORM_NONLINEAR_ITER": "1", "DEFORM_CONSOLE_OUTPUT": "YES",
        "DEFORM_LINEAR_SOLVER_ERROR": "1E-14", "DEFORM_STIFFNESS_TYPE": "INVERSE_VOLUME",
        "OPT_OBJECTIVE": "DRAG * 0.001",
        "OPT_ITERATIONS": str(ITERATIONS), "OPT_ACCURACY": "1E-10",
    }
    if param == "ffd":
        keys.update({
            "DV_KIND": "FFD_SETTING", "DV_PARAM": "( 1.0 )", "DV_VALUE": "0.0",
            "FFD_DEFINITION": ffd_definition(), "FFD_DEGREE": f"({FFD_COLUMNS - 1}, 1, 0)",
            "FFD_CONTINUITY": "USER_INPUT", "FFD_TOLERANCE": "1E-10", "FFD_ITERATIONS": "500",
            "OPT_CONSTRAINT": f"( AIRFOIL_THICKNESS > {thickness:.6g} ) * 1.0; ( AIRFOIL_AREA > {area:.6g} ) * 1.0",
            "OPT_BOUND_UPPER": f"{BOUND:g}", "OPT_BOUND_LOWER": f"{-BOUND:g}",
            "DEFINITION_DV": ffd_variables(),
        })
    elif param == "hh":
        keys.update({
            "DV_KIND": "HICKS_HENNE", "DV_PARAM": "( 1, 0.5 )", "DV_VALUE": "0.0",
            "OPT_CONSTRAINT": "NONE",
            "OPT_BOUND_UPPER": f"{BOUND:g}", "OPT_BOUND_LOWER": "0.0",
            "DEFINITION_DV": hh_variables(),
        })
    else:
        raise ValueError(f"parameterization {param!r}: expected 'ffd' or 'hh'")
    return keys


def run_program(args: list[str], folder: Path, log: str) -> None:
    """Run an SU2 program in ``folder`` under nice -n 5; raise with the log's path on failure."""
    with open(folder / log, "w") as fh:
        rc = subprocess.run(["nice", "-n", "5", *args], cwd=folder, stdout=fh, stderr=subprocess.STDOUT,
                            env=su2_env()).returncode
    if rc != 0:
        raise RuntimeError(f"{args[0]} failed (exit {rc}): see {folder / log}")


def geometry(folder: Path, mesh_name: str, config: Path = CONFIG, marker: str = "airfoil") -> dict[str, float]:
    """SU2_GEO's 2-D functions of ``folder/mesh_name`` (AIRFOIL_AREA, AIRFOIL_THICKNESS, ...), its wall
    ``marker``, with ``config``'s other keys (Case 1's by default)."""
    text = with_keys(read_config(config), {"MESH_FILENAME": mesh_name, "GEO_MARKER": f"( {marker} )",
                                           "GEO_DESCRIPTION": "AIRFOIL", "GEO_MODE": "FUNCTION",
                                           "VALUE_OBJFUNC_FILENAME": "of_func.csv"})
    (folder / "geo.cfg").write_text(text)
    run_program([str(su2_bin() / "SU2_GEO"), "geo.cfg"], folder, "geo.log")
    with open(folder / "of_func.csv") as fh:
        rows = list(csv.reader(fh))
    return {k.strip().strip('"'): float(v) for k, v in zip(rows[0], rows[1])}


def setup(param: str, mesh: Path, folder: Path) -> Path:
    """Write ``folder/config.cfg`` (and the mesh; for ``ffd`` the mesh with SU2's box embedded)."""
    folder.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(mesh, folder / "mesh.su2")
    geo = geometry(folder, "mesh.su2")
    mesh_name = "mesh.su2"
    keys = config_keys(param, mesh_name, geo["AIRFOIL_THICKNESS"], geo["AIRFOIL_AREA"])
    if param == "ffd":
        box = with_keys(read_config(CONFIG), {**keys, "MESH_OUT_FILENAME": "mesh_ffd.su2"})
        (folder / "box.cfg").write_text(box)
        run_program([str(su2_bin() / "SU2_DEF"), "box.cfg"], folder, "box.log")
        keys["MESH_FILENAME"] = mesh_name = "mesh_ffd.su2"
    (folder / "config.cfg").write_text(with_keys(read_config(CONFIG), keys))
    (folder / "baseline_geometry.json").write_text(json.dumps(geo, indent=1))
    return folder / "config.cfg"


def run(folder: Path, resume: bool = False) -> float:
    """``shape_optimization.py -g DISCRETE_ADJOINT -o SLSQP -f config.cfg`` in ``folder``; wall seconds.

    With ``resume`` and a ``project.pkl`` from an earlier piece, SU2's own restart (``-r project.pkl``):
    its project answers every design it already holds from its cache (a design is found when its
    variables equal the requested ones exactly), so SLSQP, which is deterministic, retraces the earlier
    piece without a solve and goes on from where it stopped; a design whose adjoint was cut short
    solves that adjoint again. Each piece's wall time is kept in ``run.json`` (``pieces``).
    """
    cmd = [sys.executable, str(su2_bin() / "shape_optimization.py"), "-g", "DISCRETE_ADJOINT", "-o", "SLSQP",
           "-f", "config.cfg"]
    pieces = []
    if resume and (folder / "project.pkl").is_file():
        cmd += ["-r", "project.pkl"]
        old = folder / "run.json"
        pieces = json.loads(old.read_text()).get("pieces", []) if old.is_file() else []
    t0 = time.time()
    (folder / "run.json").unlink(missing_ok=True)
    with open(folder / "optimizer.log", "a" if resume else "w") as fh:
        rc = subprocess.run(["nice", "-n", "5", *cmd], cwd=folder, stdout=fh, stderr=subprocess.STDOUT,
                            env=su2_env()).returncode
    wall = time.time() - t0
    pieces.append({"start": t0, "wall": wall, "rc": rc})
    (folder / "run.json").write_text(json.dumps({"rc": rc, "wall": sum(p["wall"] for p in pieces), "start": t0,
                                                 "command": cmd[1:], "pieces": pieces}))
    return wall


def _dsn_number(p: Path) -> int:
    m = re.search(r"(\d+)$", p.name)
    return int(m.group(1)) if m else -1


def designs(folder: Path) -> list[Path]:
    """The run's ``DESIGNS/DSN_*`` folders in creation order."""
    return sorted((folder / "DESIGNS").glob("DSN_*"), key=_dsn_number)


def run_state(folder: Path) -> tuple[dict | None, float]:
    """A run's ``run.json`` (None while it runs or after it was stopped) and its wall seconds: the pieces'
    sum when finished, else from ``config.cfg``'s time to the newest design folder or log."""
    meta = folder / "run.json"
    state = json.loads(meta.read_text()) if meta.is_file() else None
    log = folder / "optimizer.log"
    start = os.path.getmtime(folder / "config.cfg")
    wall = state["wall"] if state else (max(os.path.getmtime(p) for p in [log, *designs(folder)]) - start
                                        if log.is_file() else 0.0)
    return state, wall


def project_rows(folder: Path) -> list[dict[str, float]]:
    """``history_project.csv``: one row per design whose flow finished, in order."""
    path = folder / "history_project.csv"
    if not path.is_file():
        return []
    with open(path, newline="") as fh:
        rows = list(csv.reader(fh))
    head = [h.strip().strip('"') for h in rows[0]]
    return [{h: float(v) for h, v in zip(head, r)} for r in rows[1:] if r]


def finished_adjoints(dsn: Path) -> int:
    """The adjoints SU2 finished for a design folder ``DSN_k``: its ``ADJOINT_<FUNCTION>`` folders holding
    a gradient file (``of_grad*.csv``, written by SU2_DOT after the adjoint converged)."""
    return sum(1 for a in Path(dsn).glob("ADJOINT_*") if list(a.glob("of_grad*.csv")))


#: Two of SU2's designs whose variables differ by no more than this (each, in its units) are one design.
SAME_DESIGN = 1e-12


def repeats(folder: Path, n: int) -> list[bool]:
    """Whether each of SU2's designs 1..n repeats an earlier one (every ``DV_VALUE_NEW`` within
    :data:`SAME_DESIGN`). SU2's restart (``-r project.pkl``) replays SLSQP, whose designs can come back
    different in the last bit; its project reuses a design only at distance 0.0, so it makes such a
    design again with its flow and adjoints. A run not stopped would not have: the reports do not count
    those solves against SU2 (they say how many there were)."""
    seen: list[np.ndarray] = []
    out = []
    for k in range(n):
        cfg = Path(folder) / "DESIGNS" / f"DSN_{k + 1:03d}" / "config_DSN.cfg"
        raw = config_value(read_config(cfg), "DV_VALUE_NEW") if cfg.is_file() else None
        if raw is None:
            out.append(False)
            continue
        x = np.array([float(v) for v in raw.replace(";", ",").split(",") if v.strip()])
        out.append(any(len(y) == len(x) and np.abs(y - x).max() <= SAME_DESIGN for y in seen))
        seen.append(x)
    return out


def flow_converged(folder: Path, n: int) -> list[bool]:
    """Whether each of SU2's designs 1..n has a flow that reached the configuration's
    ``CONV_RESIDUAL_MINVAL`` (the last ``rms[Rho]`` of ``DESIGNS/DSN_k/DIRECT/history_direct.csv``):
    SU2's scripts take a flow stopped at ``ITER`` short of it as a value; ffd counts such a flow a failed
    evaluation. Without ``config.cfg``, its key or a design's history: True (nothing to judge by)."""
    cfg = Path(folder) / "config.cfg"
    lines = read_config(cfg) if cfg.is_file() else []
    minval = config_value(lines, "CONV_RESIDUAL_MINVAL")
    if not minval or cauchy_only(lines):             # a coefficient's Cauchy criterion: no residual to judge
        return [True] * n
    out = []
    for k in range(n):
        path = Path(folder) / "DESIGNS" / f"DSN_{k + 1:03d}" / "DIRECT" / "history_direct.csv"
        rho = read_history(path).get("rms[Rho]") if path.is_file() else None
        out.append(not rho or rho[-1] <= float(minval) + 1e-9)
    return out


def design_mesh(dsn: Path) -> Path | None:
    """The mesh a design's flow ran on: ``DIRECT/``'s mesh (the deformed one), else the design folder's."""
    for sub in (dsn / "DIRECT", dsn):
        found = sorted(sub.glob("*.su2"))
        if found:
            return found[0]
    return None


def report(folder: Path, baseline: Path) -> dict:
    """What a (finished or running) run reached: solves, designs with CD and SU2_GEO's functions, the
    rule at every wall node of each design's mesh, the best design by SU2's constraints and by the rule."""
    folder = Path(folder)
    cfg = read_config(folder / "config.cfg")
    geo = json.loads((folder / "baseline_geometry.json").read_text())
    constrained = "AIRFOIL_THICKNESS" in (next((ln for ln in cfg if ln.startswith("OPT_CONSTRAINT")), ""))
    base = read_mesh(baseline)
    ids = wall_nodes(base)
    adjoints = 0
    rows = []
    table = project_rows(folder)
    flows = len(table)
    again = repeats(folder, len(table))
    # finished only: a flow's row in history_project.csv, an adjoint's gradient
    for k, dsn in enumerate(designs(folder)):
        if not (k < len(again) and again[k]):
            adjoints += finished_adjoints(dsn)
    flows -= sum(again)
    converged = flow_converged(folder, len(table))
    for k, row in enumerate(table):
        dsn = folder / "DESIGNS" / f"DSN_{k + 1:03d}"
        mesh = design_mesh(dsn)
        margin = None
        if mesh is not None:
            m = add_material(base.points[ids, :2], read_mesh(mesh).points[ids, :2])
            margin = {"upper": m.upper, "lower": m.lower, "thickness": m.thickness}
        tc, area = row.get("AIRFOIL_THICKNESS", np.nan), row.get("AIRFOIL_AREA", np.nan)
        su2_ok = (not constrained) or (tc >= geo["AIRFOIL_THICKNESS"] - TOLERANCE
                                       and area >= geo["AIRFOIL_AREA"] - TOLERANCE)
        rows.append({"design": dsn.name, "CD": row["DRAG"], "CL": row["LIFT"], "thickness": tc, "area": area,
                     "converged": converged[k], "su2_constraints_met": bool(su2_ok), "rule": margin,
                     "rule_met": margin is not None and min(margin["upper"], margin["lower"]) >= -TOLERANCE,
                     "repeat": again[k]})

    def best(key: str):
        ok = [r for r in rows if r[key] and r["converged"]]
        return min(ok, key=lambda r: r["CD"]) if ok else None

    state, wall = run_state(folder)
    b0 = rows[0]["CD"] if rows else None
    out = {"folder": str(folder), "finished": state is not None, "rc": None if state is None else state["rc"],
           "flow_solves": flows, "adjoint_solves": adjoints, "repeated_designs": sum(again), "designs": rows,
           "wall": wall, "baseline_CD": b0, "best_su2": best("su2_constraints_met"), "best_rule": best("rule_met"),
           "baseline_geometry": {"AIRFOIL_THICKNESS": geo["AIRFOIL_THICKNESS"], "AIRFOIL_AREA": geo["AIRFOIL_AREA"]}}
    return out


def repeated_line(rep: dict) -> str:
    """The words a report adds when SU2's restart made designs again (:func:`repeats`), else nothing."""
    n = rep.get("repeated_designs", 0)
    return (f" (not counting {n} design{'s' if n != 1 else ''} SU2's restart made again, equal to earlier ones "
            "to the last bits, with their solves)") if n else ""


def summary(rep: dict) -> str:
    """Plain-text lines of a report."""
    lines = [f"{rep['folder']}: {'finished (exit ' + str(rep['rc']) + ')' if rep['finished'] else 'RUNNING'}, "
             f"{rep['flow_solves']} flow + {rep['adjoint_solves']} adjoint solves, {rep['wall']:.0f} s wall"
             + repeated_line(rep)]
    for r in rep["designs"]:
        m = r["rule"]
        rule = "-" if m is None else f"{min(m['upper'], m['lower']):+.2e}"
        stalled = "" if r.get("converged", True) else "  FLOW NOT CONVERGED (no result)"
        lines.append(f"  {r['design']}: CD {r['CD']:.6f}  t {r['thickness']:.6f}  area {r['area']:.7f}  "
                     f"SU2 constraints {'met' if r['su2_constraints_met'] else 'NOT met'}  "
                     f"rule margin {rule} ({'met' if r['rule_met'] else 'VIOLATED'}){stalled}")
    b0 = rep["baseline_CD"]
    for key, what in (("best_su2", "by SU2's own constraints"), ("best_rule", "meeting the add-material rule")):
        r = rep[key]
        lines.append(f"best {what}: " + ("none" if r is None else
                     f"{r['design']} CD {r['CD']:.6f} ({100 * (1 - r['CD'] / b0):.1f} % below {b0:.6f})"))
    return "\n".join(lines)


def side_parser(prog: str, description: str, setup_help: str,
                report_help: str) -> tuple[argparse.ArgumentParser, argparse.ArgumentParser, argparse.ArgumentParser]:
    """The ``setup | run | report`` command line every SU2 side-by-side module shares: ``setup --mesh
    --folder``, ``run FOLDER [--resume]``, ``report FOLDER [--json]``. Returns the parser and the
    ``setup`` and ``report`` sub-parsers, for a case's own arguments."""
    ap = argparse.ArgumentParser(prog=prog, description=description)
    sub = ap.add_subparsers(dest="command", required=True)
    s = sub.add_parser("setup", help=setup_help)
    s.add_argument("--mesh", type=Path, required=True)
    s.add_argument("--folder", type=Path, required=True)
    r = sub.add_parser("run", help="run shape_optimization.py in FOLDER (set up first)")
    r.add_argument("folder", type=Path)
    r.add_argument("--resume", action="store_true",
                   help="go on from an earlier piece's project.pkl (SU2's -r: designs it holds are not solved again)")
    p = sub.add_parser("report", help=report_help)
    p.add_argument("folder", type=Path)
    p.add_argument("--json", action="store_true")
    return ap, s, p


def dispatch(args: argparse.Namespace, setup_of, report_of, summary_of) -> int:
    """Carry out a command parsed by :func:`side_parser` and print its result: ``setup_of(args)``, the
    run (:func:`run`), or ``report_of(args)`` as JSON or through ``summary_of``. Returns the exit code."""
    if args.command == "setup":
        mesh = getattr(args, "mesh", None)
        if mesh is not None and not Path(mesh).is_file():
            print(f"error: --mesh {mesh}: no such file; give the baseline mesh (the ADODG meshes are built by "
                  "`python -m benchmarks.adodg.meshes`, `case2_meshes` and `case3_meshes`)", file=sys.stderr)
            return 2
        print(setup_of(args))
    elif args.command in ("run", "report") and not (Path(args.folder) / "config.cfg").is_file():
        print(f"error: {args.folder} has no config.cfg: run `setup --mesh MESH --folder {args.folder}` first",
              file=sys.stderr)
        return 2
    elif args.command == "run":
        print(f"{run(args.folder, args.resume):.0f} s")
    else:
        rep = report_of(args)
        print(json.dumps(rep, indent=1) if args.json else summary_of(rep))
    return 0


def main(argv: list[str] | None = None) -> int:
    ap, s, p = side_parser("python -m benchmarks.adodg.su2_side", __doc__.split("\n")[0],
                           "write config.cfg and the mesh into FOLDER",
                           "solves, CD, constraints and the add-material rule of a run")
    s.add_argument("param", choices=["ffd", "hh"])
    p.add_argument("--baseline", type=Path, required=True, help="the baseline mesh the run started from")
    return dispatch(ap.parse_args(argv), lambda a: setup(a.param, a.mesh, a.folder),
                    lambda a: report(a.folder, a.baseline), summary)


if __name__ == "__main__":
    sys.exit(main())
