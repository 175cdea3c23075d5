"""``ffd deform`` on each MPI rank's local mesh (issue 17: no rank holds every node): 3 ranks as threads
(:mod:`ffdcli.testing.threadcomm`) against the serial run, bit for bit.

Each rank's mesh is its local mesh (:func:`ffdcli.parallel.partition.localize`: owned nodes, halo, every marker
node); every row it moves (its part's, owned and halo, and the surface's) equals the serial run's row
of that node, the other ranks' marker nodes stay where they were, the gate's report and the
recovery attempts are the serial ones, and the files rank 0 writes from the gathered rows are the
serial files byte for byte.
"""

from __future__ import annotations

import numpy as np
import pytest
import yaml
from conftest import SAMPLES

from ffdcli.app.deformation import deform
from ffdcli.app.run import load_run
from ffdcli.app.write import write_outputs
from ffdcli.design import load_design
from ffdcli.io import formats
from ffdcli.io.formats.su2_surface import read_surface_file
from ffdcli.mesh import diagonal as serial_diagonal
from ffdcli.parallel.distributed import diagonal, extent, gather_points
from ffdcli.parallel.partition import localize, node_owners
from ffdcli.testing.threadcomm import run_ranks
from ffdcli.testing.wings import extruded_wing_mesh

RANKS = 3


@pytest.fixture(scope="module")
def wing_file(tmp_path_factory):
    """A generated hexahedral wing mesh (1440 nodes) as an SU2 file."""
    mesh = extruded_wing_mesh(n_around=33, n_radial=9, n_span=5)
    path = tmp_path_factory.mktemp("wing") / "wing.su2"
    formats.write_mesh(mesh, path, mesh.points)
    return path


def _design(tmp_path, data: dict, name: str = "d.yaml"):
    p = tmp_path / name
    p.write_text(yaml.safe_dump(data))
    return p


def _serial_and_ranks(design, tmp_path, outputs: dict, *, cache_dir=None):
    """(serial run, its result, its written files) and, per rank, (local mesh, rows moved, points,
    report, recovery, recovered_with, from_cache, written) of the same design on local meshes."""
    serial_dir, mpi_dir = tmp_path / "serial", tmp_path / "mpi"
    serial_dir.mkdir()
    mpi_dir.mkdir()
    kw = {"use_cache": cache_dir is not None, "cache_dir": cache_dir}
    run = load_run(load_design(design), **kw)
    res = deform(run)
    written = write_outputs(run, res, **{k: serial_dir / v for k, v in outputs.items()})

    def one(comm):
        r = load_run(load_design(design), comm=comm, local=True, **kw)
        x = deform(r)
        w = write_outputs(r, x, comm=comm, **{k: mpi_dir / v for k, v in outputs.items()})
        q = None if x.quality is None else x.quality.to_dict()
        moved = np.union1d(r.warp_targets(), r.surface_ids)        # the part's rows and the surface
        return r.prep.mesh, moved, x.points, q, x.recovery, x.recovered_with, r.prep.from_cache, w

    return (run, res, written), run_ranks(RANKS, one)


def _same_files(serial_written: dict, mpi_written: dict):
    for kind, path in serial_written.items():
        if kind == "su2_ffd":
            continue
        for a, b in zip(np.atleast_1d(path), np.atleast_1d(mpi_written[kind]), strict=True):
            assert open(a, "rb").read() == open(b, "rb").read(), kind


def test_extent_and_diagonal_of_the_ranks_rows_are_the_whole_meshs(wing_file):
    mesh = formats.read_mesh(wing_file)
    owner = node_owners(mesh.points, RANKS)

    def one(comm):
        local, _ = localize(mesh, owner, comm.rank)
        return extent(local.points, comm), diagonal(local.points, comm), diagonal(np.zeros((0, 3)), comm)

    for (lo, hi), d, empty in run_ranks(RANKS, one):
        np.testing.assert_array_equal(lo, mesh.points.min(axis=0))
        np.testing.assert_array_equal(hi, mesh.points.max(axis=0))
        assert d == serial_diagonal(mesh.points) and empty == 0.0


@pytest.mark.parametrize("chunk", [1, 97, 1 << 20])
def test_gather_points_puts_every_owned_row_in_place_on_rank_0(wing_file, chunk):
    mesh = formats.read_mesh(wing_file)
    owner = node_owners(mesh.points, RANKS)
    X = mesh.points * 2.0 + 1.0

    def one(comm):
        local, part = localize(mesh, owner, comm.rank)
        return gather_points(part, X[local.global_ids], mesh.n_points, comm, chunk=chunk)

    got = run_ranks(RANKS, one)
    np.testing.assert_array_equal(got[0], X)
    assert all(g is None for g in got[1:])


def test_a_design_that_needs_recovery_gives_the_serial_rows_report_and_files(wing_file, tmp_path):
    """Dihedral 40 with IDWarp's short reach fails the gate: every recovery attempt runs (longer
    reach, rotation, increments: the warp rebuilt on each step's local rows), each rank's rows
    are the serial ones, the report and attempts too, and the files are the serial ones."""
    design = _design(tmp_path, {"mesh": str(wing_file), "surface": "wing", "box": {"points": [4, 4, 2]},
                                "changes": [{"dihedral": 40}], "volume": {"alpha": 0.25}})
    outputs = {"mesh_path": "out.su2", "lattice_path": "out_lattice.vtk", "surface_file": "surface.dat"}
    (run, res, written), ranks = _serial_and_ranks(design, tmp_path, outputs)
    assert len(res.recovery) >= 5 and any("increments" in a["attempt"] for a in res.recovery)
    seen = np.zeros(run.prep.mesh.n_points, dtype=int)
    for local, moved, pts, q, recovery, used, _, w in ranks:
        g = local.global_ids
        assert len(g) < run.prep.mesh.n_points          # a local mesh: not every node
        # the part's rows and the surface: the serial rows bit for bit; the other ranks' marker nodes
        # (not this rank's to warp) where they were
        np.testing.assert_array_equal(pts[moved], res.points[g[moved]])
        rest = np.setdiff1d(np.arange(len(g)), moved)
        assert len(rest)
        np.testing.assert_array_equal(pts[rest], local.points[rest])
        assert q == res.quality.to_dict()
        assert recovery == res.recovery and used == res.recovered_with
        seen[g[moved]] += 1
        assert w == ranks[0][7]             # what was written, agreed on every rank
    assert seen.min() >= 1
    assert sorted(ranks[0][7]) == sorted(written) == ["lattice", "mesh", "surface_file"]
    _same_files(written, ranks[0][7])
    ids, _ = read_surface_file(tmp_path / "mpi" / "surface.dat", 3)
    np.testing.assert_array_equal(ids, run.surface_ids)       # global node ids


def test_another_output_format_is_written_from_every_cell(wing_file, tmp_path):
    """A local mesh written as VTU (not the input's format): rank 0 reads the whole file again."""
    design = _design(tmp_path, {"mesh": str(wing_file), "surface": "wing", "box": {"points": [4, 4, 2]},
                                "changes": [{"twist": {"tip": 5}}]})
    (run, res, written), ranks = _serial_and_ranks(design, tmp_path, {"mesh_path": "out.vtu",
                                                                      "lattice_path": "out_lattice.vtk"})
    back = formats.read_mesh(ranks[0][7]["mesh"])
    assert back.n_cells == run.prep.mesh.n_cells
    np.testing.assert_array_equal(back.points, res.points)
    assert open(written["mesh"], "rb").read() == open(ranks[0][7]["mesh"], "rb").read()


def test_two_components_on_local_meshes_equal_the_serial_run(tmp_path):
    """Wing, tail and fin (three boxes, one volume motion) on the ranks' local meshes, the boxes
    read from the cache the serial run wrote (its surface ids are global on every rank)."""
    design = _design(tmp_path, {"mesh": str(SAMPLES / "wing_tail_fin.su2"), "components": [
        {"name": "wing", "surface": "wing", "box": {"points": [6, 8, 2]}, "changes": [{"twist": {"tip": -3}}]},
        {"name": "htail", "surface": "htail", "box": {"points": [5, 4, 2]}, "changes": [{"dihedral": 5}]}]})
    cache = tmp_path / "cache"
    cache.mkdir()
    (run, res, written), ranks = _serial_and_ranks(design, tmp_path, {"mesh_path": "out.su2"}, cache_dir=cache)
    assert not run.single
    for local, moved, pts, q, recovery, _, from_cache, _ in ranks:
        assert from_cache
        np.testing.assert_array_equal(pts[moved], res.points[local.global_ids[moved]])
        assert q == res.quality.to_dict() and recovery == res.recovery
    assert open(written["mesh"], "rb").read() == open(ranks[0][7]["mesh"], "rb").read()


def test_the_constraints_of_ffd_deform_on_local_meshes_are_the_serial_ones(tmp_path):
    """``ffd deform --json`` reports the design's constraints (surface and lattice only): the same
    table from every rank's local mesh."""
    from ffdcli.api import constraints_report

    design = _design(tmp_path, {"mesh": str(SAMPLES / "rect_wing.su2"), "surface": "wing",
                                "box": {"points": [6, 8, 2], "sections": "xy"}, "changes": [{"twist": {"tip": 3}}],
                                "constraints": [{"volume": {"lower": 1.0}},
                                                {"thickness": {"chord": [0.3, 0.6], "span": [0.2, 0.8]}}]})
    serial = constraints_report(load_run(load_design(design), use_cache=False))
    got = run_ranks(RANKS, lambda comm: constraints_report(load_run(load_design(design), use_cache=False, comm=comm,
                                                                    local=True)))
    assert len(serial) > 2 and all(g == serial for g in got)


def _printed_by_parts(path, X, monkeypatch, piece):
    """(rank 0's written bytes, the serial writer's bytes, by_parts flags) of ``X`` (every node's new
    coordinates) written as SU2 by 3 thread ranks that read ``path`` by parts."""
    from ffdcli.io import parts
    from ffdcli.io.formats import su2
    from ffdcli.parallel.partition import node_owners

    monkeypatch.setattr(su2, "CHUNK_BYTES", 1 << 12)      # many parse chunks: every rank holds rows
    whole = formats.read_mesh(path)
    out = path.parent / f"{path.stem}_serial_out.su2"
    formats.write_mesh(whole, out, X)

    def one(comm):
        local, part = su2.read_part(path, comm)
        assert np.array_equal(local.global_ids[part.rows], part.ids)
        used, mesh = parts.rendered_mesh(local, part, X[local.global_ids], out.with_name("p.su2"), comm,
                                               piece=piece)
        if used and comm.is_root:
            target = path.parent / f"{path.stem}_parts_out.su2"
            formats.write_mesh(mesh, target, mesh.points)
            return used, target.read_bytes()
        return used, None

    got = run_ranks(RANKS, one)
    owner = node_owners(whole.points, RANKS)
    assert len(set(owner.tolist())) == RANKS
    return got, out.read_bytes()


@pytest.mark.parametrize("piece", [4099, 1 << 26])
def test_the_ranks_print_their_own_rows_and_rank_0_writes_the_serial_file(wing_file, tmp_path, monkeypatch,
                                                                            piece):
    """Each rank prints the SU2 point rows it read (the moved ones; the others keep their text) and
    rank 0 copies the texts, received in rounds of ``piece`` bytes: the serial writer's file byte
    for byte, also when only some rows move and for a 2D mesh with CRLF line ends."""
    mesh = formats.read_mesh(wing_file)
    rng = np.random.default_rng(3)
    some = mesh.points.copy()
    some[rng.random(len(some)) < 0.3] += 1e-3 * np.pi
    cases = [(wing_file, mesh.points * 1.1 + 1 / 3), (wing_file, some)]
    text = (SAMPLES / "naca0012_2d.su2").read_bytes().replace(b"\n", b"\r\n")
    crlf = tmp_path / "crlf_2d.su2"
    crlf.write_bytes(text)
    m2 = formats.read_mesh(crlf)
    moved2 = m2.points.copy()
    moved2[:, :2] *= 1.0 + 1e-7
    cases.append((crlf, moved2))
    for path, X in cases:
        got, serial = _printed_by_parts(path, X, monkeypatch, piece)
        assert all(used for used, _ in got)
        assert got[0][1] == serial
        assert all(b is None for _, b in got[1:])


def test_a_file_with_su2s_ffd_section_is_gathered_and_its_section_refreshed(tmp_path, monkeypatch):
    """SU2's FFD section needs every surface node: no printing by parts (the gather, then the
    serial writer, which refreshes the section)."""
    from conftest import shared_file

    from ffdcli.io import parts
    from ffdcli.io.formats import su2

    src = shared_file("su2/deformation__rae2822__mesh_RAE2822_turb_ffd.su2")
    path = tmp_path / "ffd.su2"
    path.write_bytes(src.read_bytes())
    X = formats.read_mesh(path).points.copy()
    X[:, 1] *= 1.01

    def one(comm):
        local, part = su2.read_part(path, comm)
        return parts.rendered_mesh(local, part, X[local.global_ids], tmp_path / "o.su2", comm)

    assert run_ranks(RANKS, one) == [(False, None)] * RANKS


@pytest.fixture(scope="module")
def rans_ogrid(tmp_path_factory):
    """A NACA 0012 O-mesh with a 1e-6 chord first cell (a boundary layer of quads, 4365 nodes)."""
    from ffdcli.testing.ogrid import airfoil_ogrid_mesh

    path = tmp_path_factory.mktemp("rans") / "ogrid.su2"
    formats.write_mesh(airfoil_ogrid_mesh("0012", n_around=97, n_radial=45, first_cell=1e-6), path)
    return path


@pytest.mark.parametrize("mesh, ranks", [("ogrid", 2), ("ogrid", 3), ("ogrid", 5), ("rae2822", 3)])
def test_a_boundary_layer_moves_on_local_meshes_as_in_the_serial_run(mesh, ranks, rans_ogrid, tmp_path):
    """The wall layer of a RANS mesh (its stacks walked through cells that no one rank's part holds
    whole) moves on 2, 3 and 5 ranks' local meshes as in the serial run: every row each rank moves, the
    wall report and the gate's, and the files, bit for bit; the first cells kept (the layer did move)."""
    from conftest import shared_file

    if mesh == "rae2822":
        path, surface = shared_file("su2/deformation__rae2822__mesh_RAE2822_turb_ffd.su2"), "AIRFOIL"
    else:
        path, surface = rans_ogrid, "airfoil"
    design = _design(tmp_path, {"mesh": str(path), "surface": surface, "box": {"points": [6, 5]},
                                "changes": [{"shape": {"upper": [0, 0.01, 0.02, 0.02, 0.01, 0],
                                                       "lower": [0, -0.01, 0, -0.01, 0, 0], "sections": "all"}}]})
    outputs = {"mesh_path": "out.su2"}
    serial_dir, mpi_dir = tmp_path / "serial", tmp_path / "mpi"
    serial_dir.mkdir()
    mpi_dir.mkdir()
    run = load_run(load_design(design), use_cache=False)
    res = deform(run)
    written = write_outputs(run, res, **{k: serial_dir / v for k, v in outputs.items()})
    assert run.volume.model().layer is not None
    assert res.wall_layer is not None and abs(res.wall_layer.ratio_min - 1) < 1e-3 > abs(res.wall_layer.ratio_max - 1)

    def one(comm):
        r = load_run(load_design(design), comm=comm, local=True, use_cache=False)
        x = deform(r)
        w = write_outputs(r, x, comm=comm, **{k: mpi_dir / v for k, v in outputs.items()})
        moved = np.union1d(r.warp_targets(), r.surface_ids)
        return r.prep.mesh.global_ids, moved, x.points, x.quality.to_dict(), x.wall_layer, w

    got = run_ranks(ranks, one)
    for g, moved, pts, q, wall, _ in got:
        assert len(g) < run.prep.mesh.n_points
        np.testing.assert_array_equal(pts[moved], res.points[g[moved]])
        assert q == res.quality.to_dict() and wall == res.wall_layer
    _same_files(written, got[0][5])


@pytest.mark.parametrize("ranks, seed", [(2, 0), (3, 1), (4, 2), (5, 3), (5, -1)])
def test_the_wall_layer_of_any_split_is_the_serial_layers_rows(ranks, seed, rans_ogrid):
    """Any owner of each node (random splits, and node ids dealt round the ranks: every step of a stack on
    another rank than the one before; the Morton split is the other tests'): each rank's
    wall layer (off-wall edges from the owners, stacks walked step by step by the owners of their tops)
    is the serial layer's rows of its targets, bit for bit."""
    from ffdcli.parallel.distributed import RankNodes
    from ffdcli.volume.warp import WarpSettings, prepare_mesh_warp

    mesh = formats.read_mesh(rans_ogrid)
    serial, _ = prepare_mesh_warp(mesh, "airfoil", WarpSettings())
    ser = serial.layer
    assert ser is not None
    if seed < 0:            # dealt round: ring k of 96 nodes, node i on rank (k + i) % 5: each ring on another
        owner = np.arange(mesh.n_points) % ranks
    else:
        owner = np.random.default_rng(seed).integers(0, ranks, mesh.n_points)

    def one(comm):
        local, part = localize(mesh, owner, comm.rank)
        owned = np.zeros(len(local.points), dtype=bool)
        owned[part.rows[part.owned]] = True
        nodes = RankNodes(comm, local.global_ids, owned)
        model, _ = prepare_mesh_warp(local, "airfoil", WarpSettings(), targets=part.rows, nodes=nodes,
                                     size=serial_diagonal(mesh.points))
        return local.global_ids, model

    where = {int(t): i for i, t in enumerate(serial.target_ids[ser.rows])}
    covered = set()
    for g, model in run_ranks(ranks, one):
        lay = model.layer
        if lay is None:
            assert not len(model.target_ids)
            continue
        gid = g[model.target_ids[lay.rows]]
        idx = np.array([where[int(t)] for t in gid], dtype=np.int64)
        np.testing.assert_array_equal(lay.weight, ser.weight[idx])
        np.testing.assert_array_equal(lay.position, ser.position[idx])
        assert (lay.partition != ser.partition[idx]).nnz == 0
        np.testing.assert_array_equal(lay.partition[np.argsort(idx)].indices, ser.partition[np.sort(idx)].indices)
        np.testing.assert_array_equal(lay.normals, ser.normals)
        assert lay.thickness == ser.thickness
        covered |= set(gid.tolist())
    assert covered == set(where)
