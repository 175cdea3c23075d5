"""DesignModel's reverse products at new design values, in process: ``python benchmarks/bench_model_vjp.py``.

What an optimiser's gradient costs ffd at each new design: set the values, then one surface and one
all-node reverse product (``surface_vjp``, ``mesh_vjp``: the volume motion's transpose and the frames'
derivative), then a second all-node product at the same values (a second function's adjoint). Median
over random designs within the bounds, after one warm-up design (numba compiled, box cached). Only the
public API both older and newer trees have, so that ``benchmarks/beside.py`` runs it from each tree.
Prints one JSON line: ``{"seconds": total median, "rows": {design: {step: median seconds}}}``.
"""

from __future__ import annotations

import json
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from ffdcli.api import DesignModel

REPO = Path(__file__).resolve().parents[1]
DESIGNS = ("naca0012_optimize.yaml", "rect_twist_linear.yaml")


def _design(model, rng) -> np.ndarray:
    lo = np.where(np.isfinite(model.lower), model.lower, model.values - 1.0)
    hi = np.where(np.isfinite(model.upper), model.upper, model.values + 1.0)
    return model.values + 0.05 * (rng.uniform(lo, hi) - model.values)


def time_design(name: str, cache: Path, repeats: int) -> dict:
    model = DesignModel.from_file(REPO / "configs" / name, cache_dir=cache)
    v0 = model.values.copy()
    rng = np.random.default_rng(0)
    n = model.run.prep.mesh.n_points
    S = len(model.surface_ids)
    steps: dict[str, list[float]] = {"set_values": [], "surface_vjp": [], "mesh_vjp": [], "mesh_vjp again": []}
    for k in range(repeats + 1):
        g = rng.standard_normal((n, 3))
        t0 = time.perf_counter()
        model.set_values(v0 if k == 0 else _design(model, rng))
        t1 = time.perf_counter()
        model.surface_vjp(g[model.surface_ids] if S else g[:0])
        t2 = time.perf_counter()
        model.mesh_vjp(g)
        t3 = time.perf_counter()
        model.mesh_vjp(-g)
        t4 = time.perf_counter()
        if k:           # the first design warms up (the warp model, numba)
            for key, dt in zip(steps, (t1 - t0, t2 - t1, t3 - t2, t4 - t3), strict=True):
                steps[key].append(dt)
    return {key: statistics.median(v) for key, v in steps.items()}


def main(argv=None) -> int:
    repeats = 5
    with tempfile.TemporaryDirectory(prefix="ffd-vjp-") as tmp:
        rows = {name: time_design(name, Path(tmp), repeats) for name in DESIGNS}
    total = sum(sum(r.values()) for r in rows.values())
    print(json.dumps({"seconds": total, "rows": rows}))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
