"""One rank's share of a mesh: a contiguous block of nodes, the cells around them and their halo.

An MPI run (:mod:`ffdcli.parallel`) splits the nodes into contiguous blocks of global ids
(:func:`ffdcli.parallel.share`): rank r owns ``[lo, hi)``. What a rank needs of the volume mesh to
judge its nodes and cells (the quality gate) is a :class:`MeshPart`:

* the cells that touch an owned node, in global order within each cell block (so every edge of an
  owned node has all its cells here: its dual face, and so the node's orthogonality, is computed
  by the same additions in the same order as in the serial run);
* the coordinates of every node of those cells (owned nodes and the halo), local ids sorted by
  global id (the renumbering keeps the order of ids, so sorts and tie-breaks agree with serial);
* the global index of each local cell, and which cells this rank counts: a cell is counted by the
  rank that owns its first node (exactly one rank).

Parts are built from a whole mesh (:func:`part_of`, the rank that holds it) or read directly by
rank (:func:`ffdcli.formats.cgns.read_part`, :func:`ffdcli.formats.su2.read_part`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ffdcli.mesh import CELL_NODES, CellBlock, Mesh
from ffdcli.parallel import share


@dataclass(frozen=True, eq=False)
class MeshPart:
    """One rank's share of a mesh's volume (see the module docstring).

    n_points, n_cells
        Global node and cell counts.
    lo, hi
        The owned block of global node ids ``[lo, hi)``.
    ids
        (n,) sorted global ids of the local nodes (owned block and halo).
    points
        (n, 3) their coordinates.
    dim
        Topological dimension of the cells.
    types
        Cell type of every global cell block, in the mesh's order (the same on every rank, empty
        blocks included: the gate's orientation is per block).
    cells
        One :class:`CellBlock` per entry of ``types``, node ids LOCAL (rows of ``points``).
    cell_ids
        Per block: (k,) global index of each local cell in the concatenation of the mesh's blocks.
    counted
        Per block: (k,) bool, the cells this rank counts (its first node is owned).
    """

    n_points: int
    n_cells: int
    lo: int
    hi: int
    ids: np.ndarray
    points: np.ndarray
    dim: int
    types: tuple
    cells: tuple
    cell_ids: tuple
    counted: tuple

    @property
    def owned(self) -> np.ndarray:
        """(n,) bool: the local nodes of the owned block."""
        return (self.ids >= self.lo) & (self.ids < self.hi)

    def local(self, global_ids: np.ndarray) -> np.ndarray:
        """Local rows of global node ids (which must be local nodes)."""
        return np.searchsorted(self.ids, global_ids)

    def take(self, points: np.ndarray) -> np.ndarray:
        """The local rows of an (N, 3) array of every node (a rank that holds the whole mesh)."""
        return np.asarray(points, dtype=np.float64)[self.ids]

    def nbytes(self) -> int:
        """Bytes held by the part's arrays (points, ids, cells)."""
        return int(self.ids.nbytes + self.points.nbytes + sum(b.data.nbytes for b in self.cells)
                   + sum(c.nbytes for c in self.cell_ids) + sum(c.nbytes for c in self.counted))


def touching(data: np.ndarray, lo: int, hi: int) -> np.ndarray:
    """(k,) bool: the cells (rows of ``data``, global node ids) with a node in ``[lo, hi)``."""
    if not len(data):
        return np.zeros(0, dtype=bool)
    return np.any((data >= lo) & (data < hi), axis=1)


def assemble_part(n_points: int, n_cells: int, lo: int, hi: int, dim: int, types, blocks, cell_ids,
                  coordinates) -> MeshPart:
    """A :class:`MeshPart` from the cells touching ``[lo, hi)`` (global node ids).

    Parameters
    ----------
    blocks
        Per entry of ``types``: (k, nodes) global node ids of the cells touching the owned block,
        in global order.
    cell_ids
        Per block: (k,) their global cell indices.
    coordinates
        ``coordinates(ids) -> (len(ids), 3)``: the coordinates of sorted global node ids (a slice of
        an array in memory, or a read from the file).
    """
    parts = [np.asarray(b, dtype=np.int64).ravel() for b in blocks]
    ids = np.union1d(np.arange(lo, hi, dtype=np.int64),
                     np.unique(np.concatenate(parts)) if parts else np.zeros(0, np.int64))
    cells = tuple(CellBlock(t, np.searchsorted(ids, np.asarray(b, dtype=np.int64)).reshape(len(b), -1))
                  for t, b in zip(types, blocks, strict=True))
    counted = tuple((np.asarray(b, dtype=np.int64)[:, 0] >= lo) & (np.asarray(b, dtype=np.int64)[:, 0] < hi)
                    if len(b) else np.zeros(0, dtype=bool) for b in blocks)
    pts = np.ascontiguousarray(coordinates(ids), dtype=np.float64).reshape(len(ids), 3)
    return MeshPart(int(n_points), int(n_cells), int(lo), int(hi), ids, pts, int(dim), tuple(types), cells,
                    tuple(np.asarray(c, dtype=np.int64) for c in cell_ids), counted)


def part_of(mesh: Mesh, lo: int, hi: int) -> MeshPart:
    """The :class:`MeshPart` of the owned block ``[lo, hi)`` of a whole mesh in memory."""
    cells = [b for b in mesh.cells if len(b)]
    types, blocks, cell_ids, start = [], [], [], 0
    for b in cells:
        mask = touching(b.data, lo, hi)
        types.append(b.type)
        blocks.append(b.data[mask])
        cell_ids.append(start + np.flatnonzero(mask))
        start += len(b)
    return assemble_part(mesh.n_points, start, lo, hi, mesh.dim, types, blocks, cell_ids,
                         lambda ids: mesh.points[ids])


def rank_part(mesh: Mesh, comm) -> MeshPart:
    """This rank's part of a whole mesh that every rank holds (``comm``: :mod:`ffdcli.parallel`)."""
    lo, hi = comm.share(mesh.n_points)
    return part_of(mesh, lo, hi)


def redistribute(comm, n_points: int, types, blocks, cell_ids) -> tuple[list, list]:
    """Cells read in blocks of cells (any split) sent to every rank that owns one of their nodes.

    ``blocks``/``cell_ids``: per cell type, the (k, nodes) global node ids and (k,) global indices
    of the cells this rank read. Returns, per type, the cells touching this rank's node block,
    sorted by global index (one all-to-all of the ranks)."""
    size = comm.size
    bounds = [share(n_points, r, size) for r in range(size)]
    outgoing = []
    for lo, hi in bounds:
        outgoing.append([(b[m], c[m]) for b, c in zip(blocks, cell_ids, strict=True)
                         for m in [touching(b, lo, hi)]])
    incoming = comm.alltoall(outgoing)
    out_blocks, out_ids = [], []
    for k, t in enumerate(types):
        got = [msg[k] for msg in incoming]
        data = np.concatenate([g[0] for g in got]) if got else np.zeros((0, CELL_NODES[t]), np.int64)
        ids = np.concatenate([g[1] for g in got]) if got else np.zeros(0, np.int64)
        order = np.argsort(ids, kind="stable")
        out_blocks.append(data[order].reshape(len(ids), -1))
        out_ids.append(ids[order])
    return out_blocks, out_ids


def gather_owned(comm, part: MeshPart, values: np.ndarray) -> np.ndarray | None:
    """The owned rows of ``values`` (local rows, (n, k)) of every rank, in global order, on rank 0
    ((n_points, k); None on the other ranks): what rank 0 writes."""
    return comm.gather_rows(np.ascontiguousarray(np.asarray(values)[part.owned]))
