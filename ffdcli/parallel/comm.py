"""Runs over MPI ranks: a small communicator abstraction, passed down explicitly (no global state).

``ffd`` runs unchanged in one process: every function that can share its work takes ``comm=None``
and then uses :class:`SerialComm`, whose methods are the identity. Under ``mpiexec -n N ffd ...``
the command line makes one :class:`MPIComm` (:func:`world`) and passes it down; the work is split
at the edges, by contiguous index ranges (:meth:`Comm.share`):

* the mesh is read by rank 0 and broadcast (see ``docs/mpi.md``);
* each rank embeds its share of the surface points; the parameters are gathered on every rank (a
  surface is small next to its volume);
* each rank warps its share of the volume nodes; the displacements are gathered;
* rank 0 writes every output once, prints the messages and the ``--json`` summary.

Each point is computed by the same arithmetic whatever the rank count, so the results are those of
the serial run bit for bit.

Errors: :meth:`Comm.agree` is the collective error agreement at the end of each phase. Every rank
calls it with what happened to it (nothing, or an exception); if any rank failed, every rank raises
the first failure (its message and exit status, :class:`RankError` on the ranks where it did not
happen), so all ranks stop together, with the same exit status, and none waits forever. Only rank
0 prints the error.
"""

from __future__ import annotations

import os
import signal

import numpy as np

from ffdcli.errors import (  # noqa: F401
    SIZE_VARIABLES,
    FfdError,
    InputError,
    SignalRecorder,
    Terminated,
    interrupt_message,
)


class RankError(FfdError):
    """An error that happened on another rank, re-raised here by :meth:`Comm.agree`.

    ``str()`` is the failing rank's message; ``exit_code`` its exit status."""

    def __init__(self, message: str, exit_code: int, rank: int, report: dict | None = None):
        self.exit_code = int(exit_code)
        self.rank = int(rank)
        self.report = report or {}
        super().__init__(message)


def _describe(exc: BaseException) -> tuple[str, int, dict | None]:
    """(message, exit status, report) of an exception, as the command line reports it."""
    if isinstance(exc, FfdError):
        return str(exc), int(exc.exit_code), getattr(exc, "report", None)
    if isinstance(exc, KeyboardInterrupt):
        return interrupt_message(exc), 130, None
    if isinstance(exc, Terminated):
        return interrupt_message(exc), 128 + exc.signum, None
    if isinstance(exc, MemoryError):
        return "out of memory", 1, None
    return (f"internal error: {type(exc).__name__}: {exc} (this is a bug in ffd; -v shows where)", 1, None)


def share(n: int, rank: int, size: int) -> tuple[int, int]:
    """The contiguous block ``[lo, hi)`` of ``n`` items that rank ``rank`` of ``size`` owns.

    Blocks differ in length by at most one; rank order is index order, so gathering the blocks in
    rank order gives back the whole."""
    n, rank, size = int(n), int(rank), int(size)
    return rank * n // size, (rank + 1) * n // size


class SerialComm:
    """The communicator of a run in one process: every collective is the identity."""

    rank = 0
    size = 1

    @property
    def is_root(self) -> bool:
        return self.rank == 0

    def share(self, n: int) -> tuple[int, int]:
        """``[lo, hi)``: this rank's block of ``n`` items (see :func:`share`)."""
        return share(n, self.rank, self.size)

    def bcast(self, obj, root: int = 0):
        """``obj`` of rank ``root`` on every rank."""
        return obj

    def allgather(self, obj) -> list:
        """The ``obj`` of every rank, in rank order."""
        return [obj]

    def allgather_rows(self, a: np.ndarray) -> np.ndarray:
        """Concatenate every rank's array along axis 0, in rank order, on every rank.

        The trailing shape and dtype must agree across ranks."""
        return np.array(a, copy=True)

    def gather_rows(self, a: np.ndarray) -> np.ndarray | None:
        """Concatenate every rank's array along axis 0, in rank order, on rank 0 (None elsewhere)."""
        return np.array(a, copy=True)

    def alltoall(self, objs: list) -> list:
        """``objs[r]`` goes to rank r; returns what every rank sent to this one, in rank order."""
        return list(objs)

    def allreduce_sum(self, x):
        """The sum over ranks of ``x`` (a number or an array of the same shape on every rank)."""
        return np.array(x, dtype=np.float64, copy=True) if isinstance(x, np.ndarray) else x

    def allreduce_max(self, x: float) -> float:
        return x

    def barrier(self) -> None:
        pass

    def agree(self, error: BaseException | None = None, *, signals: bool = True) -> None:
        """Collective error agreement (see the module docstring): raise ``error`` if given.

        Over MPI: every rank calls it; if any rank gives an error, every rank raises the error of
        the lowest failing rank (that rank its own exception, the others a :class:`RankError` with its
        message and exit status), so every rank exits with the same status. Errors
        raised here have ``ffd_agreed = True``: the command line does not agree on them again.
        ``signals``: a SIGTERM/SIGHUP recorded by :meth:`watch_signals` counts as this rank's error
        (:class:`~ffdcli.errors.Terminated`)."""
        if error is not None:
            raise error


    def run(self, fn, *args, **kwargs):
        """``fn(*args, **kwargs)`` on every rank, then :meth:`agree` on how it went; its result."""
        try:
            out = fn(*args, **kwargs)
        except BaseException as e:      # noqa: BLE001 - every failure is agreed on, then re-raised
            self.agree(e)
            raise
        self.agree(None)
        return out

    def root_then_bcast(self, fn, *args, **kwargs):
        """``fn`` on rank 0 only, agreed on, and its (picklable) result broadcast to every rank. A
        signal recorded meanwhile waits for the next agreement: what rank 0 did (a write) is done."""
        out = None
        try:
            if self.is_root:
                out = fn(*args, **kwargs)
        except BaseException as e:      # noqa: BLE001 - every failure is agreed on, then re-raised
            self.agree(e)
            raise
        self.agree(None, signals=False)
        return self.bcast(out)


class MPIComm(SerialComm):
    """A :class:`SerialComm` over an ``mpi4py`` communicator (``MPI.COMM_WORLD`` by default)."""

    def __init__(self, comm=None):
        from mpi4py import MPI  # noqa: PLC0415 (the [mpi] extra)

        self.comm = MPI.COMM_WORLD if comm is None else comm
        self.rank = self.comm.Get_rank()
        self.size = self.comm.Get_size()
        self.signals: SignalRecorder | None = None      # the command line's (ffd under mpiexec)

    def bcast(self, obj, root: int = 0):
        return self.comm.bcast(obj, root=root)

    def allgather(self, obj) -> list:
        return self.comm.allgather(obj)

    def allgather_rows(self, a: np.ndarray) -> np.ndarray:
        a = np.ascontiguousarray(a)
        shapes = self.comm.allgather((a.shape, a.dtype.str))
        tail = {s[1:] for s, _ in shapes}
        kinds = {d for _, d in shapes}
        if len(tail) != 1 or len(kinds) != 1:
            raise ValueError(f"allgather_rows: the ranks' arrays differ in trailing shape or dtype: {shapes}")
        row = int(np.prod(a.shape[1:], dtype=np.int64))
        counts = np.array([s[0] * row for s, _ in shapes], dtype=np.int64)
        out = np.empty((sum(s[0] for s, _ in shapes),) + a.shape[1:], dtype=a.dtype)
        send = a.view(np.uint8).reshape(-1) if a.dtype == np.bool_ else a.reshape(-1)
        recv = out.view(np.uint8).reshape(-1) if a.dtype == np.bool_ else out.reshape(-1)
        displs = np.concatenate([[0], np.cumsum(counts)[:-1]])
        self.comm.Allgatherv(send, [recv, counts, displs, _mpi_type(send.dtype)])
        return out

    def gather_rows(self, a: np.ndarray) -> np.ndarray | None:
        a = np.ascontiguousarray(a)
        shapes = self.comm.allgather((a.shape, a.dtype.str))
        if len({s[1:] for s, _ in shapes}) != 1 or len({d for _, d in shapes}) != 1:
            raise ValueError(f"gather_rows: the ranks' arrays differ in trailing shape or dtype: {shapes}")
        row = int(np.prod(a.shape[1:], dtype=np.int64))
        counts = np.array([s[0] * row for s, _ in shapes], dtype=np.int64)
        send = a.view(np.uint8).reshape(-1) if a.dtype == np.bool_ else a.reshape(-1)
        if not self.is_root:
            self.comm.Gatherv(send, None, root=0)
            return None
        out = np.empty((sum(s[0] for s, _ in shapes),) + a.shape[1:], dtype=a.dtype)
        recv = out.view(np.uint8).reshape(-1) if a.dtype == np.bool_ else out.reshape(-1)
        displs = np.concatenate([[0], np.cumsum(counts)[:-1]])
        self.comm.Gatherv(send, [recv, counts, displs, _mpi_type(send.dtype)], root=0)
        return out

    def alltoall(self, objs: list) -> list:
        return self.comm.alltoall(objs)

    def allreduce_sum(self, x):
        from mpi4py import MPI  # noqa: PLC0415 (the [mpi] extra)

        if isinstance(x, np.ndarray):
            x = np.ascontiguousarray(x, dtype=np.float64)
            out = np.empty_like(x)
            self.comm.Allreduce(x, out, op=MPI.SUM)
            return out
        return self.comm.allreduce(x, op=MPI.SUM)

    def allreduce_max(self, x: float) -> float:
        from mpi4py import MPI  # noqa: PLC0415 (the [mpi] extra)

        return self.comm.allreduce(x, op=MPI.MAX)

    def barrier(self) -> None:
        self.comm.Barrier()

    def agree(self, error: BaseException | None = None, *, signals: bool = True) -> None:
        signals_seen = getattr(self, "signals", None)
        got = signals_seen.signum if signals_seen is not None else None
        if error is None and signals and got is not None:
            error = Terminated(got)                 # mpiexec forwarded SIGTERM/SIGHUP: stop together
        mine = None if error is None else _describe(error) + (self.rank,)
        failures = [f for f in self.allgather(mine) if f is not None]
        if not failures:
            return
        message, code, report, rank = failures[0]          # the lowest failing rank's, on every rank
        err = error if rank == self.rank else RankError(message, code, rank, report)
        if isinstance(err, KeyboardInterrupt):
            # click turns a KeyboardInterrupt into a new Abort, which has lost the agreement: this rank
            # then waited in one more agreement than the others (a deadlock on Ctrl-C)
            err = Terminated(signal.SIGINT)
        err.ffd_agreed = True
        raise err


def _mpi_type(dtype: np.dtype):
    from mpi4py import MPI  # noqa: PLC0415 (the [mpi] extra)

    return {np.dtype(np.float64): MPI.DOUBLE, np.dtype(np.float32): MPI.FLOAT, np.dtype(np.int64): MPI.INT64_T,
            np.dtype(np.int32): MPI.INT32_T, np.dtype(np.uint8): MPI.UINT8_T}[np.dtype(dtype)]


Comm = SerialComm


def launched_size(environ=None) -> int:
    """The process count an MPI launcher announced in the environment (1 when not launched)."""
    env = os.environ if environ is None else environ
    for name in SIZE_VARIABLES:
        value = env.get(name, "")
        if value.strip().isdigit():
            return max(1, int(value))
    return 1


def mpi_available() -> bool:
    """Whether ``mpi4py`` can be imported (the ``[mpi]`` extra)."""
    try:
        import mpi4py  # noqa: F401, PLC0415 (the [mpi] extra)
    except ImportError:
        return False
    return True


def world(environ=None) -> SerialComm:
    """The communicator of this process: :class:`MPIComm` over ``COMM_WORLD`` when an MPI launcher
    started more than one process, else :class:`SerialComm` (``mpi4py`` is then never imported).

    Raises :class:`ffdcli.errors.InputError` when launched by ``mpiexec -n N`` (N > 1) without
    ``mpi4py``: N copies of the serial run would each write the same files."""
    if launched_size(environ) <= 1:
        return SerialComm()
    if not mpi_available():
        raise InputError("started by an MPI launcher with several processes, but mpi4py is not installed; "
                         "install the extra: pip install 'ffdcli[mpi]' (or run without mpiexec)")
    comm = MPIComm()
    return comm if comm.size > 1 else SerialComm()
