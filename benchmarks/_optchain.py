"""The adjoint chain SU2 -> ffd on SU2's NACA0012 case: the ``--chain`` part of ``bench_optimize``.

(i) SU2's projection: for one Hicks-Henne bump of SU2's own config, the displacement ``SU2_DEF`` makes
    for it (a difference of its output meshes; the bump is linear in its value, so the difference is its
    exact linear response up to the printed digits), dotted with dJ/dX read from SU2's files, against
    SU2's own gradient of that bump:
    continuous: dJ/dX = -S n_hat at the wall (``surface_adjoint.csv``, ``SU2_DOT``);
    discrete: dJ/dX of every node (``restart_adj_cd.csv``, ``SU2_DOT_AD``, whose projection carries
    the volume nodes through SU2's own elastic mesh motion, so the full mesh displacement is dotted).
(ii) ffd's own automatic box (``box: {points: [8, 2]}``, twist and shape variables): ``ffd grad --sens``
    of the adjoints' files against central differences of converged SU2_CFD solutions on meshes
    ``ffd deform --set`` wrote (restarted from the baseline flow, residuals to 1e-13 as SU2's config asks).

Every SU2 run is cached by its config and inputs (:func:`benchmarks._su2.cached_run`).
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np

from benchmarks import _su2
from ffdcli.io.formats import read_mesh
from ffdcli.io.formats.sensitivity import read_sensitivity

HH_PARAM = "( 1, 0.50 )"          # the upper-surface bump at mid-chord of SU2's 38
HH_STEP = 1e-3                    # SU2_DEF value of the bump (linear: any value gives its response)
TWIST_STEP = 0.003                # degrees: the lift is nonlinear in incidence (docs/optimize.md: 0.01 is 4e-3 off)
SHAPE_STEP = 1e-4                 # chord lengths
BOX_POINTS = (8, 2)


def base_config(**extra) -> str:
    """SU2's NACA0012 config at 16 digits with restart, ASCII restart and surface CSV outputs."""
    keys = dict(MESH_FILENAME="mesh.su2", OUTPUT_PRECISION=16, RESTART_SOL="NO",
                OUTPUT_FILES="(RESTART, RESTART_ASCII, SURFACE_CSV)",
                DV_KIND="HICKS_HENNE", DV_PARAM=HH_PARAM, DV_VALUE=1.0)
    keys.update(extra)
    return _su2.cfg_set(_su2.NACA_CFG.read_text(), **keys)


def _solver_run(root: Path, label: str, cfg: str, mesh: Path, program: str, links: dict | None = None,
                force: bool = False) -> dict:
    """Run one SU2 program on ``mesh`` with config ``cfg`` (cached); ``links`` are files copied in first."""
    links = links or {}
    inputs = [mesh] + [Path(p) for p in links.values()]

    def body(folder: Path) -> dict:
        shutil.copyfile(mesh, folder / "mesh.su2")
        for name, src in links.items():
            shutil.copyfile(src, folder / name)
        (folder / "run.cfg").write_text(cfg)
        rc, wall = _su2.run([program, "run.cfg"], folder, "solver.log")
        if rc != 0:
            raise RuntimeError(f"{program} failed (exit {rc}): {folder / 'solver.log'}")
        out = {"rc": rc, "wall_s": wall, "program": program}
        hist = folder / "history.csv"
        if hist.exists():
            last = _su2.last_history(hist)
            out["last"] = {k: last[k] for k in ("CD", "CL", "CMz", "rms[Rho]", "Inner_Iter") if k in last}
        return out

    return _su2.cached_run(root, label, cfg, inputs, [program, *sorted(links)], body, force=force)


HISTORY = "(ITER, RMS_RES, AERO_COEFF)"     # SU2's default history of this config has no coefficients


def flow(root: Path, mesh: Path, restart_from: Path | None = None, force: bool = False) -> dict:
    """A converged flow on ``mesh`` (optionally restarted from a baseline ``restart_flow.dat``)."""
    if restart_from is None:
        return _solver_run(root, "flow", base_config(HISTORY_OUTPUT=HISTORY), mesh, "SU2_CFD", force=force)
    cfg = base_config(RESTART_SOL="YES", HISTORY_OUTPUT=HISTORY)
    return _solver_run(root, "flow", cfg, mesh, "SU2_CFD", {"solution_flow.dat": restart_from}, force=force)


def adjoint(root: Path, mesh: Path, flow_dir: Path, function: str, kind: str) -> dict:
    """The ``kind`` (discrete|continuous) adjoint of ``function`` (DRAG|LIFT) at a converged flow."""
    problem = "DISCRETE_ADJOINT" if kind == "discrete" else "CONTINUOUS_ADJOINT"
    cfg = base_config(MATH_PROBLEM=problem, OBJECTIVE_FUNCTION=function)
    program = "SU2_CFD_AD" if kind == "discrete" else "SU2_CFD"
    return _solver_run(root, f"adj-{kind[:4]}-{function.lower()}", cfg, mesh, program,
                       {"solution_flow.dat": Path(flow_dir) / "restart_flow.dat"})


# ----------------------------------------------------------------------------------------------
# dJ/dX of the continuous adjoint: -S n_hat (until ffd's own reader lands)
# ----------------------------------------------------------------------------------------------

def wall_normals_2d(mesh, marker: str) -> tuple[np.ndarray, np.ndarray]:
    """SU2's unit vertex normals into the fluid at the nodes of a 2D wall marker.

    Each wall edge is oriented so that the third node of its triangle lies to its left; its normal is
    the edge vector turned +90 degrees (length = edge length, pointing into that triangle, the fluid);
    a vertex's normal is the sum of the halves of its edges' normals, then made unit.

    Returns
    -------
    ids : (K,) int, the marker's node ids (sorted)
    nhat : (K, 2) float, their unit normals
    """
    edges = np.vstack([b.data for b in mesh.markers[marker]])[:, :2].astype(np.int64)       # (E, 2)
    tris = np.vstack([np.column_stack([c.data[:, i], c.data[:, (i + 1) % c.data.shape[1]],
                                       c.data[:, (i + 2) % c.data.shape[1]]])
                      for c in mesh.cells for i in range(c.data.shape[1])]).astype(np.int64)
    # every cell edge (a, b) with one more node c of that cell: match the wall edges by sorted key
    n = len(mesh.points)
    key = np.minimum(tris[:, 0], tris[:, 1]) * n + np.maximum(tris[:, 0], tris[:, 1])
    wkey = np.minimum(edges[:, 0], edges[:, 1]) * n + np.maximum(edges[:, 0], edges[:, 1])
    order = np.argsort(key)
    pos = np.searchsorted(key[order], wkey)
    if np.any(key[order][np.minimum(pos, len(key) - 1)] != wkey):
        raise RuntimeError("a wall edge belongs to no cell")
    third = tris[order][pos, 2]
    p = mesh.points[:, :2]
    a, b = edges[:, 0], edges[:, 1]
    t = p[b] - p[a]
    left = t[:, 0] * (p[third, 1] - p[a, 1]) - t[:, 1] * (p[third, 0] - p[a, 0]) > 0
    a, b = np.where(left, a, b), np.where(left, b, a)
    t = p[b] - p[a]
    en = np.column_stack([-t[:, 1], t[:, 0]])                                              # into the fluid
    ids = np.unique(edges)
    acc = np.zeros((n, 2))
    np.add.at(acc, a, 0.5 * en)
    np.add.at(acc, b, 0.5 * en)
    nv = acc[ids]
    return ids, nv / np.linalg.norm(nv, axis=1)[:, None]


def read_surface_csv(path: Path) -> dict:
    """Columns of an SU2 surface CSV (``surface_adjoint.csv``) as float arrays, keys unquoted."""
    with open(path) as f:
        head = [h.strip().strip('"') for h in f.readline().split(",")]
    data = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    return {h: data[:, i] for i, h in enumerate(head)}


def continuous_dJdX(mesh, surface_adjoint: Path, marker: str = "airfoil") -> tuple[np.ndarray, np.ndarray, str]:
    """(ids, dJ/dX (K, 2), whose reader) = -S n_hat from the continuous adjoint's ``surface_adjoint.csv``.

    ffd's own reader (``ffdcli.io.formats.wall_normals``, from the ``optimize`` work) when the package
    has it, else :func:`wall_normals_2d` of this module."""
    cols = read_surface_csv(surface_adjoint)
    pid = (cols["Point"] if "Point" in cols else cols["PointID"]).astype(np.int64)
    try:
        from ffdcli.io.formats.wall_normals import surface_sensitivity_gradient  # noqa: PLC0415
    except ImportError:
        surface_sensitivity_gradient = None
    if surface_sensitivity_gradient is not None:
        order = np.argsort(pid)
        ids, S = pid[order], cols["Surface_Sensitivity"][order]
        return ids, surface_sensitivity_gradient(mesh, mesh.points, ids, S)[:, :2], "ffdcli.io.formats.wall_normals"
    ids, nhat = wall_normals_2d(mesh, marker)
    s = np.zeros(len(mesh.points))
    s[pid] = cols["Surface_Sensitivity"]
    return ids, -s[ids][:, None] * nhat, "benchmarks._optchain.wall_normals_2d"


def write_sens_csv(path: Path, points: np.ndarray, ids: np.ndarray, djdx: np.ndarray) -> None:
    """SU2's ``surface_sens.csv`` layout (PointID, x, y, Sensitivity_x, Sensitivity_y), 17 digits."""
    rows = np.column_stack([ids, points[ids, :2], djdx[:, :2]])
    header = '"PointID","x","y","Sensitivity_x","Sensitivity_y"'
    np.savetxt(path, rows, fmt=["%d"] + ["%.17g"] * 4, delimiter=",", header=header, comments="")


def read_of_grad(folder: Path) -> float:
    """The gradient of the one design variable in SU2_DOT's ``of_grad*`` file: the ``GRADIENT`` column
    of SU2_DOT_AD's CSV, or the number under SU2_DOT's ``DRAG gradient`` line."""
    files = sorted(Path(folder).glob("of_grad*"))
    if not files:
        raise RuntimeError(f"{folder}: no of_grad file")
    lines = [ln for ln in files[0].read_text().splitlines() if ln.strip()]
    head = [h.strip().strip('"').strip() for h in lines[0].split(",")]
    if "GRADIENT" in head:
        return float(lines[1].split(",")[head.index("GRADIENT")])
    return float(lines[1].replace(",", " ").split()[0])


# ----------------------------------------------------------------------------------------------
# (i) SU2's projection of one Hicks-Henne bump
# ----------------------------------------------------------------------------------------------

def _def_mesh(root: Path, value: float) -> Path:
    """SU2_DEF's mesh for the bump at ``value`` (cached); returns the written mesh's path."""
    cfg = base_config(DV_VALUE=value, MESH_OUT_FILENAME="mesh_out.su2")
    r = _solver_run(root, "def", cfg, _su2.NACA_MESH, "SU2_DEF")
    return Path(r["folder"]) / "mesh_out.su2"


def _dot(root: Path, adj_dir: Path, kind: str) -> float:
    """SU2_DOT (continuous) or SU2_DOT_AD (discrete) gradient of the bump for the DRAG adjoint."""
    if kind == "continuous":
        cfg = base_config(MATH_PROBLEM="CONTINUOUS_ADJOINT", OBJECTIVE_FUNCTION="DRAG")
        links = {"surface_adjoint.csv": Path(adj_dir) / "surface_adjoint.csv"}
        program = "SU2_DOT"
    else:
        cfg = base_config(MATH_PROBLEM="DISCRETE_ADJOINT", OBJECTIVE_FUNCTION="DRAG")
        links = {"solution_adj_cd.dat": Path(adj_dir) / "restart_adj_cd.dat",
                 "solution_flow.dat": Path(adj_dir) / "solution_flow.dat"}
        program = "SU2_DOT_AD"
    r = _solver_run(root, f"dot-{kind[:4]}", cfg, _su2.NACA_MESH, program, links)
    return read_of_grad(Path(r["folder"]))


def projection_check(root: Path, flow_dir: Path, adj: dict) -> list[dict]:
    """Rows of check (i): SU2's gradient of the bump, ffd's dot product and their relative difference."""
    mesh = read_mesh(_su2.NACA_MESH)
    moved = read_mesh(_def_mesh(root, HH_STEP))
    dxde = (moved.points - mesh.points)[:, :2] / HH_STEP                          # (N, 2) exact: linear
    rows = []
    for kind in ("continuous", "discrete"):
        adj_dir = Path(adj[(kind, "DRAG")]["folder"])
        su2 = _dot(root, adj_dir, kind)
        if kind == "continuous":
            ids, g, reader = continuous_dJdX(mesh, adj_dir / "surface_adjoint.csv")
            src = f"surface_adjoint.csv: -S n_hat at the wall ({reader})"
        else:
            sens = read_sensitivity(adj_dir / "restart_adj_cd.csv", mesh.points, dim=2)
            ids, g = sens.ids, sens.values[:, :2]
            src = "restart_adj_cd.csv: every node"
        ours = float(np.sum(g * dxde[ids]))
        rows.append({"adjoint": kind, "dJdX": src, "SU2": su2, "ffd": ours,
                     "relative": abs(ours - su2) / abs(su2)})
    return rows


# ----------------------------------------------------------------------------------------------
# (ii) ffd's box: ffd grad against central differences of SU2_CFD
# ----------------------------------------------------------------------------------------------

FD_VARIABLES = {  # ffd variable name -> (--set key, step)
    "c0.twist": ("changes.0.twist", TWIST_STEP),
    "c1.shape.upper[2]": ("changes.1.shape.upper.2", SHAPE_STEP),
    "c1.shape.upper[5]": ("changes.1.shape.upper.5", SHAPE_STEP),
    "c1.shape.lower[2]": ("changes.1.shape.lower.2", SHAPE_STEP),
    "c1.shape.lower[5]": ("changes.1.shape.lower.5", SHAPE_STEP),
}
QUICK_VARIABLES = ("c0.twist", "c1.shape.upper[2]")


def design_text(mesh: Path) -> str:
    """ffd's design file on SU2's NACA0012 mesh: the automatic box, twist and 2 x 8 shape variables."""
    n = BOX_POINTS[0]
    zeros = ", ".join(["0.0"] * n)
    return (f"mesh: {mesh}\nsurface: airfoil\nbox: {{points: [{BOX_POINTS[0]}, {BOX_POINTS[1]}]}}\n"
            f"changes:\n  - twist: 0.0\n  - shape: {{upper: [{zeros}], lower: [{zeros}]}}\n"
            "output: {mesh: out/design.su2}\n")


def ffd_env(ffd_path: Path | None = None) -> dict:
    """Environment running ffd from ``ffd_path`` (default: this repository)."""
    env = dict(os.environ)
    env["PYTHONPATH"] = str(ffd_path or _su2.REPO)
    return env


def ffd(*args, cwd: Path, ffd_path: Path | None = None) -> dict:
    """Run ``python -m ffdcli ARGS --json`` in ``cwd``; returns its JSON summary (raises on failure)."""
    cmd = [sys.executable, "-m", "ffdcli", *map(str, args), "--json"]
    p = subprocess.run(["nice", "-n", "5", *cmd], cwd=cwd, capture_output=True, text=True,
                       env=ffd_env(ffd_path))
    if p.returncode != 0:
        raise RuntimeError(f"ffd {' '.join(map(str, args))} failed ({p.returncode}): {p.stderr[-2000:]}")
    return json.loads(p.stdout.strip().splitlines()[-1])


def _fd_mesh(work: Path, key: str, value: float) -> Path:
    """ffd's deformed mesh with one ``--set`` (kept in ``work/meshes``; reused if already written)."""
    out = work / "meshes" / f"{key}={value!r}.su2"
    if not out.exists():
        out.parent.mkdir(parents=True, exist_ok=True)
        ffd("deform", "design.yaml", "--set", f"{key}={value!r}", "-o", out, "--cache-dir", work / "cache",
            cwd=work)
    return out


def _gradient(work: Path, sens: Path) -> dict:
    """``ffd grad design.yaml --sens SENS`` -> {variable: dJ/dv}."""
    out = ffd("grad", "design.yaml", "--sens", sens, "--cache-dir", work / "cache", cwd=work)
    return out.get("gradient", out)


def gradient_check(root: Path, flow_dir: Path, adj: dict, quick: bool = False) -> list[dict]:
    """Rows of check (ii): per function (CD, CL) and variable, the adjoints' and the FD's gradients."""
    work = Path(root) / "ffdbox"
    work.mkdir(parents=True, exist_ok=True)
    (work / "design.yaml").write_text(design_text(_su2.NACA_MESH))
    base = read_mesh(_su2.NACA_MESH)
    grads = {}
    for (kind, fn), r in adj.items():
        d = Path(r["folder"])
        suffix = {"DRAG": "cd", "LIFT": "cl"}[fn]
        if kind == "discrete":
            sens = d / f"restart_adj_{suffix}.csv"
        else:
            sens = d / "dJdX_from_S.csv"
            ids, g, _ = continuous_dJdX(base, d / "surface_adjoint.csv")
            write_sens_csv(sens, base.points, ids, g)
        grads[(kind, fn)] = _gradient(work, sens)
    restart = Path(flow_dir) / "restart_flow.dat"
    rows = []
    names = QUICK_VARIABLES if quick else tuple(FD_VARIABLES)
    for name in names:
        key, h = FD_VARIABLES[name]
        vals = {}
        for sgn in (+1, -1):
            mesh = _fd_mesh(work, key, sgn * h)
            r = flow(root / "fd", mesh, restart_from=restart)
            vals[sgn] = r["last"]
        for fn, col in (("DRAG", "CD"), ("LIFT", "CL")):
            fd = (vals[1][col] - vals[-1][col]) / (2 * h)
            row = {"function": col, "variable": name, "step": h, "fd": fd,
                   "rms_rho": max(vals[1]["rms[Rho]"], vals[-1]["rms[Rho]"])}
            for kind in ("discrete", "continuous"):
                if (kind, fn) in grads:
                    a = grads[(kind, fn)][name]
                    row[kind] = a
                    row[f"{kind}_rel"] = abs(a - fd) / max(abs(fd), 1e-12)
            rows.append(row)
    return rows


def run_chain(quick: bool = False, root: Path | None = None) -> dict:
    """Both checks; returns {"projection": rows (i), "gradient": rows (ii), "folder": root}."""
    root = Path(root or _su2.SCRATCH / "chain")
    root.mkdir(parents=True, exist_ok=True)
    f = flow(root, _su2.NACA_MESH)
    fdir = Path(f["folder"])
    adj = {}
    for kind in ("discrete", "continuous"):
        for fn in ("DRAG", "LIFT"):
            adj[(kind, fn)] = adjoint(root, _su2.NACA_MESH, fdir, fn, kind)
    return {"baseline": f["last"], "projection": projection_check(root, fdir, adj),
            "gradient": gradient_check(root, fdir, adj, quick=quick), "folder": str(root)}
