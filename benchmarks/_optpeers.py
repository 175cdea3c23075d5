"""SU2's own optimiser on SU2's NACA0012 case: the peer rows of ``bench_optimize``.

``shape_optimization.py`` (SLSQP, 8 iterations) on the mesh and flow of
``inv_NACA0012_basic.cfg`` (Euler, M 0.8, alpha 1.25 deg), with
(a) its own 38 Hicks-Henne bumps and (b) SU2's FFD box (the ``_v8`` mesh of the inverse-design case,
the same 5,233 points, 11 x 2 ``FFD_CONTROL_POINT_2D`` variables moving in y), each with the discrete
and the continuous adjoint, constrained as SU2's ``inv_NACA0012_adv`` (CL >= 0.328486, MOMENT_Z >= 0,
t/c >= 0.12, each scaled by 0.001 as SU2's case does) and unconstrained. Every run lives in its own
cached folder (see :func:`benchmarks._su2.cached_run`); the table is read back from its ``DESIGNS``.
"""

from __future__ import annotations

import math
import re
import shutil
import sys
from dataclasses import dataclass
from pathlib import Path

from benchmarks import _su2

CONSTRAINTS = "( LIFT > 0.328486 ) * 0.001; ( MOMENT_Z > 0.0 ) * 0.001; ( AIRFOIL_THICKNESS > 0.12 ) * 0.001"
BOUNDS = {"LIFT": 0.328486, "MOMENT_Z": 0.0, "AIRFOIL_THICKNESS": 0.12}
ITERATIONS = 8


@dataclass(frozen=True)
class PeerCase:
    """One run of ``shape_optimization.py``: parameterisation, adjoint, constrained or not."""

    param: str          # "hh" (Hicks-Henne) or "ffd" (SU2's FFD box)
    adjoint: str        # "discrete" or "continuous"
    constrained: bool

    @property
    def label(self) -> str:
        return f"peer-{self.param}-{self.adjoint[:4]}-{'con' if self.constrained else 'unc'}"

    @property
    def mesh(self) -> Path:
        return _su2.NACA_FFD_MESH if self.param == "ffd" else _su2.NACA_MESH

    @property
    def gradient(self) -> str:
        return "DISCRETE_ADJOINT" if self.adjoint == "discrete" else "CONTINUOUS_ADJOINT"


def all_cases() -> list[PeerCase]:
    """The eight peer runs, constrained ones first."""
    return [PeerCase(p, a, c) for c in (True, False) for p in ("hh", "ffd")
            for a in ("discrete", "continuous")]


def ffd_dvs() -> str:
    """``DEFINITION_DV`` of SU2's FFD box of the ``_v8`` mesh: every control point (11 x 2) in y."""
    return "; ".join(f"( 19, 1.0 | airfoil | BOX, {i}, {j}, 0.0, 1.0 )"
                     for j in range(2) for i in range(11))


def config_text(case: PeerCase) -> str:
    """The config of a peer run: SU2's basic config with only what the script and the case need."""
    text = _su2.NACA_CFG.read_text()
    keys = dict(MESH_FILENAME="mesh.su2", OPT_ITERATIONS=ITERATIONS, RESTART_SOL="NO",
                OUTPUT_FILES="(RESTART, SURFACE_CSV)",
                OPT_CONSTRAINT=CONSTRAINTS if case.constrained else "NONE")
    if case.param == "ffd":
        keys.update(DV_KIND="FFD_SETTING", DV_PARAM="( 1.0 )", DEFINITION_DV=ffd_dvs(),
                    FFD_TOLERANCE="1E-10", FFD_ITERATIONS=500)
    return _su2.cfg_set(text, **keys)


def command(case: PeerCase) -> list[str]:
    b = _su2.su2_bin()
    return [sys.executable, str(b / "shape_optimization.py"), "-g", case.gradient, "-o", "SLSQP",
            "-f", "config.cfg"]


def run_case(case: PeerCase, root: Path | None = None, force: bool = False,
             only_cached: bool = False) -> dict | None:
    """Run (or reuse) one peer; returns its result dict (exit code, wall seconds, folder, ...)."""
    root = Path(root or _su2.SCRATCH / "peers")
    cfg = config_text(case)
    cmd = command(case)

    def body(folder: Path) -> dict:
        shutil.copyfile(case.mesh, folder / "mesh.su2")
        (folder / "config.cfg").write_text(cfg)
        rc, wall = _su2.run(cmd, folder, "optimizer.log")
        return {"label": case.label, "rc": rc, "wall_s": wall, "command": " ".join(cmd[1:])}

    return _su2.cached_run(root, case.label, cfg, [case.mesh], [Path(c).name for c in cmd], body,
                           force=force, only_cached=only_cached)


# ----------------------------------------------------------------------------------------------
# Reading a finished run
# ----------------------------------------------------------------------------------------------

def _dsn_number(p: Path) -> int:
    m = re.search(r"(\d+)$", p.name)
    return int(m.group(1)) if m else -1


def designs(folder: Path) -> list[Path]:
    """The run's ``DESIGNS/DSN_*`` folders in creation order."""
    return sorted((Path(folder) / "DESIGNS").glob("DSN_*"), key=_dsn_number)


def count_solves(folder: Path) -> tuple[int, int]:
    """(flow solves, adjoint solves): the DSN folders' DIRECT and ADJOINT_* runs that wrote a history."""
    flow = adj = 0
    for d in designs(folder):
        if list((d / "DIRECT").glob("history*.csv")):
            flow += 1
        for a in d.glob("ADJOINT_*"):
            if list(a.glob("history*.csv")):
                adj += 1
    return flow, adj


def final_design(folder: Path) -> Path:
    """The last design SLSQP evaluated (its final iterate; the script has no other record of it)."""
    done = [d for d in designs(folder) if list((d / "DIRECT").glob("history*.csv"))]
    if not done:
        raise RuntimeError(f"{folder}: no finished flow solve")
    return done[-1]


def flow_values(dsn: Path) -> dict:
    """CD, CL, CMz of a design's converged flow (the last row of its history)."""
    h = _su2.last_history(sorted((dsn / "DIRECT").glob("history*.csv"))[0])
    return {"CD": h["CD"], "CL": h["CL"], "CMz": h["CMz"]}


def worst_violation(values: dict) -> float:
    """Largest bound violation (>= 0) of CL, CMz and t/c against the constrained case's bounds."""
    v = [BOUNDS["LIFT"] - values["CL"], BOUNDS["MOMENT_Z"] - values["CMz"],
         BOUNDS["AIRFOIL_THICKNESS"] - values["tc"]]
    return max(0.0, *[x for x in v if not math.isnan(x)])


def project_rows(folder: Path) -> list[dict]:
    """``history_project.csv``: one row per design the script evaluated, in order."""
    return _su2.read_history(Path(folder) / "history_project.csv")


def design_mesh(dsn: Path) -> Path:
    """The mesh a design's flow ran on (the deformed one; the first design has the input mesh)."""
    m = dsn / "mesh_deform.su2"
    return m if m.exists() else dsn / "mesh.su2"


def airfoil_thickness(mesh: Path, folder: Path) -> float:
    """SU2_GEO's ``AIRFOIL_THICKNESS`` of a mesh (SU2's basic config, ``GEO_MODE= FUNCTION``)."""
    folder.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(mesh, folder / "mesh.su2")
    cfg = _su2.cfg_set(_su2.NACA_CFG.read_text(), MESH_FILENAME="mesh.su2", GEO_MODE="FUNCTION")
    (folder / "geo.cfg").write_text(cfg)
    rc, _ = _su2.run(["SU2_GEO", "geo.cfg"], folder, "geo.log")
    if rc != 0:
        raise RuntimeError(f"SU2_GEO failed: {folder / 'geo.log'}")
    return _su2.last_history(folder / "of_func.csv")["AIRFOIL_THICKNESS"]


def peer_row(case: PeerCase, result: dict) -> dict:
    """The table row of a finished peer run: final CD, CL, CMz, t/c, worst violation, solves, wall."""
    folder = Path(result["folder"])
    rows = project_rows(folder)
    last = rows[-1]
    final = final_design(folder)
    values = {"CD": last["DRAG"], "CL": last["LIFT"], "CMz": last["MOMENT_Z"]}
    tc = last.get("AIRFOIL_THICKNESS", 0.0)
    if not tc:
        geo = folder / "final_geometry"
        done = geo / "of_func.csv"
        tc = _su2.last_history(done)["AIRFOIL_THICKNESS"] if done.exists() else \
            airfoil_thickness(design_mesh(final), geo)
    values["tc"] = tc
    flow, adj = count_solves(folder)
    viol = worst_violation(values)
    return {"run": {"hh": "(a) SU2 Hicks-Henne (38)", "ffd": "(b) SU2 FFD box (22)"}[case.param],
            "adjoint": case.adjoint, "constrained": case.constrained, **values,
            "worst_violation": viol, "feasible": viol <= 1e-4, "flow": flow, "adjoint_solves": adj,
            "wall_s": result["wall_s"], "designs": len(rows), "final_design": final.name,
            "initial_CD": rows[0]["DRAG"], "rc": result["rc"], "folder": str(folder)}
