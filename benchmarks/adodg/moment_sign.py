"""Which way SU2's ``MOMENT_Z`` turns an airfoil, read from SU2's own output (ADODG Case 2's CM bound).

ADODG Case 2 bounds the pitching moment about the quarter chord in the aerodynamic sign (nose-up
positive): CM >= -0.092. SU2 reports ``CMz``, the z-component of r x F about ``REF_ORIGIN_MOMENT``
(SU2's ``Pressure_Forces`` accumulates ``(F_y dx - F_x dy) / L_ref``): with x downstream and y up, a
positive CMz turns +x toward +y, the trailing edge up and the nose down. This module integrates the
pressure of a flow's ``surface_flow.csv`` over the wall's segments in that right-hand sense and prints
it beside SU2's CL and CMz: the same sign and size (the rest is skin friction) show that SU2's CMz is
nose-down positive, so CM = -CMz and ``CM >= -0.092`` is ``MOMENT_Z <= 0.092``.

    python -m benchmarks.adodg.moment_sign out/adodg/case2/evals/0001          # a flow's folder
"""

from __future__ import annotations

import argparse
import csv
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from benchmarks.adodg.case2_meshes import wall_section
from ffdcli.optimize.solvers.su2 import config_value, read_config, read_history


@dataclass(frozen=True)
class PressureLoads:
    """Pressure-only coefficients of a closed 2-D wall: ``cl`` (normal to the free stream), ``cd``,
    ``cmz`` (right-hand about +z through ``origin``: positive turns the nose down when x is downstream)."""

    cl: float
    cd: float
    cmz: float


def pressure_loads(loop: np.ndarray, cp: np.ndarray, alpha_deg: float, origin=(0.25, 0.0)) -> PressureLoads:
    """Integrate ``cp`` (n,) given at the points of the closed counter-clockwise wall ``loop`` (n, 2)
    (first point = last) by the trapezoidal rule on each segment, chord 1.

    The force on the body is -Cp times the outward normal (dy, -dx) of a counter-clockwise segment."""
    loop, cp = np.asarray(loop, float), np.asarray(cp, float)
    d = np.diff(loop, axis=0)
    mid = 0.5 * (loop[:-1] + loop[1:])
    c = 0.5 * (cp[:-1] + cp[1:])
    fx, fy = -c * d[:, 1], c * d[:, 0]
    a = np.radians(alpha_deg)
    cl = float(np.sum(fy * np.cos(a) - fx * np.sin(a)))
    cd = float(np.sum(fx * np.cos(a) + fy * np.sin(a)))
    cmz = float(np.sum((mid[:, 0] - origin[0]) * fy - (mid[:, 1] - origin[1]) * fx))
    return PressureLoads(cl=cl, cd=cd, cmz=cmz)


def folder_loads(folder: Path, marker: str = "AIRFOIL") -> tuple[PressureLoads, dict[str, float]]:
    """(the pressure loads of ``folder``'s ``surface_flow.csv`` on its mesh's wall, SU2's last CL, CMz)."""
    folder = Path(folder)
    cfg = read_config(folder / "flow.cfg")
    loop = wall_section(folder / (config_value(cfg, "MESH_FILENAME") or "mesh.su2"), marker)
    with open(folder / "surface_flow.csv", newline="") as fh:
        rows = list(csv.DictReader(fh, skipinitialspace=True))
    pts = np.array([[float(r["x"]), float(r["y"])] for r in rows])
    cp = np.array([float(r["Pressure_Coefficient"]) for r in rows])
    _, idx = cKDTree(pts).query(loop)
    origin = tuple(float(config_value(cfg, f"REF_ORIGIN_MOMENT_{c}") or 0.0) for c in "XY")
    loads = pressure_loads(loop, cp[idx], float(config_value(cfg, "AOA") or 0.0), origin)
    hist = read_history(folder / "history.csv")
    return loads, {"CL": hist["CL"][-1], "CMz": hist["CMz"][-1]}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.adodg.moment_sign", description=__doc__.split("\n")[0])
    ap.add_argument("folder", type=Path, help="a flow's folder: flow.cfg, its mesh, history.csv, surface_flow.csv")
    ap.add_argument("--marker", default="AIRFOIL")
    args = ap.parse_args(argv)
    loads, su2 = folder_loads(args.folder, args.marker)
    print(f"SU2:             CL {su2['CL']:.5f}  CMz {su2['CMz']:+.5f}")
    print(f"pressure, r x F: CL {loads.cl:.5f}  CMz {loads.cmz:+.5f}  (right-hand about +z, x downstream, y up)")
    print(f"CM(c/4), nose-up positive: {-su2['CMz']:+.5f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
