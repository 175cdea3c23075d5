"""The in-memory mesh that every reader returns and every writer takes.

A :class:`Mesh` holds points, interior cells and named boundary markers. Readers keep whatever
they need to write a deformed copy of the *same* file in ``source`` (byte offsets of the SU2
point block, the CGNS node paths of the coordinates, ...), so that writing patches only the
coordinates and everything else survives byte for byte.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ffdcli.errors import InputError
from ffdcli.mesh.idsets import unique_ids

#: Cell types use meshio's names. Nodes per cell and topological dimension of each type.
CELL_NODES = {"vertex": 1, "line": 2, "triangle": 3, "quad": 4, "tetra": 4, "pyramid": 5,
              "wedge": 6, "hexahedron": 8}
CELL_DIM = {"vertex": 0, "line": 1, "triangle": 2, "quad": 2, "tetra": 3, "pyramid": 3,
            "wedge": 3, "hexahedron": 3}
#: VTK (and SU2) element type ids.
VTK_ID = {"vertex": 1, "line": 3, "triangle": 5, "quad": 9, "tetra": 10, "hexahedron": 12,
          "wedge": 13, "pyramid": 14}
VTK_TYPE = {v: k for k, v in VTK_ID.items()}


@dataclass
class CellBlock:
    """Cells of one type: ``data[c]`` lists the 0-based point ids of cell ``c`` (VTK node order)."""

    type: str
    data: np.ndarray

    def __post_init__(self):
        self.data = np.asarray(self.data, dtype=np.int64)
        if self.data.ndim != 2 or self.data.shape[1] != CELL_NODES[self.type]:
            raise ValueError(f"{self.type} cells need {CELL_NODES[self.type]} nodes, "
                             f"got array of shape {self.data.shape}")

    def __len__(self) -> int:
        return len(self.data)


@dataclass
class Mesh:
    """A mesh as read from a file.

    points
        (N, 3) float64. 2D meshes have a third coordinate too (0 for SU2 ``NDIME= 2``).
    dim
        Topological dimension of the interior cells: 2 (an airfoil mesh) or 3.
    cells
        Interior cells (``dim``-dimensional). May be empty for a surface-only mesh.
    markers
        Boundary markers by name, exactly as named in the file, in file order. Each is a list of
        cell blocks (faces in 3D, lines in 2D; a marker given only as nodes is one ``vertex`` block).
    path, format
        Where it was read from and the format name (``su2``, ``cgns``, ``vtu``, ``vtk``).
    source
        Reader-private information used by the writer of the same format to patch a copy of the
        input file. ``None`` for meshes built in memory.
    partial
        True for one MPI rank's view of a mesh read by parts (:func:`ffdcli.io.formats.read_part`):
        ``cells`` only those around the rank's nodes. Writing it in another format reads the whole
        file again (the writing rank only).
    global_ids
        ``None`` for a mesh that has every node. A *local* mesh (one MPI rank's, see
        :func:`ffdcli.parallel.partition.localize`) has only some nodes: ``points`` are the rows of the sorted
        global node ids ``global_ids`` (n,), and ``cells`` and ``markers`` use local ids (rows of
        ``points``); ``n_global`` is the whole mesh's node count.
    """

    points: np.ndarray
    dim: int
    cells: list[CellBlock] = field(default_factory=list)
    markers: dict[str, list[CellBlock]] = field(default_factory=dict)
    path: Path | None = None
    format: str = ""
    source: Any = None
    partial: bool = False
    global_ids: np.ndarray | None = None
    n_global: int | None = None
    polyhedra: Any = None

    def __post_init__(self):
        self.points = np.asarray(self.points, dtype=np.float64)
        if self.points.ndim != 2 or self.points.shape[1] != 3:
            raise ValueError(f"points must be (N, 3), got {self.points.shape}")

    @property
    def n_points(self) -> int:
        return len(self.points)

    @property
    def is_local(self) -> bool:
        """True for one rank's local mesh (some nodes only, local ids: see ``global_ids``)."""
        return self.global_ids is not None

    @property
    def n_points_global(self) -> int:
        """The whole mesh's node count (``n_points`` unless the mesh is local)."""
        return self.n_points if self.global_ids is None else int(self.n_global)

    @property
    def n_cells(self) -> int:
        return sum(len(b) for b in self.cells) + (0 if self.polyhedra is None else self.polyhedra.n_cells)

    def marker_point_ids(self, names: str | list[str] | tuple[str, ...]) -> np.ndarray:
        """Sorted unique point ids of one or more markers. Unknown names raise InputError."""
        if isinstance(names, str):
            names = [names]
        check_markers(self.markers, names, path=self.path)
        ids = []
        for name in names:
            ids.extend(b.data.ravel() for b in self.markers[name])
        if not ids:
            return np.zeros(0, dtype=np.int64)
        return unique_ids(*ids)

    def marker_faces(self, names: str | list[str] | tuple[str, ...]) -> list[CellBlock]:
        """The boundary cell blocks of one or more markers (vertex blocks left out)."""
        if isinstance(names, str):
            names = [names]
        check_markers(self.markers, names, path=self.path)
        out = []
        for name in names:
            out.extend(b for b in self.markers[name] if b.type != "vertex")
        return out

    def with_points(self, points: np.ndarray) -> Mesh:
        """A copy sharing cells and markers, with new point coordinates."""
        return Mesh(points=np.asarray(points, dtype=np.float64).reshape(self.points.shape),
                    dim=self.dim, cells=self.cells, markers=self.markers, path=self.path,
                    format=self.format, source=self.source, partial=self.partial,
                    global_ids=self.global_ids, n_global=self.n_global, polyhedra=self.polyhedra)


def check_markers(markers, names, *, path=None, key: str | None = None) -> None:
    """The one rule of marker names: every name in ``names`` is a key of ``markers``.

    Raises :class:`InputError` for the first unknown name, listing the mesh's markers (``key`` is
    the design-file key that named it, e.g. ``volume.fixed``)."""
    for name in names:
        if name not in markers:
            have = ", ".join(markers) or "(none)"
            raise InputError(f"no marker named {name!r}; the markers are: {have}", path=path, key=key,
                             hint="marker names are case-sensitive")


def diagonal(points: np.ndarray) -> float:
    """The length of the bounding-box diagonal of points (N, d): the size scale of a point set
    (0 for no points). Tolerances relative to "the size of the mesh/surface/lattice" use it."""
    pts = np.asarray(points, dtype=np.float64)
    if len(pts) == 0:
        return 0.0
    pts = pts.reshape(len(pts), -1) if pts.ndim != 2 else pts
    return float(np.linalg.norm(pts.max(axis=0) - pts.min(axis=0)))
