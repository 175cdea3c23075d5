"""The RAE2822's baseline in ADODG Case 2's flow (RANS SA, M 0.734, Re 6.5e6) on each mesh: at the case's
angle of attack (2.79 deg) and at its lift (CL 0.824, SU2's fixed-CL mode), one SU2_CFD run each with
the numerics of ``configs/adodg/case2.cfg`` (converged to rms[Rho] 1e-8; the fixed-CL runs also to
SU2's lift criterion), one after the other, and a table of CL, CD, CM(c/4) (aerodynamic sign: SU2's
CMz negated), iterations and seconds.

Run (from the repository root, after ``python -m benchmarks.adodg.case2_meshes --out out/adodg``)::

    nice -n 5 python -m benchmarks.adodg.case2_baseline --meshes out/adodg --work out/adodg/case2_baseline \\
        --cases rae2822_su2:alpha rae2822_su2:cl rae2822_c0:alpha rae2822_c0:cl rae2822_c1:alpha rae2822_c1:cl
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import time
from pathlib import Path

from ffdcli.optimize.solvers.base import find_program
from ffdcli.optimize.solvers.su2 import read_config, read_history, with_keys

ROOT = Path(__file__).resolve().parents[2]
CONFIG = ROOT / "configs" / "adodg" / "case2.cfg"
TARGET_CL = 0.824


def case_config(mesh: Path, mode: str) -> str:
    """case2.cfg for ``mesh`` (its marker names' case taken from the mesh) at alpha or at the target CL."""
    text = mesh.read_text(errors="replace")
    lower = "MARKER_TAG= airfoil" in text
    a, f = ("airfoil", "farfield") if lower else ("AIRFOIL", "FARFIELD")
    keys = {"MESH_FILENAME": mesh.name, "MARKER_HEATFLUX": f"( {a}, 0.0 )", "MARKER_FAR": f"( {f} )",
            "MARKER_PLOTTING": f"( {a} )", "MARKER_MONITORING": f"( {a} )", "ITER": "20000",
            "HISTORY_OUTPUT": "(ITER, WALL_TIME, RMS_RES, AERO_COEFF, CFL_NUMBER)",
            "OUTPUT_FILES": "(RESTART, SURFACE_CSV)"}
    if mode == "cl":
        keys.update({"FIXED_CL_MODE": "YES", "TARGET_CL": f"{TARGET_CL}", "DCL_DALPHA": "0.2",
                     "UPDATE_AOA_ITER_LIMIT": "100", "ITER_DCL_DALPHA": "0"})
    return with_keys(read_config(CONFIG), keys)


def run(mesh: Path, mode: str, work: Path, su2: Path) -> dict:
    folder = work / f"{mesh.stem}_{mode}"
    folder.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(mesh, folder / mesh.name)
    (folder / "flow.cfg").write_text(case_config(mesh, mode))
    t0 = time.time()
    with open(folder / "flow.log", "w") as log:
        rc = subprocess.call([str(su2), "flow.cfg"], cwd=folder, stdout=log, stderr=subprocess.STDOUT)
    hist = read_history(folder / "history.csv")
    aoa = None                                  # fixed CL: SU2's last "Previous AOA" + "Changed AoA by"
    rows = [ln.split("|") for ln in (folder / "flow.log").read_text(errors="replace").splitlines()]
    for i, r in enumerate(rows):
        if mode == "cl" and len(r) > 2 and r[1].strip() == "Previous AOA":
            try:
                aoa = float(r[2]) + float(rows[i + 1][2])
            except (ValueError, IndexError):
                pass
    return {"case": f"{mesh.stem}:{mode}", "rc": rc, "CL": hist["CL"][-1], "CD": hist["CD"][-1],
            "CM": -hist["CMz"][-1], "iterations": int(hist["Inner_Iter"][-1]) + 1,
            "rms": hist["rms[Rho]"][-1], "wall": time.time() - t0, "aoa": aoa}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--meshes", type=Path, default=Path("out/adodg"))
    ap.add_argument("--work", type=Path, default=Path("out/adodg/case2_baseline"))
    ap.add_argument("--cases", nargs="+", default=["rae2822_su2:alpha", "rae2822_su2:cl"])
    args = ap.parse_args(argv)
    su2 = find_program("SU2_CFD", "SU2_RUN", (ROOT.parent / "shared" / "su2" / "bin",))
    if su2 is None:
        print("SU2_CFD not found (SU2_RUN, PATH)", file=sys.stderr)
        return 2
    print("| mesh:mode | CL | CD (counts) | CM(c/4) | iterations | rms[Rho] | wall (s) |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    for case in args.cases:
        name, mode = case.split(":")
        r = run(args.meshes / f"{name}.su2", mode, args.work, su2)
        print(f"| {r['case']} | {r['CL']:.4f} | {1e4 * r['CD']:.1f} | {r['CM']:.4f} | {r['iterations']} | "
              f"{r['rms']:.2f} | {r['wall']:.0f} |" + ("" if r["rc"] == 0 else f" (exit {r['rc']})"), flush=True)
        if r["aoa"] is not None:
            print(f"  angle of attack at CL {TARGET_CL}: {r['aoa']:.4f} deg", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
