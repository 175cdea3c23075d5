"""An ADODG Case 1 optimum evaluated on another level of the mesh family, with the optimisation's lattice.

The pitfall of Destarac et al.: an optimum that only holds on its own mesh is not an optimum. This
takes the best design of an ``ffd optimize`` run (the lowest CD among its feasible evaluations, ffd's
own rule, as ``best.yaml``), and applies its values to the finest mesh **with the same lattice**: the
run's automatic lattice is written to a Plot3D file (``ffd box --export-plot3d``) and the evaluation's
design file names it as ``box.file``: an automatic box fitted to the finer mesh takes its extent from
that mesh's sampling of the surface, so only the run's own lattice is the optimum's shape by
construction. Then:

* the lattice is checked: the run's mesh is rebuilt on its own level from the file and its wall nodes
  compared with the run's best mesh (``lattice_error``), and on the finer level the wall nodes that are
  also the run level's (the family is nested: every other node) compared with the optimum's
  (``shape_error``: the finer surface is the same continuous shape);
* the add-material rule at every wall node of the finer mesh (:mod:`benchmarks.adodg.surface`);
* SU2_CFD (``configs/adodg/case1.cfg``, the mesh changed, under ``nice -n 5``; warm-started from the
  level's baseline solution when ``--baseline-run`` holds one) gives CD, printed beside the run's CD
  and the reduction from each level's baseline (docs/adodg-case1.md).

    python -m benchmarks.adodg.evaluate --design configs/adodg/case1_v8.yaml --run out/adodg/case1_v8 \\
        --mesh out/adodg/adodg_L3.su2 --work out/adodg/eval/case1_v8 --baseline-run out/adodg/eval/baseline_L3

``--no-solve`` stops after the lattice and rule checks (no SU2). ``--baseline-run FOLDER`` solves the
undeformed finer mesh there first when it has no converged solve yet (reused by every design);
``--restart FILE`` starts from another converged solution on the same mesh instead; without either,
the solve starts from the run's own converged solution of the design prolonged to the finer mesh
(each node the inverse-distance average of its 4 nearest coarse nodes). A warm start only: the same
residual target, so the same CD to the convergence level. Run it without an outer ``nice``:
SU2 is started under ``nice -n 5`` here.
"""

from __future__ import annotations

import argparse
import copy
import csv
import json
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import yaml
from scipy.spatial import cKDTree

from benchmarks.adodg.baseline import CONFIG, SEARCH, read_solve
from benchmarks.adodg.surface import add_material, wall_nodes
from ffdcli.io.formats import read_mesh
from ffdcli.optimize.best import value_path
from ffdcli.optimize.solvers.base import find_program
from ffdcli.optimize.solvers.su2 import read_config, read_history, with_keys

BASELINE_CD = {"L0": 0.039897, "L1": 0.044669, "L2": 0.046262, "L3": 0.046695}   # docs/adodg-case1.md
TOLERANCE = 1e-6          # the case's constraint tolerance, chords
MATCH = 1e-10             # two wall nodes of two levels are the same point within this (chords)


def ffd(*args: str) -> dict:
    """Run ``ffd <args> --json`` (this interpreter's ffdcli) and return its JSON summary."""
    p = subprocess.run([sys.executable, "-m", "ffdcli", *args, "--json"], capture_output=True, text=True)
    if p.returncode != 0:
        raise RuntimeError(f"ffd {' '.join(args)} failed (exit {p.returncode}): {p.stderr.strip()[-2000:]}")
    return json.loads(p.stdout)


def level_of(mesh: Path) -> str:
    """``L3`` of ``.../adodg_L3.su2`` (the level names of benchmarks.adodg.meshes), else the stem."""
    stem = Path(mesh).stem
    return stem.rsplit("_", 1)[-1] if "_L" in stem else stem


def load_yaml(path: Path) -> dict:
    with open(path) as fh:
        return yaml.safe_load(fh)


def best_row(run: Path, feasibility: float) -> dict:
    """The run's best evaluation by ffd's rule: the lowest objective among the finished evaluations whose
    worst violation is at most ``feasibility``, else the least violating. Returns its history row with
    ``values`` (every design value of the file, in ``ffd vars`` order) from its ``result.json``."""
    with open(run / "history.csv", newline="") as fh:
        rows = [r for r in csv.DictReader(fh) if not r.get("failed")]
    if not rows:
        raise RuntimeError(f"{run / 'history.csv'}: no finished evaluation")
    feasible = [r for r in rows if float(r["violation"]) <= feasibility]
    best = (min(feasible, key=lambda r: (float(r["objective"]), int(r["evaluation"]))) if feasible else
            min(rows, key=lambda r: (float(r["violation"]), float(r["objective"]))))
    result = json.loads((run / best["folder"] / "result.json").read_text())
    return {**best, "feasible": bool(feasible), "values": [float(v) for v in result["values"]]}


def design_data(design: Path, mesh: Path, *, values: list[float] | None, names: list[str] | None,
                box_file: Path | None, output: Path) -> dict:
    """The design file's data for ``mesh`` (absolute paths), its changes set to ``values`` (by ``names``),
    its box read from ``box_file`` when given (points then come from the file), without ``optimize``."""
    data = copy.deepcopy(load_yaml(design))
    data.pop("optimize", None)
    data["mesh"] = str(Path(mesh).resolve())
    if box_file is not None:
        box = {k: v for k, v in (data.get("box") or {}).items() if k not in ("points", "margin")}
        box["file"] = str(Path(box_file).resolve())
        data["box"] = box
    data["output"] = {"mesh": str(Path(output).resolve())}
    for name, v in zip(names or [], values or [], strict=True):
        cur = data
        path = value_path(name, data)
        for key in path[:-1]:
            cur = cur[key]
        cur[path[-1]] = float(v)
    return data


def write_yaml(path: Path, data: dict) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w") as fh:
        yaml.safe_dump(data, fh, sort_keys=False, default_flow_style=None)
    return path


def export_lattice(design: Path, run_mesh: Path, work: Path) -> Path:
    """Write the run's automatic lattice (the design file's box settings on ``run_mesh``) as Plot3D."""
    yml = write_yaml(work / "box_run_level.yaml",
                     design_data(design, run_mesh, values=None, names=None, box_file=None,
                                 output=work / "unused.su2"))
    xyz = work / "lattice.xyz"
    ffd("box", str(yml), "--export-plot3d", str(xyz), "--lattice", str(work / "lattice.vtk"),
        "--cache-dir", str(work / "cache"))
    return xyz


def run_mesh_of(design: Path, run: Path, folder: str, values: list[float], names: list[str],
                work: Path) -> tuple[Path, bool]:
    """The mesh the run wrote for the evaluation in ``run/folder`` and whether it had to be rebuilt.

    A run restored from its record (``benchmarks.adodg.record``) has each evaluation's ``result.json``
    but not its mesh (meshes are not kept in git). The mesh is then made again as the run made it: the
    design file on the run's mesh with its automatic lattice and the evaluation's ``values``, written
    to ``work/run_mesh_<folder name>.su2``; the evaluation reports ``run_mesh_rebuilt``, and its
    ``lattice_error`` then compares the lattice file with the automatic lattice of the same run."""
    kept = Path(run) / folder / "mesh.su2"
    if kept.is_file():
        return kept, False
    data = load_yaml(design)
    run_mesh = (Path(design).parent / data["mesh"]).resolve()
    out = Path(work) / f"run_mesh_{Path(folder).name}.su2"
    if not out.is_file():
        ffd("deform", str(write_yaml(Path(work) / f"design_run_mesh_{Path(folder).name}.yaml",
                                     design_data(design, run_mesh, values=values, names=names, box_file=None,
                                                 output=out))),
            "--cache-dir", str(Path(work) / "cache"))
    return out, True


def wall_xy(mesh_path: Path, marker: str = "airfoil") -> np.ndarray:
    """(n, 2) wall node coordinates of ``marker``, in node-id order."""
    mesh = read_mesh(mesh_path)
    return mesh.points[wall_nodes(mesh, marker), :2]


def common_nodes(coarse: np.ndarray, fine: np.ndarray, tol: float = MATCH) -> tuple[np.ndarray, np.ndarray]:
    """Indices (i_coarse, i_fine) of the nodes two walls share (same baseline point within ``tol``)."""
    dist, idx = cKDTree(fine).query(coarse)
    hit = dist <= tol
    return np.flatnonzero(hit), idx[hit]


RESTART_MAGIC = 535532     # SU2's binary restart: int32 magic, fields, points, 0, 0; 33-byte names; float64 rows
NAME_BYTES = 33


def read_restart(path: Path) -> tuple[list[str], np.ndarray]:
    """(field names, (points, fields) values) of an SU2 binary restart file."""
    raw = Path(path).read_bytes()
    head = np.frombuffer(raw[:20], dtype=np.int32) if len(raw) >= 20 else np.zeros(1, dtype=np.int32)
    if head[0] != RESTART_MAGIC:
        raise ValueError(f"{path}: not an SU2 binary restart file (no {RESTART_MAGIC} at its start)")
    nf, npt = int(head[1]), int(head[2])
    names = [raw[20 + NAME_BYTES * k:20 + NAME_BYTES * (k + 1)].split(b"\0")[0].decode() for k in range(nf)]
    off = 20 + NAME_BYTES * nf
    if len(raw) < off + 8 * nf * npt:
        raise ValueError(f"{path}: {npt} points x {nf} fields announced, the file is shorter")
    return names, np.frombuffer(raw[off:off + 8 * nf * npt], dtype=np.float64).reshape(npt, nf).copy()


def write_restart(path: Path, names: list[str], values: np.ndarray) -> None:
    """Write an SU2 binary restart file (the layout :func:`read_restart` reads)."""
    head = np.array([RESTART_MAGIC, len(names), len(values), 0, 0], dtype=np.int32).tobytes()
    labels = b"".join(n.encode().ljust(NAME_BYTES, b"\0") for n in names)
    Path(path).write_bytes(head + labels + np.ascontiguousarray(values, dtype=np.float64).tobytes())


def prolong_restart(coarse: Path, fine_mesh: Path, out: Path, k: int = 4) -> Path:
    """A starting solution for ``fine_mesh`` from a converged one on a coarser mesh of the family: each
    fine node gets the inverse-distance average of its ``k`` nearest coarse nodes (a shared node its
    coarse value exactly). Only a warm start: the fine solve converges to its own residual target."""
    names, values = read_restart(coarse)
    xy_c = values[:, [names.index("x"), names.index("y")]]
    xy_f = read_mesh(fine_mesh).points[:, :2]
    dist, idx = cKDTree(xy_c).query(xy_f, k=k)
    w = 1.0 / np.maximum(dist, 1e-300)
    exact = dist[:, 0] <= 1e-12
    w[exact] = 0.0
    w[exact, 0] = 1.0
    w /= w.sum(axis=1, keepdims=True)
    fine = np.einsum("nk,nkf->nf", w, values[idx])
    fine[:, names.index("x")], fine[:, names.index("y")] = xy_f[:, 0], xy_f[:, 1]
    write_restart(out, names, fine)
    return out


def solve(mesh: Path, folder: Path, restart: Path | None = None) -> dict:
    """SU2_CFD (case1.cfg, ``mesh``) in ``folder`` under nice -n 5, warm-started from ``restart``
    (a converged solution on a mesh of the same nodes) when given; CD, iterations, residual, times."""
    program = find_program("SU2_CFD", "SU2_RUN", SEARCH)
    if program is None:
        raise RuntimeError("SU2_CFD not found (SU2_RUN, PATH or ../shared/su2/bin)")
    folder.mkdir(parents=True, exist_ok=True)
    keys = {"MESH_FILENAME": str(Path(mesh).resolve())}
    if restart is not None:
        keys.update(RESTART_SOL="YES", SOLUTION_FILENAME=str(Path(restart).resolve()))
    (folder / "flow.cfg").write_text(with_keys(read_config(CONFIG), keys))
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    with open(folder / "log.txt", "w") as log:
        subprocess.run(["nice", "-n", "5", str(program), "flow.cfg"], cwd=folder, stdout=log,
                       stderr=subprocess.STDOUT, check=True)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    (folder / "run.json").write_text(json.dumps({"wall": wall, "cpu": cpu, "mesh": str(mesh),
                                                 "restart": None if restart is None else str(restart)}))
    return solved(folder, mesh)


#: iterations over which an unconverged solve's CD is averaged (its range reported beside the mean)
TAIL = 2000


def solved(folder: Path, mesh: Path) -> dict:
    """The solve in ``folder``: CD and CL of a solve converged to 1e-12, or, for one that ran to its
    iteration limit without converging (a flow that settles into a limit cycle), the mean CD and CL of
    its last ``TAIL`` iterations with the CD range over them and ``converged`` False, so the evaluation
    says so instead of quoting the last iterate. Raises when there is no finished solve."""
    hist = read_history(folder / "history.csv")
    if hist["rms[Rho]"][-1] <= -12 + 1e-9:
        s = read_solve(level_of(mesh), folder, mesh)
        return {"cd": s.cd, "cl": s.cl, "iterations": s.iterations, "residual": s.residual,
                "wall": s.wall, "cpu": s.cpu, "folder": str(folder), "converged": True}
    times = json.loads((folder / "run.json").read_text())
    cd, cl = np.asarray(hist["CD"])[-TAIL:], np.asarray(hist["CL"])[-TAIL:]
    return {"cd": float(cd.mean()), "cl": float(cl.mean()), "cd_range": [float(cd.min()), float(cd.max())],
            "iterations": int(hist["Inner_Iter"][-1]) + 1, "residual": float(hist["rms[Rho]"][-1]),
            "wall": times["wall"], "cpu": times["cpu"], "folder": str(folder), "converged": False}


def reuse_or_solve(mesh: Path, folder: Path, restart: Path | None = None) -> dict:
    """A converged solve of ``mesh`` already in ``folder`` (same mesh), else a new one."""
    meta = folder / "run.json"
    if meta.is_file() and json.loads(meta.read_text()).get("mesh") == str(mesh):
        try:
            return solved(folder, mesh)             # finished: converged, or at its iteration limit
        except (RuntimeError, FileNotFoundError, KeyError):
            pass
    return solve(mesh, folder, restart)


def evaluate(design: Path, run: Path, mesh: Path, work: Path, *, baseline_run: Path | None = None,
             restart: Path | None = None, run_solve: bool = True) -> dict:
    """Evaluate the run's best design on ``mesh``; see the module docstring. Returns the summary."""
    data = load_yaml(design)
    run_mesh = (design.parent / data["mesh"]).resolve()
    feasibility = float((data.get("optimize") or {}).get("feasibility", 1e-4))
    best = best_row(run, feasibility)
    names = [v["name"] for v in ffd("vars", str(design))["variables"]]
    work.mkdir(parents=True, exist_ok=True)
    xyz = export_lattice(design, run_mesh, work)
    out: dict = {"design": str(design), "run": str(run), "evaluation": int(best["evaluation"]),
                 "feasible": best["feasible"], "violation": float(best["violation"]),
                 "run_level": level_of(run_mesh), "level": level_of(mesh), "values": dict(zip(names, best["values"]))}
    out["cd_run"] = float(best["objective"])

    # the run's own level rebuilt from the lattice file: the same wall as the run's best mesh?
    own = work / f"{out['run_level']}.su2"
    ffd("deform", str(write_yaml(work / f"design_{out['run_level']}.yaml",
                                 design_data(design, run_mesh, values=best["values"], names=names, box_file=xyz,
                                             output=own))), "--cache-dir", str(work / "cache"))
    run_best, out["run_mesh_rebuilt"] = run_mesh_of(design, run, best["folder"], best["values"], names, work)
    out["lattice_error"] = float(np.abs(wall_xy(own) - wall_xy(run_best)).max())

    # the finer level with the same lattice
    fine = work / f"{out['level']}.su2"
    rep = ffd("deform", str(write_yaml(work / f"design_{out['level']}.yaml",
                                       design_data(design, mesh, values=best["values"], names=names, box_file=xyz,
                                                   output=fine))), "--cache-dir", str(work / "cache"))
    out["outside"] = rep.get("outside", rep.get("box", {}).get("outside") if isinstance(rep.get("box"), dict) else None)
    base_c, base_f = wall_xy(run_mesh), wall_xy(mesh)
    ic, jf = common_nodes(base_c, base_f)
    des_c, des_f = wall_xy(run_best), wall_xy(fine)
    out["common_nodes"] = int(len(ic))
    out["shape_error"] = float(np.abs(des_c[ic] - des_f[jf]).max())
    rule = add_material(base_f, des_f)
    out["rule"] = {"nodes": rule.nodes, "upper": rule.upper, "lower": rule.lower, "thickness": rule.thickness,
                   "met": bool(rule.margin >= -TOLERANCE)}
    rule_run = add_material(base_c, des_c)
    out["rule_run_level"] = {"nodes": rule_run.nodes, "upper": rule_run.upper, "lower": rule_run.lower,
                             "met": bool(rule_run.margin >= -TOLERANCE)}
    lvl = out["level"]
    if run_solve:
        if baseline_run is not None:
            b = reuse_or_solve(Path(mesh).resolve(), baseline_run)
            out["baseline"] = b
            restart = baseline_run / "restart_flow.dat"
        elif restart is None and (run / best["folder"] / "restart_flow.dat").is_file():
            (work / "su2").mkdir(parents=True, exist_ok=True)
            restart = prolong_restart(run / best["folder"] / "restart_flow.dat", fine, work / "su2" / "prolonged.dat")
        out["warm_start"] = None if restart is None else str(restart)
        s = reuse_or_solve(fine.resolve(), work / "su2", restart)
        out["solve"] = s
        out["cd"] = s["cd"]
    for key, level in (("run", out["run_level"]), ("", lvl)):
        cd = out["cd_run"] if key == "run" else out.get("cd")
        if cd is not None and level in BASELINE_CD:
            out[f"reduction{'_' + key if key else ''}"] = 1.0 - cd / BASELINE_CD[level]
    (work / "evaluation.json").write_text(json.dumps(out, indent=1))
    return out


def summary(out: dict) -> str:
    """Plain-text lines of an evaluation."""
    r = out["rule"]
    lines = [f"{out['design']}: evaluation {out['evaluation']} of {out['run']} "
             f"({'feasible' if out['feasible'] else 'INFEASIBLE'}, worst violation {out['violation']:.1e})",
             f"lattice: the run's {out['run_level']} wall rebuilt from the lattice file to {out['lattice_error']:.1e}; "
             f"{out['level']} at the {out['common_nodes']} shared wall nodes equal to the optimum to "
             f"{out['shape_error']:.1e}",
             f"add-material rule on {out['level']}: {r['nodes']} wall nodes, upper y - y0 >= {r['upper']:.3e}, "
             f"lower y0 - y >= {r['lower']:.3e}, thickness - t0 >= {r['thickness']:.3e} (chords): "
             f"{'met' if r['met'] else 'VIOLATED'} to 1e-6 chord",
             f"CD on {out['run_level']} {out['cd_run']:.6f} "
             f"(reduction {100 * out.get('reduction_run', float('nan')):.1f} % "
             f"from {BASELINE_CD.get(out['run_level'], float('nan')):.6f})"]
    if "cd" in out:
        s = out["solve"]
        lines.append(f"CD on {out['level']} {out['cd']:.6f} "
                     f"(reduction {100 * out.get('reduction', float('nan')):.1f} % "
                     f"from {BASELINE_CD.get(out['level'], float('nan')):.6f}); {s['iterations']} iterations, "
                     f"rms[Rho] {s['residual']:.1f}, {s['wall']:.0f} s wall, {s['cpu']:.0f} s CPU")
        if not s.get("converged", True):
            lo, hi = s["cd_range"]
            lines.append(f"NOT CONVERGED on {out['level']}: CD above is the mean of the last {TAIL} iterations "
                         f"(range {lo:.6f} ... {hi:.6f})")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.adodg.evaluate", description=__doc__.split("\n")[0])
    ap.add_argument("--design", type=Path, required=True, help="the run's design file (configs/adodg/case1*.yaml)")
    ap.add_argument("--run", type=Path, required=True, help="the run's folder (optimize.folder: history.csv, evals/)")
    ap.add_argument("--mesh", type=Path, required=True, help="the level to evaluate on (e.g. out/adodg/adodg_L3.su2)")
    ap.add_argument("--work", type=Path, help="where to write (default: <run>_<level>)")
    ap.add_argument("--baseline-run", type=Path, help="folder of the level's baseline solve (solved there if absent); "
                                                      "the design's solve starts from its solution")
    ap.add_argument("--restart", type=Path, help="start the solve from this converged solution (restart_flow.dat) of "
                                               "a design on the same mesh (e.g. another lattice's evaluation)")
    ap.add_argument("--no-solve", action="store_true", help="only the lattice and rule checks (no SU2)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    work = args.work or args.run.with_name(f"{args.run.name}_{level_of(args.mesh)}")
    out = evaluate(args.design, args.run, args.mesh, work, baseline_run=args.baseline_run,
                   restart=args.restart, run_solve=not args.no_solve)
    print(json.dumps(out, indent=1) if args.json else summary(out))
    return 0 if out["rule"]["met"] else 1


if __name__ == "__main__":
    sys.exit(main())
