"""ffd and pyGeo side by side, live: the same lattice and points in one run, one thread each.

``python -m benchmarks.bench_pygeo [--quick]`` (also a module of ``make bench``). pyGeo 1.17.1 and
pySpline 1.5.3 live in a virtual environment of their own (see ``../shared/peers/README.md``:
``python3 -m venv ~/pygeo-venv && ~/pygeo-venv/bin/pip install ../shared/peers/wheels/*.whl mpi4py
mpich``); ``FFD_PYGEO_PYTHON`` names its interpreter (default ``~/pygeo-venv/bin/python``). Without
it the module prints one row saying so.

The lattice is :mod:`benchmarks.bench_core`'s 8 x 6 x 2 wing box of degree (3, 3, 1), written as
Plot3D in the layout ``DVGeometry`` reads (it takes degree min(4, n) - 1 = (3, 3, 1) and uniform
clamped knots: the same splines); the points are random inside it. Three child processes run in
turn, ffd / pyGeo / ffd (ffd's figure is the better of its two runs), each with one thread
(``NUMBA_NUM_THREADS=1``, ``OMP_NUM_THREADS=1``):

* embed: ``embed(lattice, X)`` against ``DVGeometry.addPointSet(X, name)``, 22k / 100k / 1M points;
* deform: ``Embedding.evaluate(P1, out=buf)`` (``B @ P`` with moved control points) against
  ``setDesignVars`` + ``update(name)``, 1M points;
* Jacobian: ffd's factored Jacobian (``ffd jacobian`` writes ``B`` and ``dP/dv``: the basis matrix and
  the 101-variable lattice Jacobian of :mod:`benchmarks.bench_derivatives`) against
  ``computeTotalJacobian(name)`` with 96 local design variables (one per control point, thickness
  direction), 1M points;
* vjp: ``derivatives.vjp(embedding, g, D)`` (``D^T (B^T g)``, ``B^T g`` by ``Embedding.rmatvec``)
  against ``totalSensitivity(g, name)``, 22k / 100k / 1M points.

Each figure is the min over repeats (pyGeo's 1M embedding: one run, it takes minutes).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

TITLE = "ffd and pyGeo side by side, one thread each (benchmarks/bench_pygeo.py)"
REPO = Path(__file__).resolve().parents[1]
SHAPE, DEGREE = (8, 6, 2), (3, 3, 1)
SIZES = (22_000, 100_000, 1_000_000)
QUICK_SIZES = (22_000, 100_000)
#: The reference ratios (pyGeo time / ffd time, measured on this machine at load ~4); a run keeps at least these.
FLOOR = {("embed", 22_000): 107, ("embed", 100_000): 287, ("embed", 1_000_000): 221, ("deform", 1_000_000): 18,
         ("jacobian", 1_000_000): 104, ("vjp", 22_000): 4.3, ("vjp", 100_000): 4.7, ("vjp", 1_000_000): 10}

PYGEO_CHILD = r'''
import json, sys, time
import numpy as np
from pygeo import DVGeometry
box, pts_file, sizes = sys.argv[1], sys.argv[2], [int(s) for s in sys.argv[3].split(",")]
X_all = np.load(pts_file)
out = {"embed": {}, "vjp": {}}
dv = DVGeometry(box)
dv.addLocalDV("shape", lower=-1.0, upper=1.0, axis="z", scale=1.0)
rng = np.random.default_rng(1)
for n in sizes:
    best = 1e300
    for rep in range(1 if n >= 1_000_000 else (2 if n >= 100_000 else 3)):
        name = f"p{n}_{rep}"
        t0 = time.perf_counter(); dv.addPointSet(X_all[:n], name); best = min(best, time.perf_counter() - t0)
    out["embed"][n] = best
    g = rng.normal(size=(1, n, 3))
    best = 1e300
    for _ in range(3 if n >= 1_000_000 else 10):
        t0 = time.perf_counter(); dv.totalSensitivity(g, name); best = min(best, time.perf_counter() - t0)
    out["vjp"][n] = best
n = sizes[-1]
x = dv.getValues()
best = 1e300
for k in range(5):
    x["shape"] = x["shape"] + 1e-3
    dv.setDesignVars(x)
    t0 = time.perf_counter(); dv.update(name); best = min(best, time.perf_counter() - t0)
out["deform"] = {"N": n, "min": best}
best = 1e300
for _ in range(2):
    dv.JT[name] = None
    t0 = time.perf_counter(); dv.computeTotalJacobian(name); best = min(best, time.perf_counter() - t0)
out["jacobian"] = {"N": n, "min": best, "n_vars": int(dv.getNDV())}
err = float(np.abs(dv.update(name) - X_all[:n]).max())
out["max move"] = err
print(json.dumps(out))
'''


def pygeo_python() -> str | None:
    """The interpreter of pyGeo's own environment, or None."""
    cand = os.environ.get("FFD_PYGEO_PYTHON") or str(Path.home() / "pygeo-venv" / "bin" / "python")
    return cand if Path(cand).is_file() else None


def _min_time(fn, repeat: int) -> float:
    fn()
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def measure_ffd(pts_file: str, sizes) -> dict:
    """ffd's side (run in a child with one numba thread)."""
    from benchmarks.bench_core import wing_control_points
    from benchmarks.bench_derivatives import design_changes
    from ffdcli.lattice.embedding import embed
    from ffdcli.lattice.lattice import Lattice
    from ffdcli.parameterization.changes import LatticeFrame
    from ffdcli.parameterization.derivatives import lattice_jacobian, vjp

    lattice = Lattice(wing_control_points(SHAPE), DEGREE)
    X_all = np.load(pts_file)
    rng = np.random.default_rng(1)
    embed(lattice, X_all[:1000]).rmatvec(X_all[:1000])          # load the kernels
    P0 = lattice.control_points
    frame = LatticeFrame.from_lattice(SHAPE, (1.0, 0.0, 0.0), (0.0, 0.0, 1.0), (0.0, 1.0, 0.0))
    out = {"embed": {}, "vjp": {}}
    emb = None
    for n in sizes:
        X = X_all[:n]
        out["embed"][n] = _min_time(lambda X=X: embed(lattice, X), 2 if n >= 1_000_000 else 5)
        emb = embed(lattice, X)
        D = lattice_jacobian(P0, frame, design_changes(SHAPE[1], SHAPE[0], SHAPE[2]))
        g = rng.normal(size=(n, 3))
        out["vjp"][n] = _min_time(lambda emb=emb, g=g, D=D: vjp(emb, g, D), 5 if n >= 1_000_000 else 20)
    n = sizes[-1]
    P1 = P0 + 0.05 * lattice.size * np.sin(P0 * np.array([1.3, 0.7, 2.1]))
    buf = np.empty((n, 3))
    out["deform"] = {"N": n, "min": _min_time(lambda: emb.evaluate(P1, out=buf), 10)}

    def factored():
        emb.basis_matrix()
        lattice_jacobian(P0, frame, design_changes(SHAPE[1], SHAPE[0], SHAPE[2]))

    D = lattice_jacobian(P0, frame, design_changes(SHAPE[1], SHAPE[0], SHAPE[2]))
    out["jacobian"] = {"N": n, "min": _min_time(factored, 3), "n_vars": int(D.shape[1])}
    out["outside"] = int((~emb.inside).sum())
    return out


def _run_child(cmd: list[str], env_extra: dict) -> dict:
    env = dict(os.environ)
    env.update(env_extra)
    env["PYTHONPATH"] = str(REPO) + os.pathsep + env.get("PYTHONPATH", "")
    proc = subprocess.run(cmd, cwd=REPO, env=env, capture_output=True, text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"{cmd[0]} child failed: {proc.stderr.strip().splitlines()[-5:]}")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def _size(n: int) -> str:
    return f"{n / 1e6:g}M" if n >= 1_000_000 else f"{n // 1000}k"


def _fmt(t: float) -> str:
    return f"{t:.3g} s"


def run(quick: bool = False) -> list[dict]:
    py = pygeo_python()
    if py is None:
        return [{"case": "pyGeo side by side", "measured": "skipped: no pyGeo environment (set FFD_PYGEO_PYTHON, "
                 "see ../shared/peers/README.md)", "target": "", "pyGeo reference": "", "met": None}]
    from benchmarks.bench_core import wing_control_points
    from ffdcli.io.formats.plot3d import write_plot3d
    from ffdcli.lattice.lattice import Lattice, evaluate

    sizes = QUICK_SIZES if quick else SIZES
    one = {"NUMBA_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
    load0 = os.getloadavg()[0]
    with tempfile.TemporaryDirectory(prefix="ffd-pygeo-") as tmp:
        box, pts, script = Path(tmp) / "box.xyz", Path(tmp) / "points.npy", Path(tmp) / "pygeo_child.py"
        P = wing_control_points(SHAPE)
        write_plot3d(box, [P])
        rng = np.random.default_rng(0)
        np.save(pts, evaluate(Lattice(P, DEGREE), rng.uniform(0.0, 1.0, (max(sizes), 3))))
        script.write_text(PYGEO_CHILD)
        arg = ",".join(str(n) for n in sizes)
        ffd_cmd = [sys.executable, "-m", "benchmarks.bench_pygeo", "--child", str(pts), arg]
        runs = [_run_child(ffd_cmd, one)]
        pg = _run_child([py, str(script), str(box), str(pts), arg], one)
        runs.append(_run_child(ffd_cmd, one))
    load1 = os.getloadavg()[0]
    ffd = {"embed": {n: min(float(r["embed"][str(n)]) for r in runs) for n in sizes},
           "vjp": {n: min(float(r["vjp"][str(n)]) for r in runs) for n in sizes},
           "deform": min(r["deform"]["min"] for r in runs), "jacobian": min(r["jacobian"]["min"] for r in runs)}
    rows = []

    def row(case, key, t_ffd, t_pg, detail=""):
        ratio = t_pg / t_ffd
        floor = FLOOR.get(key)
        rows.append({"case": case, "measured": f"{_fmt(t_ffd)}: {ratio:.3g}x pyGeo", "target":
                     f">= {floor:g}x" if floor else "", "pyGeo reference": _fmt(t_pg) + " (live)",
                     "met": ratio >= floor if floor else None, "ratio": ratio, "detail": detail})

    for n in sizes:
        row(f"embed {_size(n)} points", ("embed", n), ffd["embed"][n], float(pg["embed"][str(n)]))
    n = sizes[-1]
    row(f"deform {_size(n)} points", ("deform", n), ffd["deform"], pg["deform"]["min"],
        "ffd: B @ P1 into a buffer; pyGeo: setDesignVars + update")
    row(f"Jacobian {_size(n)} points", ("jacobian", n), ffd["jacobian"], pg["jacobian"]["min"],
        f"ffd factored (B + dP/dv, {runs[0]['jacobian']['n_vars']} variables); pyGeo computeTotalJacobian "
        f"({pg['jacobian']['n_vars']} local variables)")
    for n in sizes:
        row(f"vjp {_size(n)} points", ("vjp", n), ffd["vjp"][n], float(pg["vjp"][str(n)]),
            "ffd: D^T (Embedding.rmatvec(g)); pyGeo: totalSensitivity")
    rows.append({"case": "machine", "measured": f"load {load0:.2f} -> {load1:.2f} (2 cores, shared)",
                 "target": "", "pyGeo reference": "", "met": None, "ratio": None,
                 "detail": f"one thread each; ffd outside {runs[0]['outside']}; pyGeo's largest move after "
                           f"its deform steps (5 local changes of 1e-3) {pg['max move']:.1e}"})
    return rows


def summary(rows: list[dict]) -> list[dict]:
    return [{k: r.get(k) for k in ("case", "measured", "target", "pyGeo reference", "met")} for r in rows]


if __name__ == "__main__":
    if "--child" in sys.argv:
        i = sys.argv.index("--child")
        print(json.dumps(measure_ffd(sys.argv[i + 1], [int(s) for s in sys.argv[i + 2].split(",")])))
    else:
        for r in run("--quick" in sys.argv):
            print(json.dumps(r))
