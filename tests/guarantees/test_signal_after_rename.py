"""Issue 43, item 5: the exit status and the message tell the truth about the files when a signal comes
as the outputs are put in place, or just after. Found: a Ctrl-C or SIGTERM just after the renames said
"interrupted; nothing was written" (130/143) while the new outputs were complete and the old ones gone;
a little later the process died by the signal with no message."""

from __future__ import annotations

import os
import signal
import types

import pytest
from conftest import file_hash
from hostile import ffd_inproc
from wingcase import write_design, write_volume_wing

import ffdcli.cli.console as console_module
import ffdcli.io.outputs as outputs_module

pytestmark = pytest.mark.usefixtures("default_sigint")   # Ctrl-C as in a terminal, also in an xdist worker

SIGNALS = [signal.SIGINT, signal.SIGTERM, signal.SIGHUP]
#: when the signal comes: inside a writer (before any rename), at the first rename, at the last one,
#: after the write returned (as the summary is printed)
MOMENTS = ["writing", "first_rename", "last_rename", "summary"]


@pytest.fixture(scope="module")
def case(tmp_path_factory):
    d = tmp_path_factory.mktemp("late_signal")
    mesh = write_volume_wing(d)
    write_design(d, mesh, [{"twist": {"tip": 3}}], volume={"method": "none"})
    proc = ffd_inproc("deform", "design.yaml", "-q", "--force", cwd=d)
    assert proc.returncode == 0, proc.stderr
    ref = {p: file_hash(d / p) for p in ("out_design.su2", "out_design_lattice.vtk")}
    return d, ref


def _arm(monkeypatch, moment: str, sig: int) -> None:
    """Send ``sig`` to this process at ``moment`` of the next run."""
    fire = lambda: os.kill(os.getpid(), sig)  # noqa: E731
    if moment == "writing":
        real = outputs_module.make_temp
        calls = []

        def make_temp(path):
            calls.append(path)
            if len(calls) == 2:               # the second output's temporary file: the first is written
                fire()
            return real(path)
        monkeypatch.setattr(outputs_module, "make_temp", make_temp)
    elif moment in ("first_rename", "last_rename"):
        calls = []

        def replace(src, dst):
            calls.append(dst)
            if (moment == "first_rename" and len(calls) == 1) or (moment == "last_rename" and len(calls) == 2):
                fire()
            os.replace(src, dst)
        monkeypatch.setattr(outputs_module, "os", types.SimpleNamespace(**{**vars(os), "replace": replace}))
    else:
        real = console_module._print

        def _print(text):
            fire()
            real(text)
        monkeypatch.setattr(console_module, "_print", _print)


@pytest.mark.parametrize("moment", MOMENTS)
@pytest.mark.parametrize("sig", SIGNALS, ids=[s.name for s in SIGNALS])
def test_the_message_and_status_tell_the_truth_about_the_files(case, monkeypatch, moment, sig):
    folder, ref = case
    for name in ref:
        (folder / name).unlink(missing_ok=True)
    old = {s: signal.getsignal(s) for s in SIGNALS}
    _arm(monkeypatch, moment, sig)
    args = ["deform", "design.yaml", "--force"] + ([] if moment == "summary" else ["-q"])
    proc = ffd_inproc(*args, cwd=folder)
    assert {s: signal.getsignal(s) for s in SIGNALS} == old       # the handlers as they were
    assert proc.returncode == 128 + sig, (moment, proc.returncode, proc.stderr)
    errors = [ln for ln in proc.stderr.splitlines() if ln.startswith("ffd: error:")]
    assert len(errors) == 1 and "Traceback" not in proc.stderr, proc.stderr
    written = [n for n in ref if (folder / n).exists()]
    assert not list(folder.glob(".*part*"))
    if moment == "writing":
        assert written == [] and errors[0].endswith("nothing was written"), errors
    else:
        assert written == list(ref), (moment, written)              # complete, every one
        assert all(file_hash(folder / n) == ref[n] for n in ref)
        assert "nothing was written" not in errors[0] and "after the outputs were written" in errors[0], errors
        assert all(n in errors[0] for n in ref) and errors[0].endswith("are complete"), errors
