"""The bundled SU2 drag sensitivity (samples/naca0012_2d_cd_sens.csv): ffd grad of it against SU2 itself.

The file is SU2's discrete adjoint of CD on samples/naca0012_2d.su2 (samples/README.md). Without SU2
the file is still checked (layout, one row per mesh node, coordinates of the bundled mesh) and read by
`ffd grad`; with SU2 (SU2_RUN, PATH or ../shared/su2/bin) the gradient of the twist and of one shape
variable is compared with central differences of converged SU2 flows on meshes `ffd deform` wrote.
"""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import numpy as np
import pytest
from conftest import REPO, SAMPLES, SU2_MISSING, run_ffd, su2_folder

SENS = SAMPLES / "naca0012_2d_cd_sens.csv"
DESIGN = REPO / "configs" / "naca0012_grad.yaml"
CFG = SAMPLES / "naca0012_2d_euler.cfg"


def test_sample_is_every_node_of_the_bundled_mesh():
    head = SENS.read_text().splitlines()[0]
    assert head == '"PointID","x","y","Sensitivity_x","Sensitivity_y"'
    data = np.loadtxt(SENS, delimiter=",", skiprows=1)
    assert data.shape == (6560, 5)
    assert np.array_equal(data[:, 0], np.arange(6560))
    assert np.abs(data[:, 3:]).max() > 0.0              # a real sensitivity: never an all-zero column
    assert np.all(np.abs(data[:, 3:]).max(axis=0) > 0.0)


def test_grad_reads_the_sample(tmp_path):
    proc = run_ffd("grad", DESIGN, "--sens", SENS, "--json", "--cache-dir", tmp_path)
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout)
    grad = out.get("gradient", out)
    assert len([k for k in grad if k.startswith("c1.shape")]) == 16
    assert grad["c0.twist"] > 0.0                       # more incidence, more (wave) drag


def _cd(mesh: Path, folder: Path, bindir: Path) -> float:
    folder.mkdir(parents=True)
    cfg = CFG.read_text().replace("MESH_FILENAME= naca0012_2d.su2", f"MESH_FILENAME= {mesh}")
    cfg = cfg.replace("OUTPUT_FILES= (RESTART, RESTART_ASCII, SURFACE_CSV)", "OUTPUT_FILES= (RESTART)")
    (folder / "flow.cfg").write_text(cfg)
    proc = subprocess.run([str(bindir / "SU2_CFD"), "flow.cfg"], cwd=folder, capture_output=True, text=True)
    assert proc.returncode == 0, proc.stdout[-2000:]
    lines = (folder / "history.csv").read_text().splitlines()
    head = [h.strip().strip('"') for h in lines[0].split(",")]
    last = dict(zip(head, (float(v) for v in lines[-1].split(","))))
    assert last["rms[Rho]"] < -11.5, last                 # converged as the sample's flow was (-12)
    return last["CD"]


@pytest.mark.solver
@pytest.mark.skipif(su2_folder() is None, reason=SU2_MISSING)
@pytest.mark.parametrize("key, name, step", [("changes.0.twist", "c0.twist", 0.01),
                                             ("changes.1.shape.upper.3", "c1.shape.upper[3]", 1e-4)])
def test_grad_of_the_sample_matches_su2_finite_differences(tmp_path, key, name, step):
    bindir = su2_folder()
    proc = run_ffd("grad", DESIGN, "--sens", SENS, "--json", "--cache-dir", tmp_path)
    assert proc.returncode == 0, proc.stderr
    grad = json.loads(proc.stdout)
    adjoint = grad.get("gradient", grad)[name]
    cd = {}
    for sgn in (1, -1):
        mesh = tmp_path / f"m{sgn}.su2"
        p = run_ffd("deform", DESIGN, "--set", f"{key}={sgn * step!r}", "-o", mesh, "--cache-dir", tmp_path)
        assert p.returncode == 0, p.stderr
        cd[sgn] = _cd(mesh, tmp_path / f"run{sgn}", bindir)
    fd = (cd[1] - cd[-1]) / (2 * step)
    assert adjoint == pytest.approx(fd, rel=2e-3), (adjoint, fd)
