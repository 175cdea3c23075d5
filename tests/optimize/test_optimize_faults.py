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
