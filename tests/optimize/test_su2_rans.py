"""The SU2 adapter's RANS rules (:mod:`ffdcli.optimize.solvers.su2_settings`): an adjoint of a config that
adapts its CFL runs at the flow's final CFL, fixed; a warm-started RANS flow converges one order further.
The rules on their own, then through :class:`SU2`'s flow and adjoint runs with a stand-in SU2 (a Python
script that writes the history, restart and sensitivity files SU2 writes, from the config it is given),
so the configs ffd writes are the ones checked."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ffdcli.optimize.solvers.base import SolverFailure
from ffdcli.optimize.solvers.su2 import SU2, config_value, read_config
from ffdcli.optimize.solvers.su2_settings import adjoint_cfl, flow_history_groups, warm_flow_residual


def _value(lines: list[str]):
    return lambda key: config_value(lines, key)


@settings(max_examples=40, deadline=None)
@given(final=st.floats(0.5, 1e4), rows=st.integers(1, 30), spelling=st.sampled_from(["YES", "yes", " YES "]))
def test_an_adapting_config_fixes_the_adjoint_at_the_flow_final_cfl(final, rows, spelling):
    lines = ["SOLVER= RANS", "CFL_NUMBER= 10", f"CFL_ADAPT= {spelling}", "CFL_ADAPT_PARAM= ( 0.5, 1.1, 1, 50 )"]
    history = {"Inner_Iter": list(range(rows)), "Avg CFL": [*np.linspace(10.0, 2 * final, rows - 1), final]}
    keys = adjoint_cfl(_value(lines), history)
    assert keys["CFL_ADAPT"] == "NO" and float(keys["CFL_NUMBER"]) == pytest.approx(final, rel=1e-5)
    assert flow_history_groups(_value(lines)) == ("CFL_NUMBER",)


@pytest.mark.parametrize("lines", [["SOLVER= RANS", "CFL_NUMBER= 50"], ["SOLVER= RANS", "CFL_ADAPT= NO"],
                                   ["SOLVER= EULER", "CFL_ADAPT= NO % fixed"]])
def test_a_fixed_cfl_config_is_left_as_written(lines):
    assert adjoint_cfl(_value(lines), {}) == {} and flow_history_groups(_value(lines)) == ()


@pytest.mark.parametrize("history", [{}, {"Avg CFL": []}, {"Avg CFL": [12.0, float("nan")]}, {"Avg CFL": [0.0]}])
def test_no_final_cfl_is_an_error_not_a_guess(history):
    with pytest.raises(ValueError, match="Avg CFL"):
        adjoint_cfl(_value(["CFL_ADAPT= YES"]), history)


@pytest.mark.parametrize("lines, expect", [
    (["SOLVER= RANS", "CONV_RESIDUAL_MINVAL= -8"], "-9"),
    (["SOLVER= RANS", "CONV_FIELD= RMS_DENSITY", "CONV_RESIDUAL_MINVAL= -10.5"], "-11.5"),
    (["SOLVER= INC_RANS", "CONV_FIELD= (RMS_PRESSURE, RMS_NU_TILDE)", "CONV_RESIDUAL_MINVAL= -7"], "-8"),
    (["SOLVER= rans"], "-9"),                                      # SU2's default -8
    (["SOLVER= RANS", "CONV_FIELD= DRAG", "CONV_CAUCHY_EPS= 1e-6"], None),   # a Cauchy criterion
    (["SOLVER= EULER", "CONV_RESIDUAL_MINVAL= -12"], None),
    (["SOLVER= NAVIER_STOKES", "CONV_RESIDUAL_MINVAL= -8"], None),
])
def test_a_warm_rans_flow_asks_for_one_order_more(lines, expect):
    assert warm_flow_residual(_value(lines)) == expect


FAKE = r'''
import sys, os
cfg = {}
for line in open(sys.argv[1]):
    if "=" in line and not line.lstrip().startswith("%"):
        k, v = line.split("=", 1)
        cfg[k.strip().upper()] = v.split("%")[0].strip()
adjoint = cfg["MATH_PROBLEM"] != "DIRECT"
reach = float(os.environ.get("FAKE_REACH", "-9.5"))
if adjoint:
    sfx = cfg["CONV_FILENAME"].split("_")[-1]
    with open(cfg["CONV_FILENAME"] + ".csv", "w") as fh:
        fh.write('"Inner_Iter","rms[A_Rho]"\n0,-3\n300,-8.5\n')
    with open(f"restart_adj_{sfx}.csv", "w") as fh:
        fh.write('"PointID","x","y","Sensitivity_x","Sensitivity_y"\n0,0,0,0.5,1.5\n1,1,0,0.25,-2\n')
    open(f"restart_adj_{sfx}.dat", "w").write("adj")
else:
    cols = '"Inner_Iter","rms[Rho]","CD","CL","CMz"' + (',"Avg CFL"' if "CFL_NUMBER" in cfg["HISTORY_OUTPUT"] else "")
    row = f"250,{reach},0.0194,0.805,0.096" + (",48.25" if "CFL_NUMBER" in cfg["HISTORY_OUTPUT"] else "")
    with open("history.csv", "w") as fh:
        fh.write(cols + "\n" + row.replace("250", "0", 1).replace(str(reach), "-2", 1) + "\n" + row + "\n")
    open("restart_flow.dat", "w").write("flow")
'''


def _stand_in(tmp_path: Path, lines: list[str]) -> SU2:
    prog = tmp_path / "fake_su2.py"
    prog.write_text(FAKE)
    cfg = tmp_path / "user.cfg"
    cfg.write_text("\n".join(lines) + "\n")
    solver = SU2(cfg, launch=(sys.executable,))
    solver.lines = read_config(cfg)
    solver.programs = {"SU2_CFD": prog, "SU2_CFD_AD": prog}
    return solver


RANS = ["SOLVER= RANS", "KIND_TURB_MODEL= SA", "CFL_NUMBER= 10", "CFL_ADAPT= YES",
        "CFL_ADAPT_PARAM= ( 0.5, 1.1, 1.0, 50.0 )", "CONV_FIELD= RMS_DENSITY", "CONV_RESIDUAL_MINVAL= -8",
        "HISTORY_OUTPUT= (ITER, RMS_RES)", "ITER= 3000"]


def test_the_configs_ffd_writes_for_a_rans_flow_and_its_adjoint(tmp_path, monkeypatch):
    """Cold flow: the config's -8, the CFL_NUMBER history group asked for; its adjoint: CFL_ADAPT= NO at
    the flow's final Avg CFL (48.25), the rest of the CFL keys as written; a warm flow: -9 asked for."""
    solver = _stand_in(tmp_path, RANS)
    cold = tmp_path / "e0"
    cold.mkdir()
    (cold / "mesh.su2").write_text("")
    flow = solver.flow(cold, cold / "mesh.su2")
    assert flow.functions["DRAG"] == pytest.approx(0.0194)
    written = read_config(cold / "flow.cfg")
    assert config_value(written, "CONV_RESIDUAL_MINVAL") == "-8" and config_value(written, "CFL_ADAPT") == "YES"
    assert config_value(written, "HISTORY_OUTPUT") == "(ITER, RMS_RES, AERO_COEFF, CFL_NUMBER)"
    sens = solver.adjoint(cold, cold / "mesh.su2", "DRAG")
    assert sens.values.shape == (2, 3)
    adj = read_config(cold / "adjoint_cd.cfg")
    assert config_value(adj, "CFL_ADAPT") == "NO" and config_value(adj, "CFL_NUMBER") == "48.25"
    assert config_value(adj, "CFL_ADAPT_PARAM") == "( 0.5, 1.1, 1.0, 50.0 )"
    assert config_value(adj, "CONV_FIELD") == "RMS_ADJ_DENSITY"

    warm = tmp_path / "e1"
    warm.mkdir()
    (warm / "mesh.su2").write_text("")
    solver.flow(warm, warm / "mesh.su2", start=cold)                 # the stand-in reaches -9.5
    assert config_value(read_config(warm / "flow.cfg"), "CONV_RESIDUAL_MINVAL") == "-9"
    assert config_value(read_config(warm / "flow.cfg"), "RESTART_SOL") == "YES"

    monkeypatch.setenv("FAKE_REACH", "-8.5")                          # enough cold, not warm
    again = tmp_path / "e2"
    again.mkdir()
    (again / "mesh.su2").write_text("")
    with pytest.raises(SolverFailure) as e:
        solver.flow(again, again / "mesh.su2", start=cold)
    assert "warm-started flow did not converge" in e.value.reason and "rms[Rho] reached -8.5" in e.value.reason
    assert "-9 (a warm-started RANS flow: one order below user.cfg's CONV_RESIDUAL_MINVAL)" in e.value.reason
    solver.flow(again, again / "mesh.su2")                            # cold, -8.5 meets -8


def test_a_fixed_cfl_rans_config_reaches_su2_as_written(tmp_path):
    lines = [ln for ln in RANS if not ln.startswith("CFL_ADAPT")] + ["CFL_ADAPT= NO"]
    solver = _stand_in(tmp_path, lines)
    (tmp_path / "mesh.su2").write_text("")
    solver.flow(tmp_path, tmp_path / "mesh.su2")
    assert config_value(read_config(tmp_path / "flow.cfg"), "HISTORY_OUTPUT") == "(ITER, RMS_RES, AERO_COEFF)"
    solver.adjoint(tmp_path, tmp_path / "mesh.su2", "LIFT")
    adj = read_config(tmp_path / "adjoint_cl.cfg")
    assert config_value(adj, "CFL_ADAPT") == "NO" and config_value(adj, "CFL_NUMBER") == "10"


def test_an_adjoint_without_the_flow_cfl_is_a_failed_evaluation(tmp_path):
    solver = _stand_in(tmp_path, RANS)
    (tmp_path / "restart_flow.dat").write_text("flow")
    (tmp_path / "history.csv").write_text('"Inner_Iter","rms[Rho]","CD"\n0,-9,0.02\n')
    with pytest.raises(SolverFailure, match="no Avg CFL column"):
        solver.adjoint(tmp_path, tmp_path / "mesh.su2", "DRAG")
    assert not (tmp_path / "adjoint_cd.cfg").exists()
