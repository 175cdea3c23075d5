"""The errors a user sees.

Library code raises :class:`InputError` (exit 2) for anything wrong with what the user gave us
(a file, a key, a value) and :class:`QualityError` (exit 3) when a deformed mesh fails the quality
check. Messages are one line, name the file (and the key path or line) and say what was expected.
Any other exception is a bug in ffd: the command line reports it in one line with exit 1.
"""

from __future__ import annotations

import contextlib
import contextvars
import os
import signal
import threading
from collections.abc import Iterable, Iterator
from pathlib import Path

#: Environment variables by which MPI launchers give the number of processes (MPICH/Intel hydra,
#: Open MPI, PMIx, Slurm's srun).
SIZE_VARIABLES = ("PMI_SIZE", "OMPI_COMM_WORLD_SIZE", "PMIX_SIZE", "SLURM_NTASKS")
#: Signals that end an MPI run together: mpiexec forwards them to every rank (and Ctrl-C at a terminal
#: reaches every rank of its process group). SIGINT is one of them: a KeyboardInterrupt raised at once on
#: one rank, while another waits in a collective, deadlocked ``mpiexec -n 2 ffd deform`` in 12 of 21 tries.
WATCHED_SIGNALS = tuple(getattr(signal, n) for n in ("SIGTERM", "SIGHUP", "SIGINT") if hasattr(signal, n))


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
    """For the whole run of ``ffd`` under ``mpiexec`` (from before MPI starts): SIGTERM, SIGHUP and
    SIGINT (Ctrl-C), which reach every rank, are recorded (:attr:`signum`) instead of killing the rank
    or raising at once (a rank killed alone, or one that leaves its collective for the error
    agreement while another waits in the collective, leaves the others waiting forever and rank 0's
    temporary file behind). Every rank then
    stops at the next :meth:`ffdcli.parallel.comm.MPIComm.agree` (the comm's ``signals``) with
    :class:`Terminated`: one message, exit 128 + signum (130 for Ctrl-C, "interrupted"), as a serial run.
    During a write the signal raises at once (:func:`ffdcli.io.atomic.signals_raise` replaces the
    recorder), so the temporary files go.
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


#: The outputs the running command has put in place (renamed into their final names), in order: what a
#: signal's message says when it comes after them. A context variable set by the command line for one
#: command (:func:`outputs_ledger`), never a list shared between commands; None outside a command.
COMMITTED: contextvars.ContextVar[list[str] | None] = contextvars.ContextVar("ffd_committed", default=None)


def note_committed(paths: Iterable[str | Path]) -> None:
    """Record outputs that are now complete under their final names (:class:`ffdcli.io.outputs.OutputPlan`
    calls it once its renames are done). Outside :func:`outputs_ledger`: nothing."""
    ledger = COMMITTED.get()
    if ledger is not None:
        ledger.extend(str(p) for p in paths)


def committed_outputs() -> list[str]:
    """The outputs this command has put in place so far (empty outside a command)."""
    return list(COMMITTED.get() or ())


@contextlib.contextmanager
def outputs_ledger() -> Iterator[list[str]]:
    """One command's record of its complete outputs (:data:`COMMITTED`); the handlers of SIGTERM and
    SIGHUP are put back as they were at the end (a write may leave them raising :class:`Terminated`:
    :func:`ffdcli.io.atomic.signals_raise`)."""
    token = COMMITTED.set([])
    old = {}
    if threading.current_thread() is threading.main_thread():
        for s in WATCHED_SIGNALS:
            with contextlib.suppress(ValueError, OSError):
                old[s] = signal.getsignal(s)
    try:
        yield COMMITTED.get()
    finally:
        COMMITTED.reset(token)
        for s, h in old.items():
            with contextlib.suppress(ValueError, OSError, TypeError):
                signal.signal(s, h)


def interrupt_message(exc: BaseException) -> str:
    """The one line of a run stopped by Ctrl-C (KeyboardInterrupt) or :class:`Terminated`, true about the
    files: "nothing was written", or, when the signal came after the outputs were put in place, which
    outputs are complete."""
    ctrl_c = isinstance(exc, KeyboardInterrupt) or getattr(exc, "signum", None) == signal.SIGINT
    what = "interrupted" if ctrl_c else str(exc)
    done = committed_outputs()
    if not done:
        return f"{what}; nothing was written"
    names = ", ".join(done[:6]) + (f" and {len(done) - 6} more" if len(done) > 6 else "")
    return f"{what} after the outputs were written: {names} {'is' if len(done) == 1 else 'are'} complete"
