"""``ffd optimize`` on SU2's NACA0012 case: the ``--ffd`` rows (c) of ``bench_optimize``.

The design: SU2's mesh and flow (``inv_NACA0012_basic.cfg``, Euler, M 0.8, alpha 1.25 deg), ffd's
automatic box (10 x 2 control points), twist (about the trailing edge) and 2 x 9 shape variables (the
trailing-edge column left out); the constrained version bounds LIFT >= 0.328486 and MOMENT_Z >= 0 (each
with its own adjoint) and keeps t/c at 30 % chord at least the baseline's (the NACA0012's maximum
thickness station); 8 iterations of ffd's SQP with move limits (``METHOD``; scipy's SLSQP
takes full steps, which overshoot the transonic lift: docs/optimize.md).
``ffd optimize`` runs in a cached folder like the peers, in the benchmark's solver slot (one SU2 process
at a time). ``ffd_path`` points to the tree that has the command (``--ffd-path``; default this repository).
"""

from __future__ import annotations

import json
import math
import shutil
import sys
from pathlib import Path

from benchmarks import _optpeers, _su2

SHAPE_BOUND = 0.05        # chord lengths, each shape variable
TWIST_BOUND = 3.0         # degrees
POINTS = 10               # chordwise control points of the automatic box (x 2 rows)
METHOD = "SQP"            # ffd's SQP with move limits (docs/optimize.md); SLSQP: scipy's, as SU2's scripts


def design_text(adjoint: str, constrained: bool, iterations: int = _optpeers.ITERATIONS) -> str:
    """The design file of a (c) run: ``configs/naca0012_optimize.yaml`` (box 10 x 2, twist and every
    shape move but the trailing-edge column's, bounds +-3 deg and +-0.05 chord, t/c at 30 % chord >= the
    baseline's, method SQP) with the mesh and config copied beside it."""
    zeros = ", ".join(["0"] * POINTS)
    shape = [f'"c1.shape.{side}[{i}]"' for side in ("upper", "lower") for i in range(POINTS - 1)]
    lines = [
        "mesh: mesh.su2", "surface: airfoil", f"box: {{points: [{POINTS}, 2]}}", "changes:", "  - twist: 0",
        f"  - shape: {{upper: [{zeros}], lower: [{zeros}]}}",
        "bounds:", f"  c0.twist: [{-TWIST_BOUND}, {TWIST_BOUND}]",
        f"  c1.shape: [{-SHAPE_BOUND}, {SHAPE_BOUND}]",
    ]
    if constrained:
        lines += ["constraints:", "  - thickness_to_chord: {chord: [0.3], lower: 1.0}"]
    lines += ["optimize:", "  solver: su2", "  config: flow.cfg", "  objective: DRAG"]
    if constrained:
        lines += ["  functions:", f"    - {{name: LIFT, lower: {_optpeers.BOUNDS['LIFT']}}}",
                  "    - {name: MOMENT_Z, lower: 0.0}"]
    lines += [f"  variables: [c0.twist, {', '.join(shape)}]", f"  method: {METHOD}", f"  iterations: {iterations}",
              "  folder: opt/", f"  adjoint: {adjoint}", "  max_failures: 3", "output: {mesh: out/naca.su2}"]
    return "\n".join(lines) + "\n"


def flow_config() -> str:
    """SU2's basic config as the user would give it (ffd changes only mesh and output names)."""
    return _su2.cfg_set(_su2.NACA_CFG.read_text(), MESH_FILENAME="mesh.su2")


def has_optimize(ffd_path: Path) -> bool:
    """Whether the ffd tree at ``ffd_path`` has the ``optimize`` command."""
    return (Path(ffd_path) / "ffdcli" / "cli" / "optimize.py").exists()


def run_case(adjoint: str, constrained: bool, ffd_path: Path, root: Path | None = None,
             force: bool = False, only_cached: bool = False) -> dict | None:
    """Run (or reuse) ``ffd optimize`` for one row; returns the result dict with its JSON summary."""
    root, label, design, cfg, cmd, inputs = _spec(adjoint, constrained, ffd_path, root)

    def body(folder: Path) -> dict:
        shutil.copyfile(_su2.NACA_MESH, folder / "mesh.su2")
        (folder / "flow.cfg").write_text(cfg)
        (folder / "design.yaml").write_text(design)
        env = _su2.su2_env()
        env["PYTHONPATH"] = f"{ffd_path}:{env['PYTHONPATH']}"
        again = (folder / "opt" / "evals").is_dir()           # an unfinished run: ffd optimize --resume
        rc, wall = _su2.run(cmd + (["--resume"] if again else []), folder,
                            "optimize_resumed.log" if again else "optimize.log", env=env)
        log = folder / ("optimize_resumed.log" if again else "optimize.log")
        summary = None
        for line in reversed(log.read_text().splitlines()):
            if line.startswith("{"):
                try:
                    summary = json.loads(line)
                    break
                except json.JSONDecodeError:
                    continue
        return {"label": label, "rc": rc, "wall_s": wall, "summary": summary, "ffd_path": str(ffd_path),
                "resumed": again}

    return _su2.cached_run(root, label, design + cfg, inputs, cmd[2:], body, force=force,
                           only_cached=only_cached, resume=True)


def _spec(adjoint: str, constrained: bool, ffd_path: Path, root: Path | None):
    """(root, label, design text, config text, command, hashed inputs) of a (c) run."""
    root = Path(root or _su2.SCRATCH / "ffd")
    label = f"ffd-{adjoint[:4]}-{'con' if constrained else 'unc'}"
    cmd = [sys.executable, "-m", "ffdcli", "optimize", "design.yaml", "--json"]
    inputs = [_su2.NACA_MESH, *sorted(Path(ffd_path).joinpath("ffdcli").rglob("*.py"))]
    return root, label, design_text(adjoint, constrained), flow_config(), cmd, inputs


def run_folder(adjoint: str, constrained: bool, ffd_path: Path, root: Path | None = None) -> Path:
    """The folder a (c) run has (or would have), finished or not."""
    root, label, design, cfg, cmd, inputs = _spec(adjoint, constrained, ffd_path, root)
    return root / f"{label}-{_su2.case_hash(design + cfg, inputs, cmd[2:])}"


def _best_mesh(folder: Path, summary: dict) -> Path | None:
    named = [Path(summary["best_mesh"])] if summary.get("best_mesh") else []
    for cand in (*named, *sorted((folder / "opt").glob("best*.su2")), folder / "out" / "naca.su2"):
        if cand.exists():
            return cand
    return None


def ffd_row(adjoint: str, constrained: bool, result: dict) -> dict:
    """The table row of a finished (c) run, read from its JSON summary and its ``history.csv``."""
    folder = Path(result["folder"])
    s = result.get("summary") or {}
    fn = s.get("functions") or {}
    values = {"CD": fn.get("DRAG", float("nan")), "CL": fn.get("LIFT", float("nan")),
              "CMz": fn.get("MOMENT_Z", float("nan"))}
    hist = folder / "opt" / "history.csv"
    if hist.exists() and any(math.isnan(v) for v in values.values()):
        rows = _su2.read_history(hist)
        best = min((r for r in rows if not r.get("failed")), key=lambda r: r.get("DRAG", math.inf))
        values.update(CD=best.get("DRAG", values["CD"]), CL=best.get("LIFT", values["CL"]),
                      CMz=best.get("MOMENT_Z", values["CMz"]))
    mesh = _best_mesh(folder, s)
    geo = folder / "final_geometry"
    if (geo / "of_func.csv").exists():
        values["tc"] = _su2.last_history(geo / "of_func.csv")["AIRFOIL_THICKNESS"]
    elif mesh is not None:
        values["tc"] = _optpeers.airfoil_thickness(mesh, geo)
    else:
        values["tc"] = float("nan")
    viol = _optpeers.worst_violation(values)
    best = "best feasible" if constrained else "best"
    return {"run": f"(c) ffd optimize, automatic box (19), {best}", "adjoint": adjoint,
            "constrained": constrained, **values, "worst_violation": viol, "feasible": viol <= 1e-4,
            "flow": s.get("flow_solves"), "adjoint_solves": s.get("adjoint_solves"),
            "wall_s": result["wall_s"], "designs": s.get("evaluations"),
            "status": f"{s.get('status')}" + (" (resumed: wall of the last part only)"
                                              if result.get("resumed") else ""),
            "rc": result["rc"], "folder": str(folder)}


def partial_row(adjoint: str, constrained: bool, folder: Path) -> dict | None:
    """The row of an ``ffd optimize`` run that did not finish (no ``result.json``), from its evaluations'
    own ``opt/evals/*/result.json``: the best evaluation so far that meets every bound (else the last),
    the solves spent, the seconds of solver and ffd summed; ``status`` says how far it got."""
    evals = sorted((Path(folder) / "opt" / "evals").glob("*/result.json"))
    data = [json.loads(p.read_text()) for p in evals]
    done = [d for d in data if d.get("functions") and not d.get("failed")]
    if not done:
        return None

    def violation(d: dict) -> float:
        f = d["functions"]
        return _optpeers.worst_violation({"CL": f["LIFT"], "CMz": f["MOMENT_Z"], "tc": math.inf})

    ok = [d for d in done if violation(d) <= 1e-4] if constrained else done
    pick = min(ok, key=lambda d: d["functions"]["DRAG"]) if ok else done[-1]
    f = pick["functions"]
    values = {"CD": f["DRAG"], "CL": f["LIFT"], "CMz": f["MOMENT_Z"]}
    mesh = Path(folder) / "opt" / "evals" / f"{pick['index']:04d}" / "mesh.su2"
    geo = Path(folder) / f"partial_geometry_{pick['index']:04d}"
    done_geo = geo / "of_func.csv"
    values["tc"] = (_su2.last_history(done_geo)["AIRFOIL_THICKNESS"] if done_geo.exists()
                    else _optpeers.airfoil_thickness(mesh, geo))
    viol = _optpeers.worst_violation(values)
    seconds = max(p.stat().st_mtime for p in evals) - (Path(folder) / "design.yaml").stat().st_mtime
    iters = max(d.get("iteration", 0) for d in data)
    return {"run": "(c) ffd optimize, automatic box (19)", "adjoint": adjoint, "constrained": constrained,
            **values, "worst_violation": viol, "feasible": viol <= 1e-4,
            "flow": sum(d["solves"]["flow"] for d in data), "adjoint_solves": sum(d["solves"]["adjoint"] for d in data),
            "wall_s": seconds, "designs": len(data),
            "status": f"unfinished: stopped at iteration {iters} of {_optpeers.ITERATIONS}, evaluation {len(data)} "
                      f"(shown: evaluation {pick['index']}, {'best feasible' if ok else 'last'}); wall: from the "
                      "start to the last evaluation's result", "folder": str(folder)}


def last_iterate_row(adjoint: str, constrained: bool, result: dict) -> dict | None:
    """The last design the optimiser evaluated (as SU2's rows show it), beside ffd's best feasible one."""
    folder = Path(result["folder"])
    evals = sorted((folder / "opt" / "evals").glob("*/result.json"))
    done = [json.loads(p.read_text()) for p in evals]
    done = [d for d in done if d.get("functions") and not d.get("failed")]
    if not done:
        return None
    d = done[-1]
    f = d["functions"]
    values = {"CD": f["DRAG"], "CL": f["LIFT"], "CMz": f["MOMENT_Z"]}
    geo = folder / f"last_geometry_{d['index']:04d}"
    values["tc"] = (_su2.last_history(geo / "of_func.csv")["AIRFOIL_THICKNESS"] if (geo / "of_func.csv").exists()
                    else _optpeers.airfoil_thickness(folder / "opt" / "evals" / f"{d['index']:04d}" / "mesh.su2", geo))
    viol = _optpeers.worst_violation(values)
    s = result.get("summary") or {}
    return {"run": "(c) ffd optimize, automatic box (19), last iterate", "adjoint": adjoint,
            "constrained": constrained, **values, "worst_violation": viol, "feasible": viol <= 1e-4,
            "flow": s.get("flow_solves"), "adjoint_solves": s.get("adjoint_solves"), "wall_s": result["wall_s"],
            "designs": s.get("evaluations"), "status": f"evaluation {d['index']}", "rc": result["rc"],
            "folder": str(folder)}
