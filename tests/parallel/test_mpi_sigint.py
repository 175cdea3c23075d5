"""Issue 43, item 6: Ctrl-C (SIGINT) on ``mpiexec -n 2 ffd deform`` deadlocked in 12 of 21 tries (one
rank spinning in a collective while the other had left for the error agreement) and otherwise ended
with 131 or 2. Every signal ends every rank: one line, 130 (143 for SIGTERM), nothing left behind, at
whatever moment it comes and however it is delivered (to mpiexec, or to the whole process group as a
terminal's Ctrl-C)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import pytest
from conftest import file_hash
from hostile import no_parts
from test_mpi import MPIEXEC, _env, _have_mpi4py
from test_signals import _ranks_handle_sigterm, mid_wing  # noqa: F401  (the fixture)

needs_mpi = pytest.mark.skipif(not (_have_mpi4py() and MPIEXEC),
                               reason="the [mpi] extra (mpi4py + mpich) is not installed: pip install -e '.[mpi]'")


def _own_group() -> None:
    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        signal.signal(sig, signal.SIG_DFL)
    os.setsid()                      # a process group of its own, as a terminal's foreground job


#: (signal, delivery, moment): seconds after both ranks handle signals, or "write" (a temporary file exists)
TRIES = [(signal.SIGINT, "group", 0.0), (signal.SIGINT, "mpiexec", 0.3), (signal.SIGINT, "group", 1.0),
         (signal.SIGINT, "mpiexec", 2.0), (signal.SIGINT, "group", "write"), (signal.SIGINT, "mpiexec", "write"),
         (signal.SIGINT, "group", 3.5), (signal.SIGINT, "group", "write"), (signal.SIGTERM, "group", 1.5),
         (signal.SIGTERM, "group", "write")]
#: SIGHUP is not tried: mpiexec (MPICH's hydra) dies of it at once, whatever its ranks do.


@pytest.mark.slow
@needs_mpi
@pytest.mark.parametrize("sig, delivery, moment", TRIES,
                         ids=[f"{s.name}-{d}-{m}" for s, d, m in TRIES])
def test_every_signal_ends_every_rank_with_one_line(mid_wing, sig, delivery, moment):  # noqa: F811
    out = mid_wing / "out_int.su2"
    for f in (out, mid_wing / "out_int_lattice.vtk"):
        f.unlink(missing_ok=True)
    p = subprocess.Popen([MPIEXEC, "-n", "2", sys.executable, "-m", "ffdcli", "deform", "mid.yaml", "-q",
                          "--force", "-o", out.name], cwd=mid_wing, env=_env(), stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True, preexec_fn=_own_group)
    while p.poll() is None and not _ranks_handle_sigterm(p.pid, 2):
        time.sleep(0.01)
    if moment == "write":
        deadline = time.monotonic() + 120
        while p.poll() is None and time.monotonic() < deadline and not list(mid_wing.glob(".out_int*part*")):
            time.sleep(0.002)
    else:
        time.sleep(moment)
    try:
        if delivery == "group":
            os.killpg(p.pid, sig)
        else:
            p.send_signal(sig)
    except ProcessLookupError:
        pass
    try:
        stdout, err = p.communicate(timeout=120)
    except subprocess.TimeoutExpired:
        os.killpg(p.pid, signal.SIGKILL)
        p.communicate()
        pytest.fail(f"deadlock: mpiexec -n 2 did not end within 120 s of {sig.name}")
    assert no_parts(mid_wing) == [], list(mid_wing.iterdir())
    if p.returncode == 0:                         # the run had ended before the signal: complete
        assert file_hash(out) == file_hash(mid_wing / "ref.su2")
        return
    assert p.returncode == 128 + sig, (p.returncode, err, stdout)
    assert err.count("ffd: error:") == 1 and "Traceback" not in err, err
    assert "BAD TERMINATION" not in stdout + err, (stdout, err)
    word = "interrupted" if sig == signal.SIGINT else f"terminated by {sig.name}"
    assert word in err, err
    if out.exists():                              # the signal came as the outputs were renamed: complete
        assert file_hash(out) == file_hash(mid_wing / "ref.su2") and "are complete" in err, err
    else:
        assert "nothing was written" in err, err
