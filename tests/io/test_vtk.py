"""VTU and legacy VTK: marker convention (ffd_marker + names in field data), round trips, bad files."""

from __future__ import annotations

import meshio
import numpy as np
import pytest
from conftest import assert_clean_failure, run_ffd, shared_file

from ffdcli.errors import InputError
from ffdcli.io.formats import read_mesh, su2, vtk, write_mesh
from ffdcli.mesh import CellBlock, Mesh


def two_hex_mesh(rng=None) -> Mesh:
    """Two hexes along x; markers with a blank, a percent sign and mixed face types."""
    g = np.array([[x, y, z] for z in (0, 1) for y in (0, 1) for x in (0, 1, 2)], dtype=float)
    if rng is not None:
        g = g + 1e-3 * rng.random(g.shape) / 3          # digits that need all 17 to round-trip
    hexes = [[0, 1, 4, 3, 6, 7, 10, 9], [1, 2, 5, 4, 7, 8, 11, 10]]
    return Mesh(points=g, dim=3, cells=[CellBlock("hexahedron", hexes)],
                markers={"Wing lower 1": [CellBlock("quad", [[0, 3, 4, 1], [1, 4, 5, 2]])],
                         "far%field": [CellBlock("quad", [[6, 7, 10, 9]])],
                         "tip": [CellBlock("triangle", [[2, 5, 8]]), CellBlock("quad", [[5, 11, 10, 4]])]})


def same(a: Mesh, b: Mesh, exact=True):
    if exact:
        np.testing.assert_array_equal(a.points, b.points)
    else:
        # legacy ASCII: meshio prints 16 significant digits -> relative error <= ~1e-16 per coordinate
        np.testing.assert_allclose(a.points, b.points, rtol=2e-16, atol=1e-300)
    assert a.dim == b.dim
    assert [(c.type, c.data.tolist()) for c in a.cells] == [(c.type, c.data.tolist()) for c in b.cells]
    assert list(a.markers) == list(b.markers)
    for k in a.markers:
        assert [(c.type, c.data.tolist()) for c in a.markers[k]] == \
            [(c.type, c.data.tolist()) for c in b.markers[k]]


@pytest.mark.parametrize("ext", ["vtu", "vtk"])
def test_round_trip_keeps_markers(tmp_path, ext):
    m = two_hex_mesh(np.random.default_rng(3))
    write_mesh(m, tmp_path / f"m.{ext}")
    back = read_mesh(tmp_path / f"m.{ext}")
    assert back.format == ext
    same(m, back, exact=ext == "vtu")


def test_file_follows_documented_convention(tmp_path):
    m = two_hex_mesh()
    write_mesh(m, tmp_path / "m.vtu")
    raw = meshio.read(tmp_path / "m.vtu")
    assert {k: v.ravel().tolist() for k, v in raw.field_data.items()} == \
        {"Wing lower 1": [1, 2], "far%field": [2, 2], "tip": [3, 2]}
    tags = np.concatenate(raw.cell_data[vtk.MARKER_ARRAY]).tolist()
    assert tags == [0, 0, 1, 1, 2, 3, 3]


def test_vtk_reads_names_and_tags(tmp_path):
    """VTK itself (through pyvista) sees the field data names and the cell array of both formats."""
    pv = pytest.importorskip("pyvista")
    m = two_hex_mesh()
    for ext in ("vtu", "vtk"):
        write_mesh(m, tmp_path / f"m.{ext}")
        g = pv.read(tmp_path / f"m.{ext}")
        assert sorted(g.field_data.keys()) == sorted(m.markers)
        assert g.cell_data[vtk.MARKER_ARRAY].tolist() == [0, 0, 1, 1, 2, 3, 3]


def test_plain_vtu_gives_volume_cells_and_no_markers(tmp_path):
    pts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=float)
    cells = [("triangle", [[0, 1, 2]]), ("tetra", [[0, 1, 2, 3]])]
    meshio.write(tmp_path / "plain.vtu", meshio.Mesh(pts, cells))
    m = read_mesh(tmp_path / "plain.vtu")
    assert m.dim == 3 and m.markers == {}
    assert [(b.type, len(b)) for b in m.cells] == [("tetra", 1)]


def test_2d_mesh_round_trip(tmp_path):
    pts = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], dtype=float)
    m = Mesh(points=pts, dim=2, cells=[CellBlock("triangle", [[0, 1, 2], [0, 2, 3]])],
             markers={"airfoil": [CellBlock("line", [[0, 1]])],
                      "farfield": [CellBlock("line", [[2, 3], [3, 0]])]})
    for ext in ("vtu", "vtk"):
        write_mesh(m, tmp_path / f"m.{ext}")
        same(m, read_mesh(tmp_path / f"m.{ext}"))


def test_su2_to_vtu_to_su2(tmp_path):
    src = shared_file("su2/deformation__brick_pyra__mesh_brick_pyra_ffd.su2")
    m = su2.read(src)
    write_mesh(m, tmp_path / "m.vtu")
    back = read_mesh(tmp_path / "m.vtu")
    same(m, back)
    write_mesh(back, tmp_path / "again.su2")             # from-scratch SU2 writer
    same(m, su2.read(tmp_path / "again.su2"))


def test_moved_points_are_written(tmp_path):
    m = two_hex_mesh()
    pts = m.points * 1.1
    write_mesh(m, tmp_path / "m.vtu", pts)
    np.testing.assert_array_equal(read_mesh(tmp_path / "m.vtu").points, pts)


@pytest.mark.parametrize("ext,content", [
    ("vtu", b""),
    ("vtu", b"<VTKFile type='UnstructuredGrid'><UnstructuredGrid><Piece NumberOfPoints="),
    ("vtu", b"this is not xml\n"),
    ("vtk", b"# vtk DataFile Version 4.2\ntitle\nASCII\nDATASET UNSTRUCTURED_GRID\nPOINTS 4 double\n0 0\n"),
])
def test_bad_files_raise_input_error(tmp_path, ext, content):
    p = tmp_path / f"bad.{ext}"
    p.write_bytes(content)
    with pytest.raises(InputError) as err:
        read_mesh(p)
    assert str(p) in str(err.value) and "\n" not in str(err.value)
    proc = run_ffd("inspect", p)
    assert_clean_failure(proc, 2, str(p))
    assert len(proc.stderr.strip().splitlines()) == 1


def test_write_is_atomic_on_failure(tmp_path, monkeypatch):
    m = two_hex_mesh()
    out = tmp_path / "m.vtu"
    out.write_text("old")

    def boom(*a, **k):
        raise RuntimeError("disk full")

    monkeypatch.setattr(meshio, "write", boom)
    with pytest.raises(InputError, match="disk full"):
        write_mesh(m, out)
    assert out.read_text() == "old"
    assert [p.name for p in tmp_path.iterdir()] == ["m.vtu"]
