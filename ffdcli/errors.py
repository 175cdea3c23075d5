"""The errors a user sees.

Library code raises :class:`InputError` (exit 2) for anything wrong with what the user gave us
(a file, a key, a value) and :class:`QualityError` (exit 3) when a deformed mesh fails the quality
check. Messages are one line, name the file (and the key path or line) and say what was expected.
Any other exception is a bug in ffd: the command line reports it in one line with exit 1.
"""

from __future__ import annotations

import contextlib
import os
import signal
import threading
from pathlib import Path

#: Environment variables by which MPI launchers give the number of processes (MPICH/Intel hydra,
#: Open MPI, PMIx, Slurm's srun).
SIZE_VARIABLES = ("PMI_SIZE", "OMPI_COMM_WORLD_SIZE", "PMIX_SIZE", "SLURM_NTASKS")
#: Signals that mpiexec forwards to every rank and that end an MPI run together (SIGINT: KeyboardInterrupt).
WATCHED_SIGNALS = tuple(getattr(signal, n) for n in ("SIGTERM", "SIGHUP") if hasattr(signal, n))


class FfdError(Exception):
    """Base class of the errors that the command line reports without a traceback."""

    exit_code = 1

    def __init__(self, message: str, *, path: str | Path | None = None, key: str | None = None,
                 line: int | None = None, hint: str | None = None):
        self.message = message
        self.path = None if path is None else str(path)
        self.key = key
        self.line = line
        self.hint = hint
        super().__init__(self.format())

    def format(self) -> str:
        where = ""
        if self.path:
            where = self.path
            if self.line is not None:
                where += f":{self.line}"
            where += ": "
        key = f"{self.key}: " if self.key else ""
        hint = f" ({self.hint})" if self.hint else ""
        return f"{where}{key}{self.message}{hint}"


class InputError(FfdError):
    """Bad input or usage: a missing/corrupt file, a wrong key or value. Exit status 2."""

    exit_code = 2


class QualityError(FfdError):
    """The deformed mesh failed the quality check; nothing was written. Exit status 3."""

    exit_code = 3

    def __init__(self, message: str, *, report: dict | None = None, **kw):
        self.report = report or {}
        super().__init__(message, **kw)


class Terminated(BaseException):
    """SIGTERM or SIGHUP stopped the run (a BaseException, like KeyboardInterrupt, so that no
    ``except Exception`` swallows it): during a write (:func:`ffdcli.io.atomic.signals_raise`), or
    under MPI at the next agreement of the ranks (:class:`SignalRecorder`).
    The command line reports it once and exits with 128 + signum."""

    def __init__(self, signum: int):
        self.signum = signum
        super().__init__(f"terminated by {signal.Signals(signum).name}")


class SignalRecorder:
    """For the whole run of ``ffd`` under ``mpiexec`` (from before MPI starts): SIGTERM and SIGHUP,
    which ``mpiexec`` forwards to every rank, are recorded (:attr:`signum`) instead of killing the rank
    (a rank killed alone leaves the others waiting and rank 0's temporary file behind). Every rank then
    stops at the next :meth:`ffdcli.parallel.comm.MPIComm.agree` (the comm's ``signals``) with
    :class:`Terminated`: one message, exit 128 + signum, as a serial run. During a write the signal raises at once
    (:func:`ffdcli.io.atomic.signals_raise` replaces the recorder), so the temporary files go.
    ``active`` False (a serial run) or outside the main thread: nothing is installed; default: whether
    an MPI launcher started this process with more than one rank (:data:`SIZE_VARIABLES`). Nested (the
    entry point's, then the command line's), the inner one shares the outer one's record."""

    def __init__(self, active: bool | None = None):
        if active is None:
            active = any(os.environ.get(v, "").strip().isdigit() and int(os.environ[v]) > 1 for v in SIZE_VARIABLES)
        self.active = active and threading.current_thread() is threading.main_thread()
        self._signum: int | None = None
        self._outer: SignalRecorder | None = None
        self._old: dict = {}

    @property
    def signum(self) -> int | None:
        """The first signal recorded (None: none)."""
        return self._outer.signum if self._outer is not None else self._signum

    #: :func:`ffdcli.io.atomic.signals_raise` replaces this handler during a write.
    ffd_replaceable = True

    def __call__(self, signum, frame) -> None:
        """The signal handler: record the first signal."""
        if self._signum is None:
            self._signum = signum

    def __enter__(self) -> SignalRecorder:
        current = signal.getsignal(WATCHED_SIGNALS[0]) if WATCHED_SIGNALS else None
        if isinstance(current, SignalRecorder):
            self._outer = current
            return self
        if self.active:
            for s in WATCHED_SIGNALS:
                with contextlib.suppress(ValueError, OSError):
                    self._old[s] = signal.signal(s, self)
        return self

    def ignore_from_now_on(self) -> None:
        """The process is ending (the run's status is settled): the watched signals are ignored from
        here. CPython's finalization puts back the default handler of every signal that has a Python
        one, and ``MPI_Finalize`` runs after it: a SIGTERM that mpiexec forwards then killed a rank with
        no message (exit 15) after the run had finished. Active recorders only (under mpiexec)."""
        if self.active:
            for s in WATCHED_SIGNALS:
                with contextlib.suppress(ValueError, OSError):
                    signal.signal(s, signal.SIG_IGN)

    def __exit__(self, *exc) -> None:
        for s, h in self._old.items():
            with contextlib.suppress(ValueError, OSError):
                signal.signal(s, h)
        self._old.clear()
