"""A REAL two-iteration ``ffd optimize`` loop with SU2 on SU2's NACA0012 case (samples/naca0012_inv.su2,
Euler, M 0.8, alpha 1.25 deg), discrete adjoint, loosely converged (residual 1e-8) so that it takes
about a minute on a quiet machine. Skipped, with the reason, when SU2 is absent: SU2 is found through
SU2_RUN, PATH or ../shared/su2/bin beside the repository."""

from __future__ import annotations

import csv
import os
import shutil
from pathlib import Path

import pytest
import yaml

from ffdcli.optimize.solvers.base import find_program
from ffdcli.optimize.solvers.su2 import adjoint_convergence, config_value, read_config, with_keys
from ffdcli.optimize.workflow import run_optimize

ROOT = Path(__file__).resolve().parents[2]
SHARED_SU2 = ROOT.parent / "shared" / "su2" / "bin"
SEARCH = (SHARED_SU2,)


def su2_missing() -> str | None:
    for name in ("SU2_CFD", "SU2_CFD_AD"):
        if find_program(name, "SU2_RUN", SEARCH) is None:
            return f"{name} not found (SU2_RUN, PATH, {SHARED_SU2})"
    return None


@pytest.mark.solver
@pytest.mark.skipif(su2_missing() is not None, reason=str(su2_missing()))
def test_two_iterations_with_su2(tmp_path):
    shutil.copyfile(ROOT / "samples" / "naca0012_inv.su2", tmp_path / "naca0012_inv.su2")
    lines = read_config(ROOT / "samples" / "naca0012_inv.cfg")
    (tmp_path / "flow.cfg").write_text(with_keys(lines, {"CONV_RESIDUAL_MINVAL": "-8"}))
    design = yaml.safe_load((ROOT / "configs" / "naca0012_optimize.yaml").read_text())
    design.update(mesh="naca0012_inv.su2", output={"mesh": "out/best.su2"})
    design["optimize"].update(config="flow.cfg", folder="opt", iterations=2,
                              functions=[{"name": "LIFT", "lower": 0.328486}])
    path = tmp_path / "design.yaml"
    path.write_text(yaml.safe_dump(design, sort_keys=False))
    out = run_optimize(path, search=SEARCH)
    assert out["adjoint"] == "discrete"
    assert out["status"] in ("iterations", "converged"), out["message"]
    assert out["iterations"] >= 1
    assert out["objective"]["best"] < out["objective"]["initial"]
    assert out["adjoint_solves"] >= 2 * 2                      # DRAG and LIFT, at two designs at least
    with open(tmp_path / "opt" / "history.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == out["evaluations"] and not any(r["failed"] for r in rows)
    first = tmp_path / "opt" / rows[0]["folder"]
    cfg = read_config(first / "flow.cfg")
    assert config_value(cfg, "MESH_FILENAME") == "mesh.su2"
    assert config_value(cfg, "MACH_NUMBER") == "0.8"              # the user's physics untouched
    assert (first / "restart_adj_cd.csv").is_file() and (first / "restart_adj_cl.csv").is_file()
    assert (tmp_path / "opt" / "best.yaml").is_file() and (tmp_path / "opt" / "best.su2").is_file()


def test_su2_state_leaves_comments_out_and_keeps_the_old_form_as_legacy(tmp_path):
    """Two configurations that differ in comments and blank lines only are the same inputs; a setting
    changed is not; the legacy state is the old text with every line (so old runs are still found)."""
    from ffdcli.optimize.solvers.su2 import SU2, settings_lines
    base = ["% Euler on the NACA 0012", "SOLVER= EULER", "", "MACH_NUMBER= 0.85 % transonic", "CFL_NUMBER= 10"]
    commented = ["% a new comment", "SOLVER= EULER   ", "% another", "MACH_NUMBER= 0.85", "", "CFL_NUMBER= 10 % kept"]
    changed = ["SOLVER= EULER", "MACH_NUMBER= 0.86", "CFL_NUMBER= 10"]
    assert settings_lines(base) == ["SOLVER= EULER", "MACH_NUMBER= 0.85", "CFL_NUMBER= 10"]

    def solver(lines, name):
        (tmp_path / name).write_text("\n".join(lines) + "\n")
        s = SU2(tmp_path / name)
        s.lines = read_config(tmp_path / name)
        return s

    a, b, c = solver(base, "a.cfg"), solver(commented, "b.cfg"), solver(changed, "c.cfg")
    assert a.state() == b.state() != c.state()
    assert a.legacy_states() != b.legacy_states()                # the old form counted comments
    assert a.legacy_states()[0].splitlines()[:len(base)] == base  # ... every line as written


def test_with_keys_changes_only_the_named_keys():
    lines = ["% comment", "SOLVER= EULER", "MESH_FILENAME= a.su2 % the mesh", "OUTPUT_FILES= (RESTART)",
             "MESH_FILENAME= b.su2"]
    text = with_keys(lines, {"MESH_FILENAME": "mesh.su2", "MATH_PROBLEM": "DIRECT"})
    assert text.splitlines() == ["% comment", "SOLVER= EULER", "MESH_FILENAME= mesh.su2", "OUTPUT_FILES= (RESTART)",
                                 "MATH_PROBLEM= DIRECT"]
    assert config_value(lines, "MESH_FILENAME") == "b.su2"


@pytest.mark.parametrize("given, expect", [
    (None, {}),
    ("RMS_DENSITY", {"CONV_FIELD": "RMS_ADJ_DENSITY"}),
    ("( RMS_DENSITY, RMS_ENERGY )", {"CONV_FIELD": "(RMS_ADJ_DENSITY, RMS_ADJ_ENERGY)"}),
    ("RMS_ADJ_DENSITY", {"CONV_FIELD": "RMS_ADJ_DENSITY"}),
    ("DRAG", {"CONV_FIELD": "RMS_ADJ_DENSITY"}),
    ("( LIFT, DRAG )", {"CONV_FIELD": "RMS_ADJ_DENSITY"}),
    ("(RMS_DENSITY, DRAG)", {"CONV_FIELD": "(RMS_ADJ_DENSITY, DRAG)"}),
])
def test_the_adjoint_watches_its_own_residual(given, expect):
    """SU2_CFD_AD ignores a flow residual named in CONV_FIELD, and a Cauchy criterion on a coefficient
    ("Ignoring Convergence Field(s): DRAG"), and runs to ITER: the adjoint's config names the adjoint's
    residual instead."""
    lines = ["SOLVER= EULER", "CONV_RESIDUAL_MINVAL= -8"] + ([] if given is None else [f"CONV_FIELD= {given}"])
    assert adjoint_convergence(lines) == expect


def test_find_program_order(tmp_path, monkeypatch):
    a, b = tmp_path / "a", tmp_path / "b"
    for d in (a, b):
        d.mkdir()
        (d / "SU2_CFD").write_text("#!/bin/sh\n")
        (d / "SU2_CFD").chmod(0o755)
    monkeypatch.setenv("SU2_RUN", str(a))
    monkeypatch.setenv("PATH", str(b) + os.pathsep + os.environ.get("PATH", ""))
    assert find_program("SU2_CFD", "SU2_RUN") == a / "SU2_CFD"
    monkeypatch.delenv("SU2_RUN")
    assert find_program("SU2_CFD", "SU2_RUN") == b / "SU2_CFD"
    monkeypatch.setenv("PATH", "/nonexistent")
    assert find_program("SU2_CFD", "SU2_RUN", (a,)) == a / "SU2_CFD"
    assert find_program("SU2_CFD", "SU2_RUN") is None


def _stalled(tmp_path, final: float):
    """An adjoint log without SU2's "All convergence criteria satisfied" and its history (3,000 iterations,
    the first residual at ``final``)."""
    log = tmp_path / "adjoint_cd.log"
    log.write_text("Maximum number of iterations reached (ITER = 3000) before convergence.\n")
    return log, {"Inner_Iter": [0.0, 2999.0], "rms[A_Rho]": [-4.07, final], "rms[A_E]": [-4.0, -6.9]}


def test_a_stalled_adjoint_fails_with_what_to_change(tmp_path):
    """The adjoint stops at ITER above the config's CONV_RESIDUAL_MINVAL: a SolverFailure whose message
    names the residual reached, the target, and the two ways out (ITER, optimize.adjoint_residual)."""
    from ffdcli.optimize.solvers.base import SolverFailure
    from ffdcli.optimize.solvers.su2 import SU2
    solver = SU2(tmp_path / "rae.cfg")
    solver.lines = ["SOLVER= EULER", "CONV_RESIDUAL_MINVAL= -9"]
    log, hist = _stalled(tmp_path, -6.56)
    with pytest.raises(SolverFailure) as e:
        solver._converged(log, hist, "adjoint of DRAG")
    msg = e.value.reason
    assert "rms[A_Rho] reached -6.56 after 3000 iterations" in msg
    assert "rae.cfg's CONV_RESIDUAL_MINVAL -9" in msg and "raise ITER in rae.cfg" in msg
    assert "optimize.adjoint_residual" in msg and "e.g. -6.5" in msg and "--check-gradient" in msg
    with pytest.raises(SolverFailure) as e:                  # a flow: no adjoint key suggested
        solver._converged(log, {"Inner_Iter": [2999.0], "rms[Rho]": [-7.0]}, "flow")
    assert "adjoint_residual" not in e.value.reason and "loosen its CONV_RESIDUAL_MINVAL" in e.value.reason


def test_adjoint_residual_is_the_adjoints_own_target(tmp_path):
    """optimize.adjoint_residual: written into the adjoints' configs, checked instead of the config's,
    part of the solver's state (a run's evaluations are keyed by it); the flow keeps the config's."""
    from ffdcli.optimize.solvers.base import SolverFailure
    from ffdcli.optimize.solvers.su2 import SU2
    plain, loose = SU2(tmp_path / "rae.cfg"), SU2(tmp_path / "rae.cfg", adjoint_residual=-6.5)
    for s in (plain, loose):
        s.lines = ["SOLVER= EULER", "CONV_RESIDUAL_MINVAL= -9"]
    assert plain._adjoint_target() == {} and loose._adjoint_target() == {"CONV_RESIDUAL_MINVAL": "-6.5"}
    assert plain.state() != loose.state()
    log, hist = _stalled(tmp_path, -6.56)
    loose._converged(log, hist, "adjoint of DRAG", "-6.5")              # reached its own target
    log, hist = _stalled(tmp_path, -6.3)
    with pytest.raises(SolverFailure) as e:
        loose._converged(log, hist, "adjoint of DRAG", "-6.5")
    assert "optimize.adjoint_residual -6.5 is the target" in e.value.reason
    with pytest.raises(SolverFailure):                                   # the flow: the config's -9
        loose._converged(log, {"rms[Rho]": [-7.0]}, "flow")


def test_adjoint_residual_in_the_design_file(tmp_path):
    from ffdcli.design import load_design
    from ffdcli.design.optimize import optimize_settings
    (tmp_path / "flow.cfg").write_text("SOLVER= EULER\n")
    shutil.copyfile(ROOT / "samples" / "naca0012_inv.su2", tmp_path / "m.su2")
    base = {"mesh": "m.su2", "surface": "airfoil", "changes": [{"twist": 0}], "optimize": {"config": "flow.cfg"}}
    path = tmp_path / "d.yaml"
    path.write_text(yaml.safe_dump(base))
    from ffdcli.optimize.solvers.su2 import SU2
    from ffdcli.optimize.workflow import make_solver
    assert make_solver(optimize_settings(load_design(path))).adjoint_residual is None
    base["optimize"]["adjoint_residual"] = -6.5           # SU2's own key, parsed by the SU2 adapter
    path.write_text(yaml.safe_dump(base))
    solver = make_solver(optimize_settings(load_design(path)))
    assert isinstance(solver, SU2) and solver.adjoint_residual == -6.5


def test_an_incompressible_cauchy_config_watches_the_adjoint_pressure():
    lines = ["SOLVER= INC_NAVIER_STOKES", "CONV_FIELD= DRAG"]
    assert adjoint_convergence(lines) == {"CONV_FIELD": "RMS_ADJ_PRESSURE"}


def test_a_cauchy_config_without_a_residual_target_is_refused_before_any_work(tmp_path):
    """CONV_FIELD= DRAG and no CONV_RESIDUAL_MINVAL: the adjoints would run to ITER and fail; exit 2 at
    check() naming optimize.adjoint_residual. With either target given, check() passes."""
    from ffdcli.errors import InputError
    from ffdcli.optimize.solvers.su2 import SU2
    cfg = tmp_path / "cauchy.cfg"
    cfg.write_text("SOLVER= EULER\nCONV_FIELD= DRAG\nCONV_CAUCHY_EPS= 1E-6\n")
    with pytest.raises(InputError) as e:
        SU2(cfg, search=SEARCH).check()
    assert "optimize.adjoint_residual" in str(e.value) and "Cauchy" in str(e.value)
    if su2_missing() is None:
        assert SU2(cfg, search=SEARCH, adjoint_residual=-8.0).check().name == "su2"
        cfg.write_text("SOLVER= EULER\nCONV_FIELD= DRAG\nCONV_RESIDUAL_MINVAL= -8\n")
        assert SU2(cfg, search=SEARCH).check().name == "su2"
