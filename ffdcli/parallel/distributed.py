"""The pipeline on one MPI rank's local mesh: whole-mesh figures by reduction, global ids, the gathers.

Under MPI, ``ffd deform`` runs on each rank's *local mesh* (:func:`ffdcli.parallel.partition.localize`: the
nodes the rank owns, their halo and every marker node, rows sorted by global id). What the serial
run computes from every node is computed here from the ranks' rows by a reduction that gives the
same floats (minima and maxima are exact), and what leaves the run (node ids in messages and
files, the mesh written) is put back in global terms:

* :func:`extent`, :func:`diagonal`: the bounding box of every node, from the local rows of every
  rank (their union is every node);
* :func:`global_ids`: the global ids of local rows;
* :func:`gather_points`: the owned rows of every rank, in global order, on rank 0 (the writer),
  sent in chunks of global ids, so rank 0 holds the (N, 3) result and one chunk, not every rank's
  rows at once;
* :func:`rows_of_block`: the coordinates of a block of global ids (the point rows a rank read)
  from their owners, so that each rank prints the text of its own rows of an SU2 file
  (:func:`ffdcli.io.formats.su2.render_rows`) and rank 0 only copies it into the output
  (:mod:`ffdcli.io.parts`: the write of a local mesh);
* :class:`RankNodes`: which rows of a rank's local mesh it owns (it holds every cell around them),
  their global ids and the communicator: what a computation that walks from node to node through
  the cells (the wall layer's stacks, :mod:`ffdcli.volume.wall_stacks`) needs to let the owner of
  each node take each step.

Every function takes the communicator explicitly; with a mesh that has every node (``global_ids``
None) they are the serial computation.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ffdcli.mesh import Mesh

#: Global ids per message of :func:`gather_points` (24 MB of coordinates at most per chunk).
GATHER_ROWS = 1 << 20


@dataclass(frozen=True, eq=False)
class RankNodes:
    """One rank's local mesh among the ranks' (module docstring).

    comm
        The communicator (:mod:`ffdcli.parallel.comm`).
    ids
        (n,) the sorted global id of each row of the local mesh.
    owned
        (n,) bool: the rows this rank owns (every cell around such a node is in its local mesh; every
        node is owned by exactly one rank).
    """

    comm: object
    ids: np.ndarray
    owned: np.ndarray

    def rows(self, gid) -> np.ndarray:
        """The local rows of global ids this rank holds."""
        return np.searchsorted(self.ids, np.asarray(gid, dtype=np.int64))

    def owns(self, gid) -> np.ndarray:
        """(m,) bool: which of the global ids ``gid`` this rank holds and owns."""
        gid = np.asarray(gid, dtype=np.int64)
        if not len(self.ids):
            return np.zeros(len(gid), dtype=bool)
        r = np.minimum(self.rows(gid), len(self.ids) - 1)
        return (self.ids[r] == gid) & self.owned[r]


def extent(points: np.ndarray, comm=None) -> tuple[np.ndarray, np.ndarray]:
    """(lo (3,), hi (3,)): the bounding box of the union of every rank's ``points`` (n_r, 3), a
    collective (``comm=None``: these points alone). A rank with no points takes no part in it."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    mine = (np.concatenate([-pts.min(axis=0), pts.max(axis=0)]) if len(pts)
            else np.full(6, -np.inf))
    both = mine if comm is None or comm.size == 1 else np.max(np.array(comm.allgather(mine)), axis=0)
    return -both[:3], both[3:]


def diagonal(points: np.ndarray, comm=None) -> float:
    """:func:`ffdcli.mesh.diagonal` of the union of every rank's ``points`` (a collective): the same
    float as the serial diagonal of every node (0 for no points)."""
    lo, hi = extent(points, comm)
    if not np.all(np.isfinite(lo)):
        return 0.0
    return float(np.linalg.norm(hi - lo))


def global_ids(mesh: Mesh, rows) -> np.ndarray:
    """The global node ids of rows of ``mesh`` (the rows themselves for a mesh with every node)."""
    rows = np.asarray(rows, dtype=np.int64)
    return rows if mesh.global_ids is None else mesh.global_ids[rows]


def local_rows(mesh: Mesh, ids) -> np.ndarray:
    """The rows of ``mesh`` of global node ids that it holds (``ids`` themselves for a mesh with every node)."""
    ids = np.asarray(ids, dtype=np.int64)
    return ids if mesh.global_ids is None else np.searchsorted(mesh.global_ids, ids)


def gather_points(part, points: np.ndarray, n_points: int, comm, *, chunk: int = GATHER_ROWS) -> np.ndarray | None:
    """(N, 3) every node's coordinates on rank 0 (None on the others), a collective.

    Parameters
    ----------
    part
        This rank's :class:`~ffdcli.parallel.partition.MeshPart` of its local mesh (``ids``, ``owned``,
        ``rows``): each node is sent by the rank that owns it, so exactly once.
    points
        (n, 3) the local mesh's rows.
    n_points
        N, the whole mesh's node count.
    chunk
        Global ids per round: rank 0 receives the owned rows of ids ``[a, a + chunk)`` of every
        rank, then the next ones, so its buffers are the result and one chunk.
    """
    owned_ids = part.ids[part.owned]
    rows = owned_ids if part.rows is None else part.rows[part.owned]
    pts = np.asarray(points, dtype=np.float64)
    out = np.empty((int(n_points), 3)) if comm.is_root else None
    for a in range(0, max(int(n_points), 1), int(chunk)):
        lo, hi = np.searchsorted(owned_ids, [a, a + int(chunk)])
        ids = comm.gather_rows(np.ascontiguousarray(owned_ids[lo:hi]))
        xyz = comm.gather_rows(np.ascontiguousarray(pts[rows[lo:hi]]).reshape(-1, 3))
        if comm.is_root:
            out[ids] = xyz
    return out


def rows_of_block(part, points: np.ndarray, first: int, count: int, comm) -> np.ndarray:
    """(count, 3) the coordinates of global nodes ``first .. first + count - 1`` on this rank, from the
    ranks that own them (one all-to-all), a collective; each rank asks for its own block of ids (the
    blocks of any ranks, e.g. the point rows each rank read; every id asked by some rank is owned by
    exactly one).

    ``part``, ``points``: as :func:`gather_points` (this rank's part of its local mesh and the local
    mesh's rows)."""
    owned_ids = part.ids[part.owned]
    rows = owned_ids if part.rows is None else part.rows[part.owned]
    pts = np.asarray(points, dtype=np.float64)
    spans = np.array(comm.allgather((int(first), int(count))), dtype=np.int64).reshape(-1, 2)
    lo = np.searchsorted(owned_ids, spans[:, 0])
    hi = np.searchsorted(owned_ids, spans[:, 0] + spans[:, 1])
    got = comm.alltoall([(owned_ids[a:b] - int(f), np.ascontiguousarray(pts[rows[a:b]]))
                         for a, b, f in zip(lo, hi, spans[:, 0], strict=True)])
    out = np.full((int(count), 3), np.nan)
    seen = np.zeros(int(count), dtype=bool)
    for at, xyz in got:
        out[at] = xyz
        seen[at] = True
    if not seen.all():
        raise RuntimeError(f"rows_of_block: {int((~seen).sum())} of the ids asked are owned by no rank")
    return out
