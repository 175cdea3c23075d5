"""Every write failure of every command says which file and why, in one line, exit 1, and leaves
nothing behind: over the process's file-size limit (RLIMIT_FSIZE, ``ulimit -f``; Python ignores
SIGXFSZ, so the write fails with EFBIG) in every output format, and a full disk (ENOSPC).

Before: ``ffd init`` said "internal error"; a ``.vtu``/``.vtk`` output "cannot write this VTU file:
OSError: ..." (exit 2, or NumPy's "problem writing element 5601 to file"); a new ``.cgns`` crashed the
interpreter (HDF5, exit -11)."""

from __future__ import annotations

import errno
import json
import os
import resource
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import REPO
from hostile import ffd_inproc
from wingcase import write_design, write_volume_wing

from ffdcli.io.formats import read_mesh

LIMIT = 1024      # bytes: every output below is larger, every input is read (reads are not limited)


@pytest.fixture(scope="module")
def ws(tmp_path_factory):
    d = tmp_path_factory.mktemp("writefail")
    mesh = write_volume_wing(d)
    # eight design variables (a twist per section): the gradient's JSON is over the limit too
    write_design(d, mesh, [{"twist": [0, 1, 2, 3, 4, 5, 6, 7]}], name="good.yaml")
    (d / "naca.su2").write_bytes((REPO / "samples" / "naca0012_2d.su2").read_bytes())
    (d / "target.dat").write_bytes((REPO / "samples" / "s1223.dat").read_bytes())
    (d / "naca.yaml").write_text("mesh: naca.su2\nsurface: airfoil\nbox: {points: [8, 5]}\nchanges: []\n")
    proc = subprocess.run([sys.executable, "-m", "ffdcli", "deform", "good.yaml", "-o", "ref.su2"], cwd=d,
                          capture_output=True, text=True, env={**os.environ, "PYTHONPATH": str(REPO)})
    assert proc.returncode == 0, proc.stderr            # the box cached: the runs below only write
    deformed = read_mesh(d / "ref.su2")
    ids = deformed.marker_point_ids("wing")
    rows = ['"PointID","x","y","z","Sensitivity_x","Sensitivity_y","Sensitivity_z"']
    rows += [f"{i},{float(x)!r},{float(y)!r},{float(z)!r},0,0,1"
             for i, (x, y, z) in zip(ids, deformed.points[ids], strict=True)]
    (d / "sens.csv").write_text("\n".join(rows) + "\n")
    return d


def _limited(args, cwd: Path, limit: int = LIMIT) -> subprocess.CompletedProcess:
    def pre():
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))

    return subprocess.run([sys.executable, "-m", "ffdcli", *args], cwd=cwd, capture_output=True, text=True,
                          preexec_fn=pre, env={**os.environ, "PYTHONPATH": str(REPO)}, timeout=600)


WRITES = {
    "init": (["init", "vwing.su2", "--surface", "wing", "-o", "new.yaml"], "new.yaml"),
    "init 2D": (["init", "naca.su2", "-o", "new2.yaml"], "new2.yaml"),
    "deform su2": (["deform", "good.yaml", "-o", "o.su2"], "o.su2"),
    "deform vtu": (["deform", "good.yaml", "-o", "o.vtu"], "o.vtu"),
    "deform vtk": (["deform", "good.yaml", "-o", "o.vtk"], "o.vtk"),
    "deform cgns": (["deform", "good.yaml", "-o", "o.cgns"], "o.cgns"),
    "deform lattice": (["deform", "good.yaml", "-o", "o.su2"], "o"),
    "box lattice": (["box", "good.yaml", "--lattice", "b.vtk"], "b.vtk"),
    "box plot3d": (["box", "good.yaml", "--lattice", "b.vtk", "--export-plot3d", "b.xyz"], "b."),
    "plot": (["plot", "good.yaml", "-o", "p.png", "--no-3d"], "p.png"),
    "grad": (["grad", "good.yaml", "--sens", "sens.csv", "-o", "g.json"], "g.json", 128),
    "jacobian": (["jacobian", "good.yaml", "-o", "j.npz"], "j.npz"),
    "constraints": (["constraints", "good.yaml", "--jacobian", "c.npz"], "c.npz"),
    "fit": (["fit", "naca.yaml", "--target", "target.dat", "-o", "fitted.yaml"], "fitted.yaml"),
}


@pytest.mark.parametrize("as_json", [False, True], ids=["text", "json"])
@pytest.mark.parametrize("case", list(WRITES))
def test_over_the_file_size_limit_names_the_file_exit_1(ws, case, as_json):
    args, name, *limit = WRITES[case]
    before = {p.name for p in ws.iterdir()}
    proc = _limited([*args, "--json"] if as_json else args, ws, *limit)
    assert proc.returncode == 1, (case, proc.returncode, proc.stderr[-2000:])
    errors = [ln for ln in proc.stderr.splitlines() if ln.startswith("ffd: error:")]
    assert len(errors) == 1 and "Traceback" not in proc.stderr and "internal error" not in proc.stderr, proc.stderr
    line = errors[0]
    assert name in line and "file-size limit" in line and "nothing was written" in line, line
    if as_json:
        assert json.loads(proc.stdout)["exit_code"] == 1
    created = {p.name for p in ws.iterdir()} - before
    assert all(c.endswith((".ffdcache.npz", ".ffdwarp.npz")) for c in created), created   # no part, no half file


def test_the_same_runs_write_without_the_limit(ws, tmp_path):
    """The limit is what fails above: with room, the same command writes its file."""
    args, name = WRITES["deform cgns"][:2]
    proc = _limited(args, ws, limit=resource.RLIM_INFINITY)
    assert proc.returncode == 0, proc.stderr
    assert (ws / name).stat().st_size > LIMIT


@pytest.mark.parametrize("code, words", [(errno.ENOSPC, "no space left"), (errno.EDQUOT, "quota"),
                                         (errno.EIO, "input/output error")])
def test_init_on_a_full_disk_names_the_file(ws, monkeypatch, code, words):
    """``ffd init`` on a full disk (the write fails when the file is flushed to the device)."""
    import ffdcli.app.design_output as design_output

    def full(fd):
        raise OSError(code, os.strerror(code))

    monkeypatch.setattr(design_output.os, "fsync", full)
    before = {p.name for p in ws.iterdir()}
    proc = ffd_inproc("init", "vwing.su2", "--surface", "wing", "-o", "full.yaml", cwd=ws)
    assert proc.returncode == 1, proc.stderr
    line = proc.stderr.strip().splitlines()[-1]
    assert line.startswith("ffd: error: full.yaml: cannot write the design file") and words in line, line
    assert {p.name for p in ws.iterdir()} == before


def test_init_cannot_make_its_out_folder(ws, tmp_path):
    """The folder of the design's outputs cannot be made (a file named ``out`` is there)."""
    d = tmp_path / "w"
    d.mkdir()
    (d / "out").write_text("a file, not a folder")
    proc = ffd_inproc("init", ws / "vwing.su2", "--surface", "wing", "-o", d / "a.yaml", cwd=tmp_path)
    assert proc.returncode == 2 and "out" in proc.stderr and "internal error" not in proc.stderr, proc.stderr
    assert not (d / "a.yaml").exists()


KERNEL = """
from numba import njit


@njit(cache=True)
def twice(x):
    return 2 * x
"""


@pytest.mark.parametrize("limit", [1, 64, 512])
def test_a_kernel_numba_cannot_save_is_a_warning(tmp_path, limit):
    """Found here: ``ffd grad`` under a file-size limit compiled a kernel, numba could not save it in its
    cache, and the run failed ("internal error: OSError: File too large") for want of a cache."""
    (tmp_path / "kern.py").write_text(KERNEL)
    script = ("import sys; sys.path.insert(0, sys.argv[1]); from ffdcli.jit import cache_failures_warn\n"
              "with cache_failures_warn():\n    import kern; print(kern.twice(21))\n")
    proc = subprocess.run([sys.executable, "-c", script, str(tmp_path)], capture_output=True, text=True,
                          preexec_fn=lambda: resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit)),
                          env={**os.environ, "PYTHONPATH": str(REPO)}, timeout=300)
    assert proc.returncode == 0 and proc.stdout.strip() == "42", proc.stderr
    assert proc.stderr.count("cannot save a compiled kernel in numba's cache") == 1, proc.stderr
    assert not [p for p in (tmp_path / "__pycache__").iterdir() if ".tmp." in p.name]
