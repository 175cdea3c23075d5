"""Partitioned meshes (ffdcli.parallel.partition) and the quality gate shared between ranks: the report of
2, 3 or 5 ranks (threads standing in for MPI ranks, :mod:`ffdcli.testing.threadcomm`) equals the
serial report field for field (bit for bit), on meshes of every cell type, well and badly numbered,
with cells inverted and made worse by the "design", and cells already bad in the input."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import SAMPLES, shared_file

from ffdcli.io.formats import read_mesh
from ffdcli.mesh import CellBlock, Mesh
from ffdcli.parallel.comm import share
from ffdcli.parallel.partition import localize, node_owners, part_of
from ffdcli.quality.gate import check_quality, check_quality_part
from ffdcli.testing.threadcomm import run_ranks
from ffdcli.testing.wings import extruded_wing_mesh


def _renumber(mesh: Mesh, seed: int) -> Mesh:
    """The same mesh with its nodes in a random order (a partition of it has large halos)."""
    perm = np.random.default_rng(seed).permutation(mesh.n_points)
    inv = np.empty_like(perm)
    inv[perm] = np.arange(len(perm))
    return Mesh(mesh.points[perm], mesh.dim, [CellBlock(b.type, inv[b.data]) for b in mesh.cells],
                {k: [CellBlock(b.type, inv[b.data]) for b in v] for k, v in mesh.markers.items()})


def _mixed_mesh() -> Mesh:
    """A hexahedral grid whose second half is split into wedges, tetrahedra and pyramids... kept
    simple: hexahedra and the wedges of the split hexahedra of alternate columns."""
    n = 7
    g = np.stack(np.meshgrid(*[np.linspace(0, 1, n)] * 3, indexing="ij"), -1).reshape(-1, 3)
    g[:, 2] = g[:, 2] ** 2                                   # thin cells near z = 0
    idx = np.arange(n ** 3).reshape(n, n, n)
    hexes, wedges = [], []
    for i in range(n - 1):
        for j in range(n - 1):
            for k in range(n - 1):
                c = [idx[i, j, k], idx[i + 1, j, k], idx[i + 1, j + 1, k], idx[i, j + 1, k],
                     idx[i, j, k + 1], idx[i + 1, j, k + 1], idx[i + 1, j + 1, k + 1], idx[i, j + 1, k + 1]]
                if (i + j) % 2:
                    hexes.append(c)
                else:                                         # two wedges along the diagonal 0-2
                    wedges.append([c[0], c[1], c[2], c[4], c[5], c[6]])
                    wedges.append([c[0], c[2], c[3], c[4], c[6], c[7]])
    return Mesh(g, 3, [CellBlock("hexahedron", hexes), CellBlock("wedge", wedges)], {})


def _cases():
    rect = read_mesh(SAMPLES / "rect_wing.su2")
    naca = read_mesh(SAMPLES / "naca0012_2d.su2")
    hexa = extruded_wing_mesh(n_around=33, n_radial=9, n_span=5)
    mixed = _mixed_mesh()
    return {"rect_wing_tets": rect, "naca_quads_2d": naca, "wing_hexes": hexa, "mixed_hex_wedge": mixed,
            "rect_wing_shuffled": _renumber(rect, 3), "mixed_shuffled": _renumber(mixed, 4)}


CASES = _cases()


def _motion(mesh: Mesh, kind: str) -> np.ndarray:
    """Coordinates after a "design": smooth (passes), or with cells crushed and inverted."""
    rng = np.random.default_rng(7)
    size = np.ptp(mesh.points, axis=0).max()
    pts = mesh.points.copy()
    flat = int(np.argmin(np.ptp(pts, axis=0))) if mesh.dim == 2 else None
    if kind == "smooth":
        pts += 1e-3 * size * np.sin(pts[:, ::-1] / size * 3)
    else:                                                   # a few nodes thrown across their cells
        hit = rng.choice(mesh.n_points, size=max(8, mesh.n_points // 100), replace=False)
        pts[hit] += rng.normal(scale=2 * size / mesh.n_points ** (1 / mesh.dim), size=(len(hit), 3))
    if flat is not None:
        pts[:, flat] = mesh.points[:, flat]
    return pts


def _parts_report(mesh, size, after=None, before=None, **kw):
    def one(comm):
        part = part_of(mesh, node_owners(mesh.points, size), comm.rank)
        a = None if after is None else after[part.ids]
        b = None if before is None else before[part.ids]
        return check_quality_part(part, comm, a, b, **kw)

    return run_ranks(size, one)


@pytest.mark.parametrize("name", list(CASES))
@pytest.mark.parametrize("kind", ["smooth", "broken"])
def test_the_gate_of_the_parts_is_the_serial_gate(name, kind):
    mesh = CASES[name]
    after = _motion(mesh, kind)
    serial = check_quality(mesh, after, points_before=mesh.points)
    if kind == "broken":
        assert not serial.ok and serial.n_new_inverted and serial.worst[0]["failed"]
    for size in (2, 3, 5):
        reports = _parts_report(mesh, size, after, mesh.points)
        for r in reports:
            assert r == serial, (name, size)
            assert r.to_dict() == serial.to_dict()


@pytest.mark.parametrize("name", ["rect_wing_tets", "naca_quads_2d", "mixed_shuffled"])
def test_the_check_of_a_mesh_alone_and_input_cells_already_bad(name):
    """``ffd check`` (no before) and an input mesh with inverted cells (exit-2 rows)."""
    mesh = CASES[name]
    broken = _motion(mesh, "broken")
    alone = check_quality(mesh.with_points(broken))
    for r in _parts_report(mesh.with_points(broken), 3):
        assert r == alone
    # the broken mesh as the INPUT, smoothed "after": input_bad rows, the floor of the input
    bad_in = mesh.with_points(broken)
    serial = check_quality(bad_in, broken + 1e-6, points_before=broken)
    assert serial.n_input_bad and serial.input_bad
    for r in _parts_report(bad_in, 2, broken + 1e-6, broken):
        assert r == serial
    # other gate settings travel too
    kw = {"threshold": 0.2, "relative": 0.9, "ortho_min": 60.0, "ortho_loss": 1.0, "n_worst": 4}
    serial = check_quality(mesh, _motion(mesh, "smooth"), points_before=mesh.points, **kw)
    for r in _parts_report(mesh, 3, _motion(mesh, "smooth"), mesh.points, **kw):
        assert r == serial


def test_parts_cover_every_cell_once_and_hold_their_halo():
    mesh = CASES["rect_wing_shuffled"]
    total = np.zeros(mesh.n_cells, dtype=int)
    for size in (1, 4):
        total[:] = 0
        owner = node_owners(mesh.points, size)
        assert np.bincount(owner).tolist() == [hi - lo for lo, hi in (share(mesh.n_points, r, size)
                                                                      for r in range(size))]
        for r in range(size):
            part = part_of(mesh, owner, r)
            for blk, gid, counted in zip(part.cells, part.cell_ids, part.counted, strict=True):
                total[gid[counted]] += 1
                np.testing.assert_array_equal(part.ids[blk.data], mesh.cells[0].data[gid])
            np.testing.assert_array_equal(part.points, mesh.points[part.ids])
            assert np.all(np.diff(part.ids) > 0)
            owned = part.ids[part.owned]
            np.testing.assert_array_equal(owned, np.flatnonzero(owner == r))
            # every cell around an owned node is here, and only those
            around = np.flatnonzero(np.isin(mesh.cells[0].data, owned).any(axis=1))
            np.testing.assert_array_equal(part.cell_ids[0], around)
            if size == 4:       # a compact piece of space: far fewer cells than the whole, shuffled ids or not
                assert len(around) < 0.45 * mesh.n_cells
        assert np.all(total == 1)


def _sorted_owners(points, size):
    """The owner rule by a sort of every node (the reference): Morton codes in the bounding cube,
    ties by id, cut into equal runs."""
    from ffdcli.mesh.morton import morton_codes

    lo = points.min(axis=0)
    order = np.argsort(morton_codes(points, lo, max(float(np.ptp(points, axis=0).max()), 1e-300)), kind="stable")
    owner = np.empty(len(points), dtype=np.int32)
    for r in range(size):
        a, b = share(len(points), r, size)
        owner[order[a:b]] = r
    return owner


@pytest.mark.parametrize("kind", ["uniform", "repeated", "planar", "clustered", "rect_wing"])
def test_owners_of_blocks_on_ranks_are_those_of_a_sort_of_every_node(kind):
    """:func:`block_owners` (each rank: its block of rows, no rank holding every node) gives the owners
    of a sort of every node, equal runs included, for any split of the rows; :func:`node_owners` is the
    same rule on one rank. Repeated points (one code, many ids), a boundary layer 1e-9 thin inside a
    large box (most nodes in one bin of the first rounds) and fewer nodes than ranks."""
    from ffdcli.parallel.partition import block_owners

    rng = np.random.default_rng(11)
    pts = {"uniform": rng.random((3000, 3)),
           "repeated": np.repeat(rng.random((40, 3)), 25, axis=0)[rng.permutation(1000)],
           "planar": np.column_stack([rng.random((2000, 2)), np.zeros(2000)]),
           "clustered": np.vstack([1e-9 * rng.random((1500, 3)), 100 * rng.random((500, 3))]),
           "rect_wing": CASES["rect_wing_shuffled"].points}[kind]
    for n in (len(pts), 3):
        p = pts[:n]
        for size in (1, 2, 3, 5, 8):
            want = _sorted_owners(p, size)
            np.testing.assert_array_equal(node_owners(p, size), want)
            assert np.bincount(want, minlength=size).tolist() == [b - a for a, b in (share(n, r, size)
                                                                                     for r in range(size))]
            cut = np.concatenate([[0], np.sort(rng.integers(0, n + 1, size - 1)), [n]])     # uneven, some empty
            got = run_ranks(size, lambda c, p=p, cut=cut: block_owners(c, p[cut[c.rank]:cut[c.rank + 1]],
                                                                       cut[c.rank], len(p)))
            np.testing.assert_array_equal(np.concatenate(got), want)


@pytest.mark.parametrize("name", ["rect_wing_shuffled", "naca_quads_2d", "mixed_shuffled"])
def test_a_local_mesh_holds_the_owned_nodes_their_halo_and_the_markers_and_nothing_else(name):
    """:func:`localize`: the definition of one rank's local mesh that readers by parts reproduce."""
    mesh = CASES[name]
    marker_nodes = np.unique(np.concatenate([np.zeros(0, np.int64)] + [b.data.ravel() for bl in mesh.markers.values()
                                                                       for b in bl]))
    for size in (1, 3):
        owner = node_owners(mesh.points, size)
        seen = np.zeros(mesh.n_points, dtype=bool)
        for r in range(size):
            local, part = localize(mesh, owner, r)
            whole_part = part_of(mesh, owner, r)
            g = local.global_ids
            assert local.is_local and local.partial and local.n_points_global == mesh.n_points
            assert np.all(np.diff(g) > 0)
            np.testing.assert_array_equal(local.points, mesh.points[g])
            halo = np.unique(np.concatenate([b.data.ravel() for b in whole_part.cells]))
            np.testing.assert_array_equal(g, np.union1d(np.union1d(whole_part.ids, marker_nodes),
                                                        whole_part.ids[halo]))
            for name_, blocks in mesh.markers.items():      # every marker, the same faces, local ids
                for b, lb in zip(blocks, local.markers[name_], strict=True):
                    np.testing.assert_array_equal(g[lb.data], b.data)
            every = np.concatenate([b.data for b in mesh.cells]) if len({b.type for b in mesh.cells}) == 1 else None
            for lb, pb, gid in zip(local.cells, whole_part.cells, whole_part.cell_ids, strict=True):
                np.testing.assert_array_equal(g[lb.data], whole_part.ids[pb.data])
                if every is not None:
                    np.testing.assert_array_equal(g[lb.data], every[gid])
            np.testing.assert_array_equal(part.take(local.points), whole_part.points)
            np.testing.assert_array_equal(g[part.rows], part.ids)
            seen[part.ids[part.owned]] = True
        assert seen.all()


# ---------------------------------------------------------------------------------------------- reading by parts


def _same_part(a, b):
    for f in ("n_points", "n_cells", "rank", "dim", "types"):
        assert getattr(a, f) == getattr(b, f), f
    for f in ("ids", "points", "owned"):
        np.testing.assert_array_equal(getattr(a, f), getattr(b, f))
    for x, y in zip(a.cells, b.cells, strict=True):
        assert x.type == y.type
        np.testing.assert_array_equal(x.data, y.data)
    for f in ("cell_ids", "counted"):
        for x, y in zip(getattr(a, f), getattr(b, f), strict=True):
            np.testing.assert_array_equal(x, y)


def _same_local(mesh, part, whole, owner, rank):
    """A rank's read by parts is :func:`localize` of the whole read, field by field (``source``
    aside: the caller checks it)."""
    want, want_part = localize(whole, owner, rank)
    assert mesh.is_local and mesh.partial and mesh.n_global == whole.n_points
    assert (mesh.dim, mesh.format, mesh.path) == (want.dim, want.format, want.path)
    np.testing.assert_array_equal(mesh.global_ids, want.global_ids)
    np.testing.assert_array_equal(mesh.points, want.points)
    assert [b.type for b in mesh.cells] == [b.type for b in want.cells]
    for x, y in zip(mesh.cells, want.cells, strict=True):
        np.testing.assert_array_equal(x.data, y.data)
    assert list(mesh.markers) == list(want.markers)
    for k, blocks in want.markers.items():
        assert [b.type for b in mesh.markers[k]] == [b.type for b in blocks]
        for x, y in zip(mesh.markers[k], blocks, strict=True):
            np.testing.assert_array_equal(x.data, y.data)
    _same_part(part, want_part)
    np.testing.assert_array_equal(part.rows, want_part.rows)
    # no rank holds every node (but a tiny mesh's markers may be most of it)
    assert len(mesh.global_ids) <= whole.n_points


@pytest.mark.parametrize("sample", ["rect_wing.su2", "naca0012_2d.su2", "wing_body.su2"])
def test_su2_read_by_parts_is_the_local_mesh_of_the_whole_read(sample, monkeypatch):
    """Each rank parses only its chunks of the point and element rows (small chunks here: many per
    rank); its mesh and part are :func:`localize` of the serial read (owners: :func:`node_owners`),
    and each rank holds the point block's layout of the rows it parsed: in rank order, the whole
    file's (the rows each rank prints when the mesh is written)."""
    from ffdcli.io.formats import su2

    monkeypatch.setattr(su2, "CHUNK_BYTES", 1 << 14)
    whole = su2.read(SAMPLES / sample)
    for size in (2, 3, 5):
        owner = node_owners(whole.points, size)
        got = run_ranks(size, lambda c: su2.read_part(SAMPLES / sample, c))
        srcs = [mesh.source for mesh, _ in got]
        assert [s.first_row for s in srcs] == list(np.cumsum([0] + [len(s.points) for s in srcs[:-1]]))
        assert sum(len(s.points) > 0 for s in srcs) >= 2          # the rows are split
        for f in ("coord_start", "coord_end", "points"):
            np.testing.assert_array_equal(np.concatenate([getattr(s, f) for s in srcs]), getattr(whole.source, f))
        for s in srcs:          # each rank's rows end where the next rank's begin
            rows = slice(s.first_row, s.first_row + len(s.points) + 1)
            np.testing.assert_array_equal(s.row_start, whole.source.row_start[rows])
            for f in ("separator", "ndim", "size", "mtime_ns", "block_start", "block_end"):
                assert getattr(s, f) == getattr(whole.source, f)
        for r, (mesh, part) in enumerate(got):
            _same_local(mesh, part, whole, owner, r)
            # the nodes off the markers (every rank has the markers' nodes) are split between the ranks
            off = np.setdiff1d(np.arange(whole.n_points), whole.marker_point_ids(list(whole.markers)))
            held = np.setdiff1d(mesh.global_ids, whole.marker_point_ids(list(whole.markers)))
            assert len(held) < (0.7 if size == 2 else 0.55) * len(off), (len(held), len(off))


@pytest.mark.parametrize("size", [2, 3])
def test_su2_surface_mesh_without_interior_cells_reads_by_parts(tmp_path, size):
    """A surface-only SU2 mesh (NELEM= 0: a wing's wall, as MPhys runs give ffd) read by parts: every rank
    gets the marker's points (was an UnboundLocalError in read_part)."""
    from ffdcli.io.formats import su2, write_mesh
    from ffdcli.testing.wings import Planform, surface_mesh

    path = tmp_path / "wall.su2"
    write_mesh(surface_mesh(Planform(), n_chord=9, n_span=4), path)
    whole = su2.read(path)
    assert not whole.cells
    for mesh, _ in run_ranks(size, lambda c: su2.read_part(path, c)):
        np.testing.assert_array_equal(mesh.points[np.searchsorted(mesh.global_ids, whole.marker_point_ids(["wing"]))],
                                      whole.points[whole.marker_point_ids(["wing"])])


def test_su2_read_by_parts_names_a_bad_line_in_one_ranks_share_on_every_rank(tmp_path, monkeypatch):
    from ffdcli.errors import InputError
    from ffdcli.io.formats import su2

    monkeypatch.setattr(su2, "CHUNK_BYTES", 1 << 14)
    original = (SAMPLES / "rect_wing.su2").read_text().splitlines(keepends=True)
    for block, offset, row in (("NELEM", 90_000, "10 1 2 x 4 7\n"), ("NPOIN", 20_000, "0.5 nan 0.1 7\n")):
        text = list(original)
        at = next(i for i, ln in enumerate(text) if ln.startswith(block)) + offset    # in the last rank's share
        text[at] = row
        bad = tmp_path / "bad.su2"
        bad.write_text("".join(text))
        with pytest.raises(InputError) as serial:
            su2.read(bad)
        said = []

        def one(comm, bad=bad, said=said):
            try:
                su2.read_part(bad, comm)
            except Exception as e:          # noqa: BLE001 - the test looks at what each rank raised
                said.append((comm.rank, type(e).__name__, str(e)))

        run_ranks(3, one)
        assert len(said) == 3 and {s[2] for s in said} == {str(serial.value)}, said
        assert f":{at + 1}: " in str(serial.value)


CGNS_SHARED = ["cgns/disc_adj_euler__cylinder3D__cylinder3D.cgns", "cgns/euler__wedge__mesh_wedge_inv.cgns",
               "cgns/incomp_navierstokes__bend__mesh_bend_coarse.cgns", "cgns/airfoil__analysis__n0012.cgns",
               "cgns/vandv__rans__bump_in_channel__mesh_bump_2d_0089x041.cgns", "cgns/aero__meshing__volume__wing.cgns",
               "cgns/overset__mesh__near_tip.cgns"]


def _check_cgns_parts(path):
    from ffdcli.io.formats import cgns

    whole = cgns.read(path)
    for size in (2, 3, 5):
        owner = node_owners(whole.points, size)
        for r, (mesh, part) in enumerate(run_ranks(size, lambda c: cgns.read_part(path, c))):
            _same_local(mesh, part, whole, owner, r)
            assert mesh.source.zones == whole.source.zones


@pytest.mark.parametrize("rel", CGNS_SHARED)
def test_cgns_read_by_parts_is_the_part_of_the_whole_read(rel):
    """Structured and unstructured zones, several zones, 2D and 3D, surface meshes: hyperslabs of
    each rank's rows, the serial read's part."""
    _check_cgns_parts(shared_file(rel))


def test_cgns_read_by_parts_of_written_meshes(tmp_path):
    """Meshes written here (one zone, a section per type: tetrahedra; hexahedra and wedges)."""
    from ffdcli.io.formats import write_mesh

    for name in ("rect_wing_tets", "mixed_hex_wedge", "wing_hexes", "naca_quads_2d"):
        path = tmp_path / f"{name}.cgns"
        write_mesh(CASES[name], path)
        _check_cgns_parts(path)


def test_cgns_read_by_parts_names_a_bad_node_in_one_ranks_block_on_every_rank(tmp_path):
    """A NaN coordinate in the last rank's block of points (read by that rank only): every rank
    raises the serial read's error (the first bad node, how many more)."""
    import h5py

    from ffdcli.errors import InputError
    from ffdcli.io.formats import cgns, write_mesh

    path = tmp_path / "bad.cgns"
    write_mesh(CASES["rect_wing_tets"], path)
    n = CASES["rect_wing_tets"].n_points
    with h5py.File(path, "r+") as h5:
        zone = cgns.read(path).source.zones[0]
        ds = h5[zone.coordinates[1]]
        for node in (n - 5, n - 2):
            ds[node] = np.nan
    with pytest.raises(InputError) as serial:
        read_mesh(path)
    assert f"node {n - 5} " in str(serial.value) and "1 more" in str(serial.value)
    said = []

    def one(comm):
        try:
            cgns.read_part(path, comm)
        except Exception as e:          # noqa: BLE001 - the test looks at what each rank raised
            said.append((comm.rank, str(e)))

    run_ranks(3, one)
    assert len(said) == 3 and {s[1] for s in said} == {str(serial.value)}, said


def test_a_format_read_whole_is_broadcast_and_localized(tmp_path):
    """VTK (no reader by parts): :func:`ffdcli.io.formats.read_part` reads on rank 0, broadcasts and gives
    each rank the same local mesh as the readers by parts."""
    from ffdcli.io.formats import read_part, write_mesh

    path = tmp_path / "wing.vtu"
    write_mesh(CASES["mixed_hex_wedge"], path)
    whole = read_mesh(path)
    owner = node_owners(whole.points, 3)
    for r, (mesh, part) in enumerate(run_ranks(3, lambda c: read_part(path, c))):
        _same_local(mesh, part, whole, owner, r)


def test_an_adf_cgns_file_is_read_by_rank_0_and_localized(tmp_path, monkeypatch):
    """The ADF branch of :func:`ffdcli.io.formats.cgns.read_part` (h5py cannot slice ADF): rank 0 reads,
    broadcasts, each rank localizes (an HDF5 file standing in for the converted ADF one)."""
    from ffdcli.io.formats import cgns, write_mesh

    path = tmp_path / "wing.cgns"
    write_mesh(CASES["rect_wing_tets"], path)
    whole = cgns.read(path)
    monkeypatch.setattr(cgns, "container_of", lambda p: "adf")
    monkeypatch.setattr(cgns, "read", lambda p, progress=None: cgns._read_file(p, p, "hdf5", progress))
    owner = node_owners(whole.points, 2)
    for r, (mesh, part) in enumerate(run_ranks(2, lambda c: cgns.read_part(path, c))):
        _same_local(mesh, part, whole, owner, r)


def test_su2_read_by_parts_with_a_rank_that_gets_no_chunk():
    """Default chunks: the small sample's blocks are one chunk each, so rank 1 parses no row."""
    from ffdcli.io.formats import su2

    whole = su2.read(SAMPLES / "naca0012_2d.su2")
    owner = node_owners(whole.points, 2)
    for r, (mesh, part) in enumerate(run_ranks(2, lambda c: su2.read_part(SAMPLES / "naca0012_2d.su2", c))):
        _same_local(mesh, part, whole, owner, r)
