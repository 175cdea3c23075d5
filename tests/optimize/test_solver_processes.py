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
from pathlib import Path

import pytest

from ffdcli.errors import Terminated
from ffdcli.io.atomic import signals_raise
from ffdcli.optimize.problem import OptimizationProblem
from ffdcli.optimize.solvers.base import RunningProcesses, run_logged, stop_processes

pytestmark = pytest.mark.usefixtures("default_sigint")   # Ctrl-C as in a terminal, also in an xdist worker

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


# ----------------------------------------------------------------------------------------------
# Issue 43, item 7: a solver started through a wrapper is stopped with its whole process group
# ----------------------------------------------------------------------------------------------

def _child(pidfile: Path, ignore_term: bool = False) -> str:
    """Python code of the real solver behind a wrapper: writes its pid, then sleeps a minute."""
    ignore = "signal.signal(signal.SIGTERM, signal.SIG_IGN); " if ignore_term else ""
    return (f"import os, signal, time; {ignore}open({str(pidfile)!r}, 'w').write(str(os.getpid())); "
            "time.sleep(60)")


def _wrappers(tmp_path: Path, pidfile: Path) -> dict[str, list[str]]:
    """Ways a site starts its solver: a shell script that waits for it (``solver; status=$?``), one
    that puts it in the background and waits, a Python launcher, a two-level wrapper, and a solver that
    ignores SIGTERM behind a script (SIGKILL after the grace)."""
    py = sys.executable
    out = {}
    for name, body in {
        "sh_wait": f'"{py}" -c "{_child(pidfile)}"\nstatus=$?\nexit $status\n',
        "sh_background": f'"{py}" -c "{_child(pidfile)}" &\nwait\n',
        "sh_stubborn": f'"{py}" -c "{_child(pidfile, True)}"\nexit $?\n',
    }.items():
        script = tmp_path / f"{name}.sh"
        script.write_text("#!/bin/sh\n" + body)
        script.chmod(0o755)
        out[name] = [str(script)]
    launcher = tmp_path / "launcher.py"
    launcher.write_text("import subprocess, sys\n"
                        f"sys.exit(subprocess.call([sys.executable, '-c', {_child(pidfile)!r}]))\n")
    out["python"] = [py, str(launcher)]
    outer = tmp_path / "outer.sh"
    outer.write_text(f'#!/bin/sh\n"{tmp_path / "sh_wait.sh"}"\nexit $?\n')
    outer.chmod(0o755)
    out["two_levels"] = [str(outer)]
    return out


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    stat = Path(f"/proc/{pid}/stat")
    return not (stat.is_file() and stat.read_text().rsplit(")", 1)[1].split()[0] == "Z")


@pytest.mark.parametrize("wrapper", ["sh_wait", "sh_background", "sh_stubborn", "python", "two_levels"])
@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT, signal.SIGHUP])
def test_a_signal_stops_the_solver_behind_a_wrapper(tmp_path, wrapper, sig):
    """Found: ffd stopped the process it started, the wrapper, and the solver behind it kept running.
    Each solver runs in its own process group, and the group is stopped."""
    pidfile = tmp_path / "solver.pid"
    command = _wrappers(tmp_path, pidfile)[wrapper]
    running = RunningProcesses()
    holder = {}

    def fire():
        while not pidfile.is_file() or not pidfile.read_text():
            time.sleep(0.02)
        holder["pid"] = int(pidfile.read_text())
        os.kill(os.getpid(), sig)

    timer = threading.Thread(target=fire, daemon=True)
    timer.start()
    expected = KeyboardInterrupt if sig == signal.SIGINT else Terminated
    t0 = time.monotonic()
    with pytest.raises(expected), signals_raise():
        run_logged(command, tmp_path, tmp_path / "flow.log", running=running)
    timer.join(timeout=30)
    assert time.monotonic() - t0 < 30
    deadline = time.monotonic() + 10
    while _alive(holder["pid"]) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not _alive(holder["pid"]), f"the solver behind {wrapper} still runs after {sig.name}"
    assert len(running) == 0


def test_concurrent_adjoints_behind_wrappers_are_stopped_by_groups(tmp_path):
    solver = _Sleeper()
    problem = OptimizationProblem.__new__(OptimizationProblem)
    problem.solver, problem.concurrent = solver, 2
    pids = {n: tmp_path / f"{n}.pid" for n in ("DRAG", "LIFT")}
    for n, f in pids.items():
        (tmp_path / n).mkdir()
        script = tmp_path / n / "su2.sh"
        script.write_text(f'#!/bin/sh\n"{sys.executable}" -c "{_child(f)}"\nexit $?\n')
        script.chmod(0o755)

    def run(name):
        return run_logged([str(tmp_path / name / "su2.sh")], tmp_path, tmp_path / f"{name}.log", running=solver.running)

    def fire():
        while not all(f.is_file() and f.read_text() for f in pids.values()):
            time.sleep(0.02)
        os.kill(os.getpid(), signal.SIGTERM)

    threading.Thread(target=fire, daemon=True).start()
    with pytest.raises(Terminated), signals_raise():
        list(problem._solve_all(["DRAG", "LIFT"], run))
    deadline = time.monotonic() + 10
    solver_pids = [int(f.read_text()) for f in pids.values()]
    while any(_alive(p) for p in solver_pids) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not any(_alive(p) for p in solver_pids)
