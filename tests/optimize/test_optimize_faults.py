"""Issue 43 on ``ffd optimize``: a failed run says so in one ``ffd: error:`` line with exit 1 (item 10),
a misspelt function is refused when the design file is loaded (item 12), the folder is checked before
any work (item 8) and no output is ever an input (item 4)."""

from __future__ import annotations

import json
import os
import shutil
import stat
import sys
from pathlib import Path

import pytest
import yaml
from test_optimize import MESH, solver_for, write_case

from ffdcli.cli import main
from ffdcli.errors import InputError
from ffdcli.optimize.solvers.analytic import FUNCTIONS
from ffdcli.optimize.solvers.su2 import HISTORY_COLUMNS
from ffdcli.optimize.workflow import run_optimize


def run_cli(argv, capsys) -> tuple[int, str, str]:
    with pytest.raises(SystemExit) as e:
        main(["optimize", *map(str, argv)])
    out = capsys.readouterr()
    return e.value.code, out.out, out.err


# ----------------------------------------------------------------------------------------------
# Item 10: a failed run is an error, with or without -q, text or --json
# ----------------------------------------------------------------------------------------------

FAILURES = {
    "baseline": ({"fail_calls": [1]}, {}, "the baseline design failed"),
    "failures": ({"fail_calls": list(range(2, 40))}, {"max_failures": 1}, "failed evaluations (max_failures 1)"),
    "diverged": ({"fail_above": 1e-9}, {}, "the baseline design failed: diverged"),
}


@pytest.mark.parametrize("case", list(FAILURES))
@pytest.mark.parametrize("flags", [[], ["-q"], ["--json"], ["--json", "-q"], ["-v"]])
def test_a_failed_run_prints_one_error_line_and_exits_1(tmp_path, capsys, case, flags):
    analytic, opt, words = FAILURES[case]
    path = write_case(tmp_path, analytic=analytic, iterations=4, **opt)
    code, out, err = run_cli([path, *flags], capsys)
    assert code == 1, (out, err)
    errors = [ln for ln in err.splitlines() if ln.startswith("ffd: error:")]
    assert len(errors) == 1 and words in errors[0] and "optimize failed" in errors[0], err
    assert "None" not in out + err and "Traceback" not in err
    if "--json" in flags:
        lines = [ln for ln in out.splitlines() if ln.strip()]
        assert len(lines) == 1, out                          # one JSON object, the error's
        obj = json.loads(lines[0])
        assert obj["ok"] is False and obj["exit_code"] == 1 and words in obj["error"]
        assert obj["report"]["status"] == case if case != "diverged" else obj["report"]["status"] == "baseline"
    elif "-q" in flags:
        assert out == ""
    else:
        assert "ffd optimize:" in out and ("n/a" in out or case == "failures")


# ----------------------------------------------------------------------------------------------
# Item 12: the objective and the constrained functions against the solver's table, at load time
# ----------------------------------------------------------------------------------------------

MISSPELT = [("DRAGG", "DRAG"), ("drag", "DRAG"), ("LFIT", "LIFT"), ("CD", None), ("MOMENTZ", "MOMENT_Z"),
            ("Lift", "LIFT"), ("MOMENT_Y", None)]


@pytest.mark.parametrize("name, near", MISSPELT)
@pytest.mark.parametrize("where", ["objective", "functions"])
def test_a_misspelt_function_is_refused_at_load_time_with_its_line(tmp_path, name, near, where):
    assert near is None or near in FUNCTIONS
    opt = {"objective": name} if where == "objective" else {"functions": [{"name": "LIFT", "lower": 0.1},
                                                                         {"name": name, "upper": 1.0}]}
    path = write_case(tmp_path, **opt)
    solver = solver_for(path)
    with pytest.raises(InputError) as e:
        run_optimize(path, solver=solver)
    key = "optimize.objective" if where == "objective" else "optimize.functions[1].name"
    assert e.value.key == key and e.value.line is not None and e.value.path == str(path), e.value
    assert repr(name) in str(e.value) and (near is None or f"did you mean {near}" in str(e.value))
    assert solver.flows == 0 and not (tmp_path / "opt").exists()       # no work, not even the folder


def _fake_su2(folder: Path) -> Path:
    """An SU2_CFD that records every run (there must be none)."""
    folder.mkdir()
    prog = folder / "SU2_CFD"
    prog.write_text(f"#!{sys.executable}\nimport pathlib\npathlib.Path({str(folder / 'ran')!r}).touch()\n")
    prog.chmod(prog.stat().st_mode | stat.S_IEXEC)
    return prog


@pytest.mark.parametrize("name, near", [("DRAGG", "DRAG"), ("SIDE_FORCE", "SIDEFORCE"), ("CL", None),
                                        ("MOMENT_ZZ", "MOMENT_Z"), ("TORQE", "TORQUE")])
def test_su2s_objective_names_are_the_table(tmp_path, capsys, monkeypatch, name, near):
    """With SU2 (found, never run): the same refusal against SU2's objective names, exit 2, before the box
    is built or a flow solved."""
    bin_ = tmp_path / "bin"
    _fake_su2(bin_)
    monkeypatch.setenv("SU2_RUN", str(bin_))
    (tmp_path / "flow.cfg").write_text("SOLVER= EULER\nCONV_RESIDUAL_MINVAL= -8\n")
    path = write_case(tmp_path, solver="su2", config="flow.cfg", adjoint="continuous", objective=name)
    code, out, err = run_cli([path], capsys)
    assert code == 2 and err.count("ffd: error:") == 1, err
    assert f"{path.name}:" in err and "optimize.objective" in err and repr(name) in err
    assert near is None or f"did you mean {near}" in err
    assert not (bin_ / "ran").exists() and not (tmp_path / "opt").exists()
    assert set(HISTORY_COLUMNS) <= set(err.split("functions are ")[1].replace(",", " ").split())


# ----------------------------------------------------------------------------------------------
# Item 4: no output of ffd optimize is an input, under any name
# ----------------------------------------------------------------------------------------------

def _digest(path: Path) -> bytes:
    return Path(path).read_bytes()


def _collision(tmp_path: Path, how: str) -> tuple[Path, Path]:
    """A design whose run would write over one of its inputs; returns (design, the input)."""
    if how == "mesh_is_best_in_folder":
        (tmp_path / "opt").mkdir()
        shutil.copyfile(MESH, tmp_path / "opt" / "best.su2")
        path = write_case(tmp_path)
        _retarget(path, mesh="opt/best.su2")
        return path, tmp_path / "opt" / "best.su2"
    if how == "folder_dot_mesh_beside":
        shutil.copyfile(MESH, tmp_path / "best.su2")
        path = write_case(tmp_path, folder=".")
        _retarget(path, mesh="best.su2")
        return path, tmp_path / "best.su2"
    if how == "design_is_best_yaml":
        path = write_case(tmp_path, folder=".")
        return path.rename(tmp_path / "best.yaml"), tmp_path / "best.yaml"
    if how == "folder_other_spelling":
        (tmp_path / "opt").mkdir()
        shutil.copyfile(MESH, tmp_path / "opt" / "best.su2")
        path = write_case(tmp_path, folder="./opt/../opt/")
        _retarget(path, mesh=str((tmp_path / "opt" / "best.su2").resolve()))
        return path, tmp_path / "opt" / "best.su2"
    if how == "symlink":
        (tmp_path / "opt").mkdir()
        shutil.copyfile(MESH, tmp_path / "wing.su2")
        (tmp_path / "opt" / "best.su2").symlink_to(tmp_path / "wing.su2")
        path = write_case(tmp_path)
        _retarget(path, mesh="wing.su2")
        return path, tmp_path / "wing.su2"
    if how == "hard_link":
        (tmp_path / "opt").mkdir()
        shutil.copyfile(MESH, tmp_path / "wing.su2")
        os.link(tmp_path / "wing.su2", tmp_path / "opt" / "best.su2")
        path = write_case(tmp_path)
        _retarget(path, mesh="wing.su2")
        return path, tmp_path / "wing.su2"
    if how == "solver_config_is_best_yaml":
        (tmp_path / "opt").mkdir()
        path = write_case(tmp_path)
        (tmp_path / "analytic.yaml").rename(tmp_path / "opt" / "best.yaml")
        _retarget(path, config="opt/best.yaml")
        return path, tmp_path / "opt" / "best.yaml"
    if how == "history_is_the_design":
        path = write_case(tmp_path, folder=".")
        (tmp_path / "history.csv").symlink_to(path)
        return path, path
    raise ValueError(how)


def _retarget(path: Path, mesh: str | None = None, config: str | None = None) -> None:
    data = yaml.safe_load(path.read_text())
    if mesh is not None:
        data["mesh"] = mesh
    if config is not None:
        data["optimize"]["config"] = config
    path.write_text(yaml.safe_dump(data, sort_keys=False))


COLLISIONS = ["mesh_is_best_in_folder", "folder_dot_mesh_beside", "design_is_best_yaml", "folder_other_spelling",
              "symlink", "hard_link", "solver_config_is_best_yaml", "history_is_the_design"]


@pytest.mark.parametrize("how", COLLISIONS)
def test_no_output_of_optimize_is_an_input(tmp_path, capsys, how):
    """Found: ffd optimize wrote best.su2 over its input mesh (mesh opt/best.su2, or folder: . with the
    mesh best.su2 beside the design). Every collision is refused before any work, exit 2."""
    path, victim = _collision(tmp_path, how)
    before = _digest(victim)
    code, out, err = run_cli([path, "-q"], capsys)
    assert code == 2, (how, err)
    assert err.count("ffd: error:") == 1 and "would overwrite" in err, err
    assert _digest(victim) == before
    assert not list(tmp_path.rglob("result.json"))            # no evaluation ran


# ----------------------------------------------------------------------------------------------
# Item 8: optimize.folder that cannot be a folder, checked before any work
# ----------------------------------------------------------------------------------------------

@pytest.mark.parametrize("make, folder, why", [
    (lambda d: (d / "opt").write_text("notes"), "opt", "is a file, not a folder"),
    (lambda d: os.mkfifo(d / "opt"), "opt", "is a FIFO"),
    (lambda d: (d / "runs").write_text("x"), "runs/opt", "not a folder, so the folder cannot be made"),
    (lambda d: (d / "a").mkdir() or (d / "a" / "b").write_text("x"), "a/b/c/d", "not a folder"),
])
def test_a_folder_that_cannot_be_one_is_refused_before_any_work(tmp_path, capsys, make, folder, why):
    make(tmp_path)
    path = write_case(tmp_path, folder=folder)
    solver = solver_for(path)
    with pytest.raises(InputError) as e:
        run_optimize(path, solver=solver)
    assert why in str(e.value) and e.value.key == "optimize.folder" and e.value.line is not None, e.value
    assert str(tmp_path / folder.split("/")[0]) in str(e.value)
    assert solver.flows == 0
    code, _, err = run_cli([path, "-q"], capsys)
    assert code == 2 and err.count("ffd: error:") == 1 and "internal error" not in err


def _unshare_ok() -> bool:
    if shutil.which("unshare") is None or os.geteuid() != 0:
        return False
    import subprocess
    return subprocess.run(["unshare", "-m", "true"], capture_output=True).returncode == 0


@pytest.mark.skipif(not _unshare_ok(), reason="needs unshare -m (root) to mount a read-only file system")
@pytest.mark.parametrize("folder", ["ro/opt", "ro/deep/er/opt", "ro"])
def test_a_folder_on_a_read_only_file_system_is_refused_before_any_work(tmp_path, folder):
    """The folder (or where it would be made) on a read-only file system: exit 2 naming it and why, in a
    private mount namespace (a read-only bind mount of a temporary folder)."""
    import subprocess
    ro = tmp_path / "ro"
    ro.mkdir()
    path = write_case(tmp_path, folder=folder)
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[2]) + os.pathsep
           + os.environ.get("PYTHONPATH", "")}
    script = (f'mount --bind "{ro}" "{ro}" && mount -o remount,bind,ro "{ro}" && '
              f'exec "{sys.executable}" -m ffdcli optimize "{path}" -q')
    p = subprocess.run(["unshare", "-m", "sh", "-c", script], capture_output=True, text=True, env=env, timeout=300)
    assert p.returncode == 2, (p.returncode, p.stderr)
    assert p.stderr.count("ffd: error:") == 1 and "read-only file system" in p.stderr, p.stderr
    assert "optimize.folder" in p.stderr and f"{path.name}:" in p.stderr
    assert not list(tmp_path.rglob("result.json"))


@pytest.mark.skipif(not _unshare_ok(), reason="needs unshare -m (root) to mount a small file system")
@pytest.mark.parametrize("size", ["16k", "400k", "1m"])
def test_a_full_disk_during_a_run_names_the_file_and_exits_1(tmp_path, size):
    """optimize.folder on a tmpfs of ``size``: the disk fills at another moment of the run (the first
    evaluation's mesh, a result, the history); one line naming the file and why, exit 1, never an
    internal error."""
    import subprocess
    (tmp_path / "small").mkdir()
    path = write_case(tmp_path, folder="small/opt", iterations=30)
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[2]) + os.pathsep
           + os.environ.get("PYTHONPATH", "")}
    script = (f'mount -t tmpfs -o size={size} tmpfs "{tmp_path / "small"}" && '
              f'exec "{sys.executable}" -m ffdcli optimize "{path}" -q')
    p = subprocess.run(["unshare", "-m", "sh", "-c", script], capture_output=True, text=True, env=env, timeout=600)
    if p.returncode == 0:
        pytest.skip(f"the run fitted in {size}")
    assert p.returncode == 1, (p.returncode, p.stderr)
    assert p.stderr.count("ffd: error:") == 1 and "no space left on the device" in p.stderr, p.stderr
    assert "internal error" not in p.stderr and ".part" not in p.stderr and "small/opt" in p.stderr
