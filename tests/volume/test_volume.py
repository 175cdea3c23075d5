"""The volume mesh follows the wing (issue 6): no inverted cells, far field fixed, symmetry nodes on
their plane, surface nodes exactly where the FFD put them; an absurd change is refused (exit 3)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import REPO, assert_clean_failure, file_hash, run_ffd

from ffdcli.app.deformation import deform
from ffdcli.app.run import load_run
from ffdcli.design import load_design

SAMPLES = REPO / "samples"

CASES = {
    "twist15": [{"twist": {"tip": 15}}],
    "span110": [{"span": 1.1}],
    "dihedral+5": [{"dihedral": 5}],
    "dihedral-5": [{"dihedral": -5}],
    "sweep+5": [{"sweep": 5}],
    "random1.5%": [{"shape": {"random": 0.015, "seed": 3}}],
}
MESHES = {"rect_wing.su2": "xy", "crm_wing.su2": "xz"}


def design_for(tmp_path, mesh, changes, name="d.yaml", volume=None):
    import yaml

    data = {"mesh": str(SAMPLES / mesh), "surface": "wing",
            "box": {"points": [6, 8, 2], "sections": MESHES[mesh]}, "changes": changes,
            "output": {"mesh": str(tmp_path / ("out" + (SAMPLES / mesh).suffix)),
                       "lattice": str(tmp_path / "lat.vtk")}}
    if volume:
        data["volume"] = volume
    p = tmp_path / name
    p.write_text(yaml.safe_dump(data))
    return p


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """One prepared run per bundled wing (box from the cache after the first build)."""
    tmp = tmp_path_factory.mktemp("vol")
    out = {}
    for mesh in MESHES:
        out[mesh] = load_run(load_design(design_for(tmp, mesh, [{"span": 1.0}])), cache_dir=tmp)
    return out


@pytest.mark.slow
@pytest.mark.parametrize("mesh", list(MESHES))
@pytest.mark.parametrize("case", list(CASES))
def test_volume_follows_without_inverting(runs, tmp_path, mesh, case):
    from ffdcli.design import build_changes

    run = runs[mesh]
    design = load_design(design_for(tmp_path, mesh, CASES[case]))
    run.design = design
    run.changes = build_changes(design, *run.box.shape, run.box.dim)
    res = deform(run)
    mesh_obj, surf = run.prep.mesh, run.prep.surface
    assert res.quality.n_inverted == 0, res.quality.describe_worst()
    # surface nodes: exactly X0 + B (P' - P0)
    expect = surf.points + run.surface_displacement(res.lattice)
    np.testing.assert_array_equal(res.points[surf.ids], expect)
    # far field fixed, bit for bit
    far = mesh_obj.marker_point_ids("farfield")
    far = np.setdiff1d(far, surf.ids)
    np.testing.assert_array_equal(res.points[far], mesh_obj.points[far])
    # symmetry nodes stay on their plane (span coordinate 0 exactly)
    sym = np.setdiff1d(mesh_obj.marker_point_ids("symmetry"), surf.ids)
    span_axis = run.box.axes.span
    assert np.abs(res.points[sym, span_axis]).max() <= 1e-12
    # something did move in the volume
    vol = np.setdiff1d(np.arange(mesh_obj.n_points), np.r_[surf.ids, far, sym])
    assert np.abs(res.points[vol] - mesh_obj.points[vol]).max() > 1e-4


def test_absurd_twist_is_refused_and_nothing_written(tmp_path):
    d = design_for(tmp_path, "rect_wing.su2", [{"twist": {"tip": 170}}])
    mesh = SAMPLES / "rect_wing.su2"
    before = file_hash(mesh)
    proc = run_ffd("deform", str(d), "--cache-dir", str(tmp_path))
    assert_clean_failure(proc, 3, "quality")
    assert not (tmp_path / "out.su2").exists() and not (tmp_path / "lat.vtk").exists()
    assert file_hash(mesh) == before
    # --force writes it anyway, and says so
    proc = run_ffd("deform", str(d), "--cache-dir", str(tmp_path), "--force", "--json")
    assert proc.returncode == 0, proc.stderr
    s = json.loads(proc.stdout)
    assert s["quality"]["inverted"] > 0 and (tmp_path / "out.su2").exists()


def test_volume_none_moves_only_the_surface(tmp_path):
    d = design_for(tmp_path, "rect_wing.su2", [{"dihedral": 3}], volume={"method": "none"})
    run = load_run(load_design(d), cache_dir=tmp_path)
    res = deform(run)
    others = np.setdiff1d(np.arange(run.prep.mesh.n_points), run.prep.surface.ids)
    np.testing.assert_array_equal(res.points[others], run.prep.mesh.points[others])
    assert res.volume_method == "none"


def test_ffd_check_on_a_good_mesh(tmp_path):
    proc = run_ffd("check", str(SAMPLES / "naca0012_2d.su2"), "--json")
    assert proc.returncode == 0, proc.stderr
    s = json.loads(proc.stdout)
    assert s["inverted"] == 0 and s["cells"] == 6400
