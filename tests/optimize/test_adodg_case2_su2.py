"""ADODG Case 2's machinery through ``ffd optimize`` with the REAL SU2 (RANS, Spalart-Allmaras, discrete
adjoint with the turbulence model differentiated): the shipped configuration (``configs/adodg/case2.cfg``:
adaptive CFL for the flow, 3-level multigrid) on a coarse C-mesh of the RAE2822
(:func:`ffdcli.testing.cmesh.cmesh`, 97 points around, 49 out, first cell 1e-5 chord, ~7,000 points),
the baseline's DRAG adjoint beside central differences of one shape variable (``--check-gradient``).
The finite-difference flows start warm from the baseline (so they are asked for -9, one order below the
cold -8), and the adjoint runs at the flow's final CFL, fixed.

At M 0.6 (the one change to the case): at the case's M 0.734 this coarse mesh's flow does not converge
(rms[Rho] -6.6 by 180 iterations, then a blow-up near 250 with the CFL adapted to 50 or to 20, near 380
with 2 multigrid levels), while at M 0.6 it reaches -8 in a few hundred iterations: the test is of the
adjoint machinery, in minutes. Skipped, with the reason, when SU2 is absent (SU2_RUN, PATH or
../shared/su2/bin)."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from ffdcli.io.formats import write_mesh
from ffdcli.optimize.solvers.base import find_program
from ffdcli.optimize.solvers.su2 import config_value, read_config, read_history, with_keys
from ffdcli.optimize.workflow import run_optimize
from ffdcli.testing.cmesh import cmesh, read_airfoil

ROOT = Path(__file__).resolve().parents[2]
SEARCH = (ROOT.parent / "shared" / "su2" / "bin",)
AIRFOIL = ROOT.parent / "shared" / "data" / "airfoils" / "rae2822.dat"


def missing() -> str | None:
    for name in ("SU2_CFD", "SU2_CFD_AD"):
        if find_program(name, "SU2_RUN", SEARCH) is None:
            return f"{name} not found (SU2_RUN, PATH, {SEARCH[0]})"
    return None if AIRFOIL.is_file() else f"{AIRFOIL} not found"


@pytest.mark.solver
@pytest.mark.skipif(missing() is not None, reason=str(missing()))
def test_case2_rans_adjoint_gradient_on_a_coarse_c_mesh(tmp_path):
    write_mesh(cmesh(read_airfoil(AIRFOIL), 97, 25, 49, 1e-5, 100.0), tmp_path / "rae2822_c.su2")
    lines = read_config(ROOT / "configs" / "adodg" / "case2.cfg")          # the C-mesh's markers are lower case
    (tmp_path / "case2.cfg").write_text(with_keys(lines, {
        "MARKER_HEATFLUX": "( airfoil, 0.0 )", "MARKER_FAR": "( farfield )", "MARKER_PLOTTING": "( airfoil )",
        "MARKER_MONITORING": "( airfoil )", "MACH_NUMBER": "0.6"}))
    design = yaml.safe_load((ROOT / "configs" / "adodg" / "case2.yaml").read_text())
    design.update(mesh="rae2822_c.su2", surface="airfoil", output={"mesh": "out/best.su2"})
    design["optimize"].update(config="case2.cfg", folder="opt")
    design["optimize"].pop("functions")
    path = tmp_path / "design.yaml"
    path.write_text(yaml.safe_dump(design, sort_keys=False))

    out = run_optimize(path, check=["c0.shape.upper[4]"], step=0.01, search=SEARCH)
    rows = out["gradient_check"]
    assert [r["function"] for r in rows] == ["DRAG"] and rows[0]["variable"] == "c0.shape.upper[4]"
    row = rows[0]
    assert abs(row["finite_difference"]) > 1e-3, row                 # a step that moves the drag
    assert row["relative"] < 0.05, row                                 # adjoint and differences agree
    base = next(p for p in (tmp_path / "opt" / "check").rglob("adjoint_cd.cfg"))
    adj, flow = read_config(base), read_history(base.parent / "history.csv")
    assert config_value(adj, "CFL_ADAPT") == "NO"
    assert float(config_value(adj, "CFL_NUMBER")) == pytest.approx(flow["Avg CFL"][-1], rel=1e-5)
    warm = [read_config(p) for p in (tmp_path / "opt" / "check").rglob("flow.cfg")
            if config_value(read_config(p), "RESTART_SOL") == "YES"]
    assert len(warm) == 2 and all(config_value(c, "CONV_RESIDUAL_MINVAL") == "-9" for c in warm)
