"""SIGTERM sent to ffd's pid alone (a scheduler's) stops the solver processes ffd started, also those of
concurrent adjoints that threads wait on (they run in ffd's process group, but a signal to one pid
reaches that pid only)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time

import pytest

from ffdcli.errors import Terminated
from ffdcli.io.atomic import signals_raise
from ffdcli.optimize.problem import OptimizationProblem
from ffdcli.optimize.solvers.base import RunningProcesses, run_logged, stop_processes

SLEEP = [sys.executable, "-c", "import time; time.sleep(60)"]
#: ignores SIGTERM, as SU2_CFD_AD was seen to for 8 s
STUBBORN = [sys.executable, "-c",
            "import signal, time; signal.signal(signal.SIGTERM, signal.SIG_IGN); print('ready', flush=True); "
            "time.sleep(60)"]


def _term_soon(delay: float = 1.0) -> threading.Timer:
    t = threading.Timer(delay, lambda: os.kill(os.getpid(), signal.SIGTERM))
    t.start()
    return t


class _Sleeper:
    """The part of a solver that :meth:`OptimizationProblem._solve_all` uses: ``running``."""

    def __init__(self):
        self.running = RunningProcesses()
        self.started: list[int] = []


def test_sigterm_stops_the_processes_of_concurrent_adjoints(tmp_path):
    solver = _Sleeper()
    problem = OptimizationProblem.__new__(OptimizationProblem)
    problem.solver, problem.concurrent = solver, 2

    def run(name):
        return run_logged(SLEEP, tmp_path, tmp_path / f"{name}.log", running=solver.running)

    t0 = time.monotonic()
    timer = _term_soon()
    with pytest.raises(Terminated), signals_raise():
        list(problem._solve_all(["DRAG", "LIFT"], run))
    timer.join()
    assert time.monotonic() - t0 < 20          # not the solvers' 60 s
    assert len(solver.running) == 0


def test_sigterm_in_the_main_thread_stops_its_process(tmp_path):
    running = RunningProcesses()
    t0 = time.monotonic()
    timer = _term_soon()
    with pytest.raises(Terminated), signals_raise():
        run_logged(SLEEP, tmp_path, tmp_path / "flow.log", running=running)
    timer.join()
    assert time.monotonic() - t0 < 20 and len(running) == 0


def test_a_process_that_ignores_sigterm_is_killed_after_the_grace():
    p = subprocess.Popen(STUBBORN, stdout=subprocess.PIPE, text=True)
    assert p.stdout.readline().strip() == "ready"
    t0 = time.monotonic()
    stop_processes([p], grace=0.5)
    assert p.returncode == -signal.SIGKILL and time.monotonic() - t0 < 10
