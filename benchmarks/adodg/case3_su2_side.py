"""SU2's own optimiser on ADODG Case 3, beside ``ffd optimize``: same mesh, same flow, same twist lattice.

``shape_optimization.py`` (SU2 8.1: SLSQP, the discrete adjoints of DRAG and LIFT by ``SU2_CFD_AD``, the
mesh moved by ``SU2_DEF``'s linear elasticity) on the mesh of ``configs/adodg/case3.yaml`` with
``configs/adodg/case3.cfg``'s flow settings (M 0.5, alpha 4.85 deg fixed, every flow and adjoint solve to
an rms residual of 1e-10: ``CONV_FIELD= (RMS_DENSITY, RMS_ADJ_DENSITY)``, each program ignoring the
other's field, as ffd's adjoints converge to ``RMS_ADJ_DENSITY``), and:

* **SU2's FFD box on ffd's lattice**: the wing marker's bounding box grown by ffd's margin (2 % of the
  chord ahead, behind, below and above the wing), from the root (the symmetry plane) to the wing's
  outermost point (the tip cap) in span; ``FFD_BLENDING= BSPLINE_UNIFORM`` with ``FFD_BSPLINE_ORDER=
  (4, 4, 2)`` and ``FFD_DEGREE= (3, 8, 1)``: 4 x 9 x 2 control points of a clamped uniform cubic B-spline
  spanwise, which is ffd's automatic lattice for ``box.points: [4, 9, 2]`` (degrees 3, 3, 1; control
  sections equally spaced from the root to the tip), so the 9 spanwise control sections sit at the same
  stations as ffd's 9 twists.
* **9 ``FFD_TWIST`` variables** ``( 15, 1.0 | wing | BOX, j, x_te, y0, z_te, x_te, y1, z_te )``, j = 0 ... 8:
  SU2 (``CSurfaceMovement::SetFFDTwist``) turns every control point of the box's j-th spanwise plane
  about the line parallel to the span axis (y) through the point where the given segment crosses that
  plane; the segment here is the trailing-edge line (x = the wing's largest x, z = the trailing edge's z),
  so each plane turns about its trailing-edge point, ffd's axis. The root plane (j = 0) is free, as ffd's
  root twist: with alpha fixed, the root's twist about the trailing-edge line plays the angle of attack
  (docs/adodg-case3.md).
* **The angle.** SU2's twist angle is ``atan(value / REF_LENGTH)`` (REF_LENGTH 1 here): a value is the
  tangent of the angle, not degrees. ffd's bounds of +-8 deg are ``OPT_BOUND_UPPER/LOWER= +-tan(8 deg)``.
* ``OPT_CONSTRAINT= ( LIFT = 0.375 ) * 1.0`` (an equality; factor 1 because SU2's scripts scale a
  constraint's value by its factor but not its gradient, ``SU2/eval/design.py``), ``OPT_OBJECTIVE=
  DRAG * 0.1`` (the scale of SU2's own 3-D wing tutorial ``inv_ONERAM6_basic.cfg``), at most 20 SLSQP
  iterations like ffd's ``case3.yaml``, ``OPT_ACCURACY= 1E-10`` (the tutorial's).

::

    python -m benchmarks.adodg.case3_su2_side setup --mesh out/adodg3/case3_L1.su2 --folder out/adodg3/su2_twist
    python -m benchmarks.adodg.case3_su2_side run out/adodg3/su2_twist             # hours on L1; nice -n 5
    python -m benchmarks.adodg.case3_su2_side report out/adodg3/su2_twist [--cd0 CD0] [--json]

``setup`` writes ``config.cfg`` and ``box.json`` (the box, the stations, the axis) and runs ``SU2_DEF`` to
embed the box (``mesh_ffd.su2``); ``run`` is :func:`benchmarks.adodg.su2_side.run` (``optimizer.log``,
``run.json`` with the wall time when it ends; ``run --resume`` goes on from ``project.pkl`` after a
piece was stopped); ``report`` reads ``history_project.csv`` and the
``DESIGNS`` folders: flow and adjoint solves as SU2 logs them, CD, CL and the twists of every design,
and for the baseline and the best design (CL within :data:`CL_TOLERANCE` of 0.375, least CD) the span load
against the ellipse and the span efficiency (:mod:`benchmarks.adodg.case3_report`).
"""

from __future__ import annotations

import json
import math
import re
import shutil
import sys
from pathlib import Path

import numpy as np

from benchmarks.adodg.case3_report import report as load_report
from benchmarks.adodg.su2_side import (
    design_mesh,
    designs,
    dispatch,
    finished_adjoints,
    flow_converged,
    project_rows,
    run_program,
    side_parser,
    su2_bin,
)
from ffdcli.io.formats import read_mesh
from ffdcli.optimize.solvers.su2 import config_value, read_config, with_keys

ROOT = Path(__file__).resolve().parents[2]
CONFIG = ROOT / "configs" / "adodg" / "case3.cfg"
WING = "wing"
SECTIONS = 9                      # ffd's box.points[1] in case3.yaml: 9 spanwise control sections
CHORDWISE = 4                     # ffd's box.points[0]
MARGIN = 0.02                     # ffd's automatic lattice's clearance, fraction of the chord
TIP_PAD = 1e-5                    # the outboard face this far (chords) beyond the wing's outermost node
BOUND_DEG = 8.0                   # ffd's c0.twist bounds, degrees
ITERATIONS = 20                   # ffd's optimize.iterations in case3.yaml
CL_TARGET = 0.375
CL_TOLERANCE = 1e-4               # the goal for the lift equality
OBJECTIVE_SCALE = 0.1             # SU2's inv_ONERAM6_basic.cfg: OPT_OBJECTIVE= DRAG * 0.1
STRIPS = 24


def wing_box(points: np.ndarray, margin: float = MARGIN) -> dict:
    """SU2's box around the wing's points (W, 3): chord x, span y (root at the smallest y), thickness z.

    Returns ``{"x": (x0, x1), "y": (y0, y1), "z": (z0, z1), "te": (x_te, z_te), "chord": c}``: the bounding
    box grown by ``margin * chord`` in x and z; in span the root face lies on the symmetry plane (the
    smallest y) and the outboard face at the wing's outermost point, where ffd's lattice ends, plus
    :data:`TIP_PAD` chords (SU2_DEF counted the one node exactly on that face outside the box on L1, not
    on L0); and the trailing-edge point (the largest x; its z, the mean of the points there)."""
    lo, hi = points.min(axis=0), points.max(axis=0)
    chord = float(hi[0] - lo[0])
    at_te = points[:, 0] >= hi[0] - 1e-9 * chord
    te = (float(hi[0]), float(points[at_te, 2].mean()))
    m = margin * chord
    return {"x": (float(lo[0] - m), float(hi[0] + m)), "y": (float(lo[1]), float(hi[1] + TIP_PAD * chord)),
            "z": (float(lo[2] - m), float(hi[2] + m)), "te": te, "chord": chord}


def stations(box: dict, n: int = SECTIONS) -> np.ndarray:
    """(n,) span positions of the box's control sections: equally spaced from root to tip (SU2 and ffd)."""
    return np.linspace(box["y"][0], box["y"][1], n)


def ffd_definition(box: dict) -> str:
    """``FFD_DEFINITION``: the 8 corners, the lower face (z0) counter-clockwise from (x0, y0) then the upper
    face (z1): i runs along the chord, j along the span, k through the thickness (SU2's ONERA M6 order)."""
    (x0, x1), (y0, y1), (z0, z1) = box["x"], box["y"], box["z"]
    face = [(x0, y0), (x1, y0), (x1, y1), (x0, y1)]
    corners = [(x, y, z) for z in (z0, z1) for x, y in face]
    return "(BOX, " + ", ".join(f"{x:.10g}, {y:.10g}, {z:.10g}" for x, y, z in corners) + ")"


def twist_variables(box: dict, n: int = SECTIONS) -> str:
    """``DEFINITION_DV``: ``FFD_TWIST`` (kind 15) of each spanwise plane j = 0 ... n - 1, about the
    trailing-edge line, given as a segment reaching one chord past either end of the box (SU2 finds each
    plane's axis point where the segment crosses it: the segment must cross every plane)."""
    (y0, y1), (xt, zt), c = box["y"], box["te"], box["chord"]
    axis = f"{xt:.10g}, {y0 - c:.10g}, {zt:.10g}, {xt:.10g}, {y1 + c:.10g}, {zt:.10g}"
    return "; ".join(f"( 15, 1.0 | {WING} | BOX, {j}, {axis} )" for j in range(n))


def angle_to_value(degrees: float, ref_length: float = 1.0) -> float:
    """SU2's ``FFD_TWIST`` value for an angle: the angle is ``atan(value / REF_LENGTH)``."""
    return ref_length * math.tan(math.radians(degrees))


def value_to_angle(value, ref_length: float = 1.0):
    """Degrees of SU2's ``FFD_TWIST`` value(s)."""
    return np.degrees(np.arctan(np.asarray(value, dtype=float) / ref_length))


#: SU2_DEF's stiffness models offered to ``setup --stiffness``. The tutorial's ``INVERSE_VOLUME`` is the
#: default (the L0-L2 runs use it); on the hybrid H0, whose far tetrahedra are large and soft, its
#: elasticity stops at the 800-iteration cap and moves the symmetry plane by chords for a wall move of
#: 0.02 chord, while ``WALL_DISTANCE`` converges in about 100 iterations (docs/adodg-case3.md).
STIFFNESS = ("INVERSE_VOLUME", "WALL_DISTANCE", "CONSTANT_STIFFNESS")


def config_keys(mesh_name: str, box: dict, stiffness: str = "INVERSE_VOLUME") -> dict[str, str]:
    """The keys added to (or replaced in) ``case3.cfg`` for SU2's optimiser (``stiffness``: SU2_DEF's
    ``DEFORM_STIFFNESS_TYPE``, one of :data:`STIFFNESS`)."""
    if stiffness not in STIFFNESS:
        raise ValueError(f"stiffness {stiffness!r}: expected one of {', '.join(STIFFNESS)}")
    bound = angle_to_value(BOUND_DEG)
    return {
        "MESH_FILENAME": mesh_name,
        "CONV_FIELD": "(RMS_DENSITY, RMS_ADJ_DENSITY)",
        "OUTPUT_FILES": "(RESTART, SURFACE_CSV)",
        "DV_MARKER": f"( {WING} )",
        "DV_KIND": "FFD_SETTING", "DV_PARAM": "( 1.0 )", "DV_VALUE": "0.0",
        "FFD_DEFINITION": ffd_definition(box),
        "FFD_DEGREE": f"({CHORDWISE - 1}, {SECTIONS - 1}, 1)",
        "FFD_BLENDING": "BSPLINE_UNIFORM", "FFD_BSPLINE_ORDER": "(4, 4, 2)",
        "FFD_CONTINUITY": "USER_INPUT", "FFD_TOLERANCE": "1E-10", "FFD_ITERATIONS": "500",
        "DEFORM_LINEAR_SOLVER": "FGMRES", "DEFORM_LINEAR_SOLVER_PREC": "LU_SGS",
        "DEFORM_LINEAR_SOLVER_ITER": "800", "DEFORM_NONLINEAR_ITER": "1", "DEFORM_CONSOLE_OUTPUT": "YES",
        "DEFORM_LINEAR_SOLVER_ERROR": "1E-14", "DEFORM_STIFFNESS_TYPE": stiffness,
        "OPT_OBJECTIVE": f"DRAG * {OBJECTIVE_SCALE:g}",
        "OPT_CONSTRAINT": f"( LIFT = {CL_TARGET:g} ) * 1.0",
        "OPT_BOUND_UPPER": f"{bound:.12g}", "OPT_BOUND_LOWER": f"{-bound:.12g}",
        "OPT_ITERATIONS": str(ITERATIONS), "OPT_ACCURACY": "1E-10",
        "DEFINITION_DV": twist_variables(box),
    }


def wing_points(mesh) -> np.ndarray:
    """(W, 3) coordinates of the wing marker's nodes."""
    ids = np.unique(np.concatenate([b.data.ravel() for b in mesh.markers[WING]]))
    return mesh.points[ids]


def write_configs(mesh: Path, folder: Path, config: Path = CONFIG, stiffness: str = "INVERSE_VOLUME") -> dict:
    """Copy ``mesh`` to ``folder/mesh.su2``; write ``box.cfg`` (SU2_DEF embeds the box), ``config.cfg`` (the
    optimisation, on ``mesh_ffd.su2``, with ``config``'s flow settings: ``case3.cfg`` by default,
    ``case3_hybrid.cfg`` for the hybrid family) and ``box.json``; no SU2 program runs. Returns box.json's dict."""
    if stiffness not in STIFFNESS:
        raise ValueError(f"stiffness {stiffness!r}: expected one of {', '.join(STIFFNESS)}")
    lines = read_config(config)
    ref = float(config_value(lines, "REF_LENGTH") or 1.0)
    if ref != 1.0:
        raise ValueError(f"{config}: REF_LENGTH {ref}; the twist bounds assume 1 (SU2's angle is atan(v / REF_LENGTH))")
    m = read_mesh(mesh)
    if WING not in m.markers or m.dim != 3:
        raise ValueError(f"{mesh}: expected a 3-D mesh with a marker {WING!r}")
    folder.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(mesh, folder / "mesh.su2")
    box = wing_box(wing_points(m))
    keys = config_keys("mesh.su2", box, stiffness)
    (folder / "box.cfg").write_text(with_keys(lines, {**keys, "MESH_OUT_FILENAME": "mesh_ffd.su2"}))
    (folder / "config.cfg").write_text(with_keys(lines, {**keys, "MESH_FILENAME": "mesh_ffd.su2"}))
    info = {**box, "stations": stations(box).tolist(), "source_mesh": str(mesh), "wing_nodes": int(len(wing_points(m))),
            "bound_deg": BOUND_DEG, "alpha": float(config_value(lines, "AOA")), "flow_config": str(config),
            "stiffness": stiffness}
    (folder / "box.json").write_text(json.dumps(info, indent=1))
    return info


def mapped_nodes(log: str) -> tuple[int, int, int]:
    """SU2_DEF's "Number of vertices (Total, Inside FFD, Mapped to FFD): a, b, c" of its log."""
    m = re.search(r"Mapped to FFD\):\s*(\d+),\s*(\d+),\s*(\d+)", log)
    if m is None:
        raise RuntimeError("SU2_DEF's log has no 'Mapped to FFD' line: the box was not embedded")
    return tuple(int(v) for v in m.groups())


def setup(mesh: Path, folder: Path, config: Path = CONFIG, stiffness: str = "INVERSE_VOLUME") -> Path:
    """:func:`write_configs`, then ``SU2_DEF box.cfg`` (the box embedded into ``mesh_ffd.su2``); raises if a
    wing node is left outside the box."""
    folder = Path(folder)
    info = write_configs(Path(mesh), folder, Path(config), stiffness)
    run_program([str(su2_bin() / "SU2_DEF"), "box.cfg"], folder, "box.log")
    total, inside, mapped = mapped_nodes((folder / "box.log").read_text())
    if not total == inside == mapped == info["wing_nodes"]:
        raise RuntimeError(f"{folder / 'box.log'}: {mapped} of {info['wing_nodes']} wing nodes mapped to the box")
    return folder / "config.cfg"


def design_values(dsn: Path) -> list[float] | None:
    """The design's ``DV_VALUE_NEW`` (SU2's units) from its ``config_DSN.cfg``."""
    cfg = dsn / "config_DSN.cfg"
    if not cfg.is_file():
        return None
    value = config_value(read_config(cfg), "DV_VALUE_NEW") or config_value(read_config(cfg), "DV_VALUE")
    return [float(v) for v in value.split(",")] if value else None


def gradient_per_degree(dsn: Path, function: str, values: list[float] | None) -> list[float] | None:
    """d(function)/d(twist in degrees) of each variable at the design: SU2_DOT_AD's ``of_grad_<sfx>.csv`` (per
    unit of SU2's value, the tangent) times d(tan)/d(deg) = (1 + value^2) pi / 180; None until it exists."""
    found = sorted((dsn / f"ADJOINT_{function}").glob("of_grad*.csv"))
    if not found or values is None:
        return None
    g = np.genfromtxt(found[0], delimiter=",", skip_header=1, usecols=1, ndmin=1)
    return (g * (1.0 + np.asarray(values) ** 2) * math.pi / 180.0).tolist()


def solves(folder: Path) -> tuple[int, int]:
    """(flow, adjoint) solves SU2 finished: a row of ``history_project.csv`` per flow, a gradient file
    (``of_grad*.csv``) per adjoint folder ``ADJOINT_<FUNCTION>`` of each design."""
    adjoints = sum(finished_adjoints(dsn) for dsn in designs(folder))
    return len(project_rows(folder)), adjoints


def elapsed(folder: Path) -> float | None:
    """Seconds from the first design's start (its ``config_DSN.cfg``) to the newest file of ``DESIGNS``:
    how long a run that has not finished (no ``run.json``) has been going, up to its last output."""
    found = designs(folder)
    if not found or not (found[0] / "config_DSN.cfg").is_file():
        return None
    start = (found[0] / "config_DSN.cfg").stat().st_mtime
    return max(p.stat().st_mtime for p in (folder / "DESIGNS").rglob("*") if p.is_file()) - start


def span_row(dsn: Path, alpha: float, cd0: float | None, n_strips: int = STRIPS) -> dict | None:
    """Span load and efficiency of a design's flow (``DIRECT/``): :func:`benchmarks.adodg.case3_report.report`."""
    direct = dsn / "DIRECT"
    mesh = design_mesh(dsn)
    if mesh is None or not (direct / "surface_flow.csv").is_file():
        return None
    return load_report(direct, mesh, cd0=cd0, n_strips=n_strips, alpha=alpha)


def report(folder: Path, cd0: float | None = None, n_strips: int = STRIPS) -> dict:
    """What a (finished or running) run reached: solves, every design's CD, CL and twists (degrees, root
    first, and relative to the root), the best design meeting the lift equality, and the span load of the
    baseline and of that design against the ellipse."""
    folder = Path(folder)
    info = json.loads((folder / "box.json").read_text())
    alpha = info["alpha"]
    rows = []
    table = project_rows(folder)
    converged = flow_converged(folder, len(table))
    for k, row in enumerate(table):
        dsn = folder / "DESIGNS" / f"DSN_{k + 1:03d}"
        values = design_values(dsn)
        twist = None if values is None else value_to_angle(values)
        rows.append({"design": dsn.name, "CD": row["DRAG"], "CL": row["LIFT"],
                     "twist_deg": None if twist is None else twist.tolist(),
                     "twist_rel_root_deg": None if twist is None else (twist - twist[0]).tolist(),
                     "converged": converged[k],
                     "feasible": converged[k] and abs(row["LIFT"] - CL_TARGET) <= CL_TOLERANCE})
    ok = [r for r in rows if r["feasible"]]
    best = min(ok, key=lambda r: r["CD"]) if ok else None
    flows, adjoints = solves(folder)
    meta = folder / "run.json"
    state = json.loads(meta.read_text()) if meta.is_file() else None
    first = folder / "DESIGNS" / "DSN_001"
    base_values = design_values(first) if first.is_dir() else None
    out = {"folder": str(folder), "finished": state is not None, "rc": None if state is None else state["rc"],
           "wall": None if state is None else state["wall"], "elapsed": elapsed(folder),
           "flow_solves": flows, "adjoint_solves": adjoints,
           "designs": rows, "best": best, "alpha": alpha, "stations": info["stations"],
           "baseline_gradient_per_deg": {f: gradient_per_degree(first, f, base_values) for f in ("DRAG", "LIFT")}}
    for key, r in (("baseline_load", rows[0] if rows else None), ("best_load", best)):
        load = None if r is None else span_row(folder / "DESIGNS" / r["design"], alpha, cd0, n_strips)
        out[key] = None if load is None else {k: load[k] for k in ("CL", "CD", "CL_strips", "rms_pct", "max_pct",
                                                                   "e_load", "e_drag") if k in load}
    return out


def table_row(rep: dict, label: str = "SU2 `shape_optimization.py`, 9 `FFD_TWIST` (SLSQP)") -> str:
    """One markdown row: run, flow + adjoint solves, CD, CL, load - ellipse RMS / max, e_load, wall."""
    b, load = rep["best"], rep["best_load"]
    wall = f"{rep['wall']:.0f}" if rep["wall"] is not None else (
        "running" if rep["elapsed"] is None else f"running ({rep['elapsed']:.0f} so far)")
    if b is None:
        return f"| {label} | {rep['flow_solves']} + {rep['adjoint_solves']} | no design meets CL | | | | {wall} |"
    ld = "" if load is None else f"{load['rms_pct']:.2f} / {load['max_pct']:.2f}"
    e = "" if load is None else f"{load['e_load']:.4f}"
    return (f"| {label} | {rep['flow_solves']} + {rep['adjoint_solves']} | {b['CD']:.6f} | {b['CL']:.6f} | {ld} | "
            f"{e} | {wall} |")


def summary(rep: dict) -> str:
    """Plain-text lines of a report and its table row."""
    wall = (f", {rep['wall']:.0f} s wall" if rep["wall"] is not None else
            "" if rep["elapsed"] is None else f", {rep['elapsed']:.0f} s so far")
    head = "finished (exit " + str(rep["rc"]) + ")" if rep["finished"] else "RUNNING"
    lines = [f"{rep['folder']}: {head}, {rep['flow_solves']} flow + {rep['adjoint_solves']} adjoint solves{wall}"]
    for r in rep["designs"]:
        tw = "" if r["twist_deg"] is None else " twist " + " ".join(f"{t:+.3f}" for t in r["twist_deg"])
        lines.append(f"  {r['design']}: CD {r['CD']:.6f}  CL {r['CL']:.6f} ({'meets' if r['feasible'] else 'off'} "
                     f"CL {CL_TARGET}){tw}")
    for key, what in (("baseline_load", "baseline"), ("best_load", "best")):
        ld = rep[key]
        if ld is not None:
            e = f", e (CD - CD0) {ld['e_drag']:.4f}" if "e_drag" in ld else ""
            lines.append(f"{what}: load - ellipse RMS {ld['rms_pct']:.2f} %, max {ld['max_pct']:.2f} % of the "
                         f"root load; e_load {ld['e_load']:.4f}{e}")
    for f, g in rep["baseline_gradient_per_deg"].items():
        if g is not None:
            lines.append(f"baseline d{f}/d(twist, deg): " + " ".join(f"{v:.4e}" for v in g))
    lines.append("| run | flow + adjoint solves | CD | CL | load - ellipse RMS / max (%) | e_load | wall (s) |")
    lines.append("|---|---:|---:|---:|---|---:|---:|")
    lines.append(table_row(rep))
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap, s, p = side_parser("python -m benchmarks.adodg.case3_su2_side", __doc__.split("\n")[0],
                           "write config.cfg and embed SU2's box into FOLDER/mesh_ffd.su2",
                           "solves, CD, CL, twists, the best design's span load and e")
    s.add_argument("--config", type=Path, default=CONFIG,
                   help="the flow settings (default configs/adodg/case3.cfg; configs/adodg/case3_hybrid.cfg for H0-H2)")
    s.add_argument("--stiffness", choices=STIFFNESS, default="INVERSE_VOLUME",
                   help="SU2_DEF's DEFORM_STIFFNESS_TYPE (default the tutorial's INVERSE_VOLUME; WALL_DISTANCE for "
                        "the hybrid H0-H2, where INVERSE_VOLUME does not converge)")
    p.add_argument("--cd0", type=float, default=None, help="the mesh's zero-lift drag, for e from the drag")
    p.add_argument("--strips", type=int, default=STRIPS,
                   help=f"equal spanwise strips (default {STRIPS}); 0: strips between the wall's own spanwise stations")
    return dispatch(ap.parse_args(argv), lambda a: setup(a.mesh, a.folder, a.config, a.stiffness),
                    lambda a: report(a.folder, a.cd0, a.strips),
                    summary)


if __name__ == "__main__":
    sys.exit(main())
