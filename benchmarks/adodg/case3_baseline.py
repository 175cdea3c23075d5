"""The untwisted ADODG Case 3 wing on each level of its mesh family: CD and CL at the case's angle of
attack, and the zero-lift drag CD0 (alpha 0: the symmetric wing carries no lift, so every bit of drag is
the discretisation's), one SU2_CFD Euler solve each (``configs/adodg/case3.cfg`` with the level's mesh).

    python -m benchmarks.adodg.case3_meshes --out out/adodg3
    nice -n 5 python -m benchmarks.adodg.case3_baseline --meshes out/adodg3 --work out/adodg3/baseline

A level's finished solve (``run.json`` beside a converged ``log.txt``) is read back, not run again. The
levels are not nested (unstructured tetrahedra whose sizes differ by ``RATIO``), so the extrapolation
printed (Richardson with spacing ratio ``RATIO``, from the three levels) is an estimate.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from benchmarks.adodg.baseline import Solve, read_solve, richardson, run_level
from benchmarks.adodg.case3_meshes import RATIO
from ffdcli.optimize.solvers.su2 import read_config, with_keys

ROOT = Path(__file__).resolve().parents[2]
CONFIG = ROOT / "configs" / "adodg" / "case3.cfg"


def solve(level: str, mesh: Path, folder: Path, aoa: float | None) -> Solve:
    """The level's solve at the config's alpha (``aoa`` None) or at ``aoa``; read back when done."""
    if (folder / "run.json").exists():
        return read_solve(level, folder, mesh)
    folder.mkdir(parents=True, exist_ok=True)
    config = CONFIG
    if aoa is not None:
        config = folder / "case3_alpha.cfg"
        config.write_text(with_keys(read_config(CONFIG), {"AOA": str(aoa)}))
    return run_level(level, mesh, folder, config)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--meshes", required=True, type=Path, help="folder of case3_L*.su2")
    ap.add_argument("--work", required=True, type=Path, help="folder for the runs")
    ap.add_argument("--levels", nargs="+", default=["L0", "L1", "L2"], help="levels, coarsest first")
    a = ap.parse_args(argv)
    rows = ["| level | points | CL | CD | CD0 (alpha 0) | CD - CD0 | iterations | CPU (s) |",
            "|---|---:|---:|---:|---:|---:|---:|---:|"]
    cds = []
    for level in a.levels:
        mesh = a.meshes / f"case3_{level}.su2"
        lift = solve(level, mesh, a.work / level, None)
        zero = solve(level, mesh, a.work / f"{level}_alpha0", 0.0)
        cds.append(lift.cd)
        rows.append(f"| {level} | {lift.points:,} | {lift.cl:.5f} | {lift.cd:.6f} | {zero.cd:.6f} | "
                    f"{lift.cd - zero.cd:.6f} | {lift.iterations} | {lift.cpu:.0f} + {zero.cpu:.0f} |")
        print(rows[-1], flush=True)
    print("\n".join(rows))
    if len(cds) == 3:
        try:
            r = richardson(*cds, ratio=RATIO)
            print(f"CD at zero spacing (estimate): {r.value:.6f}, observed order {r.order:.2f}")
        except ValueError as err:
            print(f"no extrapolation: {err}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
