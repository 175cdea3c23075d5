"""The box with other frameworks' files (issue 4): Plot3D export/import, real meshes, odd surfaces."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import REPO, run_ffd, shared_file
from wingcase import write_surface_wing

from ffdcli.app.prepare import prepare_box
from ffdcli.io.formats.plot3d import read_plot3d
from ffdcli.settings import BoxSettings


def test_export_then_import_plot3d_gives_the_same_lattice(tmp_path):
    mesh = write_surface_wing(tmp_path, le_sweep_deg=20, taper=0.5)
    xyz = tmp_path / "wing.xyz"
    proc = run_ffd("box", str(mesh), "--export-plot3d", str(xyz), "--json")
    assert proc.returncode == 0, proc.stderr
    blocks = read_plot3d(xyz)
    assert len(blocks) == 1 and blocks[0].shape == (6, 8, 2, 3)
    auto = prepare_box(mesh, ["wing"], BoxSettings(points=(6, 8, 2)))
    np.testing.assert_allclose(blocks[0], auto.box.control_points, rtol=0, atol=1e-15)
    proc = run_ffd("box", str(mesh), "--from", str(xyz), "--json", "--lattice", str(tmp_path / "imp.vtk"))
    assert proc.returncode == 0, proc.stderr
    s = json.loads(proc.stdout)
    assert s["outside"] == 0 and s["lattice"] == [6, 8, 2]


@pytest.mark.parametrize("points", [(5, 2), (9, 2), (6, 3)])
def test_a_2d_lattice_exported_then_imported_is_the_same_lattice(tmp_path, points):
    """A 2D box written with --export-plot3d (one section: an (n, 1, l) block) read back with --from is
    the same lattice, every surface point inside: so a design made on one mesh can be applied to
    another mesh of the same airfoil with the same lattice (ADODG Case 1's evaluation on a finer
    level). Before the fix the single layer was taken for the chord (box.points [1, 2])."""
    mesh = shared_file("su2/optimization_euler__steady_naca0012__mesh_NACA0012_inv.su2")
    xyz = tmp_path / "airfoil.xyz"
    pts = ",".join(map(str, points))
    proc = run_ffd("box", str(mesh), "--points", pts, "--export-plot3d", str(xyz), "--json",
                   "--cache-dir", str(tmp_path), "--lattice", str(tmp_path / "a.vtk"))
    assert proc.returncode == 0, proc.stderr
    block = read_plot3d(xyz)[0]
    assert block.shape == (points[0], 1, points[1], 3)
    auto = prepare_box(mesh, ["airfoil"], BoxSettings(points=points), cache_dir=tmp_path)
    imported = prepare_box(mesh, ["airfoil"], BoxSettings(file=str(xyz)), cache_dir=tmp_path)
    np.testing.assert_allclose(imported.box.control_points, auto.box.control_points, rtol=0, atol=1e-15)
    proc = run_ffd("box", str(mesh), "--from", str(xyz), "--json", "--cache-dir", str(tmp_path),
                   "--lattice", str(tmp_path / "b.vtk"))
    assert proc.returncode == 0, proc.stderr
    s = json.loads(proc.stdout)
    assert s["outside"] == 0 and s["lattice"] == list(points)


def test_imported_lattice_point_outside_is_reported_not_snapped(tmp_path):
    mesh = write_surface_wing(tmp_path)
    auto = prepare_box(mesh, ["wing"], BoxSettings(points=(6, 8, 2)))
    P = auto.box.control_points.copy()
    P[..., 2] *= 0.8                      # the imported box covers only 80 % of the span
    from ffdcli.io.formats.plot3d import write_plot3d

    write_plot3d(tmp_path / "short.xyz", [P])
    proc = run_ffd("box", str(mesh), "--from", str(tmp_path / "short.xyz"), "--json")
    assert proc.returncode == 0, proc.stderr          # an imported box may leave points out: reported
    s = json.loads(proc.stdout)
    assert s["outside"] > 0 and "outside" in proc.stderr


@pytest.mark.parametrize("name", ["mach_wing__ffd.xyz", "Onera_M6_Wing__FFD__wingFFD.xyz",
                                  "CRM_Wing__FFD__wingFFD.xyz", "mach_airfoil__ffd.xyz"])
def test_real_pygeo_ffd_files_read(name):
    path = shared_file(f"reference-ffd/{name}")
    blocks = read_plot3d(path)
    assert blocks and all(b.ndim == 4 and b.shape[-1] == 3 and np.isfinite(b).all() for b in blocks)


def test_box_on_a_real_onera_m6_mesh(tmp_path):
    mesh = shared_file("oneram6/mesh_ONERAM6_gmsh_coarse.su2")
    proc = run_ffd("box", str(mesh), "--surface", "WING", "--json", "--cache-dir", str(tmp_path),
                   "--lattice", str(tmp_path / "m6.vtk"), "--sections", "xz")
    assert proc.returncode == 0, proc.stderr
    s = json.loads(proc.stdout)
    assert s["outside"] == 0 and s["axes"] == {"chord": "x", "thickness": "z", "span": "y"}
    assert s["root"] == "min"


def test_box_on_a_sphere_guesses_axes_with_a_warning(tmp_path):
    from ffdcli.io.formats import write_mesh
    from ffdcli.mesh import CellBlock, Mesh

    th, ph = np.meshgrid(np.linspace(0.05, np.pi - 0.05, 20), np.linspace(0, 2 * np.pi, 41)[:-1], indexing="ij")
    pts = np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], -1).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(19), np.arange(40), indexing="ij")
    a = i * 40 + j
    b = i * 40 + (j + 1) % 40
    quads = np.stack([a, b, b + 40, a + 40], -1).reshape(-1, 4)
    write_mesh(Mesh(points=pts, dim=3, markers={"ball": [CellBlock("quad", quads)]}), tmp_path / "ball.su2")
    proc = run_ffd("box", str(tmp_path / "ball.su2"), "--json")
    assert proc.returncode == 0, proc.stderr
    assert "not clearly wing-shaped: axes guessed" in proc.stderr
    assert json.loads(proc.stdout)["outside"] == 0


def test_left_wing_dihedral_along_minus_y(tmp_path):
    """A swept tapered left wing with dihedral, span along -y: root detected at y max (0)."""
    mesh = write_surface_wing(tmp_path, le_sweep_deg=25, taper=0.4, dihedral_deg=6, sections="xz",
                              span_sign=-1.0)
    proc = run_ffd("box", str(mesh), "--json")
    assert proc.returncode == 0, proc.stderr
    s = json.loads(proc.stdout)
    assert s["outside"] == 0 and s["root"] == "max" and s["axes"]["span"] == "y"
    assert s["residual"] <= 1e-10 * 3


def test_bad_box_inputs(tmp_path):
    from conftest import assert_clean_failure

    mesh = write_surface_wing(tmp_path)
    assert_clean_failure(run_ffd("box", str(mesh), "--surface", "nope"), 2, "nope", "wing")
    assert_clean_failure(run_ffd("box", str(mesh), "--points", "1,1,1"), 2)
    assert_clean_failure(run_ffd("box", str(mesh), "--points", "4,4,2", "--degree", "4,3,1"), 2)
    assert_clean_failure(run_ffd("box", str(REPO / "nothing.su2")), 2, "nothing.su2")


@pytest.mark.parametrize("name,marker", [
    ("optimization_euler__steady_naca0012__mesh_NACA0012_inv.su2", None),
    ("optimization_rans__steady_rae2822__mesh_RAE2822_turb.su2", None),
    ("disc_adj_rans__naca0012__naca0012_FFD.su2", "AIRFOIL"),
])
def test_box_on_real_2d_su2_meshes(tmp_path, name, marker):
    """SU2's own test meshes: the automatic 2D box contains the airfoil (0 outside, 1e-10 residual)."""
    mesh = shared_file(f"su2/{name}")
    args = ["box", str(mesh), "--json", "--cache-dir", str(tmp_path), "--lattice", str(tmp_path / "l.vtk")]
    if marker:
        args += ["--surface", marker]
    proc = run_ffd(*args)
    assert proc.returncode == 0, proc.stderr
    s = json.loads(proc.stdout)
    assert s["outside"] == 0 and s["lattice"] == [6, 5]
    assert s["residual"] <= 1e-10
    assert s["axes"]["chord"] == "x" and s["axes"]["thickness"] == "y"


def test_deform_a_real_2d_su2_mesh_keeps_its_markers_and_updates_its_ffd_section(tmp_path):
    """A real SU2 file with SU2's own FFD section: twisting writes a valid mesh, every byte of the
    markers is unchanged, and SU2's section is brought up to date (issue 20: copied unchanged, it
    would make SU2_DEF restore the original airfoil; tests/io/test_su2_ffd.py checks its contents)."""
    import yaml

    mesh = shared_file("su2/disc_adj_rans__naca0012__naca0012_FFD.su2")
    d = tmp_path / "d.yaml"
    d.write_text(yaml.safe_dump({"mesh": str(mesh), "surface": "AIRFOIL", "changes": [{"twist": 3}],
                                 "output": {"mesh": str(tmp_path / "o.su2"), "lattice": str(tmp_path / "o.vtk")}}))
    proc = run_ffd("deform", str(d), "--json", "--cache-dir", str(tmp_path))
    assert proc.returncode == 0, proc.stderr
    s = json.loads(proc.stdout)
    assert s["quality"]["inverted"] == 0
    a, b = mesh.read_bytes(), (tmp_path / "o.su2").read_bytes()
    markers = a[a.index(b"NMARK"):a.index(b"FFD_NBOX")]
    assert markers in b and b.index(markers) + len(markers) == b.index(b"FFD_NBOX")
    assert s["su2_ffd"]["boxes"][0]["tag"] == "AIRFOIL_BOX"
    assert b[b.index(b"FFD_NBOX"):] != a[a.index(b"FFD_NBOX"):]        # not the stale section
