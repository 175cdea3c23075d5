"""The SU2 glue of docs/su2.md: the shipped sensitivity file and the design-loop example."""

from __future__ import annotations

import importlib.util
import json
import os
import subprocess
import sys

import pytest
from conftest import REPO, SU2_MISSING, run_ffd, su2_folder


@pytest.fixture(scope="module")
def volume_sens(tmp_path_factory):
    """The volume oracle of configs/rect_grad.yaml (dJ/dX of the wing's volume), as make_samples writes it."""
    spec = importlib.util.spec_from_file_location("make_samples", REPO / "samples" / "make_samples.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    path = tmp_path_factory.mktemp("oracle") / "rect_wing_volume_sens.csv"
    info = mod.make_volume_sens(path)
    assert abs(info["volume"] - 0.2446) < 1e-3           # NACA0012 area 0.0822 x chord 1 x semi-span 3, faceted
    header = path.read_text().splitlines()[0]
    assert header == '"PointID","x","y","z","Sensitivity_x","Sensitivity_y","Sensitivity_z"'
    return path


def test_rect_grad_example_gives_the_volume_oracle(tmp_path, volume_sens):
    """dV/d(span) = V (volume is linear in the span factor); twist and sweep keep volume (0)."""
    proc = run_ffd("grad", REPO / "configs" / "rect_grad.yaml", "--sens", volume_sens, "--json",
                   "--cache-dir", tmp_path)
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout)
    grad = out.get("gradient", out)
    V = 0.24463859228331455
    assert grad["c1.span"] == pytest.approx(V, rel=1e-9)
    assert abs(grad["c0.twist.tip"]) < 1e-7 * V
    assert abs(grad["c2.sweep"]) < 1e-12
    assert grad["c3.chord.tip"] == pytest.approx(V, rel=1e-4)


def _rect_design(tmp_path):
    design = tmp_path / "d.yaml"
    design.write_text(f"mesh: {REPO / 'samples' / 'rect_wing.su2'}\nsurface: wing\n"
                      "box: {points: [6, 8, 2], sections: xy}\nchanges:\n  - twist: {tip: 0}\n")
    cfg = tmp_path / "flow.cfg"
    cfg.write_text("SOLVER= EULER\nMESH_FILENAME= somewhere.su2\nAOA= 0\nSIDESLIP_ANGLE= 2\n")
    return design, cfg


def test_design_loop_dry_run(tmp_path):
    design, cfg = _rect_design(tmp_path)
    proc = subprocess.run([sys.executable, str(REPO / "examples" / "su2_design_loop.py"), str(design), str(cfg),
                           "--variable", "c0.twist.tip", "--values", "0,3", "--work", str(tmp_path / "w"),
                           "--dry-run"], capture_output=True, text=True, cwd=tmp_path,
                          env={**os.environ, "PYTHONPATH": str(REPO)})
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.count("(dry run)") == 2
    for v in ("0", "3"):
        folder = tmp_path / "w" / f"c0.twist.tip={v}"
        assert (folder / "mesh.su2").is_file()
        assert f"MESH_FILENAME= {folder / 'mesh.su2'}" in (folder / "flow.cfg").read_text()
        assert "somewhere" not in (folder / "flow.cfg").read_text()
    assert len(json.loads((tmp_path / "w" / "results.json").read_text())) == 2


@pytest.mark.solver
@pytest.mark.skipif(su2_folder() is None, reason=SU2_MISSING)
def test_design_loop_with_su2(tmp_path):
    design, cfg = _rect_design(tmp_path)
    # the rectangular wing's real Euler configuration (configs/rect_euler.cfg), 50 iterations
    cfg.write_text((REPO / "configs" / "rect_euler.cfg").read_text().replace("ITER= 400", "ITER= 50"))
    proc = subprocess.run([sys.executable, str(REPO / "examples" / "su2_design_loop.py"), str(design), str(cfg),
                           "--variable", "c0.twist.tip", "--values", "0,3", "--work", str(tmp_path / "w")],
                          capture_output=True, text=True, cwd=tmp_path,
                          env={**os.environ, "PYTHONPATH": str(REPO),
                               "PATH": f"{su2_folder()}{os.pathsep}{os.environ.get('PATH', '')}"})
    assert proc.returncode == 0, proc.stderr
    rows = json.loads((tmp_path / "w" / "results.json").read_text())
    assert all(r["CL"] is not None for r in rows)
