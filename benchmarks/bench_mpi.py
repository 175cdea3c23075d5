"""Strong scaling over MPI ranks: embedding 1M points, the 1M-node volume warp, reading a
1M-node mesh by parts (SU2 and CGNS, against rank 0 reading and broadcasting it), the quality gate on
the parts, and ``ffd deform`` of the 1M-node mesh end to end, at 1 and 2 ranks; peak memory per rank,
and (case ``memory``) ``ffd deform``'s pipeline at 1, 2 and 4 ranks on local meshes and at 2 with every
node on every rank: RSS and peak per phase, the arrays held by owner, the rows per rank.

Each case runs as ``mpiexec -n R python -m benchmarks.bench_mpi --child CASE ...`` (the ``[mpi]``
extra's ``mpiexec``; skipped without it). The ranks build the same inputs (same seeds), warm the
kernels up, meet at a barrier, and time the partitioned call; the time of a run is the slowest
rank's, best of its repeats. Every case runs at 1 rank x 1 thread and 2 ranks x 1 thread
(``NUMBA_NUM_THREADS=1``: parallel efficiency = t1 / (2 t2)) ALTERNATELY, ``ROUNDS`` times, so that
both see the same load; the table gives the min and max over the rounds and the efficiency of the
minima. The 1 rank x 2 threads row (once) is the serial run as a user gets it on this machine. Peak
RSS = VmHWM of each rank (MB), max over ranks. The load average is printed beside the figures.
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

TITLE = ("MPI strong scaling: embed 1M points, warp 1M nodes, read and gate a 1M-node mesh by parts, "
         "ffd deform 1M nodes (benchmarks/bench_mpi.py)")
REPO = Path(__file__).resolve().parents[1]
REPEAT = 3
ROUNDS = 2
SCALING = ((1, 1), (2, 1))
NOTES = """
Runs: `mpiexec -n R` with NUMBA_NUM_THREADS=T per rank; 1x1 and 2x1 alternate ROUNDS times (min and
max given), 1x2 (the serial run with both cores) once. Time = slowest rank, best of its repeats, after
a warm-up; efficiency = min t(1x1) / (2 min t(2x1)); target >= 80 %. Embed: 1M random points of the
8x6x2 wing lattice of bench_core (each rank inverts its half; the all-gather that gives every rank the
whole embedding included); embed own share: each rank embeds its half and keeps it (pyGeo's model of
point sets per partition, ffd's `DesignModel(comm=)` point sets). Warp: bench_warp's
synthetic mesh, 1M volume / 50k surface nodes (each rank warps its half of the volume nodes; gather
included; the replicated tree build is reported apart). Read: bench_pipeline's 1,003,520-node hex wing
mesh as SU2 and as CGNS/HDF5, `read_part` (each rank parses its block of the point rows and of the
element rows; nodes sent to their owners, cells to their nodes' owners, halo and marker coordinates
fetched: the rank's local mesh) against `bcast` (rank 0 reads the whole mesh and broadcasts it, each
rank then localizes it: the route of VTK and ADF CGNS); also once at 4 ranks (oversubscribed: for the
memory per rank, its time means nothing). "held" = the local mesh's and part's arrays, max over ranks.
Gate: the quality gate of a smoothly
moved copy of that mesh (scaled Jacobian + node orthogonality, the input's reference included), each
rank on its part. Deform: `ffd deform --force --json` of the SU2 mesh with its box cached: wall time
of the whole command. Memory: load_run / deform / write_outputs of that design, once per row (1, 2, 4
ranks x 1 thread on local meshes, 2 ranks with every node; 4 ranks oversubscribe the cores: memory,
not time). The machine has 2 cores shared with other jobs: every figure is as loaded as
the machine was (load average in the table).
"""


#: What a child reports that the table keeps.
KEPT = ("prepare_s", "part_cells", "cells", "held_mb", "local_nodes", "nodes")


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


def _rss_mb() -> float:
    with open("/proc/self/status") as fh:
        return int(next(ln for ln in fh if ln.startswith("VmRSS:")).split()[1]) / 1024


def _timed(comm, fn, repeat=REPEAT) -> float:
    best = np.inf
    for _ in range(repeat):
        comm.barrier()
        t0 = time.perf_counter()
        fn()
        dt = time.perf_counter() - t0
        best = min(best, max(comm.allgather(dt)))
    return best


def child_embed(comm, npts: int, own: bool = False) -> dict:
    from benchmarks.bench_core import wing_control_points
    from ffdcli.lattice.embedding import embed
    from ffdcli.lattice.lattice import Lattice, evaluate

    lat = Lattice(wing_control_points((8, 6, 2)), (3, 3, 1))
    X = evaluate(lat, np.random.default_rng(0).uniform(0.0, 1.0, (npts, 3)))
    embed(lat, X[:1000], comm=comm)
    if own:             # pyGeo's model: each rank embeds the points of its partition and keeps them
        lo, hi = comm.share(npts)
        return {"seconds": _timed(comm, lambda: embed(lat, X[lo:hi]))}
    t = _timed(comm, lambda: embed(lat, X, comm=comm))
    return {"seconds": t}


def child_warp(comm, n_volume: int, n_surface: int) -> dict:
    from benchmarks.bench_warp import synthetic_mesh, twist_motion
    from ffdcli.volume.warp import WarpSettings, prepare_warp, warp

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


def child_read(comm, path: str, mode: str) -> dict:
    from ffdcli.io.formats import read_mesh, read_part
    from ffdcli.parallel.partition import localize, node_owners

    def once():
        if mode == "bcast":          # the route of the formats read whole (VTK, ADF CGNS)
            mesh = comm.root_then_bcast(read_mesh, path)
            return localize(mesh, node_owners(mesh.points, comm.size), comm.rank)
        return read_part(path, comm)

    mesh, part = once()
    del mesh, part
    t = _timed(comm, lambda: once(), repeat=2)
    mesh, part = once()
    cells = comm.allgather(sum(len(b) for b in part.cells))
    held = mesh.points.nbytes + mesh.global_ids.nbytes + sum(b.data.nbytes for b in mesh.cells) + \
        sum(b.data.nbytes for bl in mesh.markers.values() for b in bl) + part.nbytes()
    return {"seconds": t, "part_cells": cells, "cells": part.n_cells,
            "local_nodes": comm.allgather(len(mesh.global_ids)), "nodes": mesh.n_global,
            "held_mb": max(comm.allgather(held / 2**20))}


def child_gate(comm, path: str) -> dict:
    from ffdcli.io.formats import read_part
    from ffdcli.quality.gate import check_quality, check_quality_part

    mesh, part = read_part(path, comm)          # the rank's local mesh (every marker node: the far field)
    size = comm.allreduce_max(float(np.ptp(mesh.points, axis=0).max()))
    after = mesh.points + 1e-3 * size * np.sin(mesh.points[:, ::-1] / size * 3)
    if comm.size == 1:         # the serial gate (the part is the whole mesh)
        def once():
            return check_quality(mesh, after, points_before=mesh.points)
    else:
        def once():
            return check_quality_part(part, comm, part.take(after), part.points)
    report = once()
    t = _timed(comm, once, repeat=2)
    return {"seconds": t, "failed": report.n_failed}


def _held_bytes(obj, seen: set) -> int:
    """Bytes of the NumPy arrays reachable from ``obj`` through dataclass fields, attributes, dicts,
    lists and tuples (each buffer counted once over the calls sharing ``seen``)."""
    import dataclasses

    stack, total = [obj], 0
    while stack:
        o = stack.pop()
        if isinstance(o, np.ndarray):
            base = o
            while isinstance(base.base, np.ndarray):
                base = base.base
            if id(base) not in seen:
                seen.add(id(base))
                total += base.nbytes
            continue
        if id(o) in seen or o is None or isinstance(o, (str, bytes, int, float, bool, Path, type)):
            continue
        seen.add(id(o))
        if isinstance(o, dict):
            stack.extend(o.values())
        elif isinstance(o, (list, tuple)):
            stack.extend(o)
        elif dataclasses.is_dataclass(o):
            stack.extend(getattr(o, f.name) for f in dataclasses.fields(o))
        elif type(o).__module__.startswith("ffdcli") and hasattr(o, "__dict__"):
            stack.extend(vars(o).values())
    return total


def _held_mb(run, result=None) -> dict:
    """MB of the arrays a run holds, by what holds them (the rank's local mesh, the gate's part and
    reference, the warp model, the boxes/embeddings/surfaces, the result)."""
    seen: set = set()
    groups = {"mesh": run.prep.mesh, "gate part": run._share, "warp": run._volume,
              "boxes": [(c.prep.box, c.prep.embedding, c.prep.surface) for c in run.components], "result": result}
    return {k: round(_held_bytes(v, seen) / 2**20, 1) for k, v in groups.items()}


def child_memory(comm, design: str, mode: str) -> dict:
    """``ffd deform``'s pipeline (load_run, deform, write_outputs) on local meshes (``mode`` local) or
    with every node on every rank (``whole``, the path of ``ffd grad --sens``, ``ffd jacobian`` and the
    API): the resident and peak MB of every rank after each phase, and each rank's local rows."""
    from ffdcli.app.deformation import deform
    from ffdcli.app.run import load_run
    from ffdcli.app.write import write_outputs
    from ffdcli.design import load_design

    phases = {}

    def mark(name):
        phases[name] = comm.allgather((round(_rss_mb()), round(_peak_mb())))

    t0 = time.perf_counter()
    mark("start")
    run = load_run(load_design(design), comm=comm, local=mode == "local")
    mark("read")
    held = {"read": comm.allgather(_held_mb(run))}
    result = deform(run)
    mark("deform")
    held["deform"] = comm.allgather(_held_mb(run, result))
    write_outputs(run, result, comm=comm)
    mark("write")
    return {"seconds": max(comm.allgather(time.perf_counter() - t0)), "phases": phases, "held_mb": held,
            "local_rows": comm.allgather(run.prep.mesh.n_points), "nodes": run.prep.mesh.n_points_global}


def _child(argv) -> int:
    from ffdcli.parallel.comm import world

    comm = world()
    case, *args = argv
    if case == "embed":
        out = child_embed(comm, int(args[0]), own=args[1:] == ["own"])
    elif case == "warp":
        out = child_warp(comm, int(args[0]), int(args[1]))
    elif case == "read":
        out = child_read(comm, args[0], args[1])
    elif case == "memory":
        out = child_memory(comm, args[0], args[1])
    else:
        out = child_gate(comm, args[0])
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


# `ffd ...` whose JSON summary also carries the peak RSS of every rank (max), for the deform rows.
_FFD_PEAK = (
    "import json, sys\n"
    "from ffdcli.cli import main\n"
    "from ffdcli.parallel.comm import world\n"
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


def _cases(folder: Path, quick: bool) -> list[tuple[str, int, list[str], Path | None]]:
    """(case, N, child argv, cwd) of every case; builds the 1M-node mesh (SU2 and CGNS) in ``folder``."""
    from benchmarks.bench_pipeline import FULL, QUICK, build_case
    from ffdcli.io.formats import read_mesh, write_mesh

    facts = build_case(folder, QUICK if quick else FULL)
    write_mesh(read_mesh(folder / "wing.su2"), folder / "wing.cgns")
    subprocess.run([sys.executable, "-m", "ffdcli", "box", "design_idw.yaml", "-q"], cwd=folder, env=_env(2),
                   check=True)
    n_embed = 100_000 if quick else 1_000_000
    n_vol, n_surf = (100_000, 10_000) if quick else (1_000_000, 50_000)
    me = ["-m", "benchmarks.bench_mpi", "--child"]
    nodes = facts["nodes"]
    return [("embed", n_embed, me + ["embed", str(n_embed)], None),
            ("embed own share", n_embed, me + ["embed", str(n_embed), "own"], None),
            ("warp", n_vol, me + ["warp", str(n_vol), str(n_surf)], None),
            ("read SU2 by parts", nodes, me + ["read", str(folder / "wing.su2"), "parts"], None),
            ("read SU2 rank 0 + bcast", nodes, me + ["read", str(folder / "wing.su2"), "bcast"], None),
            ("read CGNS by parts", nodes, me + ["read", str(folder / "wing.cgns"), "parts"], None),
            ("read CGNS rank 0 + bcast", nodes, me + ["read", str(folder / "wing.cgns"), "bcast"], None),
            ("gate", nodes, me + ["gate", str(folder / "wing.su2")], None),
            ("deform", nodes, ["-c", _FFD_PEAK, "deform", "design_idw.yaml", "--force", "--json"], folder),
            ("memory", nodes, me + ["memory", str(folder / "design_idw.yaml")], None)]


#: (ranks, mode) of the memory rows: every node on every rank (before the local meshes) and local meshes.
MEMORY = ((1, "local"), (2, "whole"), (2, "local"), (4, "local"))


def _memory_rows(n: int, argv: list[str]) -> list[dict]:
    """One run of each of :data:`MEMORY` (1 thread a rank; 4 ranks oversubscribe 2 cores: memory only)."""
    rows = []
    for ranks, mode in MEMORY:
        _, js, _ = _launch(ranks, 1, argv + [mode])
        rows.append({"case": "memory", "N": n, "ranks": ranks, "threads": 1, "mode": mode,
                     "seconds": js["seconds"], "peak_mb_max": js["peak_mb_max"], "peak_mb": js["peak_mb"],
                     "phases": js["phases"], "held_mb": js["held_mb"], "local_rows": js["local_rows"],
                     "load": round(os.getloadavg()[0], 1)})
    return rows


def run(quick: bool = False, only: list[str] | None = None) -> list[dict]:
    if _mpiexec() is None:
        return [{"case": "mpi", "skipped": "the [mpi] extra is not installed (pip install -e '.[mpi]')"}]
    load0 = os.getloadavg()[0]
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        cases = [c for c in _cases(Path(tmp), quick) if not only or c[0].split()[0] in only]
        for case, n, argv, cwd in cases:
            if case == "memory":
                rows += _memory_rows(n, argv)
                continue
            runs: dict[tuple, list] = {}
            for _ in range(ROUNDS):
                for cfg in SCALING:                      # 1 and 2 ranks alternately: the same load
                    runs.setdefault(cfg, []).append(_launch(*cfg, argv, cwd=cwd))
            runs[(1, 2)] = [_launch(1, 2, argv, cwd=cwd)]
            if case.startswith("read"):                  # memory per rank: the split (4 ranks oversubscribe)
                runs[(4, 1)] = [_launch(4, 1, argv, cwd=cwd)]
            for (ranks, threads), got in runs.items():
                secs = [js.get("seconds", wall) if case != "deform" else wall for wall, js, _ in got]
                js = got[-1][1]
                rows.append({"case": case, "N": n, "ranks": ranks, "threads": threads, "seconds": min(secs),
                             "seconds_max": max(secs), "runs": len(secs),
                             "peak_mb_max": max(g[1].get("peak_mb_max") or g[1].get("peak_mb") or 0 for g in got),
                             **{k: v for k, v in js.items() if k in KEPT},
                             "load": round(os.getloadavg()[0], 1)})
    rows.append({"case": "machine load", "load_start": round(load0, 1), "load_end": round(os.getloadavg()[0], 1)})
    return rows


def summary(rows: list[dict]) -> list[dict]:
    out = []
    by = {(r.get("case"), r.get("ranks"), r.get("threads")): r for r in rows}
    for r in rows:
        if "skipped" in r:
            out.append({"case": "MPI scaling", "measured": r["skipped"], "target": "", "pyGeo reference": ""})
            continue
        if r["case"] == "machine load":
            out.append({"case": "machine load (1-min load average, 2 cores)",
                        "measured": f"{r['load_start']} at the start, {r['load_end']} at the end",
                        "target": "", "pyGeo reference": ""})
            continue
        if r["case"] == "memory":
            ph = r["phases"]
            rss = ", ".join(f"{k} {max(v[0] for v in ph[k])}/{max(v[1] for v in ph[k])}" for k in ph)
            per_rank = "/".join(f"{p:.0f}" for p in r["peak_mb"])
            held = r["held_mb"]["deform"]
            arrays = ", ".join(f"{k} {max(h[k] for h in held):.0f}" for k in held[0])
            out.append({"case": f"memory, ffd deform {r['N'] / 1e6:g}M, {r['ranks']} rank(s), {r['mode']} mesh",
                        "measured": f"peak {r['peak_mb_max']:.0f} MB/rank (per rank {per_rank}); "
                                    f"after each phase, max over ranks, RSS/peak MB: {rss}; arrays held after "
                                    f"the deform, MB (max over ranks): {arrays}; rows per rank "
                                    f"{'/'.join(map(str, r['local_rows']))} ({r['seconds']:.3g} s, load {r['load']})",
                        "target": "shrinks with the rank count", "pyGeo reference": ""})
            continue
        one = by.get((r["case"], 1, 1))
        eff = ""
        met = None
        if r["ranks"] == 2 and one:
            e = one["seconds"] / (2 * r["seconds"])
            eff = f", efficiency {100 * e:.0f} %"
            met = e >= 0.8 if not r["case"].startswith("read") else None
        n = f"{r['N'] / 1e6:g}M" if r["N"] >= 1_000_000 else f"{r['N'] // 1000}k"
        peak = f", {r['peak_mb_max']:.0f} MB/rank" if r.get("peak_mb_max") else ""
        spread = f"-{r['seconds_max']:.3g}" if r.get("runs", 1) > 1 else ""
        halo = ""
        if r.get("part_cells") and r["ranks"] > 1:
            halo = f", cells per rank {'/'.join(str(c) for c in r['part_cells'])} of {r['cells']}"
        if r.get("local_nodes"):
            halo += (f", nodes per rank {'/'.join(str(c) for c in r['local_nodes'])} of {r['nodes']}, "
                     f"{r['held_mb']:.0f} MB held")
        out.append({"case": f"{r['case']} {n}, {r['ranks']} rank(s) x {r['threads']} thread(s)",
                    "measured": f"{r['seconds']:.3g}{spread} s{eff}{peak}{halo} (load {r['load']})",
                    "target": ">= 80 % efficiency at 2 ranks" if r["ranks"] == 2 and met is not None else "",
                    "pyGeo reference": "", "met": met})
    return out


def _main(argv=None) -> int:
    ap = argparse.ArgumentParser(description="MPI strong scaling")
    ap.add_argument("--child", nargs="+", help=argparse.SUPPRESS)
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--only", action="append", help="case names to run (embed, warp, read, gate, deform, memory)")
    args = ap.parse_args(argv)
    if args.child:
        return _child(args.child)
    rows = run(args.quick, args.only)
    for row in summary(rows):
        print(f"{row['case']:<64} {row['measured']}")
    print(json.dumps(rows))
    return 0


if __name__ == "__main__":
    sys.exit(_main())
