"""CGNS reading and writing: from-scratch round trips, patched copies of real files, ADF, bad input."""

from __future__ import annotations

import shutil
import subprocess
import warnings

import h5py
import numpy as np
import pytest
from conftest import shared_file

from ffdcli.errors import InputError
from ffdcli.io.formats import cgns, cgns_nodes, read_mesh, write_mesh
from ffdcli.mesh import CellBlock, Mesh

REAL_HDF5 = [
    "cgns/aero__meshing__volume__wing.cgns",
    "cgns/aero__meshing__volume__wing_surf_L1.cgns",
    "cgns/airfoil__analysis__n0012.cgns",
    "cgns/disc_adj_euler__cylinder3D__cylinder3D.cgns",
    "cgns/euler__wedge__mesh_wedge_inv.cgns",
    "cgns/incomp_navierstokes__bend__mesh_bend_coarse.cgns",
    "cgns/overset__mesh__near_tip.cgns",
    "cgns/vandv__rans__bump_in_channel__mesh_bump_2d_0089x041.cgns",
]
ADF_FILE = "cgns/adf/aero__meshing__volume__wing.adf.cgns"


# ---------------------------------------------------------------------------------------------
# helpers

def _box_mesh() -> Mesh:
    """A 3x3x3-point box of hexahedra with a quad marker, a mixed tri/quad marker and a point marker."""
    shape = (3, 3, 3)
    g = np.stack(np.meshgrid(*[np.linspace(0, 1, s) for s in shape], indexing="ij"), axis=-1)
    pts = g.reshape(-1, 3, order="F") * [2.0, 1.0, 0.5] + [0.1, -0.2, 0.3]
    hexa = cgns.structured_cells(shape, 0)
    ids = cgns.structured_ids(shape, 0)
    bottom = cgns.range_faces(shape, 0, np.array([0, 0, 0]), np.array([2, 2, 0]))
    top = cgns.range_faces(shape, 0, np.array([0, 0, 2]), np.array([2, 2, 2]))
    # split the first top quad into two triangles so the marker mixes types (a MIXED section)
    q = top.data[0]
    tris = CellBlock("triangle", [[q[0], q[1], q[2]], [q[0], q[2], q[3]]])
    markers = {
        "wing": [bottom],
        "farfield": [tris, CellBlock("quad", top.data[1:])],
        "probe": [CellBlock("vertex", ids[1, 1, :][:, None])],
    }
    return Mesh(points=pts, dim=3, cells=[hexa], markers=markers)


def _square_mesh() -> Mesh:
    """A 2D 4x3 quad mesh in the z = 0 plane with two line markers."""
    shape = (4, 3)
    g = np.stack(np.meshgrid(np.linspace(0, 3, 4), np.linspace(0, 1, 3), indexing="ij"), axis=-1)
    pts = np.zeros((12, 3))
    pts[:, :2] = g.reshape(-1, 2, order="F")
    quad = cgns.structured_cells(shape, 0)
    lower = cgns.range_faces(shape, 0, np.array([0, 0]), np.array([3, 0]))
    upper = cgns.range_faces(shape, 0, np.array([0, 2]), np.array([3, 2]))
    return Mesh(points=pts, dim=2, cells=[quad], markers={"airfoil": [lower], "farfield": [upper]})


def _same_blocks(a: list[CellBlock], b: list[CellBlock]) -> bool:
    """Same cells regardless of block order (the writer groups a marker's cells by type)."""
    def key(blocks):
        return {blk.type: blk.data for blk in cgns._merge(blocks)}
    ka, kb = key(a), key(b)
    return ka.keys() == kb.keys() and all(np.array_equal(ka[t], kb[t]) for t in ka)


def _cgnscheck_errors(path) -> list[str] | None:
    """ERROR lines of the CGNS library's checker (None when it is not installed)."""
    exe = shutil.which("cgnscheck")
    if exe is None:
        return None
    # cgnscheck 3.4 aborts ("buffer overflow detected") on long paths: run it on the bare name
    out = subprocess.run([exe, path.name], capture_output=True, text=True, timeout=60, cwd=path.parent)
    errors = [line for line in (out.stdout + out.stderr).splitlines() if "ERROR" in line]
    if out.returncode != 0 and not errors:
        errors = [f"cgnscheck exit status {out.returncode}: {out.stdout[-300:]}"]
    return errors


def _tree(path) -> dict[str, tuple]:
    """Every node of an HDF5 file: groups by their attributes, datasets by dtype, shape and bytes."""
    out = {}
    with h5py.File(path, "r") as h5:
        def visit(name, obj):
            attrs = tuple(sorted((k, np.asarray(v).tobytes()) for k, v in obj.attrs.items()))
            if isinstance(obj, h5py.Dataset):
                out[name] = ("dataset", str(obj.dtype), obj.shape, obj[()].tobytes(), attrs)
            else:
                out[name] = ("group", attrs, tuple(obj.keys()))
        h5.visititems(visit)
        out["/"] = ("group", tuple(sorted((k, np.asarray(v).tobytes()) for k, v in h5.attrs.items())),
                    tuple(h5.keys()))
    return out


# ---------------------------------------------------------------------------------------------
# from-scratch round trips

def test_round_trip_3d_from_scratch(tmp_path):
    mesh = _box_mesh()
    out = tmp_path / "box.cgns"
    write_mesh(mesh, out)
    back = read_mesh(out)
    # float64 coordinates stored as R8: exact, bit for bit
    np.testing.assert_array_equal(back.points, mesh.points)
    assert back.dim == 3 and back.format == "cgns"
    assert [b.type for b in back.cells] == ["hexahedron"]
    np.testing.assert_array_equal(back.cells[0].data, mesh.cells[0].data)
    assert list(back.markers) == ["wing", "farfield", "probe"]
    for name in mesh.markers:
        assert _same_blocks(back.markers[name], mesh.markers[name]), name
    errors = _cgnscheck_errors(out)
    assert not errors, errors


def test_round_trip_2d_from_scratch_writes_two_coordinates(tmp_path):
    mesh = _square_mesh()
    out = tmp_path / "square.cgns"
    write_mesh(mesh, out)
    with h5py.File(out, "r") as h5:
        base = h5["Base"]
        assert base[" data"][()].tolist() == [2, 2]
        assert sorted(k for k in base["Zone/GridCoordinates"]) == ["CoordinateX", "CoordinateY"]
    back = read_mesh(out)
    np.testing.assert_array_equal(back.points, mesh.points)
    assert back.dim == 2
    assert list(back.markers) == ["airfoil", "farfield"]
    for name in mesh.markers:
        assert _same_blocks(back.markers[name], mesh.markers[name])
    assert "Base" not in back.markers    # a planar 2D mesh gets no whole-surface marker
    errors = _cgnscheck_errors(out)
    assert not errors, errors


def test_patch_of_own_file_keeps_everything_else(tmp_path):
    """Write-patching a file we wrote: only the coordinate datasets differ, and float32 stays float32."""
    src = tmp_path / "box.cgns"
    write_mesh(_box_mesh(), src)
    # store the coordinates in single precision, as some meshers do
    with h5py.File(src, "r+") as h5:
        for name in ("CoordinateX", "CoordinateY", "CoordinateZ"):
            node = h5["Base/Zone/GridCoordinates"][name]
            vals = node[" data"][()].astype(np.float32)
            del node[" data"]
            node.create_dataset(" data", data=vals)
    mesh = read_mesh(src)
    new = mesh.points * 2.0 - 1.0
    out = tmp_path / "moved.cgns"
    write_mesh(mesh, out, new)
    back = read_mesh(out)
    # stored as float32: the points are the float32 rounding of the new ones, exactly
    np.testing.assert_array_equal(back.points, new.astype(np.float32).astype(np.float64))
    with h5py.File(out, "r") as h5:
        assert h5["Base/Zone/GridCoordinates/CoordinateX/ data"].dtype == np.float32
    before, after = _tree(src), _tree(out)
    changed = {k for k in before if before[k] != after.get(k)}
    assert changed == {f"Base/Zone/GridCoordinates/Coordinate{a}/ data" for a in "XYZ"}


def test_writing_over_the_input_is_refused(tmp_path):
    src = tmp_path / "box.cgns"
    write_mesh(_box_mesh(), src)
    mesh = read_mesh(src)
    with pytest.raises(InputError, match="overwrite the input"):
        write_mesh(mesh, src)


def test_mixed_offsets_matches_reference():
    table = cgns.nodes_per_type_table()
    rng = np.random.default_rng(3)
    codes = rng.choice([3, 5, 7, 10, 12, 14, 17, 11], size=5000)
    conn = np.concatenate([np.r_[c, rng.integers(1, 50, table[c])] for c in codes])
    offs = cgns.mixed_offsets(conn, table)
    np.testing.assert_array_equal(offs, cgns.mixed_offsets_reference(conn, table))
    np.testing.assert_array_equal(conn[offs[:-1]], codes)
    for bad, msg in ((conn[:-1], "truncated"), (np.r_[conn, 99, 1], "type code 99")):
        with pytest.raises(ValueError, match=msg):
            cgns.mixed_offsets(bad, table)
        with pytest.raises(ValueError, match=msg):
            cgns.mixed_offsets_reference(bad, table)


def test_ngon_sections_without_cells_are_refused_naming_them(tmp_path):
    """Cells ffd cannot read are never skipped (issue 29): an NGON_n section without the NFACE_n
    that makes its faces cells is an input error naming the section, and no Python warning."""
    src = tmp_path / "box.cgns"
    write_mesh(_box_mesh(), src)
    with h5py.File(src, "r+") as h5:
        zone = h5["Base/Zone"]
        sec = cgns.new_node(zone, "Polygons", "Elements_t", "I4", np.array([cgns.NGON_N, 0], np.int32))
        cgns.new_node(sec, "ElementRange", "IndexRange_t", "I4", np.array([1000, 1000], np.int32))
        cgns.new_node(sec, "ElementConnectivity", "DataArray_t", "I4", np.array([3, 1, 2, 3], np.int32))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(InputError, match="NGON_n faces without an NFACE_n") as e:
            read_mesh(src)
    assert "Polygons" in str(e.value)


# ---------------------------------------------------------------------------------------------
# bad inputs

def _broken(tmp_path, edit):
    src = tmp_path / "broken.cgns"
    write_mesh(_box_mesh(), src)
    with h5py.File(src, "r+") as h5:
        edit(h5)
    return src


def test_not_a_cgns_file(tmp_path):
    p = tmp_path / "text.cgns"
    p.write_text("this is not a mesh\n")
    with pytest.raises(InputError, match="not a CGNS file") as exc:
        read_mesh(p)
    assert str(p) in str(exc.value)
    empty = tmp_path / "empty.cgns"
    empty.write_bytes(b"")
    with pytest.raises(InputError, match="empty"):
        read_mesh(empty)


def test_hdf5_without_base(tmp_path):
    p = tmp_path / "plain.cgns"
    with h5py.File(p, "w") as h5:
        h5["x"] = np.arange(3)
    with pytest.raises(InputError, match="no CGNSBase_t"):
        read_mesh(p)


def test_base_without_zone(tmp_path):
    p = _broken(tmp_path, lambda h5: h5["Base"].__delitem__("Zone"))
    with pytest.raises(InputError, match="no Zone_t") as exc:
        read_mesh(p)
    assert "/Base" in str(exc.value)


def test_missing_coordinates(tmp_path):
    p = _broken(tmp_path, lambda h5: h5["Base/Zone"].__delitem__("GridCoordinates"))
    with pytest.raises(InputError, match="no GridCoordinates_t") as exc:
        read_mesh(p)
    assert "/Base/Zone" in str(exc.value)
    p2 = _broken(tmp_path, lambda h5: h5["Base/Zone/GridCoordinates"].__delitem__("CoordinateY"))
    with pytest.raises(InputError, match="missing CoordinateY") as exc:
        read_mesh(p2)
    assert "/Base/Zone/GridCoordinates" in str(exc.value)


def test_bc_referencing_missing_points(tmp_path):
    def edit(h5):
        node = h5["Base/Zone/ZoneBC/probe/PointList"]
        vals = node[" data"][()]
        vals[0, 0] = 28          # the box has 27 points
        node[" data"][...] = vals
    p = _broken(tmp_path, edit)
    with pytest.raises(InputError, match="outside 1..27") as exc:
        read_mesh(p)
    assert "ZoneBC/probe" in str(exc.value)


def test_bc_referencing_missing_elements(tmp_path):
    def edit(h5):
        node = h5["Base/Zone/ZoneBC/wing/PointList"]
        vals = node[" data"][()]
        vals[-1, 0] = 10_000
        node[" data"][...] = vals
    p = _broken(tmp_path, edit)
    with pytest.raises(InputError, match="not in any readable element section") as exc:
        read_mesh(p)
    assert "ZoneBC/wing" in str(exc.value)


def test_connectivity_outside_the_zone(tmp_path):
    def edit(h5):
        node = h5["Base/Zone/HexahedronElements/ElementConnectivity"]
        vals = node[" data"][()]
        vals[5] = 99
        node[" data"][...] = vals
    p = _broken(tmp_path, edit)
    with pytest.raises(InputError, match="point ids outside"):
        read_mesh(p)


# ---------------------------------------------------------------------------------------------
# ADF

def _fake_adf(tmp_path):
    p = tmp_path / "old.cgns"
    # the first bytes of a real ADF file: "@(#)" with the high bit set, then the ADF banner
    p.write_bytes(b"\xc0\xa8\xa3\xa9ADF Database Version A02011>" + b"\0" * 200)
    return p


def test_adf_without_adf2hdf_says_what_to_do(tmp_path, monkeypatch):
    p = _fake_adf(tmp_path)
    assert cgns.container_of(p) == "adf"
    monkeypatch.setattr(cgns_nodes.shutil, "which", lambda name: None)
    with pytest.raises(InputError) as exc:
        read_mesh(p)
    msg = str(exc.value)
    assert str(p) in msg and "ADF" in msg and "h5py" in msg
    assert "cgns-convert" in msg and "adf2hdf IN.cgns OUT.cgns" in msg


def test_real_adf_header_is_detected():
    assert cgns.container_of(shared_file(ADF_FILE)) == "adf"
    assert cgns.container_of(shared_file("cgns/aero__meshing__volume__wing.cgns")) == "hdf5"


@pytest.mark.skipif(shutil.which("adf2hdf") is None, reason="adf2hdf (Debian cgns-convert) not installed")
def test_adf_read_and_write_through_adf2hdf(tmp_path):
    adf = read_mesh(shared_file(ADF_FILE))
    hdf = read_mesh(shared_file("cgns/aero__meshing__volume__wing.cgns"))
    assert adf.source.container == "adf"
    np.testing.assert_array_equal(adf.points, hdf.points)
    assert list(adf.markers) == list(hdf.markers)
    new = adf.points + [0.0, 0.0, 0.125]
    out = tmp_path / "wing.cgns"
    write_mesh(adf, out, new)
    assert cgns.container_of(out) == "hdf5"      # ADF input -> CGNS/HDF5 output (documented)
    np.testing.assert_array_equal(read_mesh(out).points, new)


# ---------------------------------------------------------------------------------------------
# real files

@pytest.mark.parametrize("rel", REAL_HDF5)
def test_write_patch_of_real_file(rel, tmp_path):
    src = shared_file(rel)
    mesh = read_mesh(src)
    lo, hi = mesh.points.min(axis=0), mesh.points.max(axis=0)
    span = np.where(hi > lo, hi - lo, 1.0)
    new = mesh.points + 0.01 * span * np.sin(mesh.points / span * 3.0)
    out = tmp_path / src.name
    write_mesh(mesh, out, new)

    before, after = _tree(src), _tree(out)
    assert before.keys() == after.keys()
    coords = {name for z in mesh.source.zones for name in (p.lstrip("/") for p in z.coordinates)}
    changed = {k for k in before if before[k] != after[k]}
    assert changed <= coords
    assert len(changed) >= len(mesh.source.zones)         # every zone was written
    # byte level: same size, and every differing byte lies in the storage of a coordinate array
    # (arrays stored compactly inside their HDF5 object header have no offset: node-level check only)
    a, b = np.fromfile(src, np.uint8), np.fromfile(out, np.uint8)
    assert len(a) == len(b)
    inside = np.zeros(len(a), dtype=bool)
    with h5py.File(out, "r") as h5:
        for p in sorted(coords):
            off = h5[p].id.get_offset()
            if off is None:
                inside[:] = True
                break
            inside[off: off + h5[p].id.get_storage_size()] = True
    assert not np.any((a != b) & ~inside)
    back = read_mesh(out)
    stored_axes = np.zeros(3, dtype=bool)
    for z in mesh.source.zones:
        for p in z.coordinates:
            stored_axes["XYZ".index(p.rsplit("/", 2)[-2][-1])] = True
    # the coordinates in the file are the new ones (R8: exactly); a 2D base stores no z
    np.testing.assert_array_equal(back.points[:, stored_axes], new[:, stored_axes])
    np.testing.assert_array_equal(back.points[:, ~stored_axes], mesh.points[:, ~stored_axes])
    assert list(back.markers) == list(mesh.markers)
    for name in mesh.markers:
        assert _same_blocks(back.markers[name], mesh.markers[name])
    # the CGNS library's checker says of the output exactly what it says of the input
    original = tmp_path / "in" / src.name
    original.parent.mkdir()
    shutil.copyfile(src, original)
    assert _cgnscheck_errors(out) == _cgnscheck_errors(original)


def test_structured_airfoil_markers_by_family():
    mesh = read_mesh(shared_file("cgns/airfoil__analysis__n0012.cgns"))
    assert mesh.dim == 3 and mesh.n_points == 293 * 2 * 129
    assert [b.type for b in mesh.cells] == ["hexahedron"] and mesh.n_cells == 292 * 1 * 128
    # BC1..BC4 carry families wall, Far, Sym, Sym: markers by family, BC3 + BC4 merged
    assert list(mesh.markers) == ["wall", "Far", "Sym"]
    assert mesh.source.bc_family == {"BC1": "wall", "BC2": "Far", "BC3": "Sym", "BC4": "Sym"}
    assert {b.type: len(b) for b in mesh.markers["wall"]} == {"quad": 292}
    assert {b.type: len(b) for b in mesh.markers["Sym"]} == {"quad": 2 * 292 * 128}
    by_bc = cgns.markers_by_bc(mesh)
    assert list(by_bc) == ["BC1", "BC2", "BC3", "BC4"]
    # the wall is the k = 1 row of the O-grid: 293 i-points times 2 j-points (one hex layer)
    wall = mesh.marker_point_ids("wall")
    assert len(wall) == 293 * 2
    np.testing.assert_array_equal(np.sort(wall), np.arange(293 * 2))


def test_structured_multiblock_surface():
    mesh = read_mesh(shared_file("cgns/aero__meshing__volume__wing_surf_L1.cgns"))
    zones = mesh.source.zones
    assert len(zones) == 8 and all(z.structured for z in zones)
    # zones are concatenated in file order: offsets are the running sums of the zone sizes
    np.testing.assert_array_equal([z.offset for z in zones],
                                  np.cumsum([0] + [z.n_points for z in zones[:-1]]))
    assert mesh.n_points == 68448 and mesh.dim == 2
    with h5py.File(shared_file("cgns/aero__meshing__volume__wing_surf_L1.cgns"), "r") as h5:
        z = zones[3]
        x = h5[z.coordinates[0]][()].ravel()      # HDF5 C order of reversed dims = i fastest
        np.testing.assert_array_equal(mesh.points[z.offset:z.offset + z.n_points, 0], x)
    assert list(mesh.markers) == ["con-10", "con-1", "con-5", "Base"]
    # placeholder family "UnspecifiedBC": named by the BC
    assert {b.type: len(b) for b in mesh.markers["con-10"]} == {"line": 16}
    assert mesh.marker_faces("Base")[0].type == "quad" and mesh.n_cells == 66944


def test_unstructured_markers_from_vertex_bcs_and_sections():
    cyl = read_mesh(shared_file("cgns/disc_adj_euler__cylinder3D__cylinder3D.cgns"))
    assert list(cyl.markers) == ["OUT", "WALL", "IN", "CYLINDER_DOWN", "CYLINDER_UP", "SIDE"]
    # vertex PointList BCs recovered as the triangles of the matching sections
    assert {b.type: len(b) for b in cyl.markers["WALL"]} == {"triangle": 512}
    assert len(cyl.marker_point_ids("WALL")) == 306

    bend = read_mesh(shared_file("cgns/incomp_navierstokes__bend__mesh_bend_coarse.cgns"))
    assert {b.type: len(b) for b in bend.cells} == {"tetra": 154, "pyramid": 333, "wedge": 31,
                                                    "hexahedron": 770}
    assert list(bend.markers) == ["INLET", "OUTLET", "SYMMETRY", "WALL1", "WALL2"]
    assert {b.type: len(b) for b in bend.markers["SYMMETRY"]} == {"triangle": 3, "quad": 207}

    bump = read_mesh(shared_file("cgns/vandv__rans__bump_in_channel__mesh_bump_2d_0089x041.cgns"))
    assert bump.dim == 2 and np.all(bump.points[:, 2] == 0)
    assert list(bump.markers) == ["bump", "inlet", "lower_downstream", "lower_upstream", "outlet",
                                  "upper"]
    assert {b.type: len(b) for b in bump.markers["bump"]} == {"line": 40}


def test_every_real_file_reads_without_warnings():
    for rel in REAL_HDF5:
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            mesh = read_mesh(shared_file(rel))
        assert mesh.n_points > 0 and mesh.n_cells > 0
        assert all(c.data.max() < mesh.n_points for c in mesh.cells)


# ---------------------------------------------------------------------------------------------
# element orientation and structured zones written by hand

def _vtk_signs(points: np.ndarray, block: CellBlock) -> np.ndarray:
    """Sign of a corner triple product that is positive for a valid cell in VTK (= SU2) node order.

    VTK's wedge lists its first triangle with the normal pointing away from the second one, hence
    the minus sign (checked on SU2's deformation/brick_prism mesh: all 29640 prisms negative).
    """
    p = points[block.data]
    d = {"tetra": (1, 2, 3, 1), "pyramid": (1, 3, 4, 1), "wedge": (1, 2, 3, -1),
         "hexahedron": (1, 3, 4, 1)}[block.type]
    t = np.einsum("ij,ij->i", np.cross(p[:, d[0]] - p[:, 0], p[:, d[1]] - p[:, 0]), p[:, d[2]] - p[:, 0])
    return np.sign(t * d[3])


def test_real_volume_cells_have_positive_vtk_volume():
    for rel in ("cgns/incomp_navierstokes__bend__mesh_bend_coarse.cgns",
                "cgns/airfoil__analysis__n0012.cgns",
                "cgns/disc_adj_euler__cylinder3D__cylinder3D.cgns"):
        mesh = read_mesh(shared_file(rel))
        for b in mesh.cells:
            assert np.all(_vtk_signs(mesh.points, b) > 0), (rel, b.type)


def test_wedge_written_in_cgns_order_and_read_back(tmp_path):
    pts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [0, 1, 1]], float)
    vtk_wedge = CellBlock("wedge", [[0, 2, 1, 3, 5, 4]])       # VTK order: first normal points down
    assert _vtk_signs(pts, vtk_wedge)[0] > 0
    bottom = CellBlock("triangle", [[0, 2, 1]])
    mesh = Mesh(points=pts, dim=3, cells=[vtk_wedge], markers={"bottom": [bottom]})
    out = tmp_path / "wedge.cgns"
    write_mesh(mesh, out)
    with h5py.File(out, "r") as h5:
        conn = h5["Base/Zone/WedgeElements/ElementConnectivity/ data"][()]
    assert conn.tolist() == [1, 2, 3, 4, 5, 6]                  # CGNS PENTA_6: bottom normal points up
    back = read_mesh(out)
    np.testing.assert_array_equal(back.cells[0].data, vtk_wedge.data)


def _structured_file(path, x_sign: float, bcs: dict[str, tuple[str, list[list[int]]]]):
    """A 4x3x2-vertex structured zone (x mirrored when x_sign < 0) with the given BCs."""
    shape = (4, 3, 2)
    g = np.meshgrid(*[np.arange(s, dtype=float) for s in shape], indexing="ij")
    with h5py.File(path, "w", track_order=True) as h5:
        for k, v in (("label", "Root Node of HDF5 File"), ("name", "HDF5 MotherNode"), ("type", "MT")):
            cgns.str_attr(h5, k, v, 33 if k != "type" else 3)
        base = cgns.new_node(h5, "B", "CGNSBase_t", "I4", np.array([3, 3], np.int32))
        zone = cgns.new_node(base, "blk", "Zone_t", "I4", np.array([shape, [3, 2, 1], [0, 0, 0]], np.int32))
        cgns.new_node(zone, "ZoneType", "ZoneType_t", "C1", cgns.char_array("Structured"))
        grid = cgns.new_node(zone, "GridCoordinates", "GridCoordinates_t")
        for a, name in enumerate(("CoordinateX", "CoordinateY", "CoordinateZ")):
            vals = g[a] * (x_sign if a == 0 else 1.0)
            cgns.new_node(grid, name, "DataArray_t", "R8", np.ascontiguousarray(vals.T))  # HDF5: reversed
        zbc = cgns.new_node(zone, "ZoneBC", "ZoneBC_t")
        for name, (loc, rng) in bcs.items():
            bc = cgns.new_node(zbc, name, "BC_t", "C1", cgns.char_array("BCWall"))
            cgns.new_node(bc, "GridLocation", "GridLocation_t", "C1", cgns.char_array(loc))
            cgns.new_node(bc, "PointRange", "IndexRange_t", "I4", np.array(rng, np.int32))
    return path


@pytest.mark.parametrize("x_sign", [1.0, -1.0])
def test_structured_block_cells_are_right_handed(tmp_path, x_sign):
    p = _structured_file(tmp_path / "s.cgns", x_sign, {"kmin": ("Vertex", [[1, 1, 1], [4, 3, 1]])})
    mesh = read_mesh(p)
    assert mesh.n_points == 24 and mesh.n_cells == 3 * 2 * 1
    np.testing.assert_array_equal(mesh.points[:4, 0], x_sign * np.arange(4.0))   # i fastest
    assert np.all(_vtk_signs(mesh.points, mesh.cells[0]) > 0)
    assert {b.type: len(b) for b in mesh.markers["kmin"]} == {"quad": 6}
    assert np.all(mesh.points[mesh.marker_point_ids("kmin"), 2] == 0)


def test_structured_face_centred_bcs(tmp_path):
    bcs = {"imax": ("IFaceCenter", [[4, 1, 1], [4, 2, 1]]),       # face index 4, cells j 1..2, k 1
           "jmin": ("FaceCenter", [[1, 1, 1], [3, 1, 1]]),        # j = 1 on the side; k has 1 cell
           "verts": ("Vertex", [[2, 2, 1], [2, 2, 2]])}           # a line of points: vertex marker
    mesh = read_mesh(_structured_file(tmp_path / "s.cgns", 1.0, bcs))
    imax = mesh.marker_point_ids("imax")
    assert len(imax) == 3 * 2 and np.all(mesh.points[imax, 0] == 3)
    jmin = mesh.marker_point_ids("jmin")
    assert len(jmin) == 4 * 2 and np.all(mesh.points[jmin, 1] == 0)
    assert [b.type for b in mesh.markers["verts"]] == ["vertex"]
    np.testing.assert_array_equal(mesh.points[mesh.marker_point_ids("verts")], [[1, 1, 0], [1, 1, 1]])


def test_structured_range_outside_zone(tmp_path):
    p = _structured_file(tmp_path / "s.cgns", 1.0, {"bad": ("Vertex", [[1, 1, 1], [5, 3, 1]])})
    with pytest.raises(InputError, match="outside the zone") as exc:
        read_mesh(p)
    assert "ZoneBC/bad" in str(exc.value)


def test_marker_names_that_cgns_cannot_hold(tmp_path):
    mesh = _box_mesh()
    mesh.markers = {"x" * 33: mesh.markers["wing"]}
    with pytest.raises(InputError, match="32 characters"):
        write_mesh(mesh, tmp_path / "long.cgns")
    assert not (tmp_path / "long.cgns").exists()


def test_marker_names_colliding_with_zone_children(tmp_path):
    mesh = _box_mesh()
    mesh.markers = {"ZoneBC": mesh.markers["wing"], "HexahedronElements": mesh.markers["farfield"]}
    out = tmp_path / "names.cgns"
    write_mesh(mesh, out)
    back = read_mesh(out)
    assert list(back.markers) == ["ZoneBC", "HexahedronElements"]
    for name in mesh.markers:
        assert _same_blocks(back.markers[name], mesh.markers[name])
    np.testing.assert_array_equal(back.cells[0].data, mesh.cells[0].data)


def test_unreferenced_boundary_sections_are_markers_by_section_name(tmp_path):
    p = _broken(tmp_path, lambda h5: h5["Base/Zone"].__delitem__("ZoneBC"))
    mesh = read_mesh(p)
    # without BCs, the 2D sections of this 3D zone are the markers, under their section names
    assert list(mesh.markers) == ["wing", "farfield"]
    assert _same_blocks(mesh.markers["farfield"], _box_mesh().markers["farfield"])


def test_truncated_file(tmp_path):
    src = tmp_path / "box.cgns"
    write_mesh(_box_mesh(), src)
    cut = tmp_path / "cut.cgns"
    cut.write_bytes(src.read_bytes()[: src.stat().st_size // 2])
    with pytest.raises(InputError) as exc:
        read_mesh(cut)
    assert str(cut) in str(exc.value)


def test_mixed_section_with_cells_and_faces(tmp_path):
    box = _box_mesh()
    hexa, quads = box.cells[0].data, box.markers["wing"][0].data

    def edit(h5):
        zone = h5["Base/Zone"]
        for name in ("HexahedronElements", "wing", "farfield", "ZoneBC"):
            del zone[name]
        conn = np.concatenate([np.hstack([np.full((len(hexa), 1), 17), hexa + 1]).ravel(),
                               np.hstack([np.full((len(quads), 1), 7), quads + 1]).ravel()])
        sec = cgns.new_node(zone, "All", "Elements_t", "I4", np.array([cgns.MIXED, 0], np.int32))
        cgns.new_node(sec, "ElementRange", "IndexRange_t", "I4", np.array([1, 12], np.int32))
        cgns.new_node(sec, "ElementConnectivity", "DataArray_t", "I4", conn.astype(np.int32))
    mesh = read_mesh(_broken(tmp_path, edit))     # no ElementStartOffset: the offsets are scanned
    assert [b.type for b in mesh.cells] == ["hexahedron"]
    np.testing.assert_array_equal(mesh.cells[0].data, hexa)
    assert list(mesh.markers) == ["All"]
    np.testing.assert_array_equal(mesh.markers["All"][0].data, quads)


def _outward_dots(mesh: Mesh, faces: np.ndarray) -> np.ndarray:
    """(face normal) . (centre of the hexahedron behind the face - face centre): < 0 when outward."""
    hexa = mesh.cells[0].data
    sides = [[0, 3, 2, 1], [4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]]
    owner = {}
    for s in sides:
        for c, key in enumerate(np.sort(hexa[:, s], axis=1)):
            owner[key.tobytes()] = c
    cells = np.array([owner[k.tobytes()] for k in np.sort(faces, axis=1)])
    p = mesh.points[faces]
    normal = np.cross(p[:, 1] - p[:, 0], p[:, 3] - p[:, 0])
    inward = mesh.points[hexa[cells]].mean(axis=1) - p.mean(axis=1)
    return np.einsum("ij,ij->i", normal, inward)


@pytest.mark.parametrize("x_sign", [1.0, -1.0])
def test_structured_bc_faces_point_out_of_the_block(tmp_path, x_sign):
    bcs = {"kmin": ("Vertex", [[1, 1, 1], [4, 3, 1]]), "kmax": ("Vertex", [[4, 3, 2], [1, 1, 2]]),
           "imax": ("Vertex", [[4, 1, 1], [4, 3, 2]]), "jmin": ("Vertex", [[1, 1, 1], [4, 1, 2]]),
           "jmax": ("Vertex", [[1, 3, 1], [4, 3, 2]])}
    mesh = read_mesh(_structured_file(tmp_path / "s.cgns", x_sign, bcs))
    for name in bcs:
        assert np.all(_outward_dots(mesh, mesh.markers[name][0].data) < 0), name


def test_real_structured_bc_faces_point_out_of_the_domain():
    mesh = read_mesh(shared_file("cgns/airfoil__analysis__n0012.cgns"))
    for name in mesh.markers:
        assert np.all(_outward_dots(mesh, mesh.markers[name][0].data) < 0), name


@pytest.mark.parametrize("rel", ["cgns/aero__meshing__volume__wing_surf_L1.cgns",
                                 "cgns/overset__mesh__near_tip.cgns"])
def test_multiblock_surface_quads_are_consistently_oriented(rel):
    """Across all blocks, every edge shared by two quads is walked once each way (points on block
    interfaces merged by coordinates), so vertex normals from these quads do not cancel."""
    mesh = read_mesh(shared_file(rel))
    _, merged = np.unique(np.round(mesh.points, 9), axis=0, return_inverse=True)
    q = merged.ravel()[mesh.marker_faces("Base")[0].data]
    edges = np.concatenate([q[:, [0, 1]], q[:, [1, 2]], q[:, [2, 3]], q[:, [3, 0]]])
    edges = edges[edges[:, 0] != edges[:, 1]]                  # collapsed edges at poles/tips
    _, shared = np.unique(np.sort(edges, axis=1), axis=0, return_counts=True)
    _, directed = np.unique(edges, axis=0, return_counts=True)
    assert np.count_nonzero(shared == 2) > len(edges) // 3     # the blocks do connect
    assert directed.max() == 1


def test_cgns_link_nodes_are_refused(tmp_path):
    def edit(h5):
        zone = h5["Base/Zone"]
        del zone["GridCoordinates"]
        link = zone.create_group("GridCoordinates")
        for k, v, n in (("name", "GridCoordinates", 33), ("label", "", 33), ("type", "LK", 3)):
            cgns.str_attr(link, k, v, n)
        link.create_dataset(" file", data=cgns.char_array("grid.cgns"))
        link.create_dataset(" path", data=cgns.char_array("/Base/Zone/GridCoordinates"))
        link[" link"] = h5py.ExternalLink("grid.cgns", "/Base/Zone/GridCoordinates")
    with pytest.raises(InputError, match="CGNS link .grid.cgns /Base/Zone/GridCoordinates") as exc:
        read_mesh(_broken(tmp_path, edit))
    assert "/Base/Zone/GridCoordinates" in str(exc.value)


def test_patch_never_writes_through_an_hdf5_external_link(tmp_path):
    other = tmp_path / "other.h5"
    box = _box_mesh()
    with h5py.File(other, "w") as h5:
        h5["x"] = box.points[:, 0]

    def edit(h5):
        node = h5["Base/Zone/GridCoordinates/CoordinateX"]
        del node[" data"]
        node[" data"] = h5py.ExternalLink(str(other), "/x")
    src = _broken(tmp_path, edit)
    mesh = read_mesh(src)                     # h5py follows the link when reading
    np.testing.assert_array_equal(mesh.points, box.points)
    before = other.read_bytes()
    with pytest.raises(InputError, match="in another file"):
        write_mesh(mesh, tmp_path / "out.cgns", mesh.points + 1.0)
    assert other.read_bytes() == before
    assert not (tmp_path / "out.cgns").exists()


def test_structured_coordinates_in_the_wrong_order(tmp_path):
    p = _structured_file(tmp_path / "s.cgns", 1.0, {})
    with h5py.File(p, "r+") as h5:
        node = h5["B/blk/GridCoordinates/CoordinateX"]
        vals = node[" data"][()]
        del node[" data"]
        node.create_dataset(" data", data=np.ascontiguousarray(vals.T))   # C order: (ni, nj, nk)
    with pytest.raises(InputError, match=r"shape \(2, 3, 4\), the zone has \(4, 3, 2\)") as exc:
        read_mesh(p)
    assert "CoordinateX/ data" in str(exc.value)
