"""Strong scaling over MPI ranks (issue 17): embedding 1M points, the 1M-node volume warp, and
``ffd deform`` of a 1M-node mesh end to end, at 1 and 2 ranks; peak memory per rank.

Each case runs as ``mpiexec -n R python -m benchmarks.bench_mpi --child CASE ...`` (the ``[mpi]``
extra's ``mpiexec``; skipped without it). The ranks build the same inputs (same seeds), warm the
kernels up, meet at a barrier, and time the partitioned call (:func:`ffdcli.embedding.embed` with
``comm``, :func:`ffdcli.warp.warp` with ``rows`` + the gather); the time of a case is the slowest
rank's, best of ``REPEAT``. Threads: ``NUMBA_NUM_THREADS=1`` per rank for the scaling pair (1 rank x 1
thread against 2 ranks x 1 thread: parallel efficiency = t1 / (2 t2)); the 1 rank x 2 threads row is
the serial run as a user gets it on this 2-core machine. Peak RSS = VmHWM of each rank (MB), max
over ranks.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

TITLE = "MPI strong scaling: embed 1M points, warp 1M nodes, ffd deform 1M nodes (benchmarks/bench_mpi.py)"
REPO = Path(__file__).resolve().parents[1]
REPEAT = 3
NOTES = """
Runs: `mpiexec -n R` with NUMBA_NUM_THREADS=T per rank (R x T = 1x1, 2x1 for the scaling pair; 1x2 =
the serial run with both cores). Time = slowest rank, best of 3, after a warm-up; efficiency =
t(1x1) / (2 t(2x1)); target >= 80 %. Embed: 1M random points of the 8x6x2 wing lattice of bench_core
(each rank inverts its half; gather of the parameters + basis rebuild included). Warp: bench_warp's
synthetic mesh, 1M volume nodes / 50k surface nodes, IDW with rotations (each rank warps its half of
the volume nodes; gather included; the tree build `prepare` is replicated on every rank and reported
apart). Deform: `ffd deform --force --json` of bench_pipeline's 1,003,520-node SU2 wing mesh with its
box cached: wall time of the whole command (rank 0 reads and broadcasts the mesh, rank 0 writes).
The machine has 2 cores shared with other jobs: every figure is as loaded as the machine was.
"""


def _mpiexec() -> str | None:
    return shutil.which("mpiexec", path=str(Path(sys.executable).parent)) or shutil.which("mpiexec")


def _env(threads: int) -> dict:
    env = {k: v for k, v in os.environ.items() if not k.startswith(("PMI_", "OMPI_", "PMIX_"))}
    env["PYTHONPATH"] = str(REPO) + os.pathsep + env.get("PYTHONPATH", "")
    env["NUMBA_NUM_THREADS"] = str(threads)
    return env


def _peak_mb() -> float:
    with open("/proc/self/status") as fh:
        return int(next(ln for ln in fh if ln.startswith("VmHWM:")).split()[1]) / 1024


def _timed(comm, fn, repeat=REPEAT) -> float:
    best = np.inf
    for _ in range(repeat):
        comm.barrier()
        t0 = time.perf_counter()
        fn()
        dt = time.perf_counter() - t0
        best = min(best, max(comm.allgather(dt)))
    return best


def child_embed(comm, npts: int) -> dict:
    from benchmarks.bench_core import wing_control_points
    from ffdcli.embedding import embed
    from ffdcli.lattice import Lattice, evaluate

    lat = Lattice(wing_control_points((8, 6, 2)), (3, 3, 1))
    X = evaluate(lat, np.random.default_rng(0).uniform(0.0, 1.0, (npts, 3)))
    embed(lat, X[:1000], comm=comm)
    t = _timed(comm, lambda: embed(lat, X, comm=comm))
    return {"seconds": t}


def child_warp(comm, n_volume: int, n_surface: int) -> dict:
    from benchmarks.bench_warp import synthetic_mesh, twist_motion
    from ffdcli.warp import WarpSettings, prepare_warp, warp

    pts, sid, fid, areas = synthetic_mesh(n_volume, n_surface)
    b, R = twist_motion(pts[sid])
    settings = WarpSettings()
    first = len(sid) + len(fid)
    small = prepare_warp(pts[: first + 1000], sid, fid, settings=settings, areas=areas[: first + 1000])
    warp(small, b, R)
    t0 = time.perf_counter()
    model = prepare_warp(pts, sid, fid, settings=settings, areas=areas)
    t_prep = max(comm.allgather(time.perf_counter() - t0))

    def run():
        part = comm.run(warp, model, b, R, rows=comm.share(model.n_targets))
        return comm.allgather_rows(part)

    t = _timed(comm, run, repeat=2)
    return {"seconds": t, "prepare_s": t_prep}


def _child(argv) -> int:
    from ffdcli.parallel import world

    comm = world()
    case, *args = argv
    out = child_embed(comm, int(args[0])) if case == "embed" else child_warp(comm, int(args[0]), int(args[1]))
    peaks = comm.allgather(_peak_mb())
    if comm.is_root:
        out.update(ranks=comm.size, peak_mb_max=max(peaks), peak_mb=peaks)
        print(json.dumps(out))
    return 0


def _launch(ranks: int, threads: int, args: list[str], cwd=None) -> tuple[float, dict | None, str]:
    mpiexec = _mpiexec()
    t0 = time.perf_counter()
    proc = subprocess.run([mpiexec, "-n", str(ranks), sys.executable, *args], env=_env(threads), cwd=cwd,
                          capture_output=True, text=True)
    wall = time.perf_counter() - t0
    lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("{")]
    if proc.returncode != 0 or not lines:
        raise RuntimeError(f"{args} on {ranks} ranks: exit {proc.returncode}: {proc.stderr.strip()[-400:]}")
    return wall, json.loads(lines[-1]), proc.stderr


def _deform_case(folder: Path, quick: bool) -> list[dict]:
    from benchmarks.bench_pipeline import FULL, QUICK, build_case

    facts = build_case(folder, QUICK if quick else FULL)
    design = "design_idw.yaml"
    subprocess.run([sys.executable, "-m", "ffdcli", "box", design, "-q"], cwd=folder, env=_env(2), check=True)
    rows = []
    for ranks, threads in ((1, 1), (2, 1), (1, 2)):
        best, peak = np.inf, None
        for _ in range(1 if not quick else 2):
            wall, js, _ = _launch(ranks, threads, ["-c", _FFD_PEAK, "deform", design, "--force", "--json"],
                                  cwd=folder)
            best = min(best, wall)
        peak = js.get("peak_mb") if js else None
        rows.append({"case": "deform", "N": facts["nodes"], "ranks": ranks, "threads": threads,
                     "seconds": best, "peak_mb_max": peak})
    return rows


# `ffd ...` whose JSON summary also carries the peak RSS of every rank (max), for the deform rows.
_FFD_PEAK = (
    "import json, sys\n"
    "from ffdcli.cli import main\n"
    "from ffdcli.parallel import world\n"
    "import io, contextlib\n"
    "buf = io.StringIO()\n"
    "code = 0\n"
    "with contextlib.redirect_stdout(buf):\n"
    "    try:\n"
    "        main(sys.argv[1:])\n"
    "    except SystemExit as e:\n"
    "        code = e.code or 0\n"
    "comm = world()\n"
    "peak = max(comm.allgather(int(next(l for l in open('/proc/self/status') if l.startswith('VmHWM:'))"
    ".split()[1]) / 1024))\n"
    "if comm.is_root:\n"
    "    lines = [l for l in buf.getvalue().splitlines() if l.startswith('{')]\n"
    "    js = json.loads(lines[-1]) if lines else {}\n"
    "    js['peak_mb'] = peak\n"
    "    print(json.dumps(js))\n"
    "sys.exit(code)\n")


def run(quick: bool = False) -> list[dict]:
    if _mpiexec() is None:
        return [{"case": "mpi", "skipped": "the [mpi] extra is not installed (pip install -e '.[mpi]')"}]
    n_embed = 100_000 if quick else 1_000_000
    n_vol, n_surf = (100_000, 10_000) if quick else (1_000_000, 50_000)
    rows = []
    for ranks, threads in ((1, 1), (2, 1), (1, 2)):
        _, js, _ = _launch(ranks, threads, ["-m", "benchmarks.bench_mpi", "--child", "embed", str(n_embed)])
        rows.append({"case": "embed", "N": n_embed, "ranks": ranks, "threads": threads, **js})
    for ranks, threads in ((1, 1), (2, 1), (1, 2)):
        _, js, _ = _launch(ranks, threads, ["-m", "benchmarks.bench_mpi", "--child", "warp", str(n_vol),
                                            str(n_surf)])
        rows.append({"case": "warp", "N": n_vol, "ranks": ranks, "threads": threads, **js})
    with tempfile.TemporaryDirectory() as tmp:
        rows += _deform_case(Path(tmp), quick)
    return rows


def summary(rows: list[dict]) -> list[dict]:
    out = []
    by = {(r.get("case"), r.get("ranks"), r.get("threads")): r for r in rows}
    for r in rows:
        if "skipped" in r:
            out.append({"case": "MPI scaling", "measured": r["skipped"], "target": "", "pyGeo reference": ""})
            continue
        one = by.get((r["case"], 1, 1))
        eff = ""
        met = None
        if r["ranks"] == 2 and one:
            e = one["seconds"] / (2 * r["seconds"])
            eff = f", efficiency {100 * e:.0f} %"
            met = e >= 0.8
        n = f"{r['N'] / 1e6:g}M" if r["N"] >= 1_000_000 else f"{r['N'] // 1000}k"
        peak = f", {r['peak_mb_max']:.0f} MB/rank" if r.get("peak_mb_max") else ""
        out.append({"case": f"{r['case']} {n}, {r['ranks']} rank(s) x {r['threads']} thread(s)",
                    "measured": f"{r['seconds']:.3g} s{eff}{peak}",
                    "target": ">= 80 % efficiency at 2 ranks" if r["ranks"] == 2 else "",
                    "pyGeo reference": "", "met": met})
    return out


def _main(argv=None) -> int:
    ap = argparse.ArgumentParser(description="MPI strong scaling (issue 17)")
    ap.add_argument("--child", nargs="+", help=argparse.SUPPRESS)
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args(argv)
    if args.child:
        return _child(args.child)
    rows = run(args.quick)
    for row in summary(rows):
        print(f"{row['case']:<48} {row['measured']}")
    print(json.dumps(rows))
    return 0


if __name__ == "__main__":
    sys.exit(_main())
