"""What every format module shares: the registry of formats (each format module registers itself
at its end, meshio's ``register_format``), the format of a path, and the check of finite coordinates."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ffdcli.errors import InputError
from ffdcli.mesh import Mesh
from ffdcli.registry import Registry

#: The mesh formats, each registered by its own module (:mod:`ffdcli.registry`).
MESH_FORMATS = Registry("mesh format")
#: The format of a folder (an OpenFOAM case or its constant/polyMesh), and of a path without extension.
FOLDER_FORMAT = "openfoam"


@dataclass(frozen=True)
class MeshFormat:
    """A mesh format as a registered kind: ``kind`` its name, the ``extensions`` it is chosen by (none:
    a folder, :data:`FOLDER_FORMAT`), its module's ``read(path, progress)``, ``write(mesh, path, points,
    progress)`` and, for a format read by MPI ranks in parts, ``read_part(path, comm, progress)``."""

    kind: str
    extensions: tuple[str, ...]
    description: str
    read: Callable
    write: Callable
    read_part: Callable | None = None

    def schema(self) -> dict:
        """The fragment of a mesh path in this format (``mesh:``, ``output.mesh``)."""
        named = ", ".join(self.extensions) or "a case folder, a path without extension"
        return {"type": "string", "minLength": 1, "description": f"{self.description} ({named})"}

    def from_spec(self, spec, context=None) -> Mesh:
        """The mesh at path ``spec``; ``context``: a progress factory (:mod:`ffdcli.progress`) or None."""
        return self.read(Path(spec), progress=context)


def extensions() -> dict[str, str]:
    """{extension: format name} of every registered format (``.su2``: ``su2``), sorted by extension."""
    return dict(sorted((ext, kind) for kind in MESH_FORMATS for ext in MESH_FORMATS[kind].extensions))


def format_of(path: str | Path, *, key: str | None = None) -> str:
    """The format name of a mesh path: from its extension; ``openfoam`` for a folder or a path
    without extension (an OpenFOAM case folder, or one to be written); InputError if unsupported."""
    p = Path(path)
    ext = p.suffix.lower()
    known = extensions()
    if ext in known:
        return known[ext]
    if str(path) and (ext in ("", ".part") or p.is_dir()):     # .part: the output plan's temporary folder
        return FOLDER_FORMAT
    raise InputError(f"unsupported mesh extension {ext or '(none)'!r}; expected one of "
                     f"{', '.join(known)}, or an OpenFOAM case folder", path=path, key=key)


def mismatch_message(read: str, written: str) -> str:
    """Why a mesh read in format ``read`` cannot be written as ``written`` (OpenFOAM cases are
    written only as a copy of an OpenFOAM case with new points; polyhedral cells have no other
    writer)."""
    if read == FOLDER_FORMAT:
        return ("the input is an OpenFOAM case: the deformed mesh is written as a copy of the case (an "
                "output folder name without extension, e.g. out/wing_case)")
    if written == FOLDER_FORMAT:
        return (f"an output without extension is an OpenFOAM case folder, written only from an OpenFOAM input; "
                f"the input is {read or 'not from a file'}: give the output an extension ({', '.join(extensions())})")
    return (f"a mesh of polyhedral cells (NGON_n/NFACE_n) read from {read} can only be written as {read} (a copy of "
            f"the input with new coordinates): give the output the .{read} extension")


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
