"""Time CGNS read and patch-write on a 1M-point, 4.85M-tetrahedron mesh (not a test; run by hand).

    PYTHONPATH=$PWD python tests/io/bench_cgns.py [N]     # N points per axis, default 100
"""

from __future__ import annotations

import os
import shutil
import sys
import tempfile
import time

import numpy as np

from ffdcli.io.formats import cgns, read_mesh, write_mesh
from ffdcli.mesh import CellBlock, Mesh


def main(n: int = 100) -> None:
    shape = (n, n, n)
    axes = [np.linspace(0, 1, s) for s in shape]
    pts = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3, order="F")
    h = cgns.structured_cells(shape, 0).data
    tets = np.concatenate([h[:, [0, 1, 3, 4]], h[:, [1, 2, 3, 6]], h[:, [1, 3, 4, 6]],
                           h[:, [4, 6, 5, 1]], h[:, [3, 7, 6, 4]]])
    bottom = cgns.range_faces(shape, 0, np.array([0, 0, 0]), np.array([n - 1, n - 1, 0])).data
    top = cgns.range_faces(shape, 0, np.array([0, 0, n - 1]), np.array([n - 1, n - 1, n - 1]))
    mesh = Mesh(points=pts, dim=3, cells=[CellBlock("tetra", tets)],
                markers={"wing": [CellBlock("triangle", np.r_[bottom[:, [0, 1, 2]], bottom[:, [0, 2, 3]]])],
                         "farfield": [top]})
    folder = tempfile.mkdtemp(prefix="ffd-bench-cgns-")
    try:
        src = os.path.join(folder, "big.cgns")
        t = time.perf_counter()
        write_mesh(mesh, src)
        print(f"from-scratch write: {time.perf_counter() - t:.2f} s ({len(pts)} points, {len(tets)} tets)")
        for _ in range(2):
            t = time.perf_counter()
            back = read_mesh(src)
            t_read = time.perf_counter() - t
            t = time.perf_counter()
            write_mesh(back, os.path.join(folder, "out.cgns"), back.points * 1.01)
            print(f"read: {t_read:.2f} s   patch write: {time.perf_counter() - t:.2f} s")
    finally:
        shutil.rmtree(folder)


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 100)
