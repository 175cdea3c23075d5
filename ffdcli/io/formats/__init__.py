"""Mesh input and output: one reader/writer API, one module per format.

Each format module registers its :class:`~ffdcli.io.formats.common.MeshFormat` at its end
(:data:`MESH_FORMATS`; this face imports them all). ``read_mesh(path)`` picks the reader from the
extension (a folder, or a path without one, is an OpenFOAM case: :mod:`ffdcli.io.formats.openfoam`);
``write_mesh(mesh, path, points)`` writes a mesh with new point coordinates. When ``path`` has the
format the mesh was read from, the writer patches a copy of the input file (only coordinates change,
everything else byte for byte); otherwise it writes the mesh from scratch in the new format, markers
included.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ffdcli.errors import InputError
from ffdcli.io.atomic import check_writable
from ffdcli.io.formats import cgns, openfoam, su2, vtk  # noqa: F401  (each registers its format)
from ffdcli.io.formats.common import (  # noqa: F401
    FOLDER_FORMAT,
    MESH_FORMATS,
    MeshFormat,
    check_finite_points,
    check_finite_rows,
    extensions,
    format_of,
    mismatch_message,
)
from ffdcli.io.inputs import check_mesh_path
from ffdcli.mesh import Mesh
from ffdcli.parallel.partition import localize, node_owners


def read_mesh(path: str | Path, *, progress=None) -> Mesh:
    """Read a mesh (.su2, .cgns, .vtu, .vtk, an OpenFOAM case folder). Raises InputError naming the
    file on any problem."""
    p = Path(path)
    fmt = format_of(p)
    check_mesh_path(p)                         # a FIFO or a device would block or never end in open()
    mesh = MESH_FORMATS[fmt].from_spec(p, progress)
    check_finite_points(mesh)
    return mesh


def read_part(path: str | Path, comm, *, progress=None):
    """One MPI rank's read of a mesh: ``(mesh, part)``, a collective (``comm``: :mod:`ffdcli.parallel.comm`).

    ``mesh`` is the rank's local mesh (:func:`ffdcli.parallel.partition.localize`: the nodes it owns, their
    halo and every marker node, rows sorted by global id, ``global_ids``, local ids in cells and
    markers), ``part`` the rank's :class:`~ffdcli.parallel.partition.MeshPart` (the quality gate's share,
    ``rows`` in the local mesh). SU2 and CGNS/HDF5 files are read by parts, no rank holding every
    node (:func:`ffdcli.io.formats.su2.read_part`, :func:`ffdcli.io.formats.cgns.read_part`); other
    formats are read by rank 0 and broadcast (every rank then holds the whole mesh until it is
    localized). An OpenFOAM case (polyhedral cells, which only the whole face list defines; ASCII
    and gzip files cannot be read from an offset either) is read by rank 0 and broadcast, and stays
    whole on every rank: ``part`` is then None (the run shares the warp by blocks of rows and judges
    the polyhedra on every rank). Errors are agreed on.
    """
    p = Path(path)
    fmt = comm.run(format_of, p)
    comm.run(check_mesh_path, p)
    if fmt == FOLDER_FORMAT:
        return comm.root_then_bcast(read_mesh, p, progress=progress), None
    if MESH_FORMATS[fmt].read_part is not None:         # read by parts: SU2, CGNS
        mesh, part = MESH_FORMATS[fmt].read_part(p, comm, progress=progress)
        comm.run(check_finite_points, mesh)
        return mesh, part
    mesh = comm.root_then_bcast(read_mesh, p, progress=progress)      # transiently whole on every rank
    return localize(mesh, node_owners(mesh.points, comm.size), comm.rank)


def write_mesh(mesh: Mesh, path: str | Path, points: np.ndarray | None = None, *,
               progress=None) -> dict:
    """Write ``mesh`` with coordinates ``points`` (default: its own) to ``path``, atomically.

    Never overwrites the file the mesh was read from. Returns notes of the writer for the run's
    summary (``{}`` for most; the SU2 writer reports what it did to SU2's own FFD section).
    """
    p = Path(path)
    fmt = format_of(p)
    if (fmt == FOLDER_FORMAT) != (mesh.format == FOLDER_FORMAT) or (mesh.polyhedra is not None and fmt != mesh.format):
        raise InputError(mismatch_message(mesh.format, fmt), path=p)
    if fmt != FOLDER_FORMAT:
        p = check_writable(p, inputs=(mesh.path,) if mesh.path else ())
    if mesh.partial and fmt != mesh.format:      # written from scratch: every cell, read again here
        mesh = read_mesh(mesh.path, progress=progress)
    pts = mesh.points if points is None else np.asarray(points, dtype=np.float64)
    if pts.shape != mesh.points.shape:
        raise ValueError(f"points {pts.shape} do not match the mesh {mesh.points.shape}")
    return MESH_FORMATS[fmt].write(mesh, p, pts, progress=progress) or {}

