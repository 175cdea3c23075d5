"""Derivatives: the surface Jacobian dX/dv of 1M surface points x 101 design variables.

One child process (``python -m benchmarks.bench_derivatives --child N``) so that its peak memory is
its own. The lattice is the 8 x 6 x 2, degree (3, 3, 1) curved wing lattice of
:mod:`benchmarks.bench_core` (swept, tapered, twisted, bent); N points at random parameters are
mapped through it and embedded with :func:`ffdcli.lattice.embedding.embed` (untimed here: bench_core times
it). The design has 101 variables, built with :mod:`ffdcli.parameterization.changes` on
``LatticeFrame.from_lattice`` (chord x, thickness z, span y), in this order:
twist [6 per-section angles], span, sweep, dihedral, chord [6 factors], sweep offsets [6],
shape upper (8 x 6 points), shape upper/lower (8 + 8, all sections), shape rows (2 x 8) = 101.

Rows:
* ``dP/dv``: :func:`ffdcli.parameterization.derivatives.lattice_jacobian` (288 x 101);
* ``B``: ``Embedding.basis_matrix()`` (sparse CSR, N x 96, 32 nonzeros per row);
* factored Jacobian = dP/dv + B: what ``ffd jacobian`` writes (dX/dv = B @ dP/dv);
* dense dX/dv: :func:`ffdcli.parameterization.derivatives.surface_jacobian` (N*3 x 101 float64, 2.4 GB at 1M),
  for reference; the time includes allocating and filling the output;
* vjp: :func:`ffdcli.parameterization.derivatives.vjp` of a random dJ/dX (N, 3) = g^T dX/dv without the dense product.
Each time is the best of several runs after a warm-up call (numba kernels loaded, pages touched).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

TITLE = "Derivatives: surface Jacobian of 1M points x 101 variables (benchmarks/bench_derivatives.py)"
REPO = Path(__file__).resolve().parents[1]
SHAPE, DEGREE = (8, 6, 2), (3, 3, 1)
NOTES = """
Lattice 8 x 6 x 2, degree (3, 3, 1), the curved wing lattice of bench_core; N random points inside,
embedded (untimed). Design: 101 variables (twist x6, span, sweep, dihedral, chord x6, sweep offsets
x6, shape upper 8x6, shape upper/lower 8+8, shape rows 2x8), changes built with ffdcli.parameterization.changes.
"factored" = lattice_jacobian + basis_matrix: the two factors of dX/dv = B @ dP/dv that `ffd jacobian`
writes. "dense" = surface_jacobian (N*3 x 101 float64 in memory: 2.4 GB at 1M). Best of 3-5 runs after
a warm-up; peak RSS = the child process (points, embedding, B, and the dense Jacobian included).
Targets: Jacobian 1M x 101 <= 2 s (pyGeo measured here: 25.8 s); vjp <= 0.2 s.
"""


def design_changes(m: int, n: int, l: int) -> list:
    """The 101-variable design on an (n, m, l) = (8, 6, 2) lattice (see the module docstring)."""
    from ffdcli.parameterization.changes import Chord, Dihedral, Shape, Span, Sweep, Twist

    j = np.arange(m) / (m - 1)
    i = np.arange(n) / (n - 1)
    bump = np.sin(np.pi * i)
    return [
        Twist(list(4.0 * j - 1.0)),
        Span(1.05),
        Sweep(delta=3.0),
        Dihedral(delta=-2.0),
        Chord(list(1.0 - 0.2 * j)),
        Sweep(offsets=list(0.02 * j ** 2)),
        Shape(upper=0.01 * bump[:, None] * (1 + j)[None, :]),
        Shape(upper=0.005 * bump, lower=-0.004 * bump),
        Shape(rows=np.stack([-0.002 * bump, 0.003 * bump])),
    ]


def peak_mb() -> float:
    """This process's peak RSS (VmHWM), MB; ``ru_maxrss`` would include the parent's peak (inherited
    at exec), e.g. the runner's after a module that built a large mesh in it."""
    with open("/proc/self/status") as fh:
        return int(next(ln for ln in fh if ln.startswith("VmHWM:")).split()[1]) / 1024


def _best(fn, repeat: int) -> float:
    fn()                                   # warm-up: kernels, first touch of the output pages
    best = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def measure(npts: int, seed: int = 0) -> dict:
    from benchmarks.bench_core import wing_control_points
    from ffdcli.lattice.embedding import embed
    from ffdcli.lattice.lattice import Lattice, evaluate
    from ffdcli.parameterization.changes import LatticeFrame, design_variables
    from ffdcli.parameterization.derivatives import lattice_jacobian, surface_jacobian, vjp

    lattice = Lattice(wing_control_points(SHAPE), DEGREE)
    P0 = lattice.control_points
    rng = np.random.default_rng(seed)
    X = evaluate(lattice, rng.uniform(0.0, 1.0, (npts, 3)))
    emb = embed(lattice, X)
    n, m, l = SHAPE
    frame = LatticeFrame.from_lattice(SHAPE, (1.0, 0.0, 0.0), (0.0, 0.0, 1.0), (0.0, 1.0, 0.0))
    changes = design_changes(m, n, l)
    names, _ = design_variables(changes)

    t_dP = _best(lambda: lattice_jacobian(P0, frame, changes), 5)
    t_B = _best(emb.basis_matrix, 3)
    J = lattice_jacobian(P0, frame, changes)
    B = emb.basis_matrix()
    t_dense = _best(lambda: surface_jacobian(B, J), 3)
    g = rng.normal(size=(npts, 3))
    t_vjp = _best(lambda: vjp(B, g, J), 5)
    # check the dense product against the factors on a few rows (the benchmark must time real work)
    dense = surface_jacobian(B, J)
    rows = rng.choice(npts, size=min(npts, 200), replace=False)
    ref = (B[rows] @ J.reshape(-1, 3 * J.shape[1])).reshape(-1, J.shape[1])
    err = float(np.abs(dense.reshape(npts, 3, -1)[rows].reshape(-1, J.shape[1]) - ref).max())
    del dense
    return {"N": npts, "n_vars": len(names), "n_ctrl": int(B.shape[1]), "nnz": int(B.nnz),
            "outside": int((~emb.inside).sum()), "dP": t_dP, "B": t_B, "dense": t_dense, "vjp": t_vjp,
            "dense_check": err, "peak_mb": peak_mb(),
            "threads": int(os.environ.get("NUMBA_NUM_THREADS", os.cpu_count() or 1))}


def _child(npts: int) -> dict:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(REPO) + os.pathsep + env.get("PYTHONPATH", "")
    proc = subprocess.run([sys.executable, "-m", "benchmarks.bench_derivatives", "--child", str(npts)],
                          cwd=REPO, env=env, capture_output=True, text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"bench_derivatives child failed: {proc.stderr.strip().splitlines()[-3:]}")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def run(quick: bool = False) -> list[dict]:
    npts = 100_000 if quick else 1_000_000
    r = _child(npts)
    full = not quick
    size = f"{npts / 1e6:g}M x {r['n_vars']}" if npts >= 1e6 else f"{npts // 1000}k x {r['n_vars']}"
    factored = r["dP"] + r["B"]
    return [
        {"case": f"dP/dv lattice_jacobian ({3 * r['n_ctrl']} x {r['n_vars']})",
         "measured": f"{r['dP']:.4f} s", "target": "", "pyGeo reference": ""},
        {"case": f"B basis_matrix ({npts // 1000}k x {r['n_ctrl']}, {r['nnz'] / 1e6:.0f}M nonzeros)",
         "measured": f"{r['B']:.3f} s", "target": "", "pyGeo reference": ""},
        {"case": f"Jacobian {size}, factored (dP/dv + B, what ffd jacobian writes)",
         "measured": f"{factored:.3f} s", "target": "<= 2 s" if full else "",
         "pyGeo reference": "25.8 s" if full else "", "met": factored <= 2.0 if full else None},
        {"case": f"Jacobian {size}, dense B @ dP/dv ({3 * npts * r['n_vars'] * 8 / 1e9:.2f} GB)",
         "measured": f"{r['dense']:.3f} s (+ factors {factored:.3f} s)",
         "target": "<= 2 s" if full else "", "pyGeo reference": "25.8 s" if full else "",
         "met": r["dense"] + factored <= 2.0 if full else None},
        {"case": f"vjp g^T dX/dv ({npts // 1000}k points)", "measured": f"{r['vjp']:.4f} s",
         "target": "<= 0.2 s" if full else "", "pyGeo reference": "",
         "met": r["vjp"] <= 0.2 if full else None},
        {"case": "peak RSS of the child (points, embedding, B, dense Jacobian)",
         "measured": f"{r['peak_mb']:.0f} MB", "target": "", "pyGeo reference": ""},
    ]


if __name__ == "__main__":
    if len(sys.argv) == 3 and sys.argv[1] == "--child":
        print(json.dumps(measure(int(sys.argv[2]))))
    else:
        for row in run("--quick" in sys.argv):
            print(json.dumps(row))
