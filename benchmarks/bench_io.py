"""Speed and memory of SU2 mesh I/O: read, patch-write and from-scratch write of a tet mesh.

``run(sizes)`` builds, for each size N, a structured n x n x n grid (n**3 ~ N points) split into six
tetrahedra per cube (~6 N tets), with markers ``wing`` (the z = 0 face) and ``farfield`` (the
other five faces), writes it as an SU2 file in a temporary folder, and times in a fresh process
each: ``read`` (ffdcli.io.formats.su2.read), ``write_patch`` (every point moved, the point block of a
copy of the file rewritten) and ``write_new`` (the whole file written from scratch). Peak memory is
the child process's maximum resident set size (``resource.getrusage``), including the interpreter
and NumPy (about 40 MB on their own).

    python -m benchmarks.bench_io [N ...]      (default 100k and 1M points)

``run(quick)`` is the entry point of the benchmark runner.
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

TITLE = "SU2 mesh I/O (ffdcli.io.formats.su2): read and write a synthetic tet mesh"
REPO = Path(__file__).resolve().parents[1]


def structured_tet_mesh(n_points: int):
    """A Mesh of the unit cube: ~n_points grid points, 6 tets per grid cube, markers wing/farfield."""
    from ffdcli.mesh import CellBlock, Mesh

    n = max(2, round(n_points ** (1 / 3)))
    x = np.linspace(0.0, 1.0, n)
    X, Y, Z = np.meshgrid(x, x, x, indexing="ij")
    points = np.column_stack([X.ravel(), Y.ravel(), Z.ravel()])
    idx = np.arange(n ** 3).reshape(n, n, n)
    c = [idx[i:n - 1 + i, j:n - 1 + j, k:n - 1 + k].ravel()
         for i, j, k in [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0),
                         (0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1)]]
    # Kuhn subdivision of each cube into 6 tets sharing the diagonal c0-c6 (positive volumes)
    tets = np.concatenate([np.column_stack([c[0], c[a], c[b], c[6]])
                           for a, b in [(1, 2), (2, 3), (3, 7), (7, 4), (4, 5), (5, 1)]])

    def face(sel):
        q = sel                                                   # (n-1, n-1, 4) corner ids
        return np.concatenate([q[..., [0, 1, 2]].reshape(-1, 3), q[..., [0, 2, 3]].reshape(-1, 3)])

    def quads(a):                                                 # a: (n, n) ids of a face
        return np.stack([a[:-1, :-1], a[1:, :-1], a[1:, 1:], a[:-1, 1:]], axis=-1)

    wing = face(quads(idx[:, :, 0]))
    far = np.concatenate([face(quads(f)) for f in (idx[:, :, -1], idx[0], idx[-1], idx[:, 0], idx[:, -1])])
    return Mesh(points=points, dim=3, cells=[CellBlock("tetra", tets)],
                markers={"wing": [CellBlock("triangle", wing)], "farfield": [CellBlock("triangle", far)]},
                format="")


_CHILD = r"""
import json, sys, time
import numpy as np
from ffdcli.io.formats import su2
op, src, out = sys.argv[1:4]
t = time.perf_counter()
if op.startswith("foam"):
    from ffdcli.io.formats import openfoam  # noqa: I001 (the child script)
    mesh = openfoam.read(src)
else:
    mesh = su2.read(src)
t_read = time.perf_counter() - t
res = {"read": t_read, "points": mesh.n_points, "cells": mesh.n_cells}
if op in ("write_patch", "foam_write"):
    pts = mesh.points + 1e-3 * np.sin(mesh.points[:, [1, 2, 0]] * 7.0)
    t = time.perf_counter()
    if op == "foam_write":
        openfoam.write(mesh, out, pts)
    else:
        su2.write(mesh, out, pts)
    res["write_patch"] = time.perf_counter() - t
elif op == "write_new":
    mesh.source, mesh.format = None, ""
    t = time.perf_counter()
    su2.write(mesh, out, mesh.points)
    res["write_new"] = time.perf_counter() - t
# VmHWM: this process's own peak (ru_maxrss would include the parent's peak, inherited at exec)
with open("/proc/self/status") as fh:
    res["peak_mb"] = int(next(ln for ln in fh if ln.startswith("VmHWM:")).split()[1]) / 1024
print(json.dumps(res))
"""


def _child(op: str, src: Path, out: Path) -> dict:
    proc = subprocess.run([sys.executable, "-c", _CHILD, op, str(src), str(out)], capture_output=True,
                          text=True, env={**os.environ, "PYTHONPATH": str(REPO)}, check=True)
    return json.loads(proc.stdout.strip().splitlines()[-1])


def run(quick: bool = False) -> list[dict]:
    """Benchmark rows for ``python -m benchmarks``: 100k points when ``quick``, else 1M points;
    and an OpenFOAM polyMesh of 100k (quick) or 1M cells against the same mesh as SU2.

    Each row: ``name``, ``points``, ``cells``, ``file_mb``, ``read_s``, ``read_peak_mb``,
    ``write_patch_s``, ``write_patch_peak_mb``, ``write_new_s``, ``write_new_peak_mb``; the
    OpenFOAM rows (``format`` openfoam-ascii, openfoam-binary-gz, su2 of the same mesh) have read
    and write (the points of a copy) only, and ``ratio_read``/``ratio_write`` to SU2.
    """
    return run_sizes((100_000,) if quick else (1_000_000,)) + run_foam(100_000 if quick else 1_000_000)


def run_foam(cells: int = 1_000_000) -> list[dict]:
    """Read and write (moved points) of the tet mesh of about ``cells`` cells as an OpenFOAM case
    (ASCII, and binary gzip-compressed) and as SU2, each in a fresh process."""
    from ffdcli.io.formats import su2
    from ffdcli.io.formats.openfoam_case import polymesh_of, write_case

    rows = []
    with tempfile.TemporaryDirectory(prefix="ffd-bench-foam-") as tmp:
        mesh = structured_tet_mesh(max(8, cells // 6))
        src = Path(tmp) / "mesh.su2"
        su2.write(mesh, src, mesh.points)
        poly, patches = polymesh_of(mesh, wall=("wing",))
        cases = {"su2": src,
                 "openfoam-ascii": write_case(Path(tmp) / "ascii", mesh.points, poly, patches),
                 "openfoam-binary-gz": write_case(Path(tmp) / "bingz", mesh.points, poly, patches, binary=True,
                                                  compress=True)}
        del mesh, poly
        ref = None
        for fmt, path in cases.items():
            foam = fmt != "su2"
            size = sum(f.stat().st_size for f in Path(path).rglob("*") if f.is_file()) if foam else src.stat().st_size
            out = Path(tmp) / ("out_" + fmt + ("" if foam else ".su2"))
            got = _child("foam_write" if foam else "write_patch", path, out)
            row = {"name": f"foam_io_{cells}", "format": fmt, "points": got["points"], "cells": got["cells"],
                   "file_mb": size / 2**20, "read_s": got["read"], "write_patch_s": got["write_patch"],
                   "peak_mb": got["peak_mb"]}
            if ref is None:
                ref = row
            else:
                row["ratio_read"] = row["read_s"] / ref["read_s"]
                row["ratio_write"] = row["write_patch_s"] / ref["write_patch_s"]
            rows.append(row)
    return rows


def run_sizes(sizes=(100_000, 1_000_000)) -> list[dict]:
    """Time read / patch write / new write of a synthetic SU2 tet mesh of each size (points)."""
    from ffdcli.io.formats import su2

    rows = []
    with tempfile.TemporaryDirectory(prefix="ffd-bench-io-") as tmp:
        for size in sizes:
            mesh = structured_tet_mesh(size)
            src = Path(tmp) / f"mesh_{size}.su2"
            su2.write(mesh, src, mesh.points)
            nbytes = src.stat().st_size
            del mesh
            read_only = _child("read", src, Path(tmp) / "unused.su2")
            patch = _child("write_patch", src, Path(tmp) / "patched.su2")
            new = _child("write_new", src, Path(tmp) / "new.su2")
            rows.append({"name": f"su2_io_{size}", "points": read_only["points"], "cells": read_only["cells"],
                         "file_mb": nbytes / 2**20,
                         "read_s": read_only["read"], "read_peak_mb": read_only["peak_mb"],
                         "write_patch_s": patch["write_patch"], "write_patch_peak_mb": patch["peak_mb"],
                         "write_new_s": new["write_new"], "write_new_peak_mb": new["peak_mb"]})
    return rows


def summary(rows: list[dict]) -> list[dict]:
    """The rows in the runner's columns: case / measured / target / pyGeo reference."""
    out = []
    for r in rows:
        if "format" in r:              # the OpenFOAM rows: against SU2 of the same mesh (target 1.5x)
            what = f"{r['format']} read + write, {r['cells'] / 1e6:.2f}M cells, {r['file_mb']:.0f} MB"
            ratio = "" if "ratio_read" not in r else f"; {r['ratio_read']:.2f}x / {r['ratio_write']:.2f}x SU2"
            out.append({"case": what, "measured": f"{r['read_s']:.2f} s + {r['write_patch_s']:.2f} s{ratio}",
                        "target": "" if "ratio_read" not in r else "<= 1.5x SU2", "pyGeo reference": ""})
            continue
        size = f"{r['points'] / 1e6:.2f}M points, {r['cells'] / 1e6:.1f}M tets, {r['file_mb']:.0f} MB"
        for key, what in (("read", "read"), ("write_patch", "write (patch the point block)"),
                          ("write_new", "write (from scratch)")):
            t = r[f"{key}_s"]
            out.append({"case": f"SU2 {what}, {size}", "measured": f"{t:.2f} s, {r[f'{key}_peak_mb']:.0f} MB",
                        "target": "", "pyGeo reference": ""})
    return out


def main(argv=None) -> None:
    argv = sys.argv[1:] if argv is None else argv
    sizes = tuple(int(float(a)) for a in argv) or (100_000, 1_000_000)
    t = time.perf_counter()
    rows = run_sizes(sizes)
    print("SU2 I/O (ffdcli.io.formats.su2), synthetic tet meshes; peak = max RSS of the process")
    print(f"{'points':>9} {'tets':>9} {'file MB':>8} | {'read s':>7} {'peak MB':>8} | "
          f"{'patch s':>7} {'peak MB':>8} | {'new s':>6} {'peak MB':>8}")
    for r in rows:
        print(f"{r['points']:>9} {r['cells']:>9} {r['file_mb']:>8.1f} | {r['read_s']:>7.2f} "
              f"{r['read_peak_mb']:>8.0f} | {r['write_patch_s']:>7.2f} {r['write_patch_peak_mb']:>8.0f} | "
              f"{r['write_new_s']:>6.2f} {r['write_new_peak_mb']:>8.0f}")
    print(f"(total {time.perf_counter() - t:.0f} s including mesh generation)")


if __name__ == "__main__":
    main()
