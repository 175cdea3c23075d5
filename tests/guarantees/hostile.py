"""Shared helpers of the guarantee tests: run the command line in this interpreter (or a fresh one),
check a clean failure and an untouched workspace, and the workspaces themselves (fixtures, imported by
the test modules that use them: ``from hostile import ws  # noqa: F401``)."""

from __future__ import annotations

import contextlib
import io
import json
import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
import yaml
from conftest import assert_clean_failure, file_hash, popen_ffd, run_ffd
from wingcase import write_design, write_volume_wing

SUBPROCESS = os.environ.get("FFD_HOSTILE_SUBPROCESS") == "1"


GOOD = [{"twist": {"tip": 5}}, {"chord": {"tip": 0.8}}]


def ffd_inproc(*args, cwd: Path) -> subprocess.CompletedProcess:
    """``ffd ARGS`` through :func:`ffdcli.cli.main` in this interpreter (same parsing and errors)."""
    from ffdcli.cli import main

    out, err = io.StringIO(), io.StringIO()
    code = None
    with contextlib.chdir(cwd), contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            main([str(a) for a in args])
        except SystemExit as e:
            code = e.code if isinstance(e.code, int) else (0 if e.code is None else 1)
        except Exception:  # noqa: BLE001  (a crash past main's handlers: show it as a traceback)
            import traceback

            err.write(traceback.format_exc())
            code = 1
    return subprocess.CompletedProcess(args, code, out.getvalue(), err.getvalue())


def ffd(*args, cwd: Path, subprocess_run: bool = False) -> subprocess.CompletedProcess:
    if SUBPROCESS or subprocess_run:
        return run_ffd(*args, cwd=cwd, timeout=300)
    return ffd_inproc(*args, cwd=cwd)


def snapshot(folder: Path) -> dict[str, str]:
    return {str(p.relative_to(folder)): file_hash(p) for p in sorted(folder.rglob("*")) if p.is_file()}


def error_line(proc) -> str:
    lines = [ln for ln in proc.stderr.splitlines() if ln.startswith("ffd: error:")]
    assert len(lines) == 1, proc.stderr
    return lines[0]


def assert_hostile(ws: Path, args, code: int, *texts: str, names=(), subprocess_run: bool = False):
    """Run ``ffd ARGS`` in ``ws`` and check the clean failure and the untouched workspace.

    ``texts`` must appear in the error line; ``names`` are file names (or key paths / lines) that the
    message must name (a usage error too: one ``ffd: error:`` line, exit 2). Returns the error line."""
    before = snapshot(ws)
    proc = ffd(*args, cwd=ws, subprocess_run=subprocess_run)
    assert_clean_failure(proc, code)
    line = error_line(proc)
    for t in (*texts, *names):
        assert t in line, (t, line)
    after = snapshot(ws)
    changed = sorted(k for k in before if after.get(k) != before[k])
    assert not changed, f"modified or removed: {changed}\n{line}"
    created = sorted(set(after) - set(before))
    assert not [c for c in created if ".part" in c], created
    for c in created:   # only the caches of a mesh that was read successfully, and complete ones
        assert c.endswith((".ffdcache.npz", ".ffdwarp.npz")), f"created {c}: {line}"
        with np.load(ws / c) as z:
            assert "header" in z.files
    return line


def bad_design(ws: Path, name: str, text: str) -> str:
    (ws / name).write_text(text)
    return name


def design_with(ws: Path, name: str, changes=None, **extra) -> str:
    write_design(ws, ws / "vwing.su2", GOOD if changes is None else changes, name=name, extra=extra or None)
    return name


def edit_design(ws: Path, name: str, edit) -> str:
    """The good design, edited by ``edit(data)``, written as ``name``."""
    data = yaml.safe_load((ws / "good.yaml").read_text())
    edit(data)
    data["output"] = {"mesh": f"out_{Path(name).stem}.su2", "lattice": f"out_{Path(name).stem}_lattice.vtk"}
    (ws / name).write_text(yaml.safe_dump(data, sort_keys=False))
    return name


def mesh_lines(ws: Path) -> list[str]:
    return (ws / "vwing.su2").read_text().splitlines(keepends=True)


def bad_mesh(ws: Path, name: str, lines) -> str:
    (ws / name).write_text("".join(lines))
    return name


def _find(lines, prefix):
    return next(i for i, ln in enumerate(lines) if ln.startswith(prefix))


def no_parts(folder: Path) -> list:
    return sorted(str(p) for p in folder.rglob("*.part*"))


def _popen_ffd(*args, cwd):
    return popen_ffd(*args, cwd=cwd)



@pytest.fixture(scope="module")
def ws(tmp_path_factory):
    d = tmp_path_factory.mktemp("hostile")
    mesh = write_volume_wing(d)
    write_design(d, mesh, GOOD, name="good.yaml")
    proc = run_ffd("deform", "good.yaml", "--json", cwd=d)
    assert proc.returncode == 0, proc.stderr
    summary = json.loads(proc.stdout)
    assert summary["from_cache"] is False
    shutil.copyfile(d / "out_good.su2", d / "ref_out.su2")
    (d / "vwing.su2.sha256").write_text(file_hash(mesh))
    return d


@pytest.fixture(scope="module")
def ws2(tmp_path_factory):
    """A small volume wing and a good design whose box is cached (one in-process run)."""
    d = tmp_path_factory.mktemp("hostile2")
    mesh = write_volume_wing(d)
    write_design(d, mesh, GOOD, name="good.yaml")
    proc = ffd("deform", "good.yaml", "--json", cwd=d)
    assert proc.returncode == 0, proc.stderr
    for p in ("out_good.su2", "out_good_lattice.vtk"):
        (d / p).unlink()
    return d

