"""The solver interface of ``ffd optimize``: what ffd needs from a flow solver, so that another solver
(OpenFOAM, ADflow) is one more module beside :mod:`ffdcli.optimize.solvers.su2`.

An evaluation of a design is a folder that holds the deformed mesh. The driver calls, in order:

1. :meth:`Solver.check` once before any work: the programs and the configuration exist (else
   :class:`~ffdcli.errors.InputError`, exit 2);
2. :meth:`Solver.flow` (folder, mesh) -> :class:`FlowResult`: the functions' values;
3. :meth:`Solver.adjoint` (folder, mesh, function) -> :class:`Sensitivity` for each function whose
   gradient is needed: dJ/dX at mesh nodes (every node for a discrete adjoint, the wall nodes for a
   surface one), which ffd chains through its own exact derivatives.

A run that fails (non-zero exit, NaN, residual not converged) raises :class:`SolverFailure` with the
reason and the path of its log; the driver records it and steps back.

A solver kind declares itself as every extension kind does (:mod:`ffdcli.registry`): ``kind`` (the
name ``optimize.solver`` gives), ``schema()`` (``{"description": ..., "properties": {its own keys of
optimize:}}``: SU2's ``adjoint`` and ``adjoint_residual`` are SU2's), ``from_spec(spec, ctx)`` (its own
keys as written, parsed by the solver; ``ctx`` a :class:`SolverContext`), and one line
``SOLVERS.register(Kind)`` at the end of its module. The design file's ``optimize:`` schema is the
driver's keys and every solver's own keys (:func:`ffdcli.design.schema.optimize_schema`).
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import threading
import time
from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ffdcli.registry import Registry

#: The flow solvers ``optimize.solver`` names, each registered by its own module.
SOLVERS = Registry("solver")


@dataclass(frozen=True)
class SolverContext:
    """What every solver kind's ``from_spec`` is handed besides its own keys: ``config`` the solver's
    configuration (``optimize.config``, resolved), ``launch`` a prefix of its commands (``optimize.launch``,
    split like a shell line), ``search`` more folders to look for its programs in."""

    config: Path
    launch: tuple[str, ...] = ()
    search: tuple[Path, ...] = ()


class SolverFailure(Exception):
    """A solver run that produced no usable result: ``reason`` in words, ``log`` its log file."""

    def __init__(self, reason: str, log: Path | str | None = None):
        self.reason = reason
        self.log = None if log is None else Path(log)
        super().__init__(reason + (f" (log: {log})" if log else ""))


@dataclass(frozen=True)
class FlowResult:
    """The functions of one flow solution, ``{name: value}`` (the optimisation's names: DRAG, LIFT)."""

    functions: dict[str, float]
    seconds: float
    log: Path | None = None


@dataclass(frozen=True)
class Sensitivity:
    """dJ/dX of one function at mesh nodes: ``ids`` (K,) 0-based node ids, ``values`` (K, 3).

    ``approximate``: the solver's gradient is known to be approximate (a continuous adjoint)."""

    ids: np.ndarray
    values: np.ndarray
    seconds: float
    log: Path | None = None
    approximate: bool = False

    def dense(self, n_points: int) -> np.ndarray:
        """(n_points, 3): zeros at the nodes the sensitivity does not cover."""
        out = np.zeros((n_points, 3))
        out[self.ids] = self.values
        return out


@dataclass(frozen=True)
class SolverInfo:
    """What a solver says about itself for the report: its name, version or programs, adjoint kind."""

    name: str
    adjoint: str
    programs: dict[str, str] = field(default_factory=dict)
    warnings: tuple[str, ...] = ()


class Solver(ABC):
    """A flow solver with an adjoint, as ``ffd optimize`` drives it (see the module docstring)."""

    #: The solver's adjoint kind for this run: ``discrete`` or ``continuous``.
    adjoint_kind: str = "discrete"

    @abstractmethod
    def check(self) -> SolverInfo:
        """Before any work: the programs, the configuration; InputError (exit 2) when one is missing."""

    @abstractmethod
    def flow(self, folder: Path, mesh: Path, start: Path | None = None) -> FlowResult:
        """Solve the flow on ``mesh`` inside ``folder`` (files and logs stay there); SolverFailure if it fails.

        ``start``: the folder of an earlier evaluation of the same mesh (a nearby design) whose solution
        the solver may start from (a warm start), or None."""

    @abstractmethod
    def adjoint(self, folder: Path, mesh: Path, function: str, start: Path | None = None) -> Sensitivity:
        """After :meth:`flow` in the same folder: dJ/dX of ``function``; SolverFailure if it fails.
        ``start``: an earlier evaluation's folder that has this function's adjoint (a warm start), or None."""

    def state(self) -> str:
        """The solver's inputs as text (its configuration): part of the key of a cached evaluation."""
        return ""

    def legacy_states(self) -> tuple[str, ...]:
        """Earlier versions' forms of :meth:`state` for the same inputs: a resumed run still reuses the
        evaluations they keyed (the runs in a folder outlive a version). None by default."""
        return ()

    def has_flow(self, folder: Path) -> bool:
        """Whether ``folder`` still holds what :meth:`adjoint` reads of its flow (a solution file): an
        evaluation resumed from its ``result.json`` alone (its files cleaned away, or the run's record
        restored on another machine) has its functions but not always its solution. True by default."""
        return True

    def outputs(self) -> tuple[str, ...] | None:
        """The names of the functions this solver reports (its table of outputs), which
        ``optimize.objective`` and ``optimize.functions`` are checked against when the design file is
        loaded, before any work; None: the solver does not say (no check)."""
        return None

    @property
    def running(self) -> RunningProcesses:
        """This solver's processes running now (:func:`run_logged`'s ``running``): what Ctrl-C or SIGTERM
        stops. Made on first use; the problem asks for it in the main thread before starting threads."""
        if "_running" not in self.__dict__:
            self._running = RunningProcesses()
        return self._running


#: Seconds a solver process gets to end on SIGTERM before it is killed (SU2_CFD_AD was measured
#: ignoring SIGTERM for 8 s).
STOP_GRACE = 3.0


class RunningProcesses:
    """The solver processes started and not yet finished (the threads of concurrent adjoints each
    start one): :meth:`stop` ends them all, from the main thread, when Ctrl-C or SIGTERM stops the
    run. A signal sent to ffd's pid alone (a scheduler's) reaches none of them, and a thread waiting
    on its process cannot be interrupted, so without this the run would wait for every solver."""

    def __init__(self):
        self._procs: set[subprocess.Popen] = set()
        self._lock = threading.Lock()

    def add(self, proc: subprocess.Popen) -> None:
        with self._lock:
            self._procs.add(proc)

    def discard(self, proc: subprocess.Popen) -> None:
        with self._lock:
            self._procs.discard(proc)

    def __len__(self) -> int:
        with self._lock:
            return len(self._procs)

    def stop(self, grace: float = STOP_GRACE) -> None:
        """SIGTERM to every running process's group, SIGKILL to those still running ``grace`` seconds later."""
        with self._lock:
            procs = list(self._procs)
        stop_processes(procs, grace)


def stop_processes(procs: list[subprocess.Popen], grace: float = STOP_GRACE) -> None:
    """SIGTERM to the process group of each of ``procs`` (:func:`run_logged` starts each in its own),
    then SIGKILL to the groups with a process still running after ``grace`` s: a solver started through a
    wrapper script (``launch:``, a site's ``SU2_CFD`` script) is stopped with its children, not only the
    process ffd started."""
    for p in procs:
        _signal_group(p, signal.SIGTERM)
    end = time.monotonic() + grace
    for p in procs:
        try:
            p.wait(timeout=max(0.0, end - time.monotonic()))
        except subprocess.TimeoutExpired:
            pass
    while time.monotonic() < end and any(_group_alive(p) for p in procs):
        time.sleep(0.05)                   # the children of a wrapper that has ended already
    for p in procs:
        if _group_alive(p):
            _signal_group(p, signal.SIGKILL)
        p.wait()


def _signal_group(proc: subprocess.Popen, signum: int) -> None:
    """``signum`` to the process group that ``proc`` leads (its own session), else to ``proc`` alone."""
    try:
        if getattr(proc, "ffd_group", False):
            os.killpg(proc.pid, signum)
        elif proc.poll() is None:
            proc.send_signal(signum)
    except (ProcessLookupError, PermissionError):
        pass


def _group_alive(proc: subprocess.Popen) -> bool:
    """Whether a process of ``proc``'s own group still runs (``proc`` itself reaped or not)."""
    if not getattr(proc, "ffd_group", False):
        return proc.poll() is None
    try:
        os.killpg(proc.pid, 0)
    except (ProcessLookupError, PermissionError):
        return False
    return True


def run_logged(command: list[str], folder: Path, log: Path, *, env: dict | None = None,
               running: RunningProcesses | None = None) -> tuple[int, float]:
    """Run ``command`` in ``folder`` with stdout and stderr into ``log``; returns (exit status, seconds).

    A missing program is a :class:`SolverFailure` naming it (the checks before the run should have
    caught it). The process runs in its own session and process group, so that everything it starts
    (a wrapper script's solver, ``mpirun``'s ranks) is stopped with it: Ctrl-C or SIGTERM raised in this
    thread while it waits stops the group (SIGTERM, then SIGKILL after :data:`STOP_GRACE` s) before the
    exception goes on; ``running`` holds it while
    it runs, so that the main thread can stop it when this is another thread
    (:meth:`RunningProcesses.stop`)."""
    t0 = time.perf_counter()
    try:
        with open(log, "wb") as out:
            proc = subprocess.Popen(command, cwd=folder, stdout=out, stderr=subprocess.STDOUT,
                                    env={**os.environ, **(env or {})}, start_new_session=True)
    except FileNotFoundError as e:
        raise SolverFailure(f"cannot start {command[0]}: {e.strerror}", log) from None
    except PermissionError as e:
        raise SolverFailure(f"cannot start {command[0]}: {e.strerror} (is it executable?)", log) from None
    proc.ffd_group = True             # its own session and process group: stopped as a group
    if running is not None:
        running.add(proc)
    try:
        rc = proc.wait()
    except BaseException:
        stop_processes([proc])
        raise
    finally:
        if running is not None:
            running.discard(proc)
    return rc, time.perf_counter() - t0


def missing_program(name: str, env_var: str | None = None, extra: tuple[Path, ...] = ()) -> str:
    """Why :func:`find_program` found no ``name``, in words: a file of that name that cannot be run (not
    executable, a folder) where it looked, else "not found"."""
    folders = [Path(os.environ[env_var])] if env_var and os.environ.get(env_var) else []
    folders += [Path(p) for p in os.environ.get("PATH", "").split(os.pathsep) if p] + list(extra)
    for f in folders:
        p = f / name
        if p.is_dir():
            return f"{p} is a folder, not the program"
        if p.exists() and not os.access(p, os.X_OK):
            return f"{p} is there but not executable (chmod +x {p})"
    return "not found"


def find_program(name: str, env_var: str | None = None, extra: tuple[Path, ...] = ()) -> Path | None:
    """``name`` in ``$<env_var>`` (a folder), then on PATH, then in ``extra`` folders; None if nowhere."""
    folders = []
    if env_var and os.environ.get(env_var):
        folders.append(Path(os.environ[env_var]))
    for f in folders:
        if (f / name).is_file() and os.access(f / name, os.X_OK):
            return f / name
    found = shutil.which(name)
    if found:
        return Path(found)
    for f in extra:
        if (f / name).is_file() and os.access(f / name, os.X_OK):
            return f / name
    return None
