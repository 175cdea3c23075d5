"""First run against later runs, from an empty numba cache.

``python -m benchmarks.bench_compile [--quick]`` (also a module of ``make bench``). Everything runs
with ``NUMBA_CACHE_DIR`` pointed at a new empty folder, in child processes (a cold process each):

1. no warm-up (a user who installed with pip alone): the first ``ffd box`` of the 2D airfoil and
   of the 3D wing sample, then the same command again (warm cache); the first run's line on stderr
   (:func:`ffdcli.jit.compile_notice`) is checked;
2. ``python -m ffdcli.app.warmup`` (what ``make demo`` / ``make test`` run after installing);
3. after it, the first ``ffd box`` with each of several degree combinations, then the same again:
   the first run's extra time over the second is what compiling still costs (target <= 10 s);
4. after it, in one process, embed / ``B @ P`` / ``B.T @ g`` / the basis matrix on a small
   lattice for every degree combination the box accepts (1 to 5 per direction, 2D and 3D: 150),
   counting numba's compiles (its "numba:compile" event, fired on a cache miss only): 0 means no
   combination pauses.
"""

from __future__ import annotations

import itertools
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

TITLE = "First run from an empty numba cache (benchmarks/bench_compile.py)"
REPO = Path(__file__).resolve().parents[1]
WING, AIRFOIL = REPO / "samples" / "rect_wing.su2", REPO / "samples" / "naca0012_2d.su2"
#: (mesh, --points, --degree) of the runs after the warm-up
CASES = [
    (AIRFOIL, "6,5", "3,3"), (AIRFOIL, "6,5", "1,1"), (AIRFOIL, "6,2", "3,1"), (AIRFOIL, "6,6", "5,5"),
    (AIRFOIL, "6,5", "2,4"),
    (WING, "6,8,2", "3,3,1"), (WING, "6,8,2", "1,1,1"), (WING, "6,8,3", "2,2,2"), (WING, "6,8,4", "3,3,3"),
    (WING, "6,8,6", "5,5,5"), (WING, "6,8,4", "4,2,3"), (WING, "6,8,3", "5,1,2"),
]
QUICK_CASES = [CASES[0], CASES[4], CASES[5], CASES[9]]
TARGET = 10.0


def _env(cache: Path) -> dict:
    env = dict(os.environ)
    env["NUMBA_CACHE_DIR"] = str(cache)
    env["PYTHONPATH"] = str(REPO) + os.pathsep + env.get("PYTHONPATH", "")
    return env


def _timed(cmd: list[str], env: dict, cwd: Path) -> tuple[float, float, str]:
    """(wall s, CPU s of the child, its stderr)."""
    t0 = time.perf_counter()
    c0 = os.times()
    proc = subprocess.run(cmd, env=env, cwd=cwd, capture_output=True, text=True)
    c1 = os.times()
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed: {proc.stderr.strip().splitlines()[-3:]}")
    cpu = (c1.children_user - c0.children_user) + (c1.children_system - c0.children_system)
    return time.perf_counter() - t0, cpu, proc.stderr


def _box(mesh: Path, points: str, degree: str, tmp: Path) -> list[str]:
    return [sys.executable, "-m", "ffdcli", "box", str(mesh), "--points", points, "--degree", degree,
            "--cache-dir", str(tmp), "--lattice", str(tmp / "lattice.vtk"), "--rebuild", "--json"]


def count_compiles() -> dict:
    """In this process: numba compiles while running the lattice kernels for every degree
    combination the box accepts (1 to 5 per direction, 2D and 3D)."""
    import numba.core.event as ev

    from ffdcli.app.warmup import lattice_kernels

    seen = []

    class Listener(ev.Listener):
        def on_start(self, event):
            func = getattr(event.data.get("dispatcher"), "py_func", None)
            seen.append(f"{getattr(func, '__module__', '?')}.{getattr(func, '__name__', '?')}")

        def on_end(self, event):
            pass

    combos = [(*d, 0) for d in itertools.product(range(1, 6), repeat=2)]
    combos += list(itertools.product(range(1, 6), repeat=3))
    ev.register("numba:compile", Listener())
    t0 = time.perf_counter()
    for d in combos:
        lattice_kernels(d)
    return {"combinations": len(combos), "compiles": len(seen), "what": sorted(set(seen))[:10],
            "seconds": time.perf_counter() - t0}


def run(quick: bool = False, warmed: Path | None = None) -> list[dict]:
    """The rows; ``warmed``: a numba cache folder the warm-up has filled (skips steps 1 and 2)."""
    rows = []
    with tempfile.TemporaryDirectory(prefix="ffd-compile-") as td:
        tmp = Path(td)
        cache = tmp / "numba-cache"
        cache.mkdir()
        env = _env(cache)
        # 1. no warm-up: the first ffd box compiles (and says so on stderr)
        for mesh, points, degree in [] if warmed else [CASES[0], CASES[5]]:
            first = _timed(_box(mesh, points, degree, tmp), env, tmp)
            again = _timed(_box(mesh, points, degree, tmp), env, tmp)
            rows.append({"case": f"no warm-up: ffd box {mesh.name} --degree {degree}",
                         "first run": first[0], "warm run": again[0], "extra": first[0] - again[0],
                         "first CPU": first[1], "target": "(pip alone: once, said on stderr)",
                         "met": "compiling its numba kernels" in first[2] and "compiling" not in again[2]})
        # 2. the warm-up of make demo / make test, from an empty cache
        cache2 = warmed or tmp / "numba-cache-2"
        cache2.mkdir(exist_ok=True)
        env = _env(cache2)
        if not warmed:
            warm = _timed([sys.executable, "-m", "ffdcli.app.warmup"], env, REPO)
            rows.append({"case": "python -m ffdcli.app.warmup (empty cache)", "first run": warm[0],
                         "warm run": None, "extra": None, "first CPU": warm[1], "target": "", "met": None})
        # 3. after it: first runs with each degree combination
        for mesh, points, degree in QUICK_CASES if quick else CASES:
            first = _timed(_box(mesh, points, degree, tmp), env, tmp)
            again = _timed(_box(mesh, points, degree, tmp), env, tmp)
            extra = first[0] - again[0]
            rows.append({"case": f"after warm-up: ffd box {mesh.name} --points {points} --degree {degree}",
                         "first run": first[0], "warm run": again[0], "extra": extra, "first CPU": first[1],
                         "target": f"<= {TARGET:g} s", "met": extra <= TARGET and "compiling" not in first[2]})
        # 4. every combination, in one process: no compile at all
        code = "import json; from benchmarks.bench_compile import count_compiles; print(json.dumps(count_compiles()))"
        proc = subprocess.run([sys.executable, "-c", code], env=env, cwd=REPO, capture_output=True, text=True)
        if proc.returncode != 0:
            raise RuntimeError(proc.stderr.strip().splitlines()[-3:])
        r = json.loads(proc.stdout.strip().splitlines()[-1])
        rows.append({"case": f"after warm-up: lattice kernels, all {r['combinations']} degree combinations "
                             f"(1-5 per direction, 2D and 3D)", "first run": r["seconds"], "warm run": None,
                     "extra": None, "first CPU": None, "target": "0 compiles",
                     "met": r["compiles"] == 0, "compiles": r["compiles"], "what": ", ".join(r["what"])})
    rows.append({"case": "machine", "first run": None, "warm run": None, "extra": None, "first CPU": None,
                 "target": f"load {os.getloadavg()[0]:.2f} at the end (2 cores, shared)", "met": None})
    return rows


def summary(rows: list[dict]) -> list[dict]:
    def s(x):
        return "" if x is None else f"{x:.1f} s"

    return [{"case": r["case"], "measured": (f"first {s(r['first run'])}, warm {s(r['warm run'])}, extra "
                                             f"{s(r['extra'])}, first CPU {s(r['first CPU'])}"
                                             if r["warm run"] is not None else
                                             f"{s(r['first run'])}" + (f", {r['compiles']} compiles"
                                                                       if "compiles" in r else "")),
             "target": r["target"], "pyGeo reference": "", "met": r["met"]} for r in rows]


if __name__ == "__main__":
    # --after-warmup DIR: a cache folder `NUMBA_CACHE_DIR=DIR python -m ffdcli.app.warmup` has filled
    warmed = Path(sys.argv[sys.argv.index("--after-warmup") + 1]) if "--after-warmup" in sys.argv else None
    for row in run("--quick" in sys.argv, warmed):
        print(json.dumps(row), flush=True)
