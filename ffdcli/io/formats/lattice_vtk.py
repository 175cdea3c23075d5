"""The lattice as a legacy VTK structured grid (opens in ParaView; no library needed).

Points are written i fastest, then j, then k (VTK's structured order), so the grid's
(i, j, k) are the lattice's chordwise, spanwise and thickness indices; a 2D lattice is n x 1 x l.
Point data: the integer indices ``i``, ``j``, ``k`` and, when given, ``original`` positions and the
``displacement`` (deformed - original).
"""

from __future__ import annotations

import io

import numpy as np

from ffdcli.io.atomic import atomic_write


def write_lattice_vtk(path, control_points: np.ndarray, original: np.ndarray | None = None,
                      title: str = "ffd lattice") -> None:
    """Write ``control_points`` (n, m, l, 3) (and the displacement from ``original``) to ``path``."""
    P = np.asarray(control_points, dtype=np.float64)
    n, m, l, _ = P.shape
    order = P.transpose(2, 1, 0, 3).reshape(-1, 3)          # i fastest
    ii, jj, kk = np.meshgrid(np.arange(n), np.arange(m), np.arange(l), indexing="ij")
    idx = [a.transpose(2, 1, 0).ravel() for a in (ii, jj, kk)]
    buf = io.StringIO()
    buf.write(f"# vtk DataFile Version 3.0\n{title}\nASCII\nDATASET STRUCTURED_GRID\n")
    buf.write(f"DIMENSIONS {n} {m} {l}\nPOINTS {len(order)} double\n")
    np.savetxt(buf, order, fmt="%.17g")
    buf.write(f"POINT_DATA {len(order)}\n")
    for name, a in zip("ijk", idx):
        buf.write(f"SCALARS {name} int 1\nLOOKUP_TABLE default\n")
        np.savetxt(buf, a[None, :], fmt="%d")
    if original is not None:
        O = np.asarray(original, dtype=np.float64).transpose(2, 1, 0, 3).reshape(-1, 3)
        for name, arr in (("original", O), ("displacement", order - O)):
            buf.write(f"VECTORS {name} double\n")
            np.savetxt(buf, arr, fmt="%.17g")
    with atomic_write(path, "w") as fh:
        fh.write(buf.getvalue())


def read_lattice_vtk(path) -> dict:
    """Read back what :func:`write_lattice_vtk` wrote: ``points`` (n, m, l, 3) and point-data arrays."""
    text = open(path).read().split()
    pos = text.index("DIMENSIONS")
    n, m, l = (int(v) for v in text[pos + 1:pos + 4])
    p = text.index("POINTS")
    N = int(text[p + 1])
    pts = np.array(text[p + 3:p + 3 + 3 * N], dtype=float).reshape(l, m, n, 3).transpose(2, 1, 0, 3)
    out = {"points": pts}
    for name in ("original", "displacement"):
        if name in text:
            q = text.index(name)
            out[name] = np.array(text[q + 2:q + 2 + 3 * N], dtype=float).reshape(l, m, n, 3) \
                .transpose(2, 1, 0, 3)
    return out
