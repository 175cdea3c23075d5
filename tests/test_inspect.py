"""``ffd inspect``: text and --json summaries, and clean failures."""

from __future__ import annotations

import json

import pytest
from conftest import assert_clean_failure, run_ffd, shared_file
from test_su2 import HEX2, TRI2D

from ffdcli.cli.inspect import inspect_mesh
from ffdcli.formats import read_mesh, write_mesh


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
    summary, text = inspect_mesh(p, ("Wing Lower-1",))
    # the marker lies in z = 0, spans x 0..2 and y 0..1: span x, chord y, thickness z
    assert summary["axes"] == {"chord": "y", "thickness": "z", "span": "x"}
    assert summary["root"] == "min" and summary["surface"] == ["Wing Lower-1"]
    assert "Wing Lower-1" in text and "span x" in text


def test_2d_mesh_text(tmp_path):
    p = tmp_path / "tri.su2"
    p.write_text(TRI2D)
    summary, text = inspect_mesh(p)
    assert summary["dim"] == 2 and summary["surface"] == ["airfoil"]
    assert summary["cells"] == {"triangle": 2, "quad": 1}
    assert "airfoil" in text and "farfield" in text and "2D" in text


def test_real_wing_text_and_json():
    src = shared_file("oneram6/mesh_ONERAM6_gmsh_coarse.su2")
    proc = run_ffd("inspect", src)
    assert proc.returncode == 0, proc.stderr
    for word in ("WING", "FARFIELD", "SYMMETRY", "16234", "8149", "tetra"):
        assert word in proc.stdout
    out, _ = inspect_mesh(src)              # the --json object, in process (one subprocess is enough)
    out = json.loads(json.dumps(out))
    assert out["surface"] == ["WING"] and out["markers"]["WING"] == {"elements": 16234, "points": 8149}
    assert out["axes"]["thickness"] == "z"


def test_vtu_inspect_same_markers(tmp_path):
    src = shared_file("su2/deformation__rae2822__mesh_RAE2822_turb_ffd.su2")
    write_mesh(read_mesh(src), tmp_path / "rae.vtu")
    a, _ = inspect_mesh(src)
    b, _ = inspect_mesh(tmp_path / "rae.vtu")
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
