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
"""

from __future__ import annotations

import os
import shutil
import subprocess
import time
from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np


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


def run_logged(command: list[str], folder: Path, log: Path, *, env: dict | None = None) -> tuple[int, float]:
    """Run ``command`` in ``folder`` with stdout and stderr into ``log``; returns (exit status, seconds).

    A missing program is a :class:`SolverFailure` naming it (the checks before the run should have
    caught it). Ctrl-C and SIGTERM reach the child (same process group) and then this process."""
    t0 = time.perf_counter()
    try:
        with open(log, "wb") as out:
            proc = subprocess.run(command, cwd=folder, stdout=out, stderr=subprocess.STDOUT,
                                  env={**os.environ, **(env or {})}, check=False)
    except FileNotFoundError as e:
        raise SolverFailure(f"cannot start {command[0]}: {e.strerror}", log) from None
    return proc.returncode, time.perf_counter() - t0


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
