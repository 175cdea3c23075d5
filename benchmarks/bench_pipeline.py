"""End to end: `ffd deform` of a 1M-node wing mesh whose box is cached, and the volume warp
on that real mesh.

The mesh: :func:`ffdcli.testing.wings.extruded_wing_mesh` of a tapered (0.5), swept (20 deg) NACA 0012 wing,
semi-span 3 (chord x, thickness y, span z): a structured hexahedral O-grid volume mesh,
``n_around=257, n_radial=20, n_span=196`` = 1,003,520 nodes, 50,176 of them on the marker ``wing``
(markers wing, farfield, symmetry, side), written as SU2 to a temporary folder. ``ffd box`` builds and
caches the 8 x 6 x 2 lattice once (untimed for the deform rows, reported as its own row); then:

* ``ffd deform design.yaml --json --force`` as a user runs it (a fresh process that reads the mesh,
  loads the cached box, applies ``twist: {tip: 5}``, moves the volume, checks quality and writes the
  SU2 mesh and the lattice VTK), once with ``volume.method: idw`` and once with ``none``. The time
  is the wall time of the process (interpreter start-up and imports included; ``cmd s`` is the
  command's own ``seconds``), peak RSS is that process's VmHWM (printed at exit by a small wrapper
  around ``python -m ffdcli``: ``ru_maxrss`` would include the parent's peak, inherited at exec).
* the same steps in one child process through :mod:`ffdcli.app.pipeline`, timed per phase: ``read+box``
  (``load_design`` + ``load_run``: read the mesh, load the cached box), ``changes`` / ``volume`` /
  ``quality`` (``Deformation.seconds`` of :func:`ffdcli.app.pipeline.deform`) and ``write``
  (``write_outputs``).
* the volume warp on this mesh: the ``volume`` phase of that run (:func:`ffdcli.volume.warp.prepare_mesh_warp`,
  the surface rotations and :func:`ffdcli.volume.warp.warp`). ``python -m benchmarks.bench_pipeline --warp
  DESIGN.yaml`` times prepare and warp separately, ``--warp-error DESIGN.yaml [N]`` compares the warp with
  the exact sum on N ranges of 300 volume nodes (not part of the table).
"""

from __future__ import annotations

import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

TITLE = "End to end: ffd deform of a cached-box wing mesh and its volume warp (benchmarks/bench_pipeline.py)"

REPO = Path(__file__).resolve().parents[1]
FULL = dict(n_around=257, n_radial=20, n_span=196)      # 1,003,520 nodes, 50,176 on the wing
QUICK = dict(n_around=129, n_radial=12, n_span=40)      # 61,440 nodes, 5,120 on the wing
TARGET_DEFORM = "<= 20 s"
TARGET_WARP = "<= 30 s, <= 4 GB"

NOTES = """
Mesh: `extruded_wing_mesh(Planform(taper=0.5, le_sweep_deg=20), n_around=257, n_radial=20,
n_span=196)` = 1,003,520 hex-mesh nodes, 50,176 wing nodes, written as SU2 (ASCII). Design: box
8 x 6 x 2 (sections xy), `twist: {tip: 5}`, output SU2 + lattice VTK; the box is built and cached once
by `ffd box design.yaml` before the timed runs. `ffd deform` rows: wall time of the whole process
(start-up, read, cached box, changes, volume, quality check, write), the faster of two runs (the
slower beside it, and the load average before and after), peak RSS (VmHWM) of that process. Phase
rows: the same steps through `ffdcli.app.pipeline` in one process (`Deformation.seconds` per phase).
Volume-phase row: the `volume` phase (prepare_mesh_warp + surface rotations + warp, IDW with rotations,
default tolerance) of the idw phases run.
Targets: deform + write of a 1M-node mesh with a cached box <= 20 s; the volume phase of 1M volume
nodes / 50k surface nodes <= 30 s and <= 4 GB. No pyGeo reference measured for these.
"""


def build_case(folder: Path, sizes: dict) -> dict:
    """Write ``wing.su2`` and the design files into ``folder``; returns mesh facts."""
    import numpy as np

    from ffdcli.io.formats import write_mesh
    from ffdcli.testing.wings import Planform, extruded_wing_mesh

    t0 = time.perf_counter()
    mesh = extruded_wing_mesh(Planform(semi_span=3.0, taper=0.5, le_sweep_deg=20.0), **sizes)
    t_build = time.perf_counter() - t0
    write_mesh(mesh, folder / "wing.su2")
    facts = {"nodes": len(mesh.points), "cells": mesh.n_cells,
             "wing_nodes": int(np.unique(mesh.markers["wing"][0].data).size),
             "build_s": t_build, "write_s": time.perf_counter() - t0 - t_build,
             "MB": (folder / "wing.su2").stat().st_size / 2**20}
    (folder / "out").mkdir(exist_ok=True)
    for method in ("idw", "none"):
        (folder / f"design_{method}.yaml").write_text(
            "mesh: wing.su2\n"
            "surface: wing\n"
            "box:\n  points: [8, 6, 2]\n  sections: xy\n"
            f"volume:\n  method: {method}\n"
            "changes:\n  - twist: {tip: 5}\n"
            f"output:\n  mesh: out/wing_{method}.su2\n  lattice: out/wing_{method}_lattice.vtk\n")
    return facts


def _env() -> dict:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(REPO) + os.pathsep + env.get("PYTHONPATH", "")
    return env


# `python -m ffdcli ...` that also writes its own peak RSS (VmHWM, read at exit) to stderr:
# ru_maxrss of a child (os.wait4) would include the parent's peak, inherited at exec.
_FFD = ("import atexit, runpy, sys\n"
        "def _peak():\n"
        "    with open('/proc/self/status') as fh:\n"
        "        kb = next(ln for ln in fh if ln.startswith('VmHWM:')).split()[1]\n"
        "    sys.stderr.write(f'\\nVMHWM_KB {kb}\\n')\n"
        "atexit.register(_peak)\n"
        "sys.argv = ['ffd'] + sys.argv[1:]\n"
        "runpy.run_module('ffdcli', run_name='__main__')\n")


def peak_mb() -> float:
    """This process's peak RSS (VmHWM), MB."""
    with open("/proc/self/status") as fh:
        return int(next(ln for ln in fh if ln.startswith("VmHWM:")).split()[1]) / 1024


def ffd(args: list[str], cwd: Path) -> dict:
    """``ffd args...`` in a fresh process: as :func:`timed_process`, with its own peak RSS."""
    return timed_process(["-c", _FFD, *args], cwd)


def timed_process(args: list[str], cwd: Path) -> dict:
    """Run ``python args...``; wall seconds, peak RSS (MB, VmHWM as printed by the child, else
    ``ru_maxrss``), exit code and its last stdout line starting with ``{`` as JSON."""
    with tempfile.TemporaryFile("w+") as out, tempfile.TemporaryFile("w+") as err:
        t0 = time.perf_counter()
        proc = subprocess.Popen([sys.executable, *args], cwd=cwd, env=_env(), stdout=out, stderr=err,
                                text=True)
        # os.wait4 gives this child's own rusage (RUSAGE_CHILDREN would be the max over all children)
        _, status, usage = os.wait4(proc.pid, 0)
        wall = time.perf_counter() - t0
        proc.returncode = os.waitstatus_to_exitcode(status)
        out.seek(0)
        err.seek(0)
        stdout, stderr = out.read(), err.read()
    hwm = [ln.split()[1] for ln in stderr.splitlines() if ln.startswith("VMHWM_KB ")]
    rss = int(hwm[-1]) / 1024 if hwm else usage.ru_maxrss / 1024
    lines = [ln for ln in stdout.strip().splitlines() if ln.startswith("{")]
    if not lines:
        raise RuntimeError(f"{' '.join(args)} exit {proc.returncode}: {stderr.strip().splitlines()[-1:]}")
    return {"wall": wall, "rss_mb": rss, "rc": proc.returncode,
            "json": json.loads(lines[-1])}


def phases(design: str) -> dict:
    """In this process: the steps of `ffd deform` through the library, timed per phase."""
    from ffdcli.app.deformation import deform
    from ffdcli.app.run import load_run
    from ffdcli.app.write import write_outputs
    from ffdcli.design import load_design

    t0 = time.perf_counter()
    d = load_design(design)
    run = load_run(d)
    t1 = time.perf_counter()
    Path(d.output["mesh"]).parent.mkdir(parents=True, exist_ok=True)
    result = deform(run)
    t2 = time.perf_counter()
    write_outputs(run, result)
    t3 = time.perf_counter()
    return {"read+box": t1 - t0, **result.seconds, "write": t3 - t2, "total": t3 - t0,
            "from_cache": run.prep.from_cache,
            "peak_mb": peak_mb()}


def warp_only(design: str) -> dict:
    """In this process: prepare_mesh_warp and warp of the design's surface motion on its mesh."""
    from ffdcli.app.run import load_run
    from ffdcli.design import load_design
    from ffdcli.volume.warp import WarpSettings, prepare_mesh_warp, warp

    run = load_run(load_design(design))
    mesh, surf = run.prep.mesh, run.prep.surface
    P1 = run.lattice_after()
    disp, rot = run.surface_displacement(P1), run.surface_frames(P1)
    t0 = time.perf_counter()
    model, _ = prepare_mesh_warp(mesh, list(surf.names), WarpSettings())
    t1 = time.perf_counter()
    c0 = resource.getrusage(resource.RUSAGE_SELF)
    t2 = time.perf_counter()
    warp(model, disp, rot)
    t3 = time.perf_counter()
    c1 = resource.getrusage(resource.RUSAGE_SELF)
    cpu = (c1.ru_utime + c1.ru_stime) - (c0.ru_utime + c0.ru_stime)
    return {"volume_nodes": int(model.n_targets), "surface_nodes": int(model.n_surface),
            "prepare": t1 - t0, "warp": t3 - t2, "warp_cpu": cpu,
            "peak_mb": peak_mb()}


def warp_error(design: str, n_ranges: int = 60, size: int = 300) -> dict:
    """The tree warp against the exact sum on ``n_ranges`` row ranges of ``size`` volume nodes spread over
    the mesh (Morton order: each range is a small neighbourhood), relative to the largest surface move.

    ``python -m benchmarks.bench_pipeline --warp-error DESIGN.yaml [N_RANGES]``; the design of
    :func:`build_case` (a 5 degree tip twist on the 1M extruded wing) gave 7.4e-4 at the default
    tolerance with 60 ranges (docs/BENCHMARKS.md).
    """
    import numpy as np

    from ffdcli.app.run import load_run
    from ffdcli.design import load_design
    from ffdcli.volume.warp import WarpSettings, prepare_mesh_warp, warp

    run = load_run(load_design(design))
    P1 = run.lattice_after()
    disp, rot = run.surface_displacement(P1), run.surface_frames(P1)
    model, _ = prepare_mesh_warp(run.prep.mesh, list(run.prep.surface.names), WarpSettings())
    d = warp(model, disp, rot)
    scale = float(np.abs(disp).max())
    errs = []
    for lo in np.linspace(0, model.n_targets - size, n_ranges).astype(int):
        exact = warp(model, disp, rot, exact=True, rows=(int(lo), int(lo) + size))
        errs.append(float(np.abs(exact - d[model.target_ids[lo:lo + size]]).max()) / scale)
    return {"ranges": n_ranges, "size": size, "err_max": max(errs), "err_median": float(np.median(errs)),
            "err_p90": float(np.quantile(errs, 0.9))}


def run(quick: bool = False) -> list[dict]:
    sizes = QUICK if quick else FULL
    repeats = 2      # min and max of two runs of each deform (the machine is shared: its load is shown)
    rows = []
    with tempfile.TemporaryDirectory(prefix="ffd-bench-pipeline-") as tmp:
        folder = Path(tmp)
        facts = build_case(folder, sizes)
        size = f"{facts['nodes'] / 1e6:.2f}M nodes / {facts['wing_nodes'] / 1e3:.0f}k wing"
        rows.append({"case": f"make the mesh ({size}, {facts['MB']:.0f} MB SU2)",
                     "measured": f"{facts['build_s']:.1f} s build + {facts['write_s']:.1f} s write",
                     "target": "", "pyGeo reference": "", "met": None, "detail": "untimed setup"})
        box = ffd(["box", "design_idw.yaml", "--json"], folder)
        rows.append({"case": "ffd box design.yaml (once: fit, embed, write cache)",
                     "measured": f"{box['wall']:.1f} s, {box['rss_mb']:.0f} MB",
                     "target": "", "pyGeo reference": "",
                     "detail": f"outside {box['json'].get('outside')}, residual "
                               f"{box['json'].get('residual', float('nan')):.1e}, "
                               f"cmd {box['json'].get('seconds')} s"})
        for method in ("idw", "none"):
            load0 = os.getloadavg()[0]
            runs = [ffd(["deform", f"design_{method}.yaml", "--json", "--force"], folder)
                    for _ in range(repeats)]
            load1 = os.getloadavg()[0]
            best = min(runs, key=lambda r: r["wall"])
            j = best["json"]
            q = j.get("quality") or {}
            walls = ", ".join(format(r["wall"], ".1f") for r in runs)
            rows.append({"case": f"ffd deform, volume {method} ({size})",
                         "measured": f"{best['wall']:.1f} s (max of {len(runs)} "
                                     f"{max(r['wall'] for r in runs):.1f} s), {best['rss_mb']:.0f} MB; "
                                     f"load {load0:.1f}-{load1:.1f} on {os.cpu_count()} cores",
                         "target": TARGET_DEFORM if not quick else "",
                         "pyGeo reference": "",
                         "met": (best["wall"] <= 20.0 and best["rc"] == 0) if not quick else None,
                         "detail": f"cmd {j.get('seconds')} s; runs {walls} s; "
                                   f"from_cache {j.get('from_cache')}; quality ok {q.get('ok')}"
                                   + ("" if best["rc"] == 0 else f"; exit {best['rc']}")})
        for method in ("idw", "none"):
            ph = timed_process(["-m", "benchmarks.bench_pipeline", "--phases",
                                str(folder / f"design_{method}.yaml")], REPO)["json"]
            parts = ", ".join(f"{k} {ph[k]:.1f}" for k in ("read+box", "changes", "volume", "quality",
                                                            "write") if k in ph)
            rows.append({"case": f"  phases, volume {method} (in one process)",
                         "measured": f"{ph['total']:.1f} s, {ph['peak_mb']:.0f} MB",
                         "target": "", "pyGeo reference": "", "detail": parts + " s"})
            if method == "idw":
                phase_idw = ph
        ph = phase_idw
        rows.append({"case": f"volume phase alone: prepare_mesh_warp + warp on this mesh ("
                             f"{facts['nodes'] / 1e6:.2f}M nodes / {facts['wing_nodes'] / 1e3:.0f}k surface)",
                     "measured": f"{ph['volume']:.1f} s, {ph['peak_mb']:.0f} MB (whole deform process)",
                     "target": TARGET_WARP if not quick else "", "pyGeo reference": "",
                     "met": (ph["volume"] <= 30.0 and ph["peak_mb"] <= 4096) if not quick else None,
                     "detail": "Deformation.seconds['volume'] of the idw phases row"})
    return rows


if __name__ == "__main__":
    if len(sys.argv) == 3 and sys.argv[1] == "--phases":
        print(json.dumps(phases(sys.argv[2])))
    elif len(sys.argv) == 3 and sys.argv[1] == "--warp":
        print(json.dumps(warp_only(sys.argv[2])))
    elif len(sys.argv) in (3, 4) and sys.argv[1] == "--warp-error":
        print(json.dumps(warp_error(sys.argv[2], *(int(a) for a in sys.argv[3:]))))
    else:
        for row in run("--quick" in sys.argv):
            print(json.dumps(row))
