"""One rank's share of a mesh: the nodes it owns (a compact piece of space), the cells around them and their halo.

An MPI run (:mod:`ffdcli.parallel`) gives every node an owner rank (:func:`node_owners`): the
nodes sorted along a Z-order (Morton) curve of their coordinates, cut into ``size`` runs of equal
length, so that a rank owns a compact piece of space whatever the file's numbering (contiguous
blocks of ids would give every rank cells all over a mesh numbered by a mesher's entities). What a
rank needs of the volume mesh to judge its nodes and cells (the quality gate) is a :class:`MeshPart`:

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

from dataclasses import dataclass, replace

import numpy as np

from ffdcli.mesh import CELL_NODES, CellBlock, Mesh
from ffdcli.parallel import share
from ffdcli.warp_tree import morton_order  # the one Z-order curve (the warp orders its targets by it)


@dataclass(frozen=True, eq=False)
class MeshPart:
    """One rank's share of a mesh's volume (see the module docstring).

    n_points, n_cells
        Global node and cell counts.
    rank
        The rank whose part this is.
    ids
        (n,) sorted global ids of the local nodes (owned and halo).
    points
        (n, 3) their coordinates.
    owned
        (n,) bool: the local nodes this rank owns.
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
        Per block: (k,) bool, the cells this rank counts (it owns their first node).
    rows
        (n,) the rows of ``ids`` in this rank's local mesh (:func:`localize`); ``None`` when the part
        was taken from a mesh that has every node (then rows are ``ids``).
    """

    n_points: int
    n_cells: int
    rank: int
    ids: np.ndarray
    points: np.ndarray
    owned: np.ndarray
    dim: int
    types: tuple
    cells: tuple
    cell_ids: tuple
    counted: tuple
    rows: np.ndarray | None = None

    def take(self, points: np.ndarray) -> np.ndarray:
        """The part's rows of an (N, 3) array of every node, or of the rank's local mesh's rows
        when the part belongs to a local mesh (``rows`` set)."""
        return np.asarray(points, dtype=np.float64)[self.ids if self.rows is None else self.rows]

    def nbytes(self) -> int:
        """Bytes held by the part's arrays (points, ids, cells)."""
        return int(self.ids.nbytes + self.points.nbytes + self.owned.nbytes + sum(b.data.nbytes for b in self.cells)
                   + sum(c.nbytes for c in self.cell_ids) + sum(c.nbytes for c in self.counted))


def node_owners(points: np.ndarray, size: int) -> np.ndarray:
    """(N,) int32 owner rank of every node: the Morton order of ``points`` (in their bounding cube)
    cut into ``size`` runs of equal length (:func:`ffdcli.parallel.share`). The same on every rank
    (same points)."""
    pts = np.asarray(points, dtype=np.float64)
    n = len(pts)
    owner = np.empty(n, dtype=np.int32)
    if not n:
        return owner
    # the same scale on every axis: two corners of the bounding cube join the points (a thin mesh,
    # one cell thick or a planar 2D mesh, is then cut across its plane, not through its thickness)
    lo = pts.min(axis=0)
    cube = np.vstack([pts, lo, lo + np.ptp(pts, axis=0).max()])
    order = morton_order(cube)
    order = order[order < n]
    for r in range(size):
        lo, hi = share(n, r, size)
        owner[order[lo:hi]] = r
    return owner


def touching(data: np.ndarray, owner: np.ndarray, rank: int) -> np.ndarray:
    """(k,) bool: the cells (rows of ``data``, global node ids) with a node that ``rank`` owns."""
    if not len(data):
        return np.zeros(0, dtype=bool)
    return np.any(owner[data] == rank, axis=1)


def assemble_part(n_points: int, n_cells: int, owner: np.ndarray, rank: int, dim: int, types, blocks,
                  cell_ids, coordinates) -> MeshPart:
    """A :class:`MeshPart` from the cells touching the nodes ``rank`` owns (global node ids).

    Parameters
    ----------
    owner
        (N,) owner rank of every node (:func:`node_owners`).
    blocks
        Per entry of ``types``: (k, nodes) global node ids of the cells touching the owned nodes,
        in global order.
    cell_ids
        Per block: (k,) their global cell indices.
    coordinates
        ``coordinates(ids) -> (len(ids), 3)``: the coordinates of sorted global node ids.
    """
    blocks = [np.asarray(b, dtype=np.int64) for b in blocks]
    mine = np.flatnonzero(owner == rank)
    ids = np.union1d(mine, np.unique(np.concatenate([b.ravel() for b in blocks])) if blocks
                     else np.zeros(0, np.int64))
    cells = tuple(CellBlock(t, np.searchsorted(ids, b).reshape(len(b), -1)) for t, b in zip(types, blocks, strict=True))
    counted = tuple(owner[b[:, 0]] == rank if len(b) else np.zeros(0, dtype=bool) for b in blocks)
    pts = np.ascontiguousarray(coordinates(ids), dtype=np.float64).reshape(len(ids), 3)
    return MeshPart(int(n_points), int(n_cells), int(rank), ids, pts, owner[ids] == rank, int(dim), tuple(types),
                    cells, tuple(np.asarray(c, dtype=np.int64) for c in cell_ids), counted)


def part_of(mesh: Mesh, owner: np.ndarray, rank: int) -> MeshPart:
    """The :class:`MeshPart` of ``rank`` of a whole mesh in memory (``owner``: :func:`node_owners`)."""
    cells = [b for b in mesh.cells if len(b)]
    types, blocks, cell_ids, start = [], [], [], 0
    for b in cells:
        mask = touching(b.data, owner, rank)
        types.append(b.type)
        blocks.append(b.data[mask])
        cell_ids.append(start + np.flatnonzero(mask))
        start += len(b)
    return assemble_part(mesh.n_points, start, owner, rank, mesh.dim, types, blocks, cell_ids,
                         lambda ids: mesh.points[ids])


def localize(mesh: Mesh, owner: np.ndarray, rank: int) -> tuple[Mesh, MeshPart]:
    """One rank's local mesh and its part, from a mesh that has every node's coordinates.

    The local mesh keeps the nodes a rank needs and no other: those it owns (``owner``), the halo
    (the other nodes of the cells touching them) and every marker node (the surface and the
    boundaries that every rank's warp and box need). Rows are sorted by global id (so every sum and
    tie-break over them runs in the order of the whole mesh); ``global_ids`` maps rows to global
    ids, ``cells`` (those touching the owned nodes, global order) and ``markers`` use local ids.
    ``mesh`` may be whole or a partial mesh with global ids whose cells include those around the
    rank's nodes. The part's ``rows`` are its nodes' rows of the local mesh.

    This is the definition every reader by parts must reproduce (``read_part`` of a format gives
    the same local mesh without any rank holding every node).
    """
    part = part_of(mesh, owner, rank)
    marker = [b.data.ravel() for blocks in mesh.markers.values() for b in blocks]
    keep = np.union1d(part.ids, np.concatenate(marker) if marker else np.zeros(0, np.int64)).astype(np.int64)
    rows = np.searchsorted(keep, part.ids)
    local = Mesh(points=mesh.points[keep], dim=mesh.dim,
                 cells=[CellBlock(b.type, rows[b.data]) for b in part.cells],
                 markers={name: [CellBlock(b.type, np.searchsorted(keep, b.data)) for b in blocks]
                          for name, blocks in mesh.markers.items()},
                 path=mesh.path, format=mesh.format, source=mesh.source, partial=True,
                 global_ids=keep, n_global=mesh.n_points)
    return local, replace(part, rows=rows)


def rank_part(mesh: Mesh, comm) -> MeshPart:
    """This rank's part of a whole mesh that every rank holds (``comm``: :mod:`ffdcli.parallel`)."""
    return part_of(mesh, node_owners(mesh.points, comm.size), comm.rank)


def redistribute(comm, owner: np.ndarray, types, blocks, cell_ids) -> tuple[list, list]:
    """Cells read in any split sent to every rank that owns one of their nodes (an all-to-all).

    ``blocks``/``cell_ids``: per cell type, the (k, nodes) global node ids and (k,) global indices
    of the cells this rank read. Returns, per type, the cells touching this rank's nodes, sorted by
    global index."""
    outgoing = [[(b[m], c[m]) for b, c in zip(blocks, cell_ids, strict=True) for m in [touching(b, owner, r)]]
                for r in range(comm.size)]
    incoming = comm.alltoall(outgoing)
    out_blocks, out_ids = [], []
    for k, t in enumerate(types):
        got = [msg[k] for msg in incoming]
        data = np.concatenate([g[0] for g in got]) if got else np.zeros((0, CELL_NODES[t]), np.int64)
        ids = np.concatenate([g[1] for g in got]) if got else np.zeros(0, np.int64)
        order = np.argsort(ids, kind="stable")
        out_blocks.append(data[order].reshape(len(ids), CELL_NODES[t]))
        out_ids.append(ids[order])
    return out_blocks, out_ids
