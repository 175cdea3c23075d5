"""The ``mesh_quality`` constraint's own cost: value and gradient on hexahedral grids.

The mesh is a unit cube of n^3 hexahedra, its nodes moved at random by 5 % of a cell (every cell
valid); the constraint is built on the unmoved grid and evaluated on the moved one:
``MeshQuality.measure(X)`` (the KS minimum over every corner's ratio) and ``measure(X, grad=True)``
(with dKS/dX (N, 3)), the compiled passes and, at the smallest size, the NumPy reference. The volume
motion (the warp and its transpose, which the design-variable Jacobian adds) is bench_warp's.
Best of 3 after a warm-up (numba compiles in the warm-up).

    python -m benchmarks.bench_mesh_quality            # 125k and 1M cells
    python -m benchmarks --only mesh_quality --quick   # 125k
"""

from __future__ import annotations

import sys
import time

import numpy as np

TITLE = ("mesh_quality constraint: KS minimum of the cells' quality ratios and its gradient "
         "(benchmarks/bench_mesh_quality.py)")
NOTES = ("Unit cube of n^3 hexahedra, nodes moved by up to 5 % of a cell; the constraint built on the "
         "unmoved grid (cell_quality of the input, once). value = KS over 8 corners a cell; gradient = "
         "value + dKS/dX (N, 3). Excludes the volume motion (bench_warp). The machine is shared (noisy).")


def hex_grid(n: int):
    """(points (N, 3), hexahedra (n^3, 8)) of the unit cube, VTK order."""
    g = np.stack(np.meshgrid(*[np.linspace(0.0, 1.0, n + 1)] * 3, indexing="ij"), -1).reshape(-1, 3)
    idx = np.arange((n + 1) ** 3).reshape(n + 1, n + 1, n + 1)
    c = np.stack([idx[:-1, :-1, :-1], idx[1:, :-1, :-1], idx[1:, 1:, :-1], idx[:-1, 1:, :-1],
                  idx[:-1, :-1, 1:], idx[1:, :-1, 1:], idx[1:, 1:, 1:], idx[:-1, 1:, 1:]], -1).reshape(-1, 8)
    return g, c


def _best(fn, repeat: int = 3) -> float:
    fn()
    best = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def measure(n: int, reference: bool) -> dict:
    from ffdcli.constraints import build_constraints
    from ffdcli.mesh import CellBlock, Mesh

    g, c = hex_grid(n)
    mesh = Mesh(points=g, cells=[CellBlock("hexahedron", c)], dim=3)
    t0 = time.perf_counter()
    mq = build_constraints([{"mesh_quality": {}}], None, None, [], mesh=mesh)[0]
    build = time.perf_counter() - t0
    X = g + np.random.default_rng(0).uniform(-0.05 / n, 0.05 / n, g.shape)
    row = {"cells": len(c), "corners": mq.n_corners, "setup_s": round(build, 3),
           "value_s": round(_best(lambda: mq.measure(X)), 3),
           "value_gradient_s": round(_best(lambda: mq.measure(X, grad=True)), 3),
           "value": round(float(mq.measure(X)[0]), 6)}
    if reference:
        t0 = time.perf_counter()
        v, G = mq.measure(X, grad=True, use_numba=False)
        row["numpy_reference_s"] = round(time.perf_counter() - t0, 3)
        vc, Gc = mq.measure(X, grad=True)
        row["reference_gap"] = float(max(abs(v - vc), np.abs(G - Gc).max() / np.abs(G).max()))
    return row


def run(quick: bool = False) -> list[dict]:
    sizes = [50] if quick else [50, 100]
    rows = [measure(n, reference=(k == 0)) for k, n in enumerate(sizes)]
    for r in rows:
        print(r, flush=True)
    return rows


if __name__ == "__main__":
    run(quick="--quick" in sys.argv)
