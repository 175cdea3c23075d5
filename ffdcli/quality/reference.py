"""What the gate needs of the input mesh, computed once and reused for every candidate geometry.

:func:`part_reference` computes it for one rank's part of a mesh (a collective): the orientation
convention of the WHOLE mesh (each block's sign from the counts of every rank, the 2D plane normal
from the sum over every rank's cells), the scaled Jacobian of the cells the rank counts, the edges
and node orthogonality of the part, and the input's worst cells over every rank. A whole mesh is
the one-part case (:func:`quality_reference`, :func:`ffdcli.parallel.partition.whole_part`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ffdcli.mesh import CellBlock, Mesh
from ffdcli.parallel.comm import SerialComm
from ffdcli.parallel.partition import whole_part
from ffdcli.quality.metrics import (
    CHUNK,
    PLANAR_TOL,
    Orientation,
    check_types,
    plane_distance,
    plane_normal,
    raw_quality,
)
from ffdcli.quality.orthogonality import EdgeTopology, edge_topology, node_orthogonality
from ffdcli.quality.polyhedral import poly_reference


@dataclass(frozen=True)
class QualityReference:
    """What the gate needs of the input mesh, computed once (:func:`quality_reference`,
    :func:`part_reference`) and reused for every candidate geometry of a design loop or a recovery.

    orientation
        The orientation convention of the whole mesh.
    q
        (k,) scaled Jacobian of the cells counted (blocks concatenated; a whole mesh: every cell).
    topology, ortho
        The edges and (n,) node orthogonality of the part (valid at its owned nodes); None when not
        wanted.
    q_min, q_min_valid
        The smallest q, and the smallest q > 0, of the whole input mesh (None: no cell, no valid
        cell); the gate's collapse floor needs them.
    surface
        The mesh's 2-D cells do not lie in one plane (:func:`~ffdcli.quality.metrics.in_one_plane`):
        a surface in space, whose cells have no volume to judge (the gate reports no volume cells).
    """

    orientation: Orientation
    q: np.ndarray
    topology: EdgeTopology | None = None
    ortho: np.ndarray | None = None
    q_min: float | None = None
    q_min_valid: float | None = None
    surface: bool = False


#: The reference of one rank's part: the same value (kept for the name of the MPI gate's API).
PartReference = QualityReference


def counted_blocks(part) -> list[CellBlock]:
    """The cell blocks of the cells ``part`` counts (local node ids; no copy of a fully counted block)."""
    return [b if c.all() else CellBlock(t, b.data[c]) for t, b, c in zip(part.types, part.cells, part.counted,
                                                                        strict=True)]


def _plane_normal(part, comm, pts: np.ndarray, counted: list[CellBlock]) -> np.ndarray:
    """The 2D mesh-plane normal of the whole mesh (:func:`ffdcli.quality.metrics.cell_orientation`)."""
    total = np.zeros(3)
    for blk in counted:
        d = blk.data
        for lo in range(0, len(d), CHUNK):
            c = d[lo:lo + CHUNK]
            total += np.cross(pts[c[:, 1]] - pts[c[:, 0]], pts[c[:, 2]] - pts[c[:, 0]]).sum(axis=0)
    total = comm.allreduce_sum(total)
    own = pts if part.owned.all() else pts[part.owned]
    box = np.concatenate([own.min(axis=0), -own.max(axis=0)]) if len(own) else np.full(6, np.inf)
    box = np.array([min(v) for v in zip(*comm.allgather(box), strict=True)])
    ext = -box[3:] - box[:3] if np.all(np.isfinite(box)) else np.ones(3)
    return plane_normal(total, ext)


def _surface_in_space(part, comm, pts: np.ndarray, counted: list[CellBlock], normal: np.ndarray) -> bool:
    """True when the whole mesh's 2-D cells do not lie in one plane (a collective; the rule of
    :func:`ffdcli.quality.metrics.in_one_plane`, the plane through the mean of every rank's owned nodes)."""
    own = pts if part.owned.all() else pts[part.owned]
    sums = comm.allreduce_sum(np.concatenate([own.sum(axis=0), [len(own)]]))
    if sums[3] == 0:
        return False
    origin = sums[:3] / sums[3]
    lo = np.array([min(v) for v in zip(*comm.allgather(own.min(axis=0) if len(own) else np.full(3, np.inf)),
                                       strict=True)])
    hi = np.array([max(v) for v in zip(*comm.allgather(own.max(axis=0) if len(own) else np.full(3, -np.inf)),
                                       strict=True)])
    size = float(np.linalg.norm(hi - lo))
    far = comm.allreduce_max(plane_distance(pts, counted, normal, origin))
    return far > PLANAR_TOL * max(size, np.finfo(float).tiny)


def part_reference(part, comm, points=None, *, orthogonality: bool = True) -> QualityReference:
    """The :class:`QualityReference` of a part at ``points`` (local rows; default its own): a
    collective (every rank calls it).

    Parameters
    ----------
    part : ffdcli.parallel.partition.MeshPart
        This rank's part (a whole mesh: :func:`ffdcli.parallel.partition.whole_part`).
    comm
        :mod:`ffdcli.parallel.comm` communicator.
    points : ndarray, shape (n, 3), optional
        Coordinates of the part's local nodes.
    orthogonality : bool
        Also the edges and the node orthogonality.
    """
    pts = part.points if points is None else np.asarray(points, dtype=np.float64)
    counted = counted_blocks(part)
    check_types(counted, part.dim)
    normal = _plane_normal(part, comm, pts, counted) if part.dim == 2 else None
    surface = part.dim == 2 and _surface_in_space(part, comm, pts, counted, normal)
    raws = comm.run(lambda: [raw_quality(pts, b.data, b.type, normal) for b in counted])
    if part.dim == 2:
        signs = np.ones(len(counted))
    else:
        tally = np.array([[np.count_nonzero(r < 0), np.count_nonzero(r > 0)] for r in raws], dtype=np.float64)
        tally = comm.allreduce_sum(tally.reshape(-1, 2)) if len(raws) else tally
        signs = np.array([-1.0 if neg > pos else 1.0 for neg, pos in tally])
    orientation = Orientation(signs, normal)
    q = (np.concatenate([np.clip(sg * r, -1.0, 1.0) for sg, r in zip(signs, raws, strict=True)]) if raws
         else np.zeros(0))
    mins = comm.allgather((float(q.min()) if len(q) else None,
                           float(q[q > 0].min()) if np.any(q > 0) else None))
    q_min = min((a for a, _ in mins if a is not None), default=None)
    q_valid = min((b for _, b in mins if b is not None), default=None)
    topo = ortho = None
    if orthogonality:
        def dual():
            t = edge_topology(list(part.cells), len(pts))
            return t, node_orthogonality(pts, list(part.cells), part.dim, orientation=orientation, topology=t)

        topo, ortho = comm.run(dual)
    return QualityReference(orientation, q, topo, ortho, q_min=q_min, q_min_valid=q_valid, surface=surface)


def quality_reference(mesh: Mesh, points: np.ndarray | None = None, *, orthogonality: bool = True
                      ) -> QualityReference:
    """The :class:`QualityReference` of a whole ``mesh`` at ``points`` (default its own): the one-part
    case of :func:`part_reference`. Pass it to :func:`ffdcli.quality.gate.check_quality` as
    ``reference`` with the same ``points_before``. Of a mesh of polyhedral cells: its
    :class:`~ffdcli.quality.polyhedral.PolyFigures` (:func:`~ffdcli.quality.polyhedral.poly_reference`)."""
    if mesh.polyhedra is not None:
        return poly_reference(mesh, points)
    return part_reference(whole_part(mesh), SerialComm(), points, orthogonality=orthogonality)
