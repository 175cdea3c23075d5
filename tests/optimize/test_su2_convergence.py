"""Issue 43, items 3 and 10: an SU2 run converged when the final row of its history meets the config's
criteria (CONV_FIELD, CONV_RESIDUAL_MINVAL, CONV_CAUCHY_EPS), never because its log says so (SU2 8.1
stopped by SIGTERM prints "All convergence criteria satisfied." and exits 0); a run that failed says
SU2's own message (the lines above "------ Error Exit ------") or the signal that killed it."""

from __future__ import annotations

import math
import shutil
import signal
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import SU2_MISSING, su2_folder

from ffdcli.errors import InputError
from ffdcli.optimize.solvers.base import SolverFailure
from ffdcli.optimize.solvers.su2 import SU2, read_config, with_keys
from ffdcli.optimize.solvers.su2_convergence import cauchy_value, exit_reason, su2_error

ROOT = Path(__file__).resolve().parents[2]
LIAR = ("All convergence criteria satisfied.\n\n"
        "------------------------- Exit Success (SU2_CFD) ------------------------\n")


def _solver(tmp_path: Path, lines: list[str]) -> SU2:
    s = SU2(tmp_path / "flow.cfg")
    s.lines = lines
    return s


def _history(rng, n: int, finals: dict[str, float]) -> dict[str, list[float]]:
    """A history of ``n`` rows whose columns end at ``finals`` (a residual falling, a coefficient settling)."""
    out = {"Inner_Iter": [float(i) for i in range(n)]}
    for col, final in finals.items():
        out[col] = list(np.linspace(final + rng.uniform(1, 4), final, n))
    return out


@pytest.mark.parametrize("seed", range(40))
def test_convergence_is_read_from_the_history_never_from_the_message(tmp_path, seed):
    """Generated configs (residual fields, their kinds and targets, SU2's default field and target) and
    histories ending above or below the target: the verdict is the history's, whatever the log says."""
    rng = np.random.default_rng(seed)
    fields = {"RMS_DENSITY": "rms[Rho]", "RMS_ENERGY": "rms[RhoE]", "RMS_MOMENTUM-X": "rms[RhoU]",
              "MAX_DENSITY": "max[Rho]", "RMS_NU_TILDE": "rms[nu]"}
    chosen = list(rng.choice(list(fields), size=rng.integers(0, 3), replace=False))
    minval = None if rng.random() < 0.25 else float(rng.integers(-14, -5))
    target = -8.0 if minval is None else minval
    n = int(rng.integers(20, 600))
    finals = {}
    for col in ["rms[Rho]", *[fields[f] for f in chosen]]:
        finals[col] = target + float(rng.choice([-0.7, -0.01, 0.0, 0.02, 1.5, 4.0]))
    lines = ["SOLVER= EULER", f"ITER= {n}"]
    lines += [] if minval is None else [f"CONV_RESIDUAL_MINVAL= {minval:g}"]
    lines += [f"CONV_FIELD= ({', '.join(chosen)})"] if chosen else []
    watched = [fields[f] for f in chosen] or ["rms[Rho]"]
    converged = all(finals[c] <= target for c in watched)
    log = tmp_path / "flow.log"
    log.write_text(LIAR)
    solver = _solver(tmp_path, lines)
    hist = _history(rng, n, finals)
    if converged:
        solver._converged(log, hist, "flow")
    else:
        with pytest.raises(SolverFailure) as e:
            solver._converged(log, hist, "flow")
        missed = next(c for c in watched if finals[c] > target)
        assert f"{missed} reached" in e.value.reason and f"CONV_RESIDUAL_MINVAL {target:g}" in e.value.reason
    # the same run stopped early by a signal (fewer rows than ITER) is never converged by its message
    short = {k: v[: n // 3] for k, v in hist.items()}
    early = {c: short[c][-1] for c in watched}
    if not all(v <= target for v in early.values()):
        lines_iter = [*lines[:1], f"ITER= {n}", *lines[2:]]
        with pytest.raises(SolverFailure) as e:
            _solver(tmp_path, lines_iter)._converged(log, short, "flow")
        assert "interrupted" in e.value.reason and f"of its ITER {n} iterations" in e.value.reason


@pytest.mark.parametrize("seed", range(12))
def test_a_cauchy_criterion_is_judged_as_su2_does(tmp_path, seed):
    """CONV_FIELD= DRAG (and LIFT): the Cauchy[CD] column against CONV_CAUCHY_EPS; without that column the
    same average from the coefficient's own column; the adjoint ignores coefficients (its residual)."""
    rng = np.random.default_rng(100 + seed)
    eps = float(10.0 ** rng.integers(-8, -3))
    elems = int(rng.integers(5, 60))
    n = elems + int(rng.integers(20, 200))
    cd = 0.02 + 1e-2 * np.exp(-np.arange(n) * rng.uniform(0.01, 0.2))
    lines = ["SOLVER= EULER", "CONV_FIELD= DRAG", f"CONV_CAUCHY_EPS= {eps:g}", f"CONV_CAUCHY_ELEMS= {elems}",
             "CONV_RESIDUAL_MINVAL= -8", f"ITER= {n}"]
    steps = np.abs(np.diff(cd)) / np.maximum(np.abs(cd[1:]), 0.1)
    expect = float(steps[-elems:].mean())
    assert math.isclose(cauchy_value(list(cd), elems), expect, rel_tol=1e-12)
    hist = {"Inner_Iter": list(map(float, range(n))), "rms[Rho]": [-9.0] * n, "CD": list(cd)}
    log = tmp_path / "flow.log"
    log.write_text(LIAR)
    solver = _solver(tmp_path, lines)
    for h in (hist, {**hist, "Cauchy[CD]": [1.0] * (n - 1) + [expect]}):
        if expect < eps:
            solver._converged(log, h, "flow")
        else:
            with pytest.raises(SolverFailure, match=r"Cauchy\[CD\] reached"):
                solver._converged(log, h, "flow")
    adj = {"Inner_Iter": [0.0, float(n - 1)], "rms[A_Rho]": [-3.0, -8.5]}
    solver._converged(log, adj, "adjoint of DRAG")            # the adjoint's residual, not Cauchy[CD]
    with pytest.raises(SolverFailure, match=r"rms\[A_Rho\] reached -7\.5"):
        solver._converged(log, {**adj, "rms[A_Rho]": [-3.0, -7.5]}, "adjoint of DRAG")
    assert "CAUCHY" in solver._history_output()              # the column SU2 writes when asked


@pytest.mark.parametrize("field", ["RMS_DENSITYX", "DRAGG", "RMS_", "TOTAL_LIFT", "(RMS_DENSITY, CL)"])
def test_a_field_ffd_cannot_judge_is_refused_before_any_work(tmp_path, field):
    """SU2 ignores a CONV_FIELD it does not know and runs every ITER iteration; ffd cannot judge it."""
    cfg = tmp_path / "flow.cfg"
    cfg.write_text(f"SOLVER= EULER\nCONV_RESIDUAL_MINVAL= -8\nCONV_FIELD= {field}\n")
    with pytest.raises(InputError) as e:
        SU2(cfg).check()
    assert "CONV_FIELD" in str(e.value) and str(cfg) in str(e.value)


@pytest.mark.parametrize("key, value", [("CONV_RESIDUAL_MINVAL", "low"), ("CONV_CAUCHY_EPS", "nan"),
                                        ("CONV_CAUCHY_ELEMS", "x")])
def test_a_criterion_that_is_not_a_number_is_refused(tmp_path, key, value):
    cfg = tmp_path / "flow.cfg"
    cfg.write_text(f"SOLVER= EULER\nCONV_FIELD= DRAG\nCONV_RESIDUAL_MINVAL= -8\n{key}= {value}\n")
    with pytest.raises(InputError, match=key):
        SU2(cfg).check()


# ----------------------------------------------------------------------------------------------
# Item 10: the reason of a failed run is SU2's message, or the signal
# ----------------------------------------------------------------------------------------------

SU2_ERRORS = [
    ('static short unsigned int CConfig::GetnDim(const std::string&, short unsigned int)',
     ["The SU2 mesh file named nothere.su2 was not found."]),
    ('void CConfig::SetConfig_Parsing(std::istream&)', ["MACH_NUMBER: improper option value for type su2double", ""]),
    ('void CSolver::Read_SU2_Restart_Metadata', ["The restart file restart_flow.dat", "has 4 variables, expected 5."]),
]


@pytest.mark.parametrize("where, body", SU2_ERRORS)
def test_the_reason_is_su2s_message_above_error_exit(where, body):
    text = ("SU2 banner\nParsing config file for zone 0\n\n\n" f'Error in "{where}": \n' + "-" * 73 + "\n"
            + "\n".join(body) + "\n" + "-" * 30 + " Error Exit " + "-" * 31 + "\n\n\n")
    said = su2_error(text)
    assert said == " ".join(b for b in body if b)
    reason = exit_reason("SU2_CFD", 1, text)
    assert reason == f"SU2_CFD exited with status 1: {said}" and "Error Exit" not in reason


def _fake(tmp_path: Path, code: str) -> Path:
    prog = tmp_path / "fake_su2.py"
    prog.write_text("import os, signal, sys\nprint('SU2 banner', flush=True)\n" + code)
    return prog


@pytest.mark.parametrize("sig", [signal.SIGSEGV, signal.SIGABRT, signal.SIGBUS, signal.SIGKILL])
@pytest.mark.parametrize("through", ["direct", "shell"])
def test_a_solver_killed_by_a_signal_says_so(tmp_path, sig, through):
    """After a segfault the log ends with nothing useful: the reason names the signal, whether SU2 ran
    directly (a negative status) or behind a launcher or script that reports 128 + n."""
    prog = _fake(tmp_path, f"os.kill(os.getpid(), {int(sig)})\n")
    solver = _solver(tmp_path, ["SOLVER= EULER"])
    if through == "direct":
        solver.launch, solver.programs = (sys.executable,), {"SU2_CFD": prog}
    else:
        wrapper = tmp_path / "launch.sh"
        wrapper.write_text(f'#!/bin/sh\n"{sys.executable}" "$@"\nexit $?\n')
        wrapper.chmod(0o755)
        solver.launch, solver.programs = (str(wrapper),), {"SU2_CFD": prog}
    (tmp_path / "mesh.su2").write_text("")
    with pytest.raises(SolverFailure) as e:
        solver.flow(tmp_path, tmp_path / "mesh.su2")
    reason = e.value.reason
    assert sig.name in reason, reason
    assert ("killed by" if through == "direct" else f"status {128 + sig} (128 + {sig.name}") in reason


@pytest.mark.solver
@pytest.mark.skipif(su2_folder() is None, reason=SU2_MISSING)
@pytest.mark.parametrize("sig, after", [("TERM", 2.0), ("INT", 3.5), ("TERM", 5.0), ("HUP", 3.0)])
def test_a_real_su2_interrupted_is_a_failed_evaluation(tmp_path, sig, after):
    """SU2_CFD 8.1 on its NACA0012 Euler case (472 iterations to its -13) stopped by a signal at a chosen
    moment: it may print "All convergence criteria satisfied." and exit 0, the evaluation fails all the
    same, with what was reached and the target."""
    shutil.copyfile(ROOT / "samples" / "naca0012_inv.su2", tmp_path / "mesh.su2")
    solver = SU2(ROOT / "samples" / "naca0012_inv.cfg", search=(su2_folder(),),
                 launch=("nice", "-n", "10", "timeout", "--preserve-status", "-s", sig, str(after)))
    solver.check()
    with pytest.raises(SolverFailure) as e:
        solver.flow(tmp_path, tmp_path / "mesh.su2")
    reason = e.value.reason
    assert ("did not converge" in reason and "interrupted" in reason) or "SIG" in reason or "wrote no" in reason, reason


@pytest.mark.solver
@pytest.mark.skipif(su2_folder() is None, reason=SU2_MISSING)
@pytest.mark.parametrize("change, said", [
    ({"MACH_NUMBER": "abc"}, "MACH_NUMBER: improper option value"),
    ({"MARKER_EULER": "( wing )"}, "DV_MARKER contains marker names that do not exist"),
    ({"SOLVER": "EULERX"}, "SOLVER"),
])
def test_a_real_su2_error_is_reported_in_su2s_words(tmp_path, change, said):
    shutil.copyfile(ROOT / "samples" / "naca0012_inv.su2", tmp_path / "mesh.su2")
    cfg = tmp_path / "user.cfg"
    cfg.write_text(with_keys(read_config(ROOT / "samples" / "naca0012_inv.cfg"), change))
    solver = SU2(cfg, search=(su2_folder(),))
    solver.check()
    with pytest.raises(SolverFailure) as e:
        solver.flow(tmp_path, tmp_path / "mesh.su2")
    assert said in e.value.reason and "Error Exit" not in e.value.reason, e.value.reason
