"""ffd's figures of OpenFOAM meshes against checkMesh's, and deformed cases that OpenFOAM runs
(needs Debian's OpenFOAM: ``make test`` installs it as root; skipped otherwise)."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest
from conftest import run_ffd

from ffdcli.api import DesignModel
from ffdcli.io.formats import read_mesh
from ffdcli.quality.polyhedral import poly_figures
from ffdcli.testing import foam

pytestmark = [pytest.mark.solver,
              pytest.mark.skipif(not foam.have_openfoam(), reason="OpenFOAM (checkMesh) is not installed: "
                                 "apt-get install openfoam openfoam-examples (make test does it as root)")]


def _agree(fig: dict, cm: dict) -> None:
    assert fig["cells"] == cm["cells"]
    assert fig["negative_volumes"] == cm["negative_volumes"]
    assert fig["face_pyramid_errors"] == cm["face_pyramid_errors"]
    assert abs(fig["max_non_orthogonality"] - cm["max_non_orthogonality"]) < 1e-3       # checkMesh prints 6 digits
    assert abs(fig["max_skewness"] - cm["max_skewness"]) < 1e-6 * max(1.0, cm["max_skewness"])


def test_airfoil2d_example_figures_equal_checkmesh(tmp_path):
    src = foam.EXAMPLE_CASES / "incompressible" / "simpleFoam" / "airFoil2D"
    if not src.is_dir():
        pytest.skip("openfoam-examples is not installed")
    case = shutil.copytree(src, tmp_path / "airFoil2D")
    mesh = read_mesh(case)
    _agree(poly_figures(mesh.points, mesh.polyhedra).summary(), foam.check_mesh(case))
    assert [p.type for p in mesh.source.patches if p.name == "walls"] == ["wall"]


def test_blockmesh_wing_deformed_runs_and_agrees(tmp_path):
    case = foam.wing_block_mesh(tmp_path / "wing", n_seg=8, n_radial=12, n_span=4)
    assert foam.foam("blockMesh", case).returncode == 0
    foam.potential_flow_files(case, {"wing": "wall", "farfield": "far", "symmetry": "symmetry", "side": "symmetry"})
    mesh = read_mesh(case)
    _agree(poly_figures(mesh.points, mesh.polyhedra).summary(), foam.check_mesh(case))
    design = tmp_path / "twist.yaml"
    design.write_text(f"mesh: {case}\nsurface: wing\nbox: {{points: [6, 4, 2]}}\nchanges:\n  - twist: {{tip: 5}}\n")
    r = run_ffd("deform", design, "--json", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    out = tmp_path / "out" / "twist"
    after = foam.check_mesh(out)
    _agree(poly_figures(read_mesh(out).points, read_mesh(out).polyhedra).summary(), after)
    rep = json.loads(r.stdout)["quality"]["polyhedral"]["after"]
    assert rep["cells"] == after["cells"] and abs(rep["max_skewness"] - after["max_skewness"]) < 1e-6
    assert after["ok"], after["log"][-2000:]
    proc = foam.foam("potentialFoam", out, "-noFunctionObjects")
    assert proc.returncode == 0 and "FOAM FATAL" not in proc.stdout + proc.stderr
    model = DesignModel.from_file(design)
    assert np.abs(read_mesh(out).points[model.surface_ids] - model.surface_points()).max() <= 1e-12


def test_gmshtofoam_prism_layers_agree(tmp_path):
    from ffdcli.testing.gmsh_wings import CASES, smaller, wing_volume_mesh

    pytest.importorskip("gmsh")
    case = foam.gmsh_case(wing_volume_mesh(smaller(CASES["rect_z_bl_ff5"], 2.5)), tmp_path / "bl")
    mesh = read_mesh(case)
    assert mesh.polyhedra.shape_counts()["prisms"] > 0
    _agree(poly_figures(mesh.points, mesh.polyhedra).summary(), foam.check_mesh(case))
