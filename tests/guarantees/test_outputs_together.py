"""The outputs of a run appear together or not at all: a full disk or any OS error of a writer leaves
nothing and names the file the user knows, never a temporary one; concurrent runs share one valid
cache; the summary on a full stdout is one error, the files complete.
"""

from __future__ import annotations

import errno
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import REPO, assert_clean_failure, file_hash, run_ffd
from hostile import (
    _popen_ffd,
    error_line,
    ffd,
    no_parts,
    snapshot,
)
from wingcase import write_design, write_volume_wing

pytest_plugins = ["hostile"]        # the workspaces: fixtures ws, ws2


@pytest.mark.slow
def test_concurrent_runs_share_the_cache(tmp_path):
    mesh = write_volume_wing(tmp_path)
    mesh_hash = file_hash(mesh)
    for name in ("a.yaml", "b.yaml"):
        write_design(tmp_path, mesh, [{"twist": {"tip": 4}}, {"sweep": 5}], name=name)
    assert not list(tmp_path.glob("*.ffdcache.npz"))
    procs = [_popen_ffd("deform", name, "--json", cwd=tmp_path) for name in ("a.yaml", "b.yaml")]
    results = [p.communicate(timeout=300) for p in procs]
    for p, (_, err) in zip(procs, results):
        assert p.returncode == 0, err
        assert "Traceback" not in err
    assert file_hash(tmp_path / "out_a.su2") == file_hash(tmp_path / "out_b.su2")
    caches = list(tmp_path.glob("*.ffdcache.npz"))
    assert len(caches) == 1, caches
    assert not list(tmp_path.glob("*.part*"))
    with np.load(caches[0]) as z:            # a complete, readable cache file
        assert "params" in z.files and json.loads(bytes(z["header"]).decode())["key"]
    write_design(tmp_path, mesh, [{"twist": {"tip": 4}}, {"sweep": 5}], name="c.yaml")
    proc = run_ffd("deform", "c.yaml", "--json", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert json.loads(proc.stdout)["from_cache"] is True
    assert file_hash(tmp_path / "out_c.su2") == file_hash(tmp_path / "out_a.su2")
    assert file_hash(mesh) == mesh_hash


def test_disk_full_while_writing_the_lattice_leaves_no_output(ws2, monkeypatch):
    """Found: the mesh was renamed into place, then the lattice hit ENOSPC: exit 1 'a bug in ffd'."""
    import ffdcli.io.formats.lattice_vtk as lv

    def full(path, *a, **k):
        Path(path).write_bytes(b"# vtk DataFile Version 3.0\n" * 100)    # some bytes, then the disk is full
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(lv, "write_lattice_vtk", full)
    before = snapshot(ws2)
    proc = ffd("deform", "good.yaml", "-o", "full.su2", cwd=ws2)
    assert_clean_failure(proc, 1, "no space left", "full_lattice.vtk")
    assert "bug" not in proc.stderr
    assert not (ws2 / "full.su2").exists() and not (ws2 / "full_lattice.vtk").exists()
    assert no_parts(ws2) == []
    assert snapshot(ws2) == before


def test_any_os_error_of_a_writer_names_the_file(ws2, monkeypatch):
    import ffdcli.io.formats as formats

    def denied(mesh, path, *a, **k):
        raise OSError(errno.EIO, "Input/output error")

    monkeypatch.setattr(formats, "write_mesh", denied)
    proc = ffd("deform", "good.yaml", "-o", "eio.su2", cwd=ws2)
    assert_clean_failure(proc, 1, "eio.su2", "input/output error")
    assert not list(ws2.glob("eio*")) and no_parts(ws2) == []


def test_plan_in_the_library():
    """The rules are one library call (the API and every command use it)."""
    from ffdcli.errors import InputError
    from ffdcli.io.outputs import KINDS, OutputKind, plan_outputs, register

    assert KINDS["lattice"].suffixes == (".vtk",) and KINDS["plot"].suffixes == (".png",)
    with pytest.raises(InputError, match="would overwrite the deformed mesh"):
        plan_outputs([("mesh", "/tmp/x.su2"), ("surface_file", "/tmp/x.su2")])
    register(OutputKind("probe_kind", "the probe", (".dat",), "probes are .dat"))
    with pytest.raises(InputError, match="probes are .dat"):
        plan_outputs([("probe_kind", "/tmp/x.txt")])
    del KINDS["probe_kind"]


def test_plan_write_is_all_or_nothing(tmp_path):
    from ffdcli.errors import FfdError
    from ffdcli.io.outputs import plan_outputs

    plan = plan_outputs([("grad", tmp_path / "a.json"), ("jacobian", tmp_path / "b.npz")])

    def fail(tmp):
        tmp.write_text("half")
        raise OSError(errno.EDQUOT, "Disk quota exceeded")

    with pytest.raises(FfdError, match="b.npz.*quota"):
        plan.write({"grad": lambda tmp: tmp.write_text("{}"), "jacobian": fail})
    assert sorted(os.listdir(tmp_path)) == []
    assert plan.write({"grad": lambda tmp: tmp.write_text("{}"), "jacobian": lambda tmp: tmp.write_text("x")}) \
        == {"grad": str(tmp_path / "a.json"), "jacobian": str(tmp_path / "b.npz")}
    assert sorted(os.listdir(tmp_path)) == ["a.json", "b.npz"]


def test_json_to_a_full_stdout(ws2):
    """Found: two chained tracebacks, exit 1, after writing the outputs."""
    env = dict(os.environ)
    env["PYTHONPATH"] = str(REPO) + os.pathsep + env.get("PYTHONPATH", "")
    with open("/dev/full", "w") as full:
        proc = subprocess.run([sys.executable, "-m", "ffdcli", "deform", "good.yaml", "-o", "full_json.su2",
                               "--json"], cwd=ws2, env=env, stdout=full, stderr=subprocess.PIPE, text=True,
                              timeout=300)
    assert proc.returncode == 1, proc.stderr
    assert "Traceback" not in proc.stderr and "Exception ignored" not in proc.stderr, proc.stderr
    line = error_line(proc)
    assert "standard output" in line
    assert (ws2 / "full_json.su2").is_file() and (ws2 / "full_json_lattice.vtk").is_file()
    assert no_parts(ws2) == []
    for f in ("full_json.su2", "full_json_lattice.vtk"):
        (ws2 / f).unlink()


def test_api_writes_through_the_plan(ws2):
    from ffdcli.api import DesignModel
    from ffdcli.errors import InputError

    model = DesignModel.from_file(ws2 / "good.yaml")
    with pytest.raises(InputError, match="overwrite the input mesh"):
        model.write(ws2 / "vwing.su2")
    with pytest.raises(InputError, match=".vtk"):
        model.write(ws2 / "api.su2", lattice=ws2 / "api.txt")
    assert not (ws2 / "api.su2").exists()
    written = model.write(ws2 / "api.su2")
    assert written == {"mesh": str(ws2 / "api.su2"), "lattice": str(ws2 / "api_lattice.vtk")}
    for p in written.values():
        Path(p).unlink()


def test_a_writer_error_names_the_output_not_its_temporary_file(ws2, monkeypatch):
    import ffdcli.io.formats as formats
    from ffdcli.errors import InputError

    def refuse(mesh, path, *a, **k):
        raise InputError("cannot be written like this", path=path)

    monkeypatch.setattr(formats, "write_mesh", refuse)
    proc = ffd("deform", "good.yaml", "-o", "named.su2", cwd=ws2)
    assert_clean_failure(proc, 2, "named.su2: cannot be written")
    assert ".part" not in proc.stderr and no_parts(ws2) == []



# ----------------------------------------------------------------------------------------------
# Issue 29: one temporary file per output; the sweep finds everything a killed run can leave
# ----------------------------------------------------------------------------------------------

@pytest.mark.parametrize("out,extra", [("o.su2", []), ("o.vtu", []), ("o.su2", ["--surface-file", "o_surf.dat"]),
                                       ("o.su2", ["--plot"])], ids=["su2", "vtu", "surface-file", "plot"])
def test_one_temporary_file_per_output(ws2, monkeypatch, out, extra):
    """The probe: the SU2 writer made its own temporary file inside the plan's (``..name.….part.su2.
    ….part.su2``), which a killed run left behind and no sweep found. Every writer writes the temporary
    file it is handed; ``make_temp`` runs once per output."""
    import ffdcli.io.atomic as atomic

    made = []
    real = atomic.make_temp

    def counting(path):
        made.append(Path(path).name)
        return real(path)

    monkeypatch.setattr(atomic, "make_temp", counting)
    import ffdcli.io.outputs as outputs

    monkeypatch.setattr(outputs, "make_temp", counting)
    proc = ffd("deform", "good.yaml", "-o", out, *extra, cwd=ws2)
    assert proc.returncode == 0, proc.stderr
    assert all(not atomic.is_temp(m) for m in made), made          # never a temporary file of a temporary file
    assert len(made) == len(set(made)), made
    assert no_parts(ws2) == []


def _leftover(folder: Path, name: str, *, host: str, pid: int, nested: bool = False, age: float = 0.0) -> Path:
    p = folder / f".{name}.{host}-{pid}-abc123_x.part{Path(name).suffix}"
    if nested:
        p = folder / f".{p.name}.{host}-{pid}-def456_y.part{Path(name).suffix}"
    p.write_text("x")
    if age:
        t = time.time() - age
        os.utime(p, (t, t))
    return p


def test_the_sweep_finds_every_leftover_and_nothing_else(tmp_path):
    """Any output's temporary file of a dead process of this host goes (nested ones too, and another
    host's once stale); a live process's, another host's fresh one and a stranger's file stay."""
    import subprocess as sp

    from ffdcli.io.atomic import _HOST, STALE_AGE, make_temp

    dead = sp.Popen(["true"])
    dead.wait()
    gone = [_leftover(tmp_path, "a.su2", host=_HOST, pid=dead.pid),
            _leftover(tmp_path, "other_lattice.vtk", host=_HOST, pid=dead.pid),
            _leftover(tmp_path, "a.su2", host=_HOST, pid=dead.pid, nested=True),
            _leftover(tmp_path, "b.su2", host="farhost", pid=1, nested=True, age=2 * STALE_AGE),
            _leftover(tmp_path, "a.su2", host="farhost", pid=1, age=2 * STALE_AGE)]
    stay = [_leftover(tmp_path, "a.su2", host=_HOST, pid=os.getppid()),
            _leftover(tmp_path, "b.su2", host="farhost", pid=1),
            _leftover(tmp_path, "c.su2", host="farhost", pid=1, age=2 * STALE_AGE)]
    (tmp_path / ".notes.part").write_text("mine")
    stay.append(tmp_path / ".notes.part")
    tmp = make_temp(tmp_path / "a.su2")
    tmp.unlink()
    assert [p for p in gone if p.exists()] == []
    assert all(p.exists() for p in stay), [p for p in stay if not p.exists()]
