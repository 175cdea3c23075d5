"""ADODG Case 2 through ``ffd optimize`` with the REAL SU2 (RANS, Spalart-Allmaras, discrete adjoint with
the turbulence model differentiated): the shipped design and configuration (``configs/adodg/case2.yaml``,
``case2.cfg``: adaptive CFL for the flow, 3-level multigrid) on SU2's RAE2822 RANS mesh (13,937 points,
the case's optimisation mesh), the baseline's DRAG adjoint beside central differences of one shape
variable (``--check-gradient``). The finite-difference flows start warm from the baseline, so they are
asked for -9, one order below the cold -8, and the adjoint runs at the flow's final CFL, fixed.

SU2's mesh, not a coarse C-mesh of ``ffdcli.testing.cmesh``: on those (97 x 49 points, first cell
1e-5 chord) SU2's flow stalls near rms[Rho] -7.5 and then diverges after 250-420 iterations, at the
case's M 0.734 and at M 0.6 alike (docs/adodg.md, Case 2). Skipped, with the reason, when SU2 or the
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
def test_case2_rans_drag_adjoint_against_finite_differences(tmp_path):
    shutil.copyfile(MESH, tmp_path / "rae2822_su2.su2")
    shutil.copyfile(ROOT / "configs" / "adodg" / "case2.cfg", tmp_path / "case2.cfg")
    design = yaml.safe_load((ROOT / "configs" / "adodg" / "case2.yaml").read_text())
    design.update(mesh="rae2822_su2.su2", output={"mesh": "out/best.su2"})
    design["optimize"].update(folder="opt")
    design["optimize"].pop("functions")
    path = tmp_path / "design.yaml"
    path.write_text(yaml.safe_dump(design, sort_keys=False))

    out = run_optimize(path, check=["c0.shape.upper[4]"], step=0.01, search=SEARCH)
    rows = out["gradient_check"]
    assert [r["function"] for r in rows] == ["DRAG"] and rows[0]["variable"] == "c0.shape.upper[4]"
    row = rows[0]
    assert abs(row["finite_difference"]) > 1e-3, row                 # a step that moves the drag
    assert row["relative"] < 0.05, row                                 # adjoint and differences agree
    check = tmp_path / "opt" / "check"
    base = next(check.rglob("adjoint_cd.cfg"))
    adj, flow = read_config(base), read_history(base.parent / "history.csv")
    assert config_value(adj, "CFL_ADAPT") == "NO"
    assert float(config_value(adj, "CFL_NUMBER")) == pytest.approx(flow["Avg CFL"][-1], rel=1e-5)
    warm = [c for c in (read_config(p) for p in check.rglob("flow.cfg")) if config_value(c, "RESTART_SOL") == "YES"]
    assert len(warm) == 2 and all(config_value(c, "CONV_RESIDUAL_MINVAL") == "-9" for c in warm)
