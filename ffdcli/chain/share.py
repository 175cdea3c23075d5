"""The MPI side of the chain: this rank's share of the mesh and every reduction over the ranks.

One object per run holds the communicator and the rank's part of the mesh, and is the one place the
chain agrees, sums or gathers across ranks: the design values every rank must share
(:meth:`MeshShare.same_values`), the reverse products summed over the ranks' points (:meth:`sum`), the
warp shared among the ranks (:meth:`warp`), the finite check (:meth:`all_finite`), the gate's counts
reduced (:meth:`check_quality`) and the whole mesh's diagonal (:meth:`diagonal`). Serial: the whole
mesh, no communication (:class:`~ffdcli.parallel.comm.SerialComm`).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from ffdcli.chain.cache import Once
from ffdcli.errors import InputError
from ffdcli.parallel.comm import SerialComm
from ffdcli.parallel.distributed import RankNodes
from ffdcli.parallel.distributed import diagonal as global_diagonal
from ffdcli.parallel.partition import rank_part
from ffdcli.quality.gate import QualityReport, check_quality, check_quality_part
from ffdcli.quality.reference import part_reference, quality_reference
from ffdcli.volume.warp import WarpModel, warp


class MeshShare:
    """This rank's share of a run's mesh and the reductions over the ranks (module docstring).

    Parameters
    ----------
    mesh : ffdcli.mesh.Mesh
        The run's mesh: every node, or (``mesh.is_local``) this rank's local mesh.
    comm : communicator, optional
        :mod:`ffdcli.parallel.comm` (None: serial).
    part : ffdcli.parallel.partition.MeshPart, optional
        The rank's part as the reader gave it (else made on first use).
    """

    def __init__(self, mesh, comm=None, part=None):
        self.mesh = mesh
        self.comm = comm or SerialComm()
        self._part = Once()
        if part is not None:
            self._part.get(lambda: part)
        self._reference = Once()
        self._part_reference = Once()

    @property
    def parallel(self) -> bool:
        return self.comm.size > 1

    @property
    def local(self) -> bool:
        """True when the mesh is this rank's local mesh (:func:`ffdcli.parallel.partition.localize`): its
        points are the rank's rows, and what the serial run takes from every node is reduced."""
        return bool(self.mesh.is_local)

    def part(self):
        """This rank's :class:`~ffdcli.parallel.partition.MeshPart` (the gate's and the writer's share)."""
        if self.local and not self._part._done:
            raise RuntimeError("a run on a local mesh needs its MeshPart (load_run(..., local=True) keeps it)")
        return self._part.get(lambda: rank_part(self.mesh, self.comm))

    def targets(self) -> np.ndarray | None:
        """The rows the warp moves: of a local mesh, its part's (owned nodes and halo); else None (all)."""
        return self.part().rows if self.local else None

    def nodes(self) -> RankNodes | None:
        """Of a local mesh, which of its rows this rank owns and their global ids (what the wall layer's
        walk through the cells shares between the ranks, :mod:`ffdcli.volume.wall_stacks`); else None."""
        if not self.local:
            return None
        part = self.part()
        owned = np.zeros(len(self.mesh.points), dtype=bool)
        owned[part.rows[part.owned]] = True
        return RankNodes(self.comm, np.asarray(self.mesh.global_ids, dtype=np.int64), owned)

    def diagonal(self, points: np.ndarray | None = None) -> float | None:
        """Of a local mesh, the bounding-box diagonal of every node at ``points`` (the local rows; default
        the input's), a collective equal to the serial figure; else None (the points are every node)."""
        if not self.local:
            return None
        return global_diagonal(self.mesh.points if points is None else points, self.comm)

    # -- reductions ------------------------------------------------------------------------------
    def same_values(self, values: np.ndarray, check: Callable[[np.ndarray], np.ndarray]) -> np.ndarray:
        """``check(values)`` on every rank (a refusal on one stops every rank), then the rule that every
        rank holds the same design: one design, or the partitions would disagree silently."""
        values = self.comm.run(check, values)
        if self.parallel:
            ranks = self.comm.allgather(np.asarray(values).tobytes())
            if any(r != ranks[0] for r in ranks):
                raise InputError("set_values: the MPI ranks were given different design values; every rank "
                                 "must set the same values")
        return values

    def sum(self, fn: Callable, *args) -> np.ndarray:
        """``fn(*args)`` on every rank (errors agreed) summed over the ranks: a reverse product of the
        ranks' own points."""
        local = self.comm.run(fn, *args)
        return self.comm.allreduce_sum(np.asarray(local, dtype=np.float64))

    def all_finite(self, points: np.ndarray) -> bool:
        """Whether every coordinate of the mesh at ``points`` is finite (the same answer on every rank)."""
        ok = bool(np.all(np.isfinite(points)))
        return all(self.comm.allgather(ok)) if self.local else ok

    def warp(self, model: WarpModel, disp: np.ndarray, frames: np.ndarray | None, progress=None) -> np.ndarray:
        """:func:`ffdcli.volume.warp.warp` of the mesh (a collective under MPI). A local mesh: each rank
        warps the rows of its part (each node's value depends on the surface only, so it is the serial
        one bit for bit), no communication but the error agreement. A mesh with every node on every
        rank: each rank its block, the blocks gathered."""
        if self.local:
            return self.comm.run(warp, model, disp, frames, progress=progress)
        return warp(model, disp, frames, progress=progress, comm=self.comm)

    def reduction_comm(self):
        """The communicator a reverse product sums over (None serially)."""
        return self.comm if self.parallel else None

    def check_quality(self, points: np.ndarray, **kw) -> QualityReport:
        """The gate's report of the mesh at ``points`` (N, 3) against the input mesh, whose reference is
        computed once. Under MPI a collective: each rank judges its part's cells and nodes and the
        counts are reduced (the same report, equal to the serial one, on every rank)."""
        mesh = self.mesh
        if not self.parallel or mesh.polyhedra is not None:
            # polyhedral cells: every rank holds the whole mesh and every point, and judges it whole
            # (the same arithmetic on every rank, so the same report)
            ref = self._reference.get(lambda: quality_reference(mesh))
            return check_quality(mesh, points, points_before=mesh.points, reference=ref, **kw)
        part = self.part()
        ref = self._part_reference.get(lambda: part_reference(part, self.comm))
        return check_quality_part(part, self.comm, part.take(points), part.points, reference=ref, **kw)
