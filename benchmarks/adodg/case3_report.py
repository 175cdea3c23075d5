"""Span load and span efficiency of one ADODG Case 3 flow solution (an evaluation folder of
``ffd optimize`` or any SU2 run folder): strip loads from ``surface_flow.csv`` and the wall triangles of
the mesh the flow ran on, against the ellipse of the same lift.

::

    python -m benchmarks.adodg.case3_report RUN_FOLDER --mesh MESH.su2 [--cd0 CD0] [--strips 24 | 0] [--json]
    python -m benchmarks.adodg.case3_report BASE_FOLDER BEST_FOLDER --plot spanload.png   # loads vs ellipse
    python -m benchmarks.adodg.case3_report RUN_FOLDER --mesh MESH.su2 --regions 0 0.02 0.3 0.9 1

``--regions X0 X1 ...`` adds the pressure drag (CD units) of the wing by chordwise region between
those x edges and of the tip cap apart (:func:`benchmarks.adodg.spanload.drag_by_region`): where a
zero-lift drag, which the exact Euler flow does not have, comes from.

``RUN_FOLDER`` holds ``surface_flow.csv`` and ``history.csv`` (CL, CD; ``history_direct.csv`` in a
``DIRECT`` folder of SU2's ``shape_optimization.py``); the mesh default is the folder's
``*.su2`` (an evaluation's deformed mesh). ``--cd0`` is the same mesh's zero-lift drag (the alpha-0
solve of the untwisted wing), for ``e = CL^2 / (pi AR (CD - CD0))``. Case constants: semispan 3,
half-wing area 3, AR 6; angle of attack from the folder's ``flow.cfg`` (else ``--alpha``).
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
from pathlib import Path

import matplotlib
import numpy as np

from benchmarks.adodg.spanload import (
    drag_by_region,
    ellipse_difference,
    fourier_coefficients,
    load_efficiency,
    span_efficiency,
    strip_loads,
    wall_stations,
)
from ffdcli.io.formats import read_mesh

SEMISPAN, S_HALF, ASPECT_RATIO = 3.0, 3.0, 6.0
#: Odd sine terms of the load's fit for ``e_load`` (n = 1, 3, ..., 11). ``e_load`` of a load that does
#: not vanish at the tip (the cap's lift in the last strip) falls as terms are added (docs/adodg-case3.md).
TERMS = 6


def read_surface_cp(path: Path, n_points: int) -> np.ndarray:
    """Pressure coefficient (n_points,) at the points ``surface_flow.csv`` lists (NaN elsewhere)."""
    data = np.genfromtxt(path, delimiter=",", names=True)
    cp = np.full(n_points, np.nan)
    cp[data["PointID"].astype(np.int64)] = data["Pressure_Coefficient"]
    return cp


def last_history(path: Path) -> dict[str, float]:
    """The last row of SU2's ``history.csv`` (names stripped of quotes and blanks)."""
    with open(path) as fh:
        rows = list(csv.reader(fh))
    names = [h.strip().strip('"') for h in rows[0]]
    return {n: float(v) for n, v in zip(names, rows[-1], strict=True)}


def history_file(folder: Path) -> Path:
    """The flow's history in ``folder``: ``history.csv`` (ffd's evaluations, SU2_CFD's default) or
    ``history_direct.csv`` (a ``DIRECT`` folder of SU2's ``shape_optimization.py``)."""
    for name in ("history.csv", "history_direct.csv"):
        if (folder / name).is_file():
            return folder / name
    return folder / "history.csv"


def config_alpha(folder: Path) -> float | None:
    for name in ("flow.cfg", "c.cfg"):
        p = folder / name
        if p.exists():
            for line in p.read_text().splitlines():
                if line.split("=")[0].strip() == "AOA":
                    return float(line.split("=")[1])
    return None


def report(folder: Path, mesh_path: Path, *, cd0: float | None, n_strips: int, alpha: float,
           regions: list[float] | None = None, terms: int = TERMS) -> dict:
    mesh = read_mesh(mesh_path)
    tris = mesh.markers["wing"][0].data
    cp = read_surface_cp(folder / "surface_flow.csv", len(mesh.points))
    if np.isnan(cp[np.unique(tris)]).any():
        raise SystemExit(f"{folder}: surface_flow.csv does not cover the wall of {mesh_path}")
    # strips over [0, 3]; the tip cap (y > 3) is counted in the last strip. n_strips 0: the strips
    # between the wall's own spanwise stations (a wall meshed in spanwise rows: the hybrid family)
    edges = None
    if n_strips == 0:
        edges = wall_stations(mesh.points, tris, SEMISPAN)
        if edges is None:
            raise SystemExit(f"{mesh_path}: the wall is not meshed in spanwise rows (--strips 0 needs them)")
        # the cap's lift goes to the last strip: keep it as wide as the default's (1/24 of the semispan)
        edges = edges[(edges <= SEMISPAN * (1.0 - 1.0 / 24.0)) | (edges == SEMISPAN)]
    load = strip_loads(mesh.points, tris, cp, n_strips=n_strips, alpha_deg=alpha, span=SEMISPAN, edges=edges)
    diff = ellipse_difference(load, SEMISPAN)
    coef = fourier_coefficients(load, SEMISPAN, n_terms=terms)
    hist = last_history(history_file(folder))
    cl, cd = hist["CL"], hist["CD"]
    out = {"folder": str(folder), "mesh": str(mesh_path), "alpha": alpha, "CL": cl, "CD": cd,
           "CL_strips": load.cl_total / S_HALF, "rms_pct": diff.rms, "max_pct": diff.max_abs,
           "e_load": load_efficiency(coef), "eta": (load.centres / SEMISPAN).tolist(), "ccl": load.ccl.tolist(),
           "ellipse": diff.ellipse.tolist()}
    if cd0 is not None:
        out["CD0"] = cd0
        out["e_drag"] = span_efficiency(cl, cd, cd0, ASPECT_RATIO)
    if regions:
        parts, cap = drag_by_region(mesh.points, tris, cp, alpha_deg=alpha, x_edges=np.asarray(regions), span=SEMISPAN)
        out["regions"] = {"x_edges": list(regions), "cd": (parts / S_HALF).tolist(), "cap": cap / S_HALF,
                          "total": float(parts.sum() + cap) / S_HALF}
    return out


def plot(reports: list[dict], path: Path) -> None:
    """Each report's strip loads (steps) and the ellipse of the first one's lift, against eta."""
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415 (after the backend is chosen)

    fig, ax = plt.subplots(figsize=(7, 4.2))
    for r in reports:
        ax.plot(r["eta"], r["ccl"], "o-", ms=3, label=f"{Path(r['folder']).name}: CL {r['CL']:.4f}, "
                f"RMS {r['rms_pct']:.2f} %, e_load {r['e_load']:.4f}")
    eta = np.linspace(0, 1, 400)
    c0 = 4.0 * reports[-1]["CL"] * S_HALF / (np.pi * SEMISPAN)
    ax.plot(eta, c0 * np.sqrt(1 - eta ** 2), "k--", label="ellipse of the last one's lift")
    ax.set_xlabel("eta = y / 3")
    ax.set_ylabel("c cl")
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("folder", type=Path, nargs="+")
    ap.add_argument("--plot", type=Path, default=None, help="write the loads against the ellipse here")
    ap.add_argument("--mesh", type=Path, default=None)
    ap.add_argument("--cd0", type=float, default=None)
    ap.add_argument("--strips", type=int, default=24,
                    help="equal strips over the semispan; 0: the strips between the wall's own spanwise "
                         "stations (a wall meshed in spanwise rows, as the hybrid family's)")
    ap.add_argument("--alpha", type=float, default=None)
    ap.add_argument("--terms", type=int, default=TERMS,
                    help=f"odd sine terms fitted to the load for e_load (default {TERMS}: n = 1, 3, ..., 11)")
    ap.add_argument("--regions", type=float, nargs="+", metavar="X",
                    help="chordwise edges: the wing's pressure drag between them and the tip cap's apart")
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args(argv)
    if a.terms < 1:
        print(f"ffd: error: --terms {a.terms}: give 1 or more", file=sys.stderr)
        return 2
    if a.regions is not None and (len(a.regions) < 2 or np.any(np.diff(a.regions) <= 0)):
        print(f"ffd: error: --regions {a.regions}: give two or more increasing x edges", file=sys.stderr)
        return 2
    reports = []
    for folder in a.folder:
        mesh = a.mesh or next(iter(sorted(folder.glob("*.su2"))), None)
        if mesh is None:
            print(f"ffd: error: {folder}: no .su2 mesh; give --mesh", file=sys.stderr)
            return 2
        alpha = a.alpha if a.alpha is not None else config_alpha(folder)
        if alpha is None:
            print(f"ffd: error: {folder}: no flow.cfg with AOA; give --alpha", file=sys.stderr)
            return 2
        reports.append(report(folder, mesh, cd0=a.cd0, n_strips=a.strips, alpha=alpha, regions=a.regions,
                              terms=a.terms))
    if a.plot is not None:
        plot(reports, a.plot)
    if a.json:
        print(json.dumps(reports if len(reports) > 1 else reports[0]))
        return 0
    for r in reports:
        show(r)
    return 0


def show(r: dict) -> None:
    e_drag = f", e (CD - CD0) {r['e_drag']:.4f}" if "e_drag" in r else ""
    print(f"CL {r['CL']:.6f} (strips {r['CL_strips']:.6f}), CD {r['CD']:.6f}; load - ellipse: RMS {r['rms_pct']:.2f} %,"
          f" max {r['max_pct']:.2f} % of the root load; e (load, Trefftz) {r['e_load']:.4f}{e_drag}")
    if "regions" in r:
        g = r["regions"]
        x = g["x_edges"]
        parts = "  ".join(f"x {x[i]:g}-{x[i + 1]:g} {v:+.6f}" for i, v in enumerate(g["cd"]))
        print(f"pressure drag by region: {parts}  cap {g['cap']:+.6f}  (sum {g['total']:+.6f})")
    for eta, c, e in zip(r["eta"], r["ccl"], r["ellipse"], strict=True):
        print(f"  eta {eta:.3f}  c*cl {c:.5f}  ellipse {e:.5f}")


if __name__ == "__main__":
    sys.exit(main())
