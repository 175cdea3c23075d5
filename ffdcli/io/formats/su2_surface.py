"""SU2's surface-positions file (``DV_KIND= SURFACE_FILE``, ``DV_FILENAME= FILE``): new surface nodes.

For users who keep SU2's own volume deformation (its linear-elastic solve in SU2_DEF), ffd can hand
over only the surface: ``ffd deform DESIGN.yaml --surface-file wing_surface.dat`` writes the deformed
position of every node of the design surface, and SU2_DEF moves the rest of the mesh. The format is
the one SU2 reads (``CSurfaceMovement::SetExternal_Deformation``) and writes as its own template when
the file is missing: one line per node, tab separated, no header::

    <global point index> <x> <y>[ <z>]        % z only in 3D (NDIME= 3)

The index is the 0-based node index of the mesh file (SU2's global index); SU2 matches each line to a
vertex of the ``DV_MARKER`` markers with that index and moves it to the given coordinates; nodes the
file does not list do not move. Coordinates are printed with ``%.17g`` (exact round trip).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ffdcli.errors import InputError
from ffdcli.io.atomic import atomic_write


def write_surface_file(path: str | Path, ids: np.ndarray, points: np.ndarray, ndim: int) -> None:
    """Write the surface-positions file of nodes ``ids`` (S,) at ``points`` (S, 3), atomically.

    ``ndim`` is the mesh's (2: ``id x y``; 3: ``id x y z``).
    """
    ids = np.asarray(ids, dtype=np.int64).reshape(-1)
    points = np.asarray(points, dtype=np.float64)
    if points.shape != (len(ids), 3):
        raise ValueError(f"points must be ({len(ids)}, 3), got {points.shape}")
    if ndim not in (2, 3):
        raise ValueError(f"ndim must be 2 or 3, got {ndim}")
    if not np.isfinite(points).all():
        raise ValueError("cannot write non-finite coordinates")
    fmt = "%d" + "\t%.17g" * ndim
    with atomic_write(path, "w") as fh:
        np.savetxt(fh, np.column_stack([ids, points[:, :ndim]]), fmt=fmt, delimiter="\t")


def read_surface_file(path: str | Path, ndim: int) -> tuple[np.ndarray, np.ndarray]:
    """Read a surface-positions file: (ids (S,) int64, points (S, 3) with z = 0 in 2D).

    Raises :class:`InputError` naming the file when a row does not have ``1 + ndim`` numbers or an
    index is not a non-negative whole number.
    """
    path = Path(path)
    try:
        data = np.loadtxt(path, dtype=np.float64, ndmin=2)
    except (OSError, ValueError) as e:
        raise InputError(f"not an SU2 surface-positions file ({e}); expected rows 'index x y"
                         f"{' z' if ndim == 3 else ''}'", path=path) from None
    if data.size == 0:
        return np.zeros(0, dtype=np.int64), np.zeros((0, 3))
    if data.shape[1] != 1 + ndim:
        raise InputError(f"rows have {data.shape[1]} numbers, expected {1 + ndim} (index, "
                         f"{'x, y' if ndim == 2 else 'x, y, z'})", path=path)
    ids = data[:, 0]
    if np.any(ids < 0) or np.any(ids != np.round(ids)):
        raise InputError("the first column must be 0-based node indices", path=path)
    points = np.zeros((len(data), 3))
    points[:, :ndim] = data[:, 1:]
    return ids.astype(np.int64), points
