"""What every format module shares: the extension table and the check of finite coordinates."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ffdcli.errors import InputError
from ffdcli.mesh import Mesh

#: extension -> format name
FORMATS = {".su2": "su2", ".cgns": "cgns", ".vtu": "vtu", ".vtk": "vtk"}


def format_of(path: str | Path, *, key: str | None = None) -> str:
    """The format name of a mesh path, from its extension; InputError if unsupported."""
    ext = Path(path).suffix.lower()
    if ext not in FORMATS:
        raise InputError(f"unsupported mesh extension {ext or '(none)'!r}; expected one of "
                         f"{', '.join(FORMATS)}", path=path, key=key)
    return FORMATS[ext]



def check_finite_points(mesh: Mesh) -> None:
    """InputError naming the file and the first node (0-based, as in the file; a local mesh's global
    id) with a NaN or infinite coordinate; every reader's mesh passes here (SU2's reader also names
    the line)."""
    pts = mesh.points
    finite = np.isfinite(pts).all(axis=1)
    if not finite.all():
        bad = np.flatnonzero(~finite)
        node = int(bad[0] if mesh.global_ids is None else mesh.global_ids[bad[0]])
        raise InputError(_non_finite(node, pts[bad[0]].tolist(), len(bad) - 1), path=mesh.path)


def check_finite_rows(comm, points: np.ndarray, first: int, path) -> None:
    """:func:`check_finite_points` of a mesh whose rows are read in blocks, a collective: ``points``
    this rank's rows ``first ..``; every rank raises the error of the whole mesh (agreed on)."""
    bad = np.flatnonzero(~np.isfinite(points).all(axis=1))
    said = [x for x in comm.allgather((first + int(bad[0]), points[bad[0]].tolist(), len(bad)) if len(bad) else None)
            if x is not None]

    def check():
        if said:
            raise InputError(_non_finite(said[0][0], said[0][1], sum(x[2] for x in said) - 1), path=path)

    comm.run(check)


def _non_finite(node: int, xyz: list, more: int) -> str:
    return (f"node {node} has a NaN or infinite coordinate ({', '.join(map(repr, xyz))})"
            f"{f' and {more} more nodes' if more else ''}; a mesh needs finite coordinates")
