"""SU2's own FFD section and surface-positions file: nothing stale is ever written (issue 20)."""

from __future__ import annotations

import numpy as np
import pytest
import yaml
from conftest import file_hash, run_ffd, shared_file

from ffdcli.io.formats import read_mesh, su2_ffd, write_mesh
from ffdcli.io.formats.su2_surface import read_surface_file, write_surface_file

WITH_FFD = [
    "su2/deformation__rae2822__mesh_RAE2822_turb_ffd.su2",          # 2D, Bezier 14 x 1
    "su2/deformation__brick_tets__mesh_brick_tets_ffd.su2",         # 3D, Bezier 4 x 4 x 1
    "su2/multiple_ffd__naca0012__mesh_NACA0012_multiFFD.su2",       # two boxes
    "su2/disc_adj_rans__naca0012__naca0012_FFD.su2",                # 10 x 10, corners clockwise
    "su2/optimization_euler__steady_inverse_design__mesh_NACA0012_inv_FFD.su2",   # no FFD_BLENDING line
]


def _section(path):
    raw = path.read_bytes()
    at = su2_ffd.find_section(raw)
    m = read_mesh(path)
    return m, su2_ffd.parse_section(raw[at:].decode(), 3 if m.dim == 3 else 2, path=path)


@pytest.mark.parametrize("rel", WITH_FFD)
def test_reembedding_the_original_surface_gives_su2s_own_parameters(rel):
    """The oracle for the inversion: SU2 wrote these parameters for these nodes; we find them again."""
    m, sec = _section(shared_file(rel))
    new, report = su2_ffd.refresh(sec, m.points)
    assert report["outside"] == 0
    for old, box in zip(sec.boxes, new.boxes, strict=True):
        np.testing.assert_array_equal(box.surface_ids, old.surface_ids)
        np.testing.assert_allclose(box.surface_params, np.clip(old.surface_params, 1e-10, 1 - 1e-10),
                                   atol=1e-9)
        X = su2_ffd.evaluate(box, box.surface_params)
        np.testing.assert_allclose(X[:, :2], m.points[box.surface_ids, :2], atol=1e-12)


def test_parse_format_round_trip():
    m, sec = _section(shared_file(WITH_FFD[2]))
    text = su2_ffd.format_section(sec, 2)
    again = su2_ffd.parse_section(text, 2)
    for a, b in zip(sec.boxes, again.boxes, strict=True):
        assert (a.tag, a.degree, a.blending) == (b.tag, b.degree, b.blending)
        np.testing.assert_array_equal(a.control_points, b.control_points)
        np.testing.assert_array_equal(a.surface_params, b.surface_params)      # %.15e of SU2's own values
        assert a.surface_tags == b.surface_tags


def test_bspline_uniform_box_round_trip():
    """A B-spline box (orders 3, 2, 2 on a curved net): points made from parameters are inverted back."""
    rng = np.random.default_rng(3)
    n = (5, 4, 2)
    idx = np.array([(i, j, k) for i in range(n[0]) for j in range(n[1]) for k in range(n[2])])
    cp = idx / (np.array(n) - 1.0) * [2.0, 1.0, 0.3] + rng.uniform(-0.03, 0.03, size=(len(idx), 3))
    params = rng.uniform(0.05, 0.95, size=(200, 3))
    box = su2_ffd.Su2FfdBox(tag="B", level=0, degree=(4, 3, 1), blending="BSPLINE_UNIFORM",
                            bspline_order=(3, 2, 2), parents=(), children=(), corners=np.zeros((8, 3)),
                            control_index=idx, control_points=cp, surface_tags=("w",) * 200,
                            surface_ids=np.arange(200), surface_params=np.full((200, 3), 0.5))
    X = su2_ffd.evaluate(box, params)
    section = su2_ffd.Su2FfdSection(nlevel=1, boxes=(box,))
    new, report = su2_ffd.refresh(section, X)
    assert report["outside"] == 0
    np.testing.assert_allclose(new.boxes[0].surface_params, params, atol=1e-9)
    text = su2_ffd.format_section(new, 3)
    assert "BSPLINE_ORDER_I= 3" in text and "FFD_DEGREE_K= 1" in text


def _deform(tmp_path, mesh, marker, changes, points, *, extra=""):
    design = tmp_path / "d.yaml"
    design.write_text(yaml.safe_dump({"mesh": str(mesh), "surface": marker, "box": {"points": points},
                                      "changes": changes,
                                      "output": {"mesh": "out.su2", "lattice": "out_lattice.vtk"}}))
    return run_ffd("deform", design, "--cache-dir", tmp_path, "--json", *extra.split(), cwd=tmp_path)


def test_deformed_rae2822_section_matches_the_deformed_surface(tmp_path):
    src = shared_file(WITH_FFD[0])
    proc = _deform(tmp_path, src, "AIRFOIL", [{"shape": {"upper": [0, 0.002, 0.003, 0.002, 0, 0]}}], [6, 5])
    assert proc.returncode == 0, proc.stderr
    import json

    summary = json.loads(proc.stdout)
    assert summary["su2_ffd"]["boxes"][0]["points"] + summary["su2_ffd"]["outside"] == 192
    out = tmp_path / "out.su2"
    m_out, sec_out = _section(out)
    m_in, sec_in = _section(src)
    box, old = sec_out.boxes[0], sec_in.boxes[0]
    moved = np.linalg.norm(m_out.points - m_in.points, axis=1)
    assert moved.max() > 1e-3
    # what SU2_DEF computes with a zero design change: the box at the stored parameters = ffd's surface
    X = su2_ffd.evaluate(box, box.surface_params)
    np.testing.assert_allclose(X[:, :2], m_out.points[box.surface_ids, :2], atol=1e-12)
    # and not the original surface (the stale section of issue 20)
    Xold = su2_ffd.evaluate(old, old.surface_params)
    assert np.abs(Xold[:, :2] - m_out.points[old.surface_ids, :2]).max() > 1e-3
    np.testing.assert_array_equal(box.control_points, old.control_points)     # the box itself is kept


def test_no_change_keeps_the_file_bit_for_bit(tmp_path):
    src = shared_file(WITH_FFD[0])
    proc = _deform(tmp_path, src, "AIRFOIL", [], [6, 5])
    assert proc.returncode == 0, proc.stderr
    assert file_hash(tmp_path / "out.su2") == file_hash(src)


def test_nodes_leaving_the_box_are_left_out_and_reported(tmp_path):
    """A 3-degree twist moves the trailing edge out of RAE2822's tight SU2 box (y = +-0.07)."""
    src = shared_file(WITH_FFD[0])
    proc = _deform(tmp_path, src, "AIRFOIL", [{"twist": 3}], [6, 5])
    assert proc.returncode == 0, proc.stderr
    assert "now outside the mesh's own SU2 FFD box" in proc.stderr
    _, sec = _section(tmp_path / "out.su2")
    assert 0 < len(sec.boxes[0].surface_ids) < 192


def test_3d_brick_box(tmp_path):
    m, sec = _section(shared_file(WITH_FFD[1]))
    pts = m.points.copy()
    ids = sec.boxes[0].surface_ids
    pts[ids, 2] += 0.01 * np.sin(np.pi * pts[ids, 0]) * np.sin(np.pi * pts[ids, 1])
    notes = write_mesh(m, tmp_path / "bump.su2", pts)
    assert notes["su2_ffd"]["outside"] == 0
    m2, sec2 = _section(tmp_path / "bump.su2")
    b = sec2.boxes[0]
    np.testing.assert_allclose(su2_ffd.evaluate(b, b.surface_params), m2.points[b.surface_ids], atol=1e-12)


def test_surface_file_format_and_round_trip(tmp_path):
    rng = np.random.default_rng(0)
    ids = rng.permutation(50)[:20]
    pts = rng.normal(size=(20, 3)) / 3.0
    write_surface_file(tmp_path / "s3.dat", ids, pts, 3)
    rows = (tmp_path / "s3.dat").read_text().splitlines()
    assert len(rows) == 20 and all(len(r.split("\t")) == 4 for r in rows)
    assert rows[0].split("\t")[0] == str(ids[0])
    back_ids, back = read_surface_file(tmp_path / "s3.dat", 3)
    np.testing.assert_array_equal(back_ids, ids)
    np.testing.assert_array_equal(back, pts)                       # %.17g: exact
    pts[:, 2] = 0.0
    write_surface_file(tmp_path / "s2.dat", ids, pts, 2)
    assert all(len(r.split("\t")) == 3 for r in (tmp_path / "s2.dat").read_text().splitlines())
    np.testing.assert_array_equal(read_surface_file(tmp_path / "s2.dat", 2)[1], pts)


def test_deform_writes_the_surface_file_of_the_deformed_surface(tmp_path):
    src = shared_file(WITH_FFD[0])
    proc = _deform(tmp_path, src, "AIRFOIL", [{"twist": 1}], [6, 5], extra="--surface-file surf.dat")
    assert proc.returncode == 0, proc.stderr
    ids, pts = read_surface_file(tmp_path / "surf.dat", 2)
    m_out = read_mesh(tmp_path / "out.su2")
    m_in = read_mesh(src)
    wing = np.unique(np.concatenate([b.data.ravel() for b in m_in.markers["AIRFOIL"]]))
    np.testing.assert_array_equal(np.sort(ids), wing)
    np.testing.assert_array_equal(pts, m_out.points[ids])
