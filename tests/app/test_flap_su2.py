"""A 10 degree flap on the rectangular wing, through SU2 (issue 31): the deformed mesh is read, the
Euler flow converges, and the lift is higher than the baseline's. Skips without SU2_CFD
(found as `ffd optimize` finds it, or in ../shared/su2/bin).

The wing's thickness axis is y, so its lift is SU2's side force CSF (configs/rect_euler.cfg sets the
incidence with SIDESLIP_ANGLE). The numbers of a full run are in docs/design-choices.md.
"""

from __future__ import annotations

import csv
import subprocess

import pytest
from conftest import REPO, SU2_MISSING, run_ffd, su2_folder

SU2 = su2_folder()
pytestmark = [pytest.mark.slow, pytest.mark.solver, pytest.mark.skipif(SU2 is None, reason=SU2_MISSING)]


def su2_run(folder, mesh):
    """(first and last rms[Rho], last CSF) of SU2_CFD's Euler run on ``mesh``."""
    folder.mkdir()
    cfg = (REPO / "configs" / "rect_euler.cfg").read_text().replace("MESH_FILENAME= mesh.su2",
                                                                     f"MESH_FILENAME= {mesh}")
    (folder / "flow.cfg").write_text(cfg.replace("ITER= 400", "ITER= 120"))
    proc = subprocess.run([str(SU2 / "SU2_CFD"), "flow.cfg"], cwd=folder, capture_output=True, text=True, timeout=3600)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    assert "Exit Success" in proc.stdout
    with open(folder / "history.csv") as f:
        rows = [{k.strip().strip('"'): v for k, v in r.items()} for r in csv.DictReader(f)]
    return float(rows[0]["rms[Rho]"]), float(rows[-1]["rms[Rho]"]), float(rows[-1]["CSF"])


def test_flap_raises_the_lift(tmp_path):
    design = tmp_path / "flap.yaml"
    design.write_text(f"mesh: {REPO / 'samples' / 'rect_wing.su2'}\nsurface: wing\n"
                      "changes:\n  - flap: {span: [0.2, 0.6], hinge: 0.75, angle: 10}\n"
                      f"output:\n  mesh: {tmp_path / 'flap.su2'}\n")
    proc = run_ffd("deform", design, "--cache-dir", tmp_path)
    assert proc.returncode == 0, proc.stderr
    r0, r1, lift = su2_run(tmp_path / "flap", tmp_path / "flap.su2")
    b0, b1, base = su2_run(tmp_path / "base", REPO / "samples" / "rect_wing.su2")
    assert r1 < r0 - 4 and b1 < b0 - 4              # converged: density residual down 4 orders
    assert lift > base + 0.05                        # the flap adds lift (full run: 0.141 -> 0.361)
