"""``ffd inspect``: text and --json summaries, and clean failures."""

from __future__ import annotations

import json

import pytest
from conftest import assert_clean_failure, run_ffd, shared_file
from test_su2 import HEX2, TRI2D

from ffdcli.app.inspection import inspect_mesh
from ffdcli.io.formats import read_mesh, write_mesh


def test_json_summary_of_hand_made_mesh(tmp_path):
    p = tmp_path / "hex.su2"
    p.write_text(HEX2)
    proc = run_ffd("inspect", p, "--json")
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout)
    assert set(out) >= {"file", "format", "dim", "points", "cells", "markers", "bounds", "axes", "root",
                        "surface"}
    assert out["file"] == str(p) and out["format"] == "su2" and out["dim"] == 3
    assert out["points"] == 12 and out["cells"] == {"hexahedron": 2}
    assert out["markers"] == {"Wing Lower-1": {"elements": 2, "points": 6},
                              "far": {"elements": 1, "points": 4},
                              "tip_tri": {"elements": 2, "points": 4}}
    assert out["bounds"] == {"min": [0, 0, 0], "max": [2, 1, 1]}
    # the markers "Wing Lower-1" and "tip_tri" both could be the wing: no guess
    assert out["surface"] is None and out["axes"] is None and out["root"] is None


def test_surface_option_gives_axes(tmp_path):
    p = tmp_path / "hex.su2"
    p.write_text(HEX2)
    summary, text = inspect_mesh(p, ("Wing Lower-1",)).report()
    # the marker lies in z = 0, spans x 0..2 and y 0..1: span x, chord y, thickness z
    assert summary["axes"] == {"chord": "y", "thickness": "z", "span": "x"}
    assert summary["root"] == "min" and summary["surface"] == ["Wing Lower-1"]
    assert "Wing Lower-1" in text and "span x" in text


def test_2d_mesh_text(tmp_path):
    p = tmp_path / "tri.su2"
    p.write_text(TRI2D)
    summary, text = inspect_mesh(p).report()
    assert summary["dim"] == 2 and summary["surface"] == ["airfoil"]
    assert summary["cells"] == {"triangle": 2, "quad": 1}
    assert "airfoil" in text and "farfield" in text and "2D" in text


def test_real_wing_text_and_json():
    src = shared_file("oneram6/mesh_ONERAM6_gmsh_coarse.su2")
    proc = run_ffd("inspect", src)
    assert proc.returncode == 0, proc.stderr
    for word in ("WING", "FARFIELD", "SYMMETRY", "16234", "8149", "tetra"):
        assert word in proc.stdout
    out, _ = inspect_mesh(src).report()              # the --json object, in process (one subprocess is enough)
    out = json.loads(json.dumps(out))
    assert out["surface"] == ["WING"] and out["markers"]["WING"] == {"elements": 16234, "points": 8149}
    assert out["axes"]["thickness"] == "z"


def test_vtu_inspect_same_markers(tmp_path):
    src = shared_file("su2/deformation__rae2822__mesh_RAE2822_turb_ffd.su2")
    write_mesh(read_mesh(src), tmp_path / "rae.vtu")
    a, _ = inspect_mesh(src).report()
    b, _ = inspect_mesh(tmp_path / "rae.vtu").report()
    assert b["format"] == "vtu"
    for key in ("dim", "points", "cells", "markers", "bounds", "axes", "root", "surface"):
        assert a[key] == b[key], key


@pytest.mark.parametrize("name,content,expect", [
    ("missing.su2", None, "no such file"),
    ("mesh.stl", "solid\n", "unsupported mesh extension"),
    ("empty.su2", "", "empty"),
])
def test_clean_failures(tmp_path, name, content, expect):
    p = tmp_path / name
    if content is not None:
        p.write_text(content)
    proc = run_ffd("inspect", p)
    assert_clean_failure(proc, 2, str(p), expect)
    assert len(proc.stderr.strip().splitlines()) == 1


def test_unknown_surface_lists_markers(tmp_path):
    p = tmp_path / "hex.su2"
    p.write_text(HEX2)
    proc = run_ffd("inspect", p, "--surface", "wing", "--json")
    assert_clean_failure(proc, 2, "'wing'", "Wing Lower-1, far, tip_tri")
    assert json.loads(proc.stdout)["exit_code"] == 2


# --------------------------------------------------------------------------------------------------
# Issue 19: a 3D surface mesh is 3D with the box's axes; a one-cell-thick extruded airfoil is named
# --------------------------------------------------------------------------------------------------

def _box_axes(path, surface=None):
    from ffdcli.app.prepare import prepare_box

    prep = prepare_box(path, surface, use_cache=False)
    return prep.box.axes.as_dict(), prep.box.axes.root, prep.warnings


@pytest.mark.parametrize("sections", ["xy", "xz", "zx"])
def test_surface_mesh_is_3d_with_the_axes_of_ffd_box(tmp_path, sections):
    from wingcase import write_surface_wing

    p = write_surface_wing(tmp_path, sections=sections, semi_span=3.0, root_chord=1.0, taper=0.6,
                           le_sweep_deg=20.0)
    summary, text = inspect_mesh(p).report()
    assert summary["dim"] == 3 and summary["surface_mesh"] is True
    axes, root, _ = _box_axes(p)
    assert summary["axes"] == axes and summary["root"] == root
    assert "3D surface mesh" in text and "span" in text


def test_multizone_cgns_wing_surface_is_3d_with_the_box_axes():
    src = shared_file("cgns/aero__meshing__volume__wing.cgns")
    summary, text = inspect_mesh(src).report()
    assert summary["dim"] == 3 and summary["surface_mesh"] is True and "2D" not in text.splitlines()[0]
    axes, root, _ = _box_axes(src)
    assert summary["axes"] == axes == {"chord": "x", "thickness": "y", "span": "z"}
    assert summary["root"] == root == "min"


def _extruded_airfoil(tmp_path, merge: bool):
    """A one-cell-thick extruded NACA0012 (span z 0..1); ``merge``: both side planes one marker."""
    from ffdcli.testing.wings import Planform, extruded_wing_mesh

    m = extruded_wing_mesh(Planform(semi_span=1.0, root_chord=1.0, sections="xy"), n_around=41,
                           n_radial=9, n_span=2)
    if merge:
        m.markers["sym"] = m.markers.pop("symmetry") + m.markers.pop("side")
    p = tmp_path / ("merged.su2" if merge else "sides.su2")
    write_mesh(m, p)
    return p


@pytest.mark.parametrize("merge", [True, False])
def test_one_cell_thick_extruded_airfoil_is_named_in_inspect_box_and_deform(tmp_path, merge):
    from wingcase import write_design

    p = _extruded_airfoil(tmp_path, merge)
    summary, text = inspect_mesh(p, ("wing",)).report()
    side = "sym" if merge else "symmetry"
    assert len(summary["warnings"]) == 1
    w = summary["warnings"][0]
    assert "one cell thick along z" in w and side in w and "box.sections: xy" in w
    assert "volume.sliding" not in w       # both side planes in one marker slide too, each in its plane
    _, _, warnings = _box_axes(p, ["wing"])
    assert any("one cell thick" in x for x in warnings)
    proc = run_ffd("box", p, "--surface", "wing", "--sections", "xy", "--lattice", tmp_path / "l.vtk")
    assert proc.returncode == 0 and "one cell thick along z" in proc.stderr, proc.stderr
    design = write_design(tmp_path, p, [{"twist": [1.0, 1.0]}], points=(6, 2, 2), sections="xy")
    proc = run_ffd("deform", design)
    assert proc.returncode == 0 and "one cell thick along z" in proc.stderr, proc.stderr


def test_real_extruded_airfoil_cgns_is_named():
    src = shared_file("cgns/airfoil__analysis__n0012.cgns")
    summary, _ = inspect_mesh(src).report()
    (w,) = summary["warnings"]
    assert "one cell thick along z" in w and "Sym" in w and "box.sections: xy" in w


def test_volume_meshes_get_no_extrusion_warning():
    from conftest import SAMPLES

    summary, _ = inspect_mesh(SAMPLES / "rect_wing.su2").report()
    assert summary["warnings"] == []
