"""SU2_CFD RANS solves of ADODG Case 2 on a given mesh, at the case's angle of attack or at its lift.

One solve is one folder: ``flow.cfg`` (``configs/adodg/case2.cfg``'s numerics, the mesh's marker names,
:func:`benchmarks.adodg.case2_baseline.case_config`), SU2's ``history.csv``, ``surface_flow.csv``,
``restart_flow.dat`` and ``log.txt``, and ``run.json`` (the mesh, the warm start, wall and CPU seconds,
the exit code). Two conditions:

* ``alpha``: alpha 2.79 deg, converged when rms[Rho] reaches ``CONV_RESIDUAL_MINVAL`` (-8 cold; -9 when
  warm-started: a warm-started flow needs one order more for the same CD, docs/adodg-case2.md);
* ``cl``: SU2's fixed-CL mode at CL 0.824, converged when rms[Rho] reaches its target **and** |CL - 0.824|
  is below half of ``CONV_CAUCHY_EPS`` (SU2's own fixed-CL test, ``CEulerSolver::FixedCL_Convergence``).
  SU2's default ``CONV_CAUCHY_EPS`` (1e-10) is never met, so the mode iterates until ``ITER``: here it is
  set to 2e-5 (the lift held to 1e-5, a tenth of the case's constraint tolerance); with ``CONV_FIELD=
  RMS_DENSITY`` SU2 uses it for nothing else.

The result of a folder (:func:`read_solve`): CD, CL, CM(c/4) nose-up positive (SU2's CMz negated, see
docs/adodg-case2.md "the sign"), the angle of attack (fixed CL: SU2's last "Previous AOA" plus "Changed AoA
by", else the ``AOA`` of SU2's ``flow.meta``), iterations, the final rms[Rho], converged or not with the
criterion, wall and CPU seconds.
"""

from __future__ import annotations

import json
import resource
import subprocess
import time
from pathlib import Path

import numpy as np

from benchmarks.adodg.case2_baseline import ROOT, TARGET_CL, case_config
from ffdcli.optimize.solvers.base import find_program
from ffdcli.optimize.solvers.su2 import config_value, read_config, read_history, with_keys

SEARCH = (ROOT.parent / "shared" / "su2" / "bin",)
CAUCHY_EPS = 2e-5          # fixed CL: |CL - target| < CAUCHY_EPS / 2 = 1e-5 at convergence
ALPHA = 2.79               # configs/adodg/case2.cfg's AOA
WRITE_EVERY = 50           # iterations between SU2's restart (and surface) files: a stopped solve keeps its state


def solve_config(mesh: Path, mode: str, *, restart: Path | None = None, iterations: int = 3000,
                 multigrid: int | None = None, cfl: float | None = None) -> str:
    """case2.cfg for ``mesh`` (absolute path) at ``mode`` ('alpha' or 'cl'), capped at ``iterations``,
    warm-started from ``restart`` (an SU2 restart on a mesh of the same nodes) and then one order tighter;
    ``multigrid`` levels instead of case2.cfg's 3 when given (the converged solution does not depend on
    them: on a C-mesh whose cut carried the wall's first cell SU2 diverged with 2 or 3, docs/adodg-case2.md);
    ``cfl``, when given, a fixed CFL instead of case2.cfg's adapted one (on ``rae2822_s1`` SU2's adaptation
    cut the CFL from 50 to 1 where a warm-started flow stalled near rms[Rho] -8.4, and the flow diverged)."""
    if mode not in ("alpha", "cl"):
        raise ValueError(f"mode {mode!r}: expected 'alpha' or 'cl'")
    lines = case_config(Path(mesh), mode).splitlines()
    keys = {"MESH_FILENAME": str(Path(mesh).resolve()), "ITER": str(int(iterations)),
            "OUTPUT_WRT_FREQ": str(WRITE_EVERY)}
    if mode == "cl":
        keys["CONV_CAUCHY_EPS"] = f"{CAUCHY_EPS:g}"
    if multigrid is not None:
        keys["MGLEVEL"] = str(int(multigrid))
    if cfl is not None:
        keys.update(CFL_ADAPT="NO", CFL_NUMBER=f"{float(cfl):g}")
    if restart is not None:
        minval = float(config_value(lines, "CONV_RESIDUAL_MINVAL") or -8)
        keys.update(RESTART_SOL="YES", SOLUTION_FILENAME=str(Path(restart).resolve()),
                    CONV_RESIDUAL_MINVAL=f"{minval - 1:g}")
    return with_keys(lines, keys)


def run_solve(mesh: Path, mode: str, folder: Path, *, restart: Path | None = None, iterations: int = 3000,
              multigrid: int | None = None, cfl: float | None = None, nice: int = 10) -> dict:
    """SU2_CFD on ``mesh`` in ``folder`` (created) under ``nice -n nice``; returns :func:`read_solve`."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "flow.cfg").write_text(solve_config(mesh, mode, restart=restart, iterations=iterations,
                                                  multigrid=multigrid, cfl=cfl))
    return launch(folder, {"mesh": str(Path(mesh).resolve()), "mode": mode,
                           "restart": None if restart is None else str(restart), "pieces": []}, nice)


def launch(folder: Path, meta: dict, nice: int) -> dict:
    """Run SU2_CFD on ``folder``'s ``flow.cfg``, then write ``run.json`` (``meta`` with the exit code,
    wall and CPU seconds of this run) and return :func:`read_solve`."""
    program = find_program("SU2_CFD", "SU2_RUN", SEARCH)
    if program is None:
        raise RuntimeError("SU2_CFD not found (SU2_RUN, PATH or ../shared/su2/bin)")
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    with open(folder / "log.txt", "w") as log:
        rc = subprocess.call(["nice", "-n", str(nice), str(program), "flow.cfg"], cwd=folder, stdout=log,
                             stderr=subprocess.STDOUT)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    (folder / "run.json").write_text(json.dumps({**meta, "rc": rc, "wall": wall, "cpu": cpu}))
    return read_solve(folder)


def continue_solve(folder: Path, mesh: Path, mode: str, nice: int = 10) -> dict:
    """Continue a solve that was stopped before it finished (no ``run.json``; SU2 wrote its restart
    every :data:`WRITE_EVERY` iterations): its history, log and last restart are kept as piece ``k``
    (``history_part{k}.csv``, ``log_part{k}.txt``, ``restart_part{k}.dat``; the first configuration as
    ``flow_part1.cfg``) and SU2 runs on from that restart with the same configuration and residual
    target (the same solve, not a new warm start). The pieces (``pieces.json``: iterations, and the wall
    time SU2 logged, since their CPU time was not measured: the process that would have measured it
    was stopped with them) count in :func:`read_solve`'s iterations."""
    k = len(list(folder.glob("history_part*.csv"))) + 1
    hist = read_history(folder / "history.csv")
    (folder / "history.csv").rename(folder / f"history_part{k}.csv")
    if (folder / "log.txt").is_file():
        (folder / "log.txt").rename(folder / f"log_part{k}.txt")
    (folder / "restart_flow.dat").rename(folder / f"restart_part{k}.dat")
    if k == 1:
        (folder / "flow.cfg").rename(folder / "flow_part1.cfg")
    first = read_config(folder / "flow_part1.cfg")
    warm = config_value(first, "SOLUTION_FILENAME") if (config_value(first, "RESTART_SOL") or "").upper() == "YES" \
        else None
    (folder / "flow.cfg").write_text(with_keys(first, {"RESTART_SOL": "YES", "SOLUTION_FILENAME":
                                                       str((folder / f"restart_part{k}.dat").resolve())}))
    n = int(hist["Inner_Iter"][-1]) + 1 if hist else 0
    wall_su2 = float(hist["Time(sec)"][-1]) * n if hist else 0.0       # SU2's mean seconds per iteration
    pieces = [*previous_pieces(folder), {"iterations": n, "wall_su2": wall_su2}]
    (folder / "pieces.json").write_text(json.dumps(pieces))
    return launch(folder, {"mesh": str(Path(mesh).resolve()), "mode": mode, "restart": warm, "pieces": pieces}, nice)


def previous_pieces(folder: Path) -> list[dict]:
    """The pieces recorded by an earlier continuation of ``folder`` (``pieces.json``)."""
    path = folder / "pieces.json"
    return json.loads(path.read_text()) if path.is_file() else []


def fixed_cl_alpha(log_text: str) -> float | None:
    """The angle of attack of a fixed-CL solve: SU2's last "Previous AOA" plus the "Changed AoA by" below it."""
    rows = [ln.split("|") for ln in log_text.splitlines()]
    aoa = None
    for i, r in enumerate(rows):
        if len(r) > 2 and r[1].strip() == "Previous AOA":
            try:
                aoa = float(r[2]) + float(rows[i + 1][2])
            except (ValueError, IndexError):
                pass
    return aoa


def meta_alpha(meta_text: str) -> float | None:
    """The angle of attack in SU2's ``flow.meta`` (``AOA= ...``, written with each restart: the angle of the
    last restart written, in fixed-CL mode the trimmed one)."""
    for line in meta_text.splitlines():
        key, _, value = line.partition("=")
        if key.strip() == "AOA":
            try:
                return float(value)
            except ValueError:
                return None
    return None


def read_solve(folder: Path) -> dict:
    """The finished solve in ``folder`` (``run.json``, ``flow.cfg``, ``history.csv``, ``log.txt``).

    Raises FileNotFoundError when the folder has no finished solve (no ``run.json``)."""
    meta = json.loads((folder / "run.json").read_text())
    cfg = read_config(folder / "flow.cfg")
    hist = read_history(folder / "history.csv")
    if not hist:
        raise FileNotFoundError(f"{folder / 'history.csv'}: no iteration written")
    target = float(config_value(cfg, "CONV_RESIDUAL_MINVAL") or -8)
    rms, cl = float(hist["rms[Rho]"][-1]), float(hist["CL"][-1])
    pieces = meta.get("pieces") or []
    iters = int(hist["Inner_Iter"][-1]) + 1 + sum(p["iterations"] for p in pieces)
    limit = int(float(config_value(cfg, "ITER") or 0))
    fixed = (config_value(cfg, "FIXED_CL_MODE") or "NO").upper() == "YES"
    out = {"folder": str(folder), "mode": meta["mode"], "cd": float(hist["CD"][-1]), "cl": cl,
           "cm": -float(hist["CMz"][-1]), "iterations": iters, "residual": rms, "wall": meta["wall"],
           "cpu": meta["cpu"], "rc": meta["rc"], "warm_start": meta.get("restart"), "pieces": len(pieces) + 1}
    if pieces:      # the last piece's CPU only: the others' were not measured (continue_solve)
        out["wall_su2_pieces"] = sum(p["wall_su2"] for p in pieces)
    if fixed:
        eps = float(config_value(cfg, "CONV_CAUCHY_EPS") or 1e-10)
        out["criterion"] = f"rms[Rho] <= {target:g} and |CL - {TARGET_CL}| < {eps / 2:g} (SU2's fixed-CL test)"
        last = int(hist["Inner_Iter"][-1]) + 1                    # this piece's iterations, against ITER
        out["converged"] = bool(rms <= target and abs(cl - TARGET_CL) < eps / 2 and last < limit)
        out["alpha"] = fixed_cl_alpha((folder / "log.txt").read_text(errors="replace"))
        if out["alpha"] is None and (folder / "flow.meta").is_file():       # SU2 8 does not always log it
            out["alpha"] = meta_alpha((folder / "flow.meta").read_text(errors="replace"))
    else:
        out["criterion"] = f"rms[Rho] <= {target:g}"
        out["converged"] = bool(rms <= target)
        out["alpha"] = float(config_value(cfg, "AOA") or ALPHA)
    out["converged"] = out["converged"] and meta["rc"] == 0
    return out


def reuse_or_solve(mesh: Path, mode: str, folder: Path, **kwargs) -> dict:
    """The finished solve of ``mesh`` at ``mode`` already in ``folder``; else the stopped one there
    continued (:func:`continue_solve`: a ``flow.cfg`` of the same mesh and mode, SU2's history and a
    restart written); else a new one (:func:`run_solve`)."""
    meta = folder / "run.json"
    if meta.is_file():
        m = json.loads(meta.read_text())
        if m.get("mesh") == str(Path(mesh).resolve()) and m.get("mode") == mode:
            return read_solve(folder)
    elif stopped(folder, mesh, mode):
        return continue_solve(folder, mesh, mode, nice=kwargs.get("nice", 10))
    return run_solve(mesh, mode, folder, **kwargs)


class SolveError(Exception):
    """A solve that cannot be continued: one line for the user."""


def stopped(folder: Path, mesh: Path, mode: str) -> bool:
    """Whether ``folder`` holds a stopped solve of ``mesh`` at ``mode`` that can be continued. Raises
    SolveError when that solve was diverging (its last rms[Rho] not finite or above its first): its
    restart is no starting point, and it is kept for the user to look at rather than overwritten."""
    cfg = folder / ("flow_part1.cfg" if (folder / "flow_part1.cfg").is_file() else "flow.cfg")
    if not (cfg.is_file() and (folder / "history.csv").is_file() and (folder / "restart_flow.dat").is_file()):
        return False
    lines = read_config(cfg)
    fixed = (config_value(lines, "FIXED_CL_MODE") or "NO").upper() == "YES"
    if config_value(lines, "MESH_FILENAME") != str(Path(mesh).resolve()) or fixed != (mode == "cl"):
        return False
    rms = read_history(folder / "history.csv").get("rms[Rho]") or [np.nan]
    if not np.isfinite(rms[-1]) or rms[-1] > rms[0]:
        raise SolveError(f"{folder}: the stopped solve there was diverging (rms[Rho] {rms[0]:.2f} -> {rms[-1]:.2f}); "
                         "move the folder away to start the solve again")
    return True
