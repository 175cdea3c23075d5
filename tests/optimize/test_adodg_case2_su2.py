"""ADODG Case 2 through ``ffd optimize`` with the REAL SU2 (RANS, Spalart-Allmaras, discrete adjoint with
the turbulence model differentiated): the shipped design and configuration (``configs/adodg/case2.yaml``,
``case2.cfg``: adaptive CFL for the flow, 3-level multigrid) on SU2's RAE2822 RANS mesh (13,937 points,
the case's optimisation mesh), the gradient of every function of the case beside central differences
of one shape variable (``--check-gradient``): the DRAG, LIFT and MOMENT_Z adjoints (three SU2_CFD_AD
runs at the baseline) and the area constraint's exact Jacobian (``k0.volume``), all against the same
two flows at +-the step. The finite-difference flows start warm from the baseline, so they are asked
for -9, one order below the cold -8, and each adjoint runs at the flow's final CFL, fixed. The three
adjoints run side by side (``concurrent_adjoints: 3``, the same values as one after the other): on 2
cores the check then costs a flow, about one and a half adjoints and two warm flows.

SU2's mesh, not a coarse C-mesh of ``ffdcli.testing.cmesh``: on those (97 x 49 points, first cell
1e-5 chord) SU2's flow stalls near rms[Rho] -7.5 and then diverges after 250-420 iterations, at the
case's M 0.734 and at M 0.6 alike (docs/adodg-case2.md). Skipped, with the reason, when SU2 or the
shared mesh is absent (SU2_RUN, PATH or ../shared/su2/bin; ../shared/data/su2)."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
import yaml

from ffdcli.optimize.solvers.base import find_program
from ffdcli.optimize.solvers.su2 import config_value, read_config, read_history
from ffdcli.optimize.workflow import run_optimize

ROOT = Path(__file__).resolve().parents[2]
SEARCH = (ROOT.parent / "shared" / "su2" / "bin",)
MESH = ROOT.parent / "shared" / "data" / "su2" / "optimization_rans__steady_rae2822__mesh_RAE2822_turb.su2"


def missing() -> str | None:
    for name in ("SU2_CFD", "SU2_CFD_AD"):
        if find_program(name, "SU2_RUN", SEARCH) is None:
            return f"{name} not found (SU2_RUN, PATH, {SEARCH[0]})"
    return None if MESH.is_file() else f"{MESH} not found"


@pytest.mark.solver
@pytest.mark.skipif(missing() is not None, reason=str(missing()))
def test_case2_rans_adjoints_of_every_function_against_finite_differences(tmp_path):
    shutil.copyfile(MESH, tmp_path / "rae2822_su2.su2")
    shutil.copyfile(ROOT / "configs" / "adodg" / "case2.cfg", tmp_path / "case2.cfg")
    design = yaml.safe_load((ROOT / "configs" / "adodg" / "case2.yaml").read_text())
    design.update(mesh="rae2822_su2.su2", output={"mesh": "out/best.su2"})
    design["optimize"].update(folder="opt", concurrent_adjoints=3)   # the three adjoints side by side
    path = tmp_path / "design.yaml"
    path.write_text(yaml.safe_dump(design, sort_keys=False))

    out = run_optimize(path, check=["c0.shape.upper[4]"], step=0.01, search=SEARCH)
    rows = {r["function"]: r for r in out["gradient_check"]}
    assert list(rows) == ["DRAG", "LIFT", "MOMENT_Z", "k0.volume"], list(rows)
    assert all(r["variable"] == "c0.shape.upper[4]" for r in rows.values())
    # the solver's functions; measured 0.44 % (DRAG), 4.7 % (LIFT), 0.93 % (MOMENT_Z). CL is strongly
    # nonlinear in this variable at this step (one-sided differences 0.035 and 0.626 about a central
    # 0.330; with the flows at -10 the central difference is 0.341, at a 3e-3 step 0.280, the adjoint
    # 0.315), so LIFT is held to 10 % (docs/adodg-case2.md, the CI check)
    for name, tol in (("DRAG", 0.05), ("LIFT", 0.10), ("MOMENT_Z", 0.05)):
        row = rows[name]
        assert abs(row["finite_difference"]) > 1e-3, row               # a step that moves the function
        assert row["relative"] < tol, row                              # adjoint and differences agree
    assert rows["k0.volume"]["relative"] < 1e-6, rows["k0.volume"]     # the area: exact, quadratic in the points
    assert rows["k0.volume"]["finite_difference"] > 0.01               # lifting the upper surface adds area
    check = tmp_path / "opt" / "check"
    adjoints = {p.name: p for p in check.rglob("adjoint_*.cfg")}
    assert set(adjoints) == {"adjoint_cd.cfg", "adjoint_cl.cfg", "adjoint_cmz.cfg"}, set(adjoints)
    flow = read_history(adjoints["adjoint_cd.cfg"].parent / "history.csv")
    for cfg in adjoints.values():                                      # each at the flow's final CFL, fixed
        adj = read_config(cfg)
        assert config_value(adj, "CFL_ADAPT") == "NO"
        assert float(config_value(adj, "CFL_NUMBER")) == pytest.approx(flow["Avg CFL"][-1], rel=1e-5)
    warm = [c for c in (read_config(p) for p in check.rglob("flow.cfg")) if config_value(c, "RESTART_SOL") == "YES"]
    assert len(warm) == 2 and all(config_value(c, "CONV_RESIDUAL_MINVAL") == "-9" for c in warm)
