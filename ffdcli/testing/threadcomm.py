"""A communicator of ranks that are threads of one process: the MPI code paths in a plain test.

:class:`ThreadComm` has the collectives of :class:`ffdcli.parallel.comm.MPIComm` (same results, same
rank order), exchanged through shared memory between threads; :func:`run_ranks` runs a function
on ``size`` such ranks and returns every rank's result. Tests use it to check that a partitioned
computation equals the serial one for 2, 3, 5 ranks in a second, without ``mpiexec``. Not for runs.
"""

from __future__ import annotations

import threading

import numpy as np

from ffdcli.parallel.comm import MPIComm


class _Hub:
    """The ranks' meeting point. One rank computes at a time (``turn``, released while waiting in a
    collective): numba's default workqueue threading layer aborts when two threads launch parallel
    kernels at once, and the tests are about results, not speed."""

    def __init__(self, size: int):
        self.size = size
        self.barrier = threading.Barrier(size, timeout=300)
        self.turn = threading.Lock()
        self.slots: list = [None] * size

    def _wait(self) -> None:
        self.turn.release()
        try:
            self.barrier.wait()
        finally:
            self.turn.acquire()

    def exchange(self, rank: int, obj) -> list:
        self.slots[rank] = obj
        self._wait()
        out = list(self.slots)
        self._wait()
        return out


class ThreadComm(MPIComm):
    """Rank ``rank`` of ``hub.size`` threads (see the module docstring)."""

    def __init__(self, hub: _Hub, rank: int):      # noqa: D107 - no mpi4py
        self.hub, self.rank, self.size, self.comm = hub, rank, hub.size, None

    def allgather(self, obj) -> list:
        return self.hub.exchange(self.rank, obj)

    def bcast(self, obj, root: int = 0):
        return self.allgather(obj)[root]

    def allgather_rows(self, a):
        got = self.allgather(np.ascontiguousarray(a))
        return np.concatenate(got)

    def gather_rows(self, a):
        got = self.allgather_rows(a)
        return got if self.is_root else None

    def alltoall(self, objs: list) -> list:
        got = self.allgather(list(objs))
        return [got[r][self.rank] for r in range(self.size)]

    def allreduce_sum(self, x):
        got = self.allgather(x)
        if isinstance(x, np.ndarray):
            out = np.array(got[0], dtype=np.float64, copy=True)
            for g in got[1:]:
                out += g
            return out
        return sum(got[1:], got[0])

    def allreduce_max(self, x):
        return max(self.allgather(x))

    def barrier(self) -> None:
        self.allgather(None)


def run_ranks(size: int, fn) -> list:
    """``fn(comm)`` on ``size`` thread ranks; the results in rank order (the first error re-raised)."""
    hub = _Hub(size)
    results: list = [None] * size
    errors: list = [None] * size

    def main(r):
        with hub.turn:
            try:
                results[r] = fn(ThreadComm(hub, r))
            except BaseException as e:      # noqa: BLE001 - re-raised below
                errors[r] = e
                hub.barrier.abort()

    threads = [threading.Thread(target=main, args=(r,)) for r in range(size)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    for e in errors:
        if e is not None and not isinstance(e, threading.BrokenBarrierError):
            raise e
    for e in errors:
        if e is not None:
            raise e
    return results
