"""Mesh input and output: one reader/writer API, one module per format.

``read_mesh(path)`` picks the reader from the extension (a folder, or a path without one, is an
OpenFOAM case: :mod:`ffdcli.formats.openfoam`); ``write_mesh(mesh, path, points)`` writes a
mesh with new point coordinates. When ``path`` has the format the mesh was read from, the writer
patches a copy of the input file (only coordinates change, everything else byte for byte);
otherwise it writes the mesh from scratch in the new format, markers included.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ffdcli.errors import InputError
from ffdcli.inputs import check_mesh_path
from ffdcli.mesh import Mesh

#: extension -> format name
FORMATS = {".su2": "su2", ".cgns": "cgns", ".vtu": "vtu", ".vtk": "vtk"}
#: The format of a folder (an OpenFOAM case or its constant/polyMesh), and of a path without extension.
FOLDER_FORMAT = "openfoam"


def format_of(path: str | Path, *, key: str | None = None) -> str:
    """The format name of a mesh path: from its extension; ``openfoam`` for a folder or a path
    without extension (an OpenFOAM case folder, or one to be written); InputError if unsupported."""
    p = Path(path)
    ext = p.suffix.lower()
    if ext in FORMATS:
        return FORMATS[ext]
    if str(path) and (ext in ("", ".part") or p.is_dir()):     # .part: the output plan's temporary folder
        return FOLDER_FORMAT
    raise InputError(f"unsupported mesh extension {ext or '(none)'!r}; expected one of "
                     f"{', '.join(FORMATS)}, or an OpenFOAM case folder", path=path, key=key)


def _module(fmt: str):
    if fmt == "su2":
        from ffdcli.formats import su2 as mod
    elif fmt == FOLDER_FORMAT:
        from ffdcli.formats import openfoam as mod
    elif fmt == "cgns":
        from ffdcli.formats import cgns as mod
    else:
        from ffdcli.formats import vtk as mod
    return mod


def read_mesh(path: str | Path, *, progress=None) -> Mesh:
    """Read a mesh (.su2, .cgns, .vtu, .vtk, an OpenFOAM case folder). Raises InputError naming the
    file on any problem."""
    p = Path(path)
    fmt = format_of(p)
    check_mesh_path(p)                         # a FIFO or a device would block or never end in open()
    mesh = _module(fmt).read(p, progress=progress)
    check_finite_points(mesh)
    return mesh


#: Formats whose reader reads one MPI rank's part itself (:func:`read_part`).
READ_BY_PARTS = ("su2", "cgns")


def read_part(path: str | Path, comm, *, progress=None):
    """One MPI rank's read of a mesh: ``(mesh, part)``, a collective (``comm``: :mod:`ffdcli.parallel`).

    ``mesh`` is the rank's local mesh (:func:`ffdcli.partition.localize`: the nodes it owns, their
    halo and every marker node, rows sorted by global id, ``global_ids``, local ids in cells and
    markers), ``part`` the rank's :class:`~ffdcli.partition.MeshPart` (the quality gate's share,
    ``rows`` in the local mesh). SU2 and CGNS/HDF5 files are read by parts, no rank holding every
    node (:func:`ffdcli.formats.su2.read_part`, :func:`ffdcli.formats.cgns.read_part`); other
    formats are read by rank 0 and broadcast (every rank then holds the whole mesh until it is
    localized). Errors are agreed on.
    """
    from ffdcli.partition import localize, node_owners

    p = Path(path)
    fmt = comm.run(format_of, p)
    comm.run(check_mesh_path, p)
    if fmt == FOLDER_FORMAT:
        comm.run(_no_polyhedra_mpi, p)
    if fmt in READ_BY_PARTS:
        mesh, part = _module(fmt).read_part(p, comm, progress=progress)
        comm.run(check_finite_points, mesh)
        return mesh, part
    mesh = comm.root_then_bcast(read_mesh, p, progress=progress)      # transiently whole on every rank
    return localize(mesh, node_owners(mesh.points, comm.size), comm.rank)


def _no_polyhedra_mpi(path) -> None:
    raise InputError("MPI runs on OpenFOAM cases (polyhedral cells) are not supported yet; run without "
                     "mpiexec (a serial run reads a 1M-cell polyMesh in seconds)", path=path)


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


def write_mesh(mesh: Mesh, path: str | Path, points: np.ndarray | None = None, *,
               progress=None) -> dict:
    """Write ``mesh`` with coordinates ``points`` (default: its own) to ``path``, atomically.

    Never overwrites the file the mesh was read from. Returns notes of the writer for the run's
    summary (``{}`` for most; the SU2 writer reports what it did to SU2's own FFD section).
    """
    from ffdcli.atomic import check_writable

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
    return _module(fmt).write(mesh, p, pts, progress=progress) or {}


def mismatch_message(read: str, written: str) -> str:
    """Why a mesh read in format ``read`` cannot be written as ``written`` (OpenFOAM cases are
    written only as a copy of an OpenFOAM case with new points; polyhedral cells have no other
    writer)."""
    if read == FOLDER_FORMAT:
        return ("the input is an OpenFOAM case: the deformed mesh is written as a copy of the case (an "
                "output folder name without extension, e.g. out/wing_case)")
    if written == FOLDER_FORMAT:
        return (f"an output without extension is an OpenFOAM case folder, written only from an OpenFOAM input; "
                f"the input is {read or 'not from a file'}: give the output an extension ({', '.join(FORMATS)})")
    return f"a mesh of polyhedral cells read from {read} can only be written as {read}"
