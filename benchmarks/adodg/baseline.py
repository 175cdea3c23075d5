"""The baseline NACA 0012 of ADODG Case 1 on each level of the mesh family, and CD at zero spacing.

One SU2_CFD Euler solve per level (``configs/adodg/case1.cfg`` with the level's mesh), one after the
other, then Richardson extrapolation of CD from the three finest levels solved: the order observed
from them, ``p = ln((f1 - f2) / (f2 - f3)) / ln 2`` (f1 coarsest), the value at zero spacing
``f3 + (f3 - f2) / (2**p - 1)`` and the fine level's grid convergence index (Roache, safety factor
1.25). The family is nested (benchmarks/adodg/meshes.py), so the spacing ratio is exactly 2.

    python -m benchmarks.adodg.meshes --out out/adodg
    nice -n 10 python -m benchmarks.adodg.baseline --meshes out/adodg --work out/adodg/baseline

``--reuse`` reads a level's finished run (its ``history.csv`` converged, ``run.json`` with its
times) instead of solving it again.
"""

from __future__ import annotations

import argparse
import json
import math
import resource
import subprocess
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import matplotlib
import numpy as np

from ffdcli.optimize.solvers.base import find_program
from ffdcli.optimize.solvers.su2 import config_value, read_config, read_history, with_keys

ROOT = Path(__file__).resolve().parents[2]
CONFIG = ROOT / "configs" / "adodg" / "case1.cfg"
SEARCH = (ROOT.parent / "shared" / "su2" / "bin",)


@dataclass(frozen=True)
class Solve:
    """One level's converged solve: CD, CL, iterations, final density residual (log10), wall and
    CPU seconds (the solver's own user + system time)."""

    level: str
    points: int
    cd: float
    cl: float
    iterations: int
    residual: float
    wall: float
    cpu: float


@dataclass(frozen=True)
class Richardson:
    """Extrapolation of three values on grids of spacing ratio ``ratio`` (coarsest first)."""

    order: float
    value: float
    gci_fine: float


def richardson(f1: float, f2: float, f3: float, ratio: float = 2.0) -> Richardson:
    """Richardson extrapolation of ``f1`` (coarsest), ``f2``, ``f3`` (finest) to zero spacing.

    Raises ValueError when the three do not converge monotonically (the differences change sign or
    the finest two are equal) or do not converge at all (the finer difference is not smaller than the
    coarser: an observed order <= 0, whose "limit" lies away from the values): no order can be
    observed then.
    """
    d12, d23 = f1 - f2, f2 - f3
    if d23 == 0 or d12 * d23 <= 0:
        raise ValueError(f"not monotone: {f1!r}, {f2!r}, {f3!r} (the order cannot be observed)")
    if abs(d23) >= abs(d12) * (1.0 - 1e-9):        # an order <= 0, to round-off
        raise ValueError(f"not converging: {f1!r}, {f2!r}, {f3!r} (the differences {d12:.3g}, {d23:.3g} "
                         "do not shrink with the spacing)")
    p = math.log(d12 / d23) / math.log(ratio)
    value = f3 - d23 / (ratio**p - 1.0)
    gci = 1.25 * abs(d23 / f3) / (ratio**p - 1.0)
    return Richardson(order=p, value=value, gci_fine=gci)


def mesh_points(mesh: Path) -> int:
    """NPOIN of an SU2 mesh (read from its header lines)."""
    with open(mesh) as fh:
        for line in fh:
            if line.strip().upper().startswith("NPOIN"):
                return int(line.split("=")[1].split()[0])
    raise ValueError(f"{mesh}: no NPOIN line")


def read_solve(level: str, folder: Path, mesh: Path) -> Solve:
    """The converged solve in ``folder`` (history.csv and run.json)."""
    hist = read_history(folder / "history.csv")
    log = (folder / "log.txt").read_text(errors="replace")
    if "All convergence criteria satisfied" not in log:
        raise RuntimeError(f"{folder / 'log.txt'}: SU2 did not converge")
    times = json.loads((folder / "run.json").read_text())
    return Solve(level, mesh_points(mesh), hist["CD"][-1], hist["CL"][-1], int(hist["Inner_Iter"][-1]) + 1,
                 hist["rms[Rho]"][-1], times["wall"], times["cpu"])


def run_level(level: str, mesh: Path, folder: Path, config: Path = CONFIG) -> Solve:
    """Solve the baseline on ``mesh`` in ``folder`` (created) and read the result."""
    program = find_program("SU2_CFD", "SU2_RUN", SEARCH)
    if program is None:
        raise RuntimeError("SU2_CFD not found (SU2_RUN, PATH or ../shared/su2/bin)")
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "flow.cfg").write_text(with_keys(read_config(config), {"MESH_FILENAME": str(mesh.resolve())}))
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    with open(folder / "log.txt", "w") as log:
        subprocess.run([str(program), "flow.cfg"], cwd=folder, stdout=log, stderr=subprocess.STDOUT, check=True)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    (folder / "run.json").write_text(json.dumps({"wall": wall, "cpu": cpu}))
    return read_solve(level, folder, mesh)


def table(solves: list[Solve], rich: Richardson | None) -> str:
    """The markdown table of the solves and the extrapolated CD."""
    rows = ["| level | points | CD | CL | iterations | rms[Rho] | wall (s) | CPU (s) |",
            "|---|---:|---:|---:|---:|---:|---:|---:|"]
    for s in solves:
        rows.append(f"| {s.level} | {s.points:,} | {s.cd:.6f} | {s.cl:.1e} | {s.iterations} | {s.residual:.1f} | "
                    f"{s.wall:.0f} | {s.cpu:.0f} |")
    if rich is not None:
        rows.append(f"| h -> 0 (Richardson, order {rich.order:.2f}) | | {rich.value:.6f} | | | | | |")
    return "\n".join(rows)


def plot_cp(folders: list[tuple[str, Path]], path: Path) -> None:
    """Cp along the upper surface (the flow is symmetric) of each level's ``surface_flow.csv``,
    -Cp upward, written to ``path`` (PNG)."""
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415 (pyplot after the backend is chosen)

    fig, ax = plt.subplots(figsize=(7, 4.2))
    for level, folder in folders:
        data = np.genfromtxt(folder / "surface_flow.csv", delimiter=",", names=True)
        up = data["y"] >= 0
        order = np.argsort(data["x"][up])
        ax.plot(data["x"][up][order], -data["Pressure_Coefficient"][up][order], lw=1.2, label=level)
    ax.set_xlabel("x / c")
    ax.set_ylabel("-Cp")
    ax.set_title("ADODG Case 1 baseline, upper surface: NACA 0012 (sharp TE), Euler, M 0.85, alpha 0", fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.adodg.baseline", description=__doc__.split("\n")[0])
    ap.add_argument("--meshes", required=True, type=Path, help="folder of adodg_L*.su2 (benchmarks.adodg.meshes)")
    ap.add_argument("--work", required=True, type=Path, help="folder for the runs (one sub-folder per level)")
    ap.add_argument("--levels", nargs="+", default=["L1", "L2", "L3"], help="levels, coarsest first")
    ap.add_argument("--reuse", action="store_true", help="read a level's finished run instead of solving again")
    ap.add_argument("--plot", type=Path, help="also write the levels' upper-surface Cp to this PNG")
    args = ap.parse_args(argv)
    solves = []
    for level in args.levels:
        mesh, folder = args.meshes / f"adodg_{level}.su2", args.work / level
        if args.reuse and (folder / "run.json").is_file():
            s = read_solve(level, folder, mesh)
        else:
            s = run_level(level, mesh, folder)
        solves.append(s)
        print(f"{level}: CD {s.cd:.6f} in {s.iterations} iterations, {s.wall:.0f} s wall, {s.cpu:.0f} s CPU",
              file=sys.stderr)
    rich = None
    if len(solves) >= 3:
        try:
            rich = richardson(*(s.cd for s in solves[-3:]))
        except ValueError as err:
            print(f"no extrapolation: {err}")
    print(table(solves, rich))
    if rich is not None:
        print(f"\nobserved order {rich.order:.3f}; CD at zero spacing {rich.value:.6f}; "
              f"GCI of the finest level {100 * rich.gci_fine:.2f} %")
    out = {"config": str(CONFIG.relative_to(ROOT)), "mach": config_value(read_config(CONFIG), "MACH_NUMBER"),
           "solves": [asdict(s) for s in solves], "richardson": asdict(rich) if rich else None}
    (args.work / "baseline.json").write_text(json.dumps(out, indent=1))
    if args.plot:
        plot_cp([(s.level, args.work / s.level) for s in solves], args.plot)
    return 0


if __name__ == "__main__":
    sys.exit(main())
