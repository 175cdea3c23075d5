"""ADODG Case 1 through ``ffd optimize`` with the REAL SU2 (Euler, discrete adjoint): two SQP
iterations of configs/adodg/case1_v8.yaml on the coarsest level of the case's mesh family (L0,
64 x 16 quads, far field 50 chords), flow residual 1e-9. Skipped, with the reason, when SU2 is absent
(SU2_RUN, PATH or ../shared/su2/bin beside the repository)."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest
import yaml

from benchmarks.adodg.meshes import family, level_mesh
from ffdcli.io.formats import write_mesh
from ffdcli.optimize.solvers.base import find_program
from ffdcli.optimize.solvers.su2 import config_value, read_config, with_keys
from ffdcli.optimize.workflow import run_optimize

ROOT = Path(__file__).resolve().parents[2]
SEARCH = (ROOT.parent / "shared" / "su2" / "bin",)


def su2_missing() -> str | None:
    for name in ("SU2_CFD", "SU2_CFD_AD"):
        if find_program(name, "SU2_RUN", SEARCH) is None:
            return f"{name} not found (SU2_RUN, PATH, {SEARCH[0]})"
    return None


@pytest.mark.solver
@pytest.mark.skipif(su2_missing() is not None, reason=str(su2_missing()))
def test_case1_two_sqp_iterations_on_the_coarsest_level(tmp_path):
    write_mesh(level_mesh(family()[0]), tmp_path / "adodg_L0.su2")
    lines = read_config(ROOT / "configs" / "adodg" / "case1.cfg")
    (tmp_path / "case1.cfg").write_text(with_keys(lines, {"CONV_RESIDUAL_MINVAL": "-9"}))
    design = yaml.safe_load((ROOT / "configs" / "adodg" / "case1_v8.yaml").read_text())
    design.update(mesh="adodg_L0.su2", output={"mesh": "out/best.su2"})
    design["optimize"].update(config="case1.cfg", folder="opt", iterations=2)
    path = tmp_path / "design.yaml"
    path.write_text(yaml.safe_dump(design, sort_keys=False))

    out = run_optimize(path, search=SEARCH)
    assert out["adjoint"] == "discrete" and len(out["variables"]) == 8
    assert out["status"] in ("iterations", "converged"), out["message"]
    assert out["iterations"] >= 1
    assert out["objective"]["best"] < out["objective"]["initial"]
    assert out["constraints_satisfied"], out["constraints"]
    added = [v for k, v in out["constraints"].items() if k.startswith("k0.add_material")]
    # every wall node, the leading- and trailing-edge points twice (held on both sides), to 1e-6 chord
    assert len(added) == 64 + 2 and min(added) >= -1e-6
    with open(tmp_path / "opt" / "history.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == out["evaluations"] and not any(r["failed"] for r in rows)
    cfg = read_config(tmp_path / "opt" / rows[0]["folder"] / "flow.cfg")
    assert config_value(cfg, "MACH_NUMBER") == "0.85" and float(config_value(cfg, "AOA")) == 0.0
    assert np.isfinite(out["objective"]["best"])
