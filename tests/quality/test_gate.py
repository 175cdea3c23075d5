"""The one quality gate end to end: ``ffd deform`` and ``ffd check`` agree, input problems are exit 2,
a mesh whose worst cell did not get worse passes (the ONERA M6 case)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import assert_clean_failure, file_hash, run_ffd, shared_file
from wingcase import write_design

from ffdcli.io.formats import read_mesh, write_mesh
from ffdcli.quality.metrics import cell_quality
from ffdcli.testing.wings import Planform, extruded_wing_mesh


@pytest.fixture(scope="module")
def wing(tmp_path_factory):
    """A small hexahedral wing mesh (span z) and its folder."""
    folder = tmp_path_factory.mktemp("gate")
    mesh = extruded_wing_mesh(Planform(semi_span=2.0, taper=0.7, le_sweep_deg=10.0), n_around=41, n_radial=9,
                              n_span=6)
    path = folder / "wing.su2"
    write_mesh(mesh, path)
    return path


def test_deform_and_check_report_the_same_counts_in_the_same_words(wing, tmp_path):
    (tmp_path / wing.name).write_bytes(wing.read_bytes())
    design = write_design(tmp_path, tmp_path / wing.name, [{"twist": {"tip": 8}}, {"chord": {"tip": 0.8}}])
    proc = run_ffd("deform", design, "--json")
    assert proc.returncode == 0, proc.stderr
    d = json.loads(proc.stdout)["quality"]
    out = tmp_path / "out_design.su2"
    c = json.loads(run_ffd("check", out, "--json").stdout)
    for key in ("cells", "inverted", "below_threshold", "threshold"):
        assert c[key] == d[key], key
    assert c["min_after"] == d["min_after"] and d["min_before"] is not None and c["min_before"] is None
    assert c["orthogonality"]["min_after"] == d["orthogonality"]["min_after"]
    assert c["orthogonality"]["below_min"] == d["orthogonality"]["below_min"]
    assert c["orthogonality"]["nodes"] == d["orthogonality"]["nodes"] > 0
    # the text: the counts of the mesh as written, under the same words
    text_d = run_ffd("deform", design, "--force").stdout
    text_c = run_ffd("check", out).stdout
    words = f"{d['cells']} cells: {d['inverted']} inverted or degenerate, {d['below_threshold']} below 0.05"
    assert words in text_d and words in text_c
    nodes = f"{d['orthogonality']['below_min']} nodes below 20 deg"
    assert nodes in text_d and nodes in text_c
    assert "before" in text_d and "before" not in text_c and "after" not in text_c


def test_a_degenerate_input_cell_is_exit_2_naming_it(wing, tmp_path):
    mesh = read_mesh(wing)
    pts = mesh.points.copy()
    hexes = mesh.cells[0].data
    # collapse one far-field cell: its node 6 onto its node 5 (an edge of zero length)
    far = int(np.argmax(np.linalg.norm(pts[hexes].mean(axis=1), axis=1)))
    pts[hexes[far, 6]] = pts[hexes[far, 5]]
    bad = mesh.with_points(pts)
    q = cell_quality(pts, bad.cells)
    assert q.min() == 0.0
    path = tmp_path / "bad.su2"
    write_mesh(bad, path)
    design = write_design(tmp_path, path, [{"twist": {"tip": 3}}])
    before = file_hash(path)
    proc = run_ffd("deform", design)
    assert_clean_failure(proc, 2, "bad.su2", "degenerate in the input mesh", "not of the design")
    first = int(np.flatnonzero(q <= 0)[np.argmin(q[q <= 0])])
    assert f"cell {first} (hexahedron)" in proc.stderr
    assert not (tmp_path / "out_design.su2").exists() and file_hash(path) == before
    # --force: deformed and written, with the warning; the input cells are not counted as the design's
    proc = run_ffd("deform", design, "--force", "--json")
    assert proc.returncode == 0, proc.stderr
    s = json.loads(proc.stdout)["quality"]
    assert s["input_degenerate"] >= 1 and s["inverted_by_design"] == 0 and "degenerate in the input" in proc.stderr
    # ffd check of the input names it too (exit 3: the check failed)
    proc = run_ffd("check", path)
    assert proc.returncode == 3 and f"cell {first} (hexahedron)" in proc.stderr


@pytest.mark.data
def test_onera_m6_chord_tip_whose_worst_cell_improves_is_not_refused(tmp_path):
    src = shared_file("oneram6/mesh_ONERAM6_gmsh_coarse.su2")
    (tmp_path / "m6.su2").write_bytes(src.read_bytes())
    design = write_design(tmp_path, tmp_path / "m6.su2", [{"chord": {"tip": 0.7}}])
    text = design.read_text().replace("surface: wing", "surface: WING")
    design.write_text(text)
    proc = run_ffd("deform", design, "--json")
    assert proc.returncode == 0, proc.stderr
    q = json.loads(proc.stdout)["quality"]
    assert q["inverted"] == 0 and q["min_after"] >= q["min_before"] and q["ok"]
