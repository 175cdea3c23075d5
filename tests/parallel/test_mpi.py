"""MPI runs (ffdcli.parallel.comm): the serial stand-in, the partitioned kernels, and ``mpiexec -n 2 ffd``
compared with the serial run on the bundled samples.

The tests that launch ``mpiexec`` need the ``[mpi]`` extra (mpi4py and the mpich wheel, which
``make test`` installs); without it they are skipped with the reason.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from conftest import REPO, SAMPLES, run_ffd

from ffdcli.parallel.comm import SerialComm, launched_size, share, world

BIN = Path(sys.executable).parent
MPIEXEC = shutil.which("mpiexec", path=str(BIN)) or shutil.which("mpiexec")


def _have_mpi4py() -> bool:
    try:
        import mpi4py  # noqa: F401
    except ImportError:
        return False
    return True


needs_mpi = pytest.mark.skipif(not (_have_mpi4py() and MPIEXEC),
                               reason="the [mpi] extra (mpi4py + mpich) is not installed: pip install -e '.[mpi]'")


@pytest.fixture(scope="module", autouse=True)
def _compiled_kernels(tmp_path_factory):
    """Compile (and cache) the numba kernels once in this process before any ``mpiexec``: ranks that
    compile the same ``cache=True`` kernel at the same moment race on writing its cache files (seen
    once here as a failed 2-rank embedding right after a kernel changed)."""
    if not (_have_mpi4py() and MPIEXEC):
        return
    from ffdcli.app.deformation import deform
    from ffdcli.app.run import load_run
    from ffdcli.design import load_design

    design = tmp_path_factory.mktemp("warmup") / "design.yaml"
    design.write_text(f"mesh: {SAMPLES / 'rect_wing.su2'}\nsurface: wing\n"
                      "box: {points: [4, 4, 2], sections: xy}\nchanges: [{twist: {tip: 1}}]\n")
    deform(load_run(load_design(design), use_cache=False))


def _env():
    e = {k: v for k, v in os.environ.items() if not k.startswith(("PMI_", "OMPI_", "PMIX_", "SLURM_"))}
    e["PYTHONPATH"] = str(REPO) + os.pathsep + e.get("PYTHONPATH", "")
    return e


def mpirun(n: int, *args, cwd=None, timeout=600) -> subprocess.CompletedProcess:
    """``mpiexec -n N python ARGS`` (text mode, captured)."""
    return subprocess.run([MPIEXEC, "-n", str(n), sys.executable, *map(str, args)], cwd=cwd, env=_env(),
                          capture_output=True, text=True, timeout=timeout)


def mpi_ffd(n: int, *args, cwd=None) -> subprocess.CompletedProcess:
    return mpirun(n, "-m", "ffdcli", *args, cwd=cwd)


def mpi_script(n: int, code: str, tmp_path: Path) -> subprocess.CompletedProcess:
    script = tmp_path / "script.py"
    script.write_text(textwrap.dedent(code))
    return mpirun(n, script, cwd=tmp_path)


# ---------------------------------------------------------------------------------------------- serial


@pytest.mark.parametrize("n", [0, 1, 2, 7, 100, 1001])
@pytest.mark.parametrize("size", [1, 2, 3, 8])
def test_share_partitions_in_rank_order(n, size):
    blocks = [share(n, r, size) for r in range(size)]
    assert blocks[0][0] == 0 and blocks[-1][1] == n
    assert all(a[1] == b[0] for a, b in zip(blocks, blocks[1:]))
    lengths = [hi - lo for lo, hi in blocks]
    assert max(lengths) - min(lengths) <= 1


def test_serial_comm_is_the_identity():
    comm = SerialComm()
    a = np.arange(6.0).reshape(3, 2)
    assert comm.size == 1 and comm.is_root and comm.share(5) == (0, 5)
    np.testing.assert_array_equal(comm.allgather_rows(a), a)
    np.testing.assert_array_equal(comm.allreduce_sum(a), a)
    assert comm.bcast({"x": 1}) == {"x": 1} and comm.allgather(3) == [3]
    assert comm.run(lambda x: x + 1, 1) == 2
    assert comm.root_then_bcast(lambda: "once") == "once"
    with pytest.raises(ZeroDivisionError):
        comm.run(lambda: 1 / 0)


def test_world_is_serial_without_a_launcher_and_refuses_mpiexec_without_mpi4py(monkeypatch):
    assert launched_size({}) == 1 and launched_size({"PMI_SIZE": "4"}) == 4
    assert launched_size({"OMPI_COMM_WORLD_SIZE": "3"}) == 3
    assert isinstance(world({}), SerialComm) and world({}).size == 1
    import ffdcli.parallel.comm as par
    from ffdcli.errors import InputError

    monkeypatch.setattr(par, "mpi_available", lambda: False)
    with pytest.raises(InputError, match=r"mpi4py is not installed.*ffdcli\[mpi\]"):
        par.world({"PMI_SIZE": "2"})


def test_warp_rows_are_the_rows_of_the_whole_warp():
    """Each rank's block of volume nodes (``warp(rows=)``) is bit for bit that block of the whole warp,
    sliding nodes included."""
    from ffdcli.io.formats import read_mesh
    from ffdcli.volume.warp import WarpSettings, prepare_mesh_warp, warp

    mesh = read_mesh(SAMPLES / "rect_wing.su2")
    model, _ = prepare_mesh_warp(mesh, ["wing"], WarpSettings())
    rng = np.random.default_rng(0)
    b = 0.01 * rng.normal(size=(model.n_surface, 3))
    ang = 0.05 * rng.normal(size=(model.n_surface, 3))
    from scipy.spatial.transform import Rotation

    R = Rotation.from_rotvec(ang).as_matrix()
    whole = warp(model, b, R)
    for size in (2, 3):
        parts = [warp(model, b, R, rows=share(model.n_targets, r, size)) for r in range(size)]
        np.testing.assert_array_equal(np.concatenate(parts), whole[model.target_ids])
    assert warp(model, b, R, rows=(5, 5)).shape == (0, 3)
    with pytest.raises(ValueError):
        warp(model, b, R, rows=(0, model.n_targets + 1))


# ---------------------------------------------------------------------------------------------- mpiexec


@needs_mpi
def test_mpi_comm_collectives_and_error_agreement(tmp_path):
    """Collectives over 2 ranks; an error on rank 1 only is raised on both ranks (rank 1 its own,
    rank 0 a RankError with rank 1's message and exit status): nobody hangs."""
    proc = mpi_script(2, """
        import numpy as np
        from ffdcli.parallel.comm import MPIComm, RankError
        from ffdcli.errors import InputError
        c = MPIComm()
        rows = c.allgather_rows(np.full((c.rank + 1, 2), float(c.rank)))
        assert rows.shape == (3, 2) and rows[0, 0] == 0 and rows[2, 0] == 1
        flags = c.allgather_rows(np.array([c.rank == 1]))
        assert flags.tolist() == [False, True]
        assert c.allreduce_sum(np.ones(3)).tolist() == [2.0, 2.0, 2.0]
        assert c.root_then_bcast(lambda: "from root") == "from root"
        def fail_on_1():
            if c.rank == 1:
                raise InputError("bad thing on rank 1", path="x.su2")
            return 1
        try:
            c.run(fail_on_1)
        except RankError as e:
            print(f"rank {c.rank}: RankError {e.exit_code} {e.rank} {e}\\n", end="", flush=True)
        except InputError as e:
            print(f"rank {c.rank}: own {e.exit_code} {e}\\n", end="", flush=True)
        else:
            print(f"rank {c.rank}: no error\\n", end="", flush=True)
    """, tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert "rank 0: RankError 2 1 x.su2: bad thing on rank 1" in proc.stdout
    assert "rank 1: own 2 x.su2: bad thing on rank 1" in proc.stdout


@needs_mpi
def test_mpi_embedding_equals_serial_bit_for_bit(tmp_path):
    proc = mpi_script(2, f"""
        import sys
        sys.path.insert(0, {str(REPO / 'tests')!r})
        import numpy as np
        from lattice_cases import wing_lattice
        from ffdcli.lattice.embedding import embed
        from ffdcli.lattice.lattice import evaluate
        from ffdcli.parallel.comm import MPIComm
        c = MPIComm()
        lat = wing_lattice((8, 6, 2), (3, 3, 1))
        rng = np.random.default_rng(1)
        X = evaluate(lat, rng.uniform(0, 1, (4001, 3)))
        X[:200] += rng.normal(scale=0.3, size=(200, 3))      # some outside
        a, b = embed(lat, X, comm=c), embed(lat, X)
        assert np.array_equal(a.params, b.params) and np.array_equal(a.residual, b.residual)
        assert np.array_equal(a.inside, b.inside) and (~a.inside).any()
        for f, g in zip(a.values, b.values):
            assert np.array_equal(f, g)
        print(f"same {{c.rank}}\\n", end="", flush=True)   # one write: ranks never interleave
    """, tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert "same 0" in proc.stdout and "same 1" in proc.stdout


def _design(tmp_path: Path, mesh: str = "rect_wing.su2", extra: str = "") -> Path:
    d = tmp_path / "design.yaml"
    d.write_text(textwrap.dedent(f"""
        mesh: {SAMPLES / mesh}
        surface: wing
        box:
          points: [6, 8, 2]
          sections: xy
        volume:
          method: idw
        changes:
          - twist: [0, 2, 4, 6, 8, 10, 12, 14]
          - sweep: 5
        output:
          mesh: out.su2
          lattice: lattice.vtk
        {extra}
    """))
    return d


@needs_mpi
def test_mpiexec_deform_writes_the_serial_mesh_once_and_prints_once(tmp_path):
    design = _design(tmp_path)
    serial = run_ffd("deform", design, "-o", tmp_path / "serial.su2", "--no-cache", "--json", cwd=tmp_path)
    assert serial.returncode == 0, serial.stderr
    (tmp_path / "cache").mkdir()
    par = mpi_ffd(2, "deform", design, "-o", tmp_path / "mpi.su2", "--json", "--cache-dir", tmp_path / "cache",
                  cwd=tmp_path)
    assert par.returncode == 0, par.stderr
    assert (tmp_path / "mpi.su2").read_bytes() == (tmp_path / "serial.su2").read_bytes()
    lines = [ln for ln in par.stdout.splitlines() if ln.strip()]
    assert len(lines) == 1, par.stdout                 # one JSON summary, from rank 0
    a, b = json.loads(serial.stdout), json.loads(lines[0])
    assert a["max_displacement"] == b["max_displacement"] and a["quality"] == b["quality"]
    # the cache written by rank 0 is read by any rank count: 2 ranks, then 3, then the serial run
    caches = list((tmp_path / "cache").glob("*.ffdcache.npz"))
    assert len(caches) == 1
    again = mpi_ffd(3, "deform", design, "-o", tmp_path / "mpi3.su2", "--json", "--cache-dir", tmp_path / "cache",
                    cwd=tmp_path)
    assert again.returncode == 0, again.stderr
    assert json.loads(again.stdout)["from_cache"] is True
    assert (tmp_path / "mpi3.su2").read_bytes() == (tmp_path / "serial.su2").read_bytes()
    cached = run_ffd("deform", design, "-o", tmp_path / "s2.su2", "--json", "--cache-dir", tmp_path / "cache",
                     cwd=tmp_path)
    assert json.loads(cached.stdout)["from_cache"] is True
    assert (tmp_path / "s2.su2").read_bytes() == (tmp_path / "serial.su2").read_bytes()


@needs_mpi
def test_mpiexec_errors_end_every_rank_with_one_message_and_one_status(tmp_path):
    design = _design(tmp_path, mesh="no_such_mesh.su2")
    proc = mpi_ffd(2, "deform", design, "--json", cwd=tmp_path)
    assert proc.returncode == 2, (proc.returncode, proc.stderr)
    assert proc.stderr.count("ffd: error:") == 1, proc.stderr
    assert "Traceback" not in proc.stderr
    assert proc.stdout.count('"exit_code": 2') == 1
    # a quality failure (exit 3): nothing written, every rank agrees
    bad = _design(tmp_path, extra="")
    bad.write_text(bad.read_text().replace("[0, 2, 4, 6, 8, 10, 12, 14]", "[0, 0, 0, 0, 0, 0, 90, -90]"))
    proc = mpi_ffd(2, "deform", bad, "-o", tmp_path / "bad.su2", "--no-cache", cwd=tmp_path)
    assert proc.returncode == 3, proc.stderr
    assert "fails the quality" in proc.stderr
    # the same refusal as the serial run, recovery attempts (intermediate warps, shared) included
    ser = run_ffd("deform", bad, "-o", tmp_path / "bad.su2", "--no-cache", "--json", cwd=tmp_path)
    par = mpi_ffd(2, "deform", bad, "-o", tmp_path / "bad.su2", "--no-cache", "--json", cwd=tmp_path)
    assert ser.returncode == par.returncode == 3
    assert json.loads(ser.stdout) == json.loads(par.stdout)
    assert proc.stderr.count("ffd: error:") == 1, proc.stderr
    assert not (tmp_path / "bad.su2").exists()


@needs_mpi
def test_mpi_design_model_point_sets_sum_their_reverse_products(tmp_path):
    """Each rank adds only its own points; points_vjp is the serial vjp of all the points (summed
    over ranks), forward products stay local, names and values are the same on every rank."""
    design = _design(tmp_path)
    proc = mpi_script(2, f"""
        import numpy as np
        from ffdcli.api import DesignModel
        from ffdcli.parallel.comm import MPIComm, RankError
        from ffdcli.errors import InputError
        c = MPIComm()
        m = DesignModel.from_file({str(design)!r}, comm=c, cache_dir={str(tmp_path)!r})
        s = DesignModel.from_file({str(design)!r}, use_cache=False)
        assert m.names == s.names and np.array_equal(m.values, s.values)
        rng = np.random.default_rng(5)
        X = m.surface_points()[::7] + rng.normal(scale=1e-3, size=(len(m.surface_points()[::7]), 3))
        g = rng.normal(size=X.shape)
        lo, hi = c.share(len(X))
        m.add_points("mine", X[lo:hi])
        s.add_points("all", X)
        v = m.values + 0.5
        m.set_values(v); s.set_values(v)
        par = m.points_vjp("mine", g[lo:hi])
        ser = s.points_vjp("all", g)
        assert np.allclose(par, ser, rtol=1e-12, atol=1e-12 * np.abs(ser).max()), (par, ser)
        dv = rng.normal(size=m.n_vars)
        assert np.array_equal(m.points_jvp("mine", dv), s.points_jvp("all", dv)[lo:hi])
        assert np.array_equal(m.points("mine"), s.points("all")[lo:hi])
        said = []
        try:
            m.set_values(v + c.rank)          # ranks disagree: refused on every rank
        except (InputError, RankError) as e:
            said.append(f"refused {{c.rank}} {{type(e).__name__}}")
        said.append(f"ok {{c.rank}}")
        # one file per rank: two ranks printing to one stdout interleave their lines
        open({str(tmp_path)!r} + f"/rank{{c.rank}}.txt", "w").write("; ".join(said))
    """, tmp_path)
    assert proc.returncode == 0, proc.stderr
    for r in (0, 1):
        said = (tmp_path / f"rank{r}.txt").read_text()
        assert f"ok {r}" in said and f"refused {r}" in said


@needs_mpi
def test_mpiexec_grad_jacobian_and_box_equal_the_serial_run(tmp_path):
    """``ffd grad`` through the volume (each rank sums its share of the transpose warp), ``ffd
    jacobian`` and ``ffd box`` under 2 ranks: the serial results, written once."""
    design = _design(tmp_path)
    # a sensitivity on every node (surface and volume) so that the transpose warp is used
    vol = tmp_path / "volume_sens.csv"
    from ffdcli.io.formats import read_mesh

    mesh = read_mesh(SAMPLES / "rect_wing.su2")
    dep = run_ffd("deform", design, "-o", tmp_path / "d.su2", "--no-cache", cwd=tmp_path)
    assert dep.returncode == 0, dep.stderr
    pts = read_mesh(tmp_path / "d.su2").points
    rng = np.random.default_rng(2)
    g = rng.normal(size=pts.shape) * np.exp(-np.linalg.norm(pts - pts.mean(0), axis=1))[:, None]
    np.savetxt(vol, np.hstack([pts, g]), delimiter=",", header="x,y,z,dJ/dx,dJ/dy,dJ/dz", comments="")
    assert mesh.n_points == len(pts)
    for sfile in (vol,):
        ser = run_ffd("grad", design, "--sens", sfile, "--json", cwd=tmp_path)
        assert ser.returncode == 0, ser.stderr
        par = mpi_ffd(2, "grad", design, "--sens", sfile, "--json", "-o", tmp_path / "grad.json", cwd=tmp_path)
        assert par.returncode == 0, par.stderr
        a, b = json.loads(ser.stdout), json.loads(par.stdout)
        assert a["through_volume"] and b["through_volume"]
        for k, v in a["gradient"].items():
            assert abs(b["gradient"][k] - v) <= 1e-12 * max(1.0, max(abs(x) for x in a["gradient"].values())), k
        assert json.loads((tmp_path / "grad.json").read_text()) == b["gradient"]
    ser = run_ffd("jacobian", design, "-o", tmp_path / "js.npz", cwd=tmp_path)
    par = mpi_ffd(2, "jacobian", design, "-o", tmp_path / "jp.npz", cwd=tmp_path)
    assert ser.returncode == 0 and par.returncode == 0, par.stderr
    with np.load(tmp_path / "js.npz") as A, np.load(tmp_path / "jp.npz") as B:
        for k in A.files:
            np.testing.assert_array_equal(A[k], B[k])
    ser = run_ffd("box", SAMPLES / "rect_wing.su2", "--points", "6,8,2", "--lattice", tmp_path / "bs.vtk",
                  "--cache-dir", tmp_path, cwd=tmp_path)
    par = mpi_ffd(2, "box", SAMPLES / "rect_wing.su2", "--points", "6,8,2", "--lattice", tmp_path / "bp.vtk",
                  "--cache-dir", tmp_path, "--rebuild", cwd=tmp_path)
    assert ser.returncode == 0 and par.returncode == 0, par.stderr
    assert (tmp_path / "bs.vtk").read_bytes() == (tmp_path / "bp.vtk").read_bytes()
    assert par.stdout.count("ffd box:") == 1


@needs_mpi
def test_mpiexec_constraints_equal_the_serial_run(tmp_path):
    """``ffd constraints --jacobian`` under 2 ranks: the serial values and Jacobian, printed and written once."""
    design = _design(tmp_path, extra="constraints: [{volume: {lower: 1.0}}, "
                                     "{thickness: {chord: [0.3, 0.6], span: [0.2, 0.8]}}]")
    ser = run_ffd("constraints", design, "--json", "--jacobian", tmp_path / "cs.npz", cwd=tmp_path)
    assert ser.returncode == 0, ser.stderr
    par = mpi_ffd(2, "constraints", design, "--json", "--jacobian", tmp_path / "cp.npz", cwd=tmp_path)
    assert par.returncode == 0, par.stderr
    assert json.loads(ser.stdout)["constraints"] == json.loads(par.stdout)["constraints"]
    assert par.stdout.count('"constraints"') == 1
    with np.load(tmp_path / "cs.npz") as A, np.load(tmp_path / "cp.npz") as B:
        assert A.files == B.files
        for k in A.files:
            np.testing.assert_array_equal(A[k], B[k])


@needs_mpi
def test_mpiexec_deform_to_another_format_writes_every_cell(tmp_path):
    """Each rank reads only the cells around its nodes; rank 0 writing a new format (.su2 -> .vtu,
    from scratch) reads the whole mesh again: every cell and marker of the serial output."""
    from ffdcli.io.formats import read_mesh

    design = _design(tmp_path)
    ser = run_ffd("deform", design, "-o", tmp_path / "s.vtu", "--no-cache", cwd=tmp_path)
    par = mpi_ffd(2, "deform", design, "-o", tmp_path / "p.vtu", "--no-cache", cwd=tmp_path)
    assert ser.returncode == 0 and par.returncode == 0, par.stderr
    a, b = read_mesh(tmp_path / "s.vtu"), read_mesh(tmp_path / "p.vtu")
    np.testing.assert_array_equal(a.points, b.points)
    assert a.n_cells == b.n_cells == read_mesh(SAMPLES / "rect_wing.su2").n_cells
    for x, y in zip(a.cells, b.cells, strict=True):
        np.testing.assert_array_equal(x.data, y.data)
    assert list(a.markers) == list(b.markers)


@needs_mpi
def test_mpiexec_deform_of_a_cgns_mesh_read_by_parts_equals_serial(tmp_path):
    """CGNS/HDF5: each rank reads hyperslabs of its rows of the connectivity; the output (the input
    file with its coordinates patched, by rank 0) and the report are the serial run's."""
    from ffdcli.io.formats import read_mesh, write_mesh

    write_mesh(read_mesh(SAMPLES / "rect_wing.su2"), tmp_path / "wing.cgns")
    design = _design(tmp_path)
    design.write_text(design.read_text().replace(str(SAMPLES / "rect_wing.su2"), str(tmp_path / "wing.cgns")))
    ser = run_ffd("deform", design, "-o", tmp_path / "s.cgns", "--no-cache", "--json", cwd=tmp_path)
    par = mpi_ffd(2, "deform", design, "-o", tmp_path / "p.cgns", "--no-cache", "--json", cwd=tmp_path)
    assert ser.returncode == 0 and par.returncode == 0, par.stderr
    a, b = json.loads(ser.stdout), json.loads(par.stdout)
    assert a["quality"] == b["quality"] and a["max_displacement"] == b["max_displacement"]
    sm, pm = read_mesh(tmp_path / "s.cgns"), read_mesh(tmp_path / "p.cgns")
    np.testing.assert_array_equal(sm.points, pm.points)
    assert sm.n_cells == pm.n_cells and list(sm.markers) == list(pm.markers)


@needs_mpi
def test_mpiexec_check_shares_the_cells_and_prints_the_serial_report(tmp_path):
    """``ffd check`` under 2 ranks: each judges its part of the mesh read by parts; the report (and a
    refusal's exit status and report) is the serial one, printed once."""
    for args in ([], ["--threshold", "0.2", "--worst", "3"]):
        ser = run_ffd("check", SAMPLES / "rect_wing.su2", "--json", *args, cwd=tmp_path)
        par = mpi_ffd(2, "check", SAMPLES / "rect_wing.su2", "--json", *args, cwd=tmp_path)
        assert ser.returncode == par.returncode == (3 if args else 0), par.stderr
        lines = [ln for ln in par.stdout.splitlines() if ln.strip()]
        assert len(lines) == 1, par.stdout
        a, b = json.loads(ser.stdout), json.loads(lines[0])
        for d in (a, b, a.get("report", {}), b.get("report", {})):
            d.pop("seconds", None)
        assert a == b


@needs_mpi
def test_mpiexec_read_by_parts_gives_each_rank_the_local_mesh_of_the_whole_read(tmp_path):
    """Over real MPI (mpi4py's all-to-alls and reductions): SU2 (small chunks: many per rank) and
    CGNS/HDF5 (hyperslabs of points and cells) read by parts equal :func:`ffdcli.parallel.partition.localize`
    of the serial read on each of 2 ranks, and no rank holds every node."""
    from ffdcli.io.formats import read_mesh, write_mesh

    write_mesh(read_mesh(SAMPLES / "rect_wing.su2"), tmp_path / "wing.cgns")
    proc = mpi_script(2, f"""
        import numpy as np
        from ffdcli.io.formats import read_mesh, read_part, su2
        from ffdcli.parallel.comm import MPIComm
        from ffdcli.parallel.partition import localize, node_owners
        c = MPIComm()
        su2.CHUNK_BYTES = 1 << 15
        for path in ({str(SAMPLES / 'rect_wing.su2')!r}, {str(tmp_path / 'wing.cgns')!r}):
            whole = read_mesh(path)
            mesh, part = read_part(path, c)
            want, want_part = localize(whole, node_owners(whole.points, 2), c.rank)
            assert mesh.is_local and len(mesh.global_ids) < whole.n_points
            for f in ("global_ids", "points"):
                assert np.array_equal(getattr(mesh, f), getattr(want, f)), f
            for x, y in zip(mesh.cells, want.cells, strict=True):
                assert x.type == y.type and np.array_equal(x.data, y.data)
            for k, v in want.markers.items():
                assert all(np.array_equal(x.data, y.data) for x, y in zip(mesh.markers[k], v, strict=True))
            for f in ("ids", "points", "owned", "rows"):
                assert np.array_equal(getattr(part, f), getattr(want_part, f)), f
            for f in ("cell_ids", "counted"):
                assert all(np.array_equal(x, y) for x, y in zip(getattr(part, f), getattr(want_part, f), strict=True))
            print(f"rank {{c.rank}} {{path[-4:]}} {{len(mesh.global_ids)}} of {{whole.n_points}}\\n", end="",
                  flush=True)
    """, tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.count(" of ") == 4, proc.stdout


@needs_mpi
@pytest.mark.parametrize("form", ["openfoam-binary-gz", "cgns-ngon"])   # (the ASCII reader: the serial tests)
def test_mpiexec_on_polyhedral_meshes_equals_the_serial_run(tmp_path, form):
    """Issue 32: an OpenFOAM case (binary, gzip) and a CGNS mesh of NGON_n/NFACE_n cells under 2 ranks: read by
    rank 0 and broadcast (polyhedra are defined by the whole face list), the warp shared by blocks
    of rows, the polyhedral gate on every rank, written once: the serial run's files byte for byte,
    its report, and a refusal's exit status; ``ffd check`` and ``ffd constraints`` too."""
    from ffdcli.io.formats.openfoam_case import polymesh_of, write_case
    from ffdcli.testing.cgns_poly import write_ngon_cgns
    from ffdcli.testing.wings import extruded_wing_mesh

    mesh = extruded_wing_mesh(n_around=25, n_radial=7, n_span=4)
    poly, patches = polymesh_of(mesh, wall=("wing",))
    if form == "cgns-ngon":
        src = write_ngon_cgns(tmp_path / "m.cgns", mesh.points, poly, patches)
        out_s, out_p = tmp_path / "s.cgns", tmp_path / "p.cgns"
    else:
        src = write_case(tmp_path / "case", mesh.points, poly, patches, binary=form.endswith("gz"),
                         compress=form.endswith("gz"))
        out_s, out_p = tmp_path / "s", tmp_path / "p"
    design = tmp_path / "twist.yaml"
    design.write_text(f"mesh: {src.name}\nsurface: wing\nbox: {{points: [5, 4, 2]}}\n"
                      "changes:\n  - twist: {tip: 4}\n  - sweep: 5\n"
                      "constraints:\n  - volume: {lower: 1}\n  - thickness: {chord: [0.3], span: [0.5]}\n")
    ser = run_ffd("deform", design, "-o", out_s, "--json", cwd=tmp_path)
    par = mpi_ffd(2, "deform", design, "-o", out_p, "--json", cwd=tmp_path)
    assert ser.returncode == 0 and par.returncode == 0, par.stderr
    lines = [ln for ln in par.stdout.splitlines() if ln.strip()]
    assert len(lines) == 1, par.stdout                                      # printed once
    a, b = json.loads(ser.stdout), json.loads(lines[0])
    assert a["quality"] == b["quality"] and a["max_displacement"] == b["max_displacement"]
    files = sorted(p.relative_to(out_s) for p in out_s.rglob("*") if p.is_file()) if out_s.is_dir() else [Path()]
    for rel in files:
        assert (out_s / rel).read_bytes() == (out_p / rel).read_bytes(), rel
    for cmd in (["check", out_p, "--json"], ["constraints", design, "--json"]):
        s, p = run_ffd(*cmd, cwd=tmp_path), mpi_ffd(2, *cmd, cwd=tmp_path)
        assert s.returncode == p.returncode == 0, p.stderr
        x, y = json.loads(s.stdout), json.loads(p.stdout)
        for d in (x, y):
            d.pop("seconds", None)
        assert x == y
    # ffd grad through the volume motion (a sensitivity at every node of the deformed mesh): the
    # serial gradient to rounding (the ranks' sums are added in another order)
    from ffdcli.io.formats import read_mesh

    pts = read_mesh(out_s).points
    sens = np.random.default_rng(0).standard_normal(pts.shape)
    rows = [f"{i},{x:.17g},{y:.17g},{z:.17g},{a:.17g},{b:.17g},{c:.17g}" for i, ((x, y, z), (a, b, c)) in
            enumerate(zip(pts, sens, strict=True))]
    (tmp_path / "sens.csv").write_text("PointID,x,y,z,Sensitivity_x,Sensitivity_y,Sensitivity_z\n" + "\n".join(rows))
    s = run_ffd("grad", design, "--sens", "sens.csv", "-o", "gs.json", cwd=tmp_path)
    p = mpi_ffd(2, "grad", design, "--sens", "sens.csv", "-o", "gp.json", cwd=tmp_path)
    assert s.returncode == p.returncode == 0, p.stderr
    gs, gp = (json.loads((tmp_path / f).read_text()) for f in ("gs.json", "gp.json"))
    assert gs.keys() == gp.keys() and all(gp[k] == pytest.approx(gs[k], rel=1e-12, abs=1e-14) for k in gs)
    # a refusal: the same status and message, nothing written
    r1, r2 = (tmp_path / f"r{k}{out_s.suffix}" for k in (1, 2))
    s = run_ffd("deform", design, "--set", "changes.0.twist.tip=80", "-o", r1, cwd=tmp_path)
    p = mpi_ffd(2, "deform", design, "--set", "changes.0.twist.tip=80", "-o", r2, cwd=tmp_path)
    assert s.returncode == p.returncode == 3, p.stderr
    assert p.stderr.count("fails the quality gate") == 1 and not r2.exists()
