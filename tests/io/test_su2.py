"""SU2 reader and writer: small hand-written meshes, real SU2 test-case files, bad inputs."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import assert_clean_failure, file_hash, run_ffd, shared_file

from ffdcli.errors import InputError
from ffdcli.io.formats import read_mesh, su2, write_mesh
from ffdcli.mesh import CellBlock, Mesh

# Two hexahedra side by side (x in 0..2), markers with awkward but legal names.
HEX2 = """\
% two hexes
NDIME= 3
NELEM= 2
12 0 1 4 3 6 7 10 9 0
12 1 2 5 4 7 8 11 10 1
NPOIN= 12
0 0 0 0
1 0 0 1
2 0 0 2
0 1 0 3
1 1 0 4
2 1 0 5
0 0 1 6
1 0 1 7
2 0 1 8
0 1 1 9
1 1 1 10
2 1 1 11
NMARK= 3
MARKER_TAG= Wing Lower-1
MARKER_ELEMS= 2
9 0 1 4 3
9 1 2 5 4
MARKER_TAG= far
MARKER_ELEMS= 1
9 6 7 10 9
MARKER_TAG= tip_tri
MARKER_ELEMS= 2
5 2 5 8
5 5 11 8
"""

FFD_TAIL = """FFD_NBOX= 1
FFD_NLEVEL= 1
FFD_TAG= MAIN_BOX
FFD_LEVEL= 0
FFD_DEGREE_I= 1
"""

# A 2D mesh: two triangles and a quad, points with an index column and a third column (0).
TRI2D = """\
NDIME= 2
NPOIN= 5
0.0 0.0 0
1.0 0.0 1
1.0 1.0 2
0.0 1.0 3
2.0 0.5 4
NELEM= 3
5 0 1 2 0
5 0 2 3 1
9 1 4 4 2 2
NMARK= 2
MARKER_TAG= airfoil
MARKER_ELEMS= 2
3 0 1
3 1 4
MARKER_TAG= farfield
MARKER_ELEMS= 1
3 2 3
"""
# (the quad above repeats points on purpose: the reader checks counts, not geometry)

# Every 3D type: tet, pyramid, wedge in one NELEM block, interleaved.
MIXED3D = """\
NDIME= 3
NELEM= 3
10 0 1 2 3
14 0 1 4 2 5
13 0 1 2 3 4 5
NPOIN= 6
0 0 0
1 0 0
0 1 0
0 0 1
1 1 0
0.5 0.5 1
NMARK= 1
MARKER_TAG= all
MARKER_ELEMS= 2
5 0 1 2
9 0 1 4 2
"""


def write_text(tmp_path, name, text):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_read_hex_names_counts_and_ids(tmp_path):
    m = su2.read(write_text(tmp_path, "hex.su2", HEX2))
    assert m.dim == 3 and m.n_points == 12 and m.format == "su2"
    assert [b.type for b in m.cells] == ["hexahedron"]
    np.testing.assert_array_equal(m.cells[0].data[1], [1, 2, 5, 4, 7, 8, 11, 10])
    assert list(m.markers) == ["Wing Lower-1", "far", "tip_tri"]       # file order, exact names
    assert [(b.type, len(b)) for b in m.markers["tip_tri"]] == [("triangle", 2)]
    np.testing.assert_array_equal(m.points[11], [2, 1, 1])


def test_read_2d_and_mixed_types(tmp_path):
    m = su2.read(write_text(tmp_path, "tri.su2", TRI2D))
    assert m.dim == 2 and m.n_points == 5
    assert {b.type: len(b) for b in m.cells} == {"triangle": 2, "quad": 1}
    assert np.all(m.points[:, 2] == 0)
    assert m.marker_point_ids("airfoil").tolist() == [0, 1, 4]
    m3 = su2.read(write_text(tmp_path, "mixed.su2", MIXED3D))
    assert [b.type for b in m3.cells] == ["tetra", "pyramid", "wedge"]
    assert [b.type for b in m3.markers["all"]] == ["triangle", "quad"]


def _same_mesh(a: Mesh, b: Mesh):
    np.testing.assert_array_equal(a.points, b.points)
    assert a.dim == b.dim
    assert [(c.type, c.data.tolist()) for c in a.cells] == [(c.type, c.data.tolist()) for c in b.cells]
    assert list(a.markers) == list(b.markers)
    for name in a.markers:
        assert [(c.type, c.data.tolist()) for c in a.markers[name]] == \
            [(c.type, c.data.tolist()) for c in b.markers[name]]


@pytest.mark.parametrize("text", [HEX2, TRI2D, MIXED3D])
def test_unchanged_points_give_identical_file(tmp_path, text):
    src = write_text(tmp_path, "in.su2", text + FFD_TAIL)
    m = su2.read(src)
    write_mesh(m, tmp_path / "out.su2")
    assert (tmp_path / "out.su2").read_bytes() == src.read_bytes()


def test_patch_changes_only_moved_rows_and_drops_an_unreadable_ffd_section(tmp_path):
    src = write_text(tmp_path, "in.su2", HEX2 + FFD_TAIL)
    m = su2.read(src)
    pts = m.points.copy()
    pts[4] += [0.1, 1 / 3, -2e-17]              # non-representable decimals: needs %.17g
    pts[9, 2] = np.nextafter(1.0, 2.0)          # one ulp: must survive the round trip
    out = tmp_path / "out.su2"
    notes = su2.write(m, out, pts)
    old, new = src.read_text().splitlines(), out.read_text().splitlines()
    n_ffd = len(FFD_TAIL.splitlines())
    assert len(old) == len(new) + n_ffd
    changed = [i for i, (a, b) in enumerate(zip(old[:-n_ffd], new, strict=True)) if a != b]
    row0 = old.index("NPOIN= 12") + 1
    assert changed == [row0 + 4, row0 + 9]
    assert new[row0 + 4].endswith(" 4")                     # index column kept
    # a truncated FFD section cannot be brought up to date: it is left out, and the writer says so
    assert "FFD_NBOX" not in out.read_text()
    assert "could not be updated" in notes["su2_ffd"]["dropped"]
    back = su2.read(out)
    np.testing.assert_array_equal(back.points, pts)          # bit for bit (%.17g)
    _same_mesh(back.with_points(m.points), m)


def test_from_scratch_writer_round_trip(tmp_path):
    for text in (HEX2, TRI2D, MIXED3D):
        m = su2.read(write_text(tmp_path, "in.su2", text))
        fresh = Mesh(points=m.points * np.pi, dim=m.dim, cells=m.cells, markers=m.markers)
        su2.write(fresh, tmp_path / "new.su2", fresh.points)
        _same_mesh(su2.read(tmp_path / "new.su2"), fresh)


def test_write_never_overwrites_input(tmp_path):
    src = write_text(tmp_path, "in.su2", HEX2)
    m = su2.read(src)
    with pytest.raises(InputError, match="overwrite the input"):
        write_mesh(m, src)


def test_patch_refuses_input_changed_on_disk(tmp_path):
    src = write_text(tmp_path, "in.su2", HEX2)
    m = su2.read(src)
    src.write_text(HEX2 + "\n")
    with pytest.raises(InputError, match="changed on disk"):
        su2.write(m, tmp_path / "out.su2", m.points)


def _replace(text, old, new):
    assert old in text
    return text.replace(old, new, 1)


BAD = {
    "empty": ("", "empty", None),
    "truncated_elem": (HEX2[:HEX2.index("12 1 2 5 4") + 8], "needs 8 point ids", 5),
    "truncated_file": (HEX2[:HEX2.index("2 0 0 2")], "ends after 2 of the 12 rows of NPOIN", 9),
    "truncated_point_row": (HEX2[:HEX2.index("2 0 0 2") + 3], "needs 3 coordinates, this one has 2", 9),
    "npoin_too_big": (_replace(HEX2, "NPOIN= 12", "NPOIN= 13"), "shorter than NPOIN", 19),
    "npoin_too_small": (_replace(HEX2, "NPOIN= 12", "NPOIN= 11"), "more rows than NPOIN", 18),
    "non_numeric": (_replace(HEX2, "1 1 0 4", "1 abc 0 4"), "'abc' is not a number", 11),
    "nan_coordinate": (_replace(HEX2, "1 1 0 4", "1 nan 0 4"), "finite", 11),
    "duplicate_marker": (_replace(HEX2, "MARKER_TAG= tip_tri", "MARKER_TAG= far"), "duplicate marker", 27),
    "missing_point": (_replace(HEX2, "9 6 7 10 9", "9 6 7 10 12"), "point id 12 is out of range", 26),
    "missing_point_elem": (_replace(HEX2, "12 0 1 4 3 6 7 10 9 0", "12 0 1 4 3 6 7 10 99 0"),
                           "point id 99", 4),
    "unknown_type": (_replace(HEX2, "5 2 5 8", "7 2 5 8"), "unknown element type 7", 29),
    "wrong_dim": (_replace(HEX2, "NDIME= 3", "NDIME= 4"), "NDIME= must be 2 or 3", 2),
    "missing_nmark": (HEX2[:HEX2.index("NMARK=")], "missing keyword NMARK", None),
    "not_su2": ("hello world\n", "unexpected line", 1),
    "multizone": ("NZONE= 2\n" + HEX2, "multi-zone", 1),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_input_names_file_and_line(tmp_path, case):
    text, msg, line = BAD[case]
    p = write_text(tmp_path, f"{case}.su2", text)
    with pytest.raises(InputError) as err:
        su2.read(p)
    e = err.value
    assert msg in str(e)
    assert e.path == str(p)
    assert e.line == line
    assert "\n" not in str(e)


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_input_through_cli_in_process(tmp_path, case, capsys):
    """Every bad input through the command line's main(): exit 2, one line naming file and line."""
    from ffdcli.cli import main

    text, msg, line = BAD[case]
    p = write_text(tmp_path, f"{case}.su2", text)
    with pytest.raises(SystemExit) as ex:
        main(["inspect", str(p)])
    err = capsys.readouterr().err
    assert ex.value.code == 2
    assert err.count("\n") == 1 and err.startswith("ffd: error: ") and "Traceback" not in err
    assert (f"{p}:{line}: " if line else f"{p}: ") in err and msg in err


@pytest.mark.parametrize("case", ["empty", "truncated_elem", "duplicate_marker", "unknown_type"])
def test_bad_input_through_cli(tmp_path, case):
    text, msg, _ = BAD[case]
    p = write_text(tmp_path, f"{case}.su2", text)
    proc = run_ffd("inspect", p)
    assert_clean_failure(proc, 2, str(p), msg)
    assert len(proc.stderr.strip().splitlines()) == 1


def test_format_int_rows_matches_percent_d():
    rng = np.random.default_rng(0)
    t = rng.integers(0, 10**9, size=(200, 5))
    t[0] = [0, 9, 10, 99, 100]
    expect = "".join("\t".join(str(v) for v in row) + "\n" for row in t.tolist()).encode()
    assert su2.format_int_rows(t) == expect
    with pytest.raises(ValueError):
        su2.format_int_rows(np.array([[-1]]))


def test_many_chunks(tmp_path, monkeypatch):
    """Blocks spanning many parse chunks give the same result as one chunk."""
    n = 3000
    pts = np.random.default_rng(1).random((n, 3))
    tets = np.column_stack([np.arange(n - 3), np.arange(1, n - 2), np.arange(2, n - 1), np.arange(3, n)])
    tri = tets[:50, :3]
    m = Mesh(points=pts, dim=3, cells=[CellBlock("tetra", tets)], markers={"w": [CellBlock("triangle", tri)]})
    su2.write(m, tmp_path / "big.su2", pts)
    one = su2.read(tmp_path / "big.su2")
    monkeypatch.setattr(su2, "CHUNK_BYTES", 997)
    many = su2.read(tmp_path / "big.su2")
    _same_mesh(one, many)
    _same_mesh(one, m)
    monkeypatch.setattr(su2, "WRITE_ROWS", 7)
    moved = pts.copy()
    moved[::3] *= 1.5
    su2.write(many, tmp_path / "moved.su2", moved)
    np.testing.assert_array_equal(su2.read(tmp_path / "moved.su2").points, moved)


REAL = ["su2/deformation__brick_pyra__mesh_brick_pyra_ffd.su2",
        "su2/deformation__rae2822__mesh_RAE2822_turb_ffd.su2",
        "su2/optimization_rans__steady_rae2822__mesh_RAE2822_turb.su2",
        "su2/optimization_euler__steady_inverse_design__mesh_NACA0012_inv_FFD.su2",
        "su2/multiple_ffd__naca0012__mesh_NACA0012_multiFFD.su2",
        "oneram6/mesh_ONERAM6_gmsh_coarse.su2"]


@pytest.mark.parametrize("rel", REAL)
def test_real_files_patch_and_round_trip(tmp_path, rel):
    src = shared_file(rel)
    m = read_mesh(src)
    write_mesh(m, tmp_path / "same.su2")
    assert file_hash(tmp_path / "same.su2") == file_hash(src)
    pts = m.points.copy()
    pts[::5, :m.dim] += 1e-3 / 3
    write_mesh(m, tmp_path / "moved.su2", pts)
    back = su2.read(tmp_path / "moved.su2")
    np.testing.assert_array_equal(back.points, pts)
    _same_mesh(back.with_points(m.points), m)
    # the bytes after the point block (markers) are untouched, up to SU2's FFD section, which is
    # brought up to date for the moved surface (tests/io/test_su2_ffd.py)
    old, new = src.read_bytes(), (tmp_path / "moved.su2").read_bytes()
    tail = old[m.source.block_end:]
    at = tail.find(b"FFD_NBOX=")
    if at < 0:
        assert new.endswith(tail)
    else:
        assert tail[:at] in new and b"FFD_SURFACE_POINTS=" in new[new.find(tail[:at]) + at:]


def test_real_file_counts():
    m = su2.read(shared_file("su2/deformation__brick_pyra__mesh_brick_pyra_ffd.su2"))
    assert m.n_points == 14030
    assert {b.type: len(b) for b in m.cells} == {"tetra": 71884, "pyramid": 741}
    assert list(m.markers) == ["x_m", "x_p", "y_m", "y_p", "z_m", "z_p"]
    m2 = su2.read(shared_file("oneram6/mesh_ONERAM6_gmsh_coarse.su2"))
    assert list(m2.markers) == ["WING", "FARFIELD", "SYMMETRY"]


def test_crlf_file_patch_keeps_line_endings(tmp_path):
    src = tmp_path / "crlf.su2"
    src.write_bytes(HEX2.replace("\n", "\r\n").encode())     # (an FFD section is rewritten with LF: SU2
    m = su2.read(src)                                           # reads it by character offsets)
    assert list(m.markers) == ["Wing Lower-1", "far", "tip_tri"]         # no stray '\r' in names
    write_mesh(m, tmp_path / "same.su2")
    assert (tmp_path / "same.su2").read_bytes() == src.read_bytes()
    pts = m.points.copy()
    pts[0] = [0.25, -0.5, 1e-300]
    write_mesh(m, tmp_path / "moved.su2", pts)
    new = (tmp_path / "moved.su2").read_bytes()
    assert new.count(b"\r\n") == src.read_bytes().count(b"\r\n") and new.count(b"\n") == new.count(b"\r\n")
    np.testing.assert_array_equal(su2.read(tmp_path / "moved.su2").points, pts)


def test_header_extras_are_ignored(tmp_path):
    text = HEX2.replace("NDIME= 3\n", "NDIME= 3\nAOA_OFFSET= 1.5\n\n% comment\n")
    m = su2.read(write_text(tmp_path, "x.su2", text))
    assert m.n_points == 12 and len(m.markers) == 3


def test_2d_write_needs_flat_z(tmp_path):
    m = su2.read(write_text(tmp_path, "tri.su2", TRI2D))
    pts = m.points.copy()
    pts[1, 2] = 0.5
    with pytest.raises(InputError, match="z = constant"):
        su2.write(m, tmp_path / "out.su2", pts)
    assert not (tmp_path / "out.su2").exists()


def test_compiled_int_parser_matches_numpy(tmp_path, monkeypatch):
    """The numba row parser gives what the NumPy path gives, and refuses what it cannot parse."""
    monkeypatch.setattr(su2, "FAST_INT_ROWS", 0)          # use it for small blocks too
    kernels = pytest.importorskip("ffdcli.io.formats._su2_kernels")
    rng = np.random.default_rng(2)
    rows = [rng.integers(-10**12, 10**12, size=rng.integers(1, 9)) for _ in range(500)]
    seps = [" ", "\t", "  ", " \t"]
    text = "".join(" " * int(rng.integers(0, 3)) + seps[i % 4].join(map(str, r)) + ("\r\n" if i % 3 else "\n")
                   for i, r in enumerate(rows)).encode()
    values, first, count, ok = kernels.parse_int_rows(np.frombuffer(text, np.uint8), len(rows))
    assert ok
    np.testing.assert_array_equal(values, np.concatenate(rows))
    np.testing.assert_array_equal(count, [len(r) for r in rows])
    np.testing.assert_array_equal(first, np.cumsum([0] + [len(r) for r in rows[:-1]]))
    for bad in (b"1 2 x\n", b"1 2.0\n", b"1 -\n", b"1 12345678901234567890\n"):
        assert not kernels.parse_int_rows(np.frombuffer(bad, np.uint8), 1)[3]
    for text in (HEX2, TRI2D, MIXED3D):
        p = write_text(tmp_path, "m.su2", text)
        _same_mesh(su2.read(p, fast_ints=True), su2.read(p, fast_ints=False))


def test_compiled_int_parser_on_real_file(monkeypatch):
    pytest.importorskip("ffdcli.io.formats._su2_kernels")
    monkeypatch.setattr(su2, "FAST_INT_ROWS", 0)
    real = shared_file("su2/deformation__rae2822__mesh_RAE2822_turb_ffd.su2")
    _same_mesh(su2.read(real, fast_ints=True), su2.read(real, fast_ints=False))


def test_non_finite_points_are_refused(tmp_path):
    m = su2.read(write_text(tmp_path, "hex.su2", HEX2))
    pts = m.points.copy()
    pts[3, 1] = np.nan
    with pytest.raises(ValueError, match="non-finite"):
        su2.write(m, tmp_path / "out.su2", pts)
    assert not (tmp_path / "out.su2").exists()
