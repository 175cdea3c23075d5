"""benchmarks/adodg/case3_plots.py on a run folder faked as ``ffd optimize`` leaves it (no solver): a flat
plate whose pressure jump is a uniform load (the baseline), an ellipse (the best feasible design) and a
trial off the lift; the design picked, its twists and stations, each evaluation's load efficiency."""

from __future__ import annotations

import json

import numpy as np
import pytest

from benchmarks.adodg.case3_plots import main, run_plot
from tests.testing.test_adodg3_su2_side import write_plate_flow

S = 3.0
HEADER = ("evaluation,iteration,norm,objective,LIFT,violation,step,solver_seconds,ffd_seconds,flow_solves,"
          "adjoint_solves,folder,failed\n")


def fake_evaluation(run, k: int, twist, jump, cl: float, cd: float, alpha: float = 2.0) -> None:
    """evals/000k: mesh.su2 (the plate), surface_flow.csv (Cp = -/+ jump/2 on the two sides), SU2's
    history.csv, flow.cfg (AOA), result.json (the twists)."""
    folder = run / "evals" / f"{k:04d}"
    folder.mkdir(parents=True)
    write_plate_flow(folder, "mesh.su2", "history.csv", jump, cl, cd, S)
    (folder / "flow.cfg").write_text(f"SOLVER= EULER\nAOA= {alpha}\n")
    (folder / "result.json").write_text(json.dumps({"index": k, "values": list(twist)}))


@pytest.fixture()
def run(tmp_path):
    c0 = 4 * 0.375 * S / (np.pi * S)
    uniform = lambda y: np.full_like(y, 0.375)                                    # noqa: E731
    ellipse = lambda y: c0 * np.sqrt(np.clip(1 - (y / S) ** 2, 0, None))          # noqa: E731
    twists = [[0.0] * 9, [0.4 - 0.25 * j for j in range(9)], [1.0] * 9]
    evals = [(1, 0, 0.00790, 0.3753, 3.2e-4, 2), (2, 1, 0.00766, 0.37501, 1e-5, 2), (3, 2, 0.00760, 0.3600, 0.015, 0)]
    lines = "".join(f"{k},{it},0,{cd},{cl},{v},0.1,100,0.5,1,{adj},evals/{k:04d},\n" for k, it, cd, cl, v, adj in evals)
    (tmp_path / "history.csv").write_text(HEADER + lines)
    for (k, _, cd, cl, _, _), tw, jump in zip(evals, twists, (uniform, ellipse, uniform), strict=True):
        fake_evaluation(tmp_path, k, tw, jump, cl, cd)
    return tmp_path


def test_the_picture_shows_the_best_feasible_design_its_twist_and_every_evaluations_efficiency(run, tmp_path):
    drawn = run_plot(run, tmp_path / "p.png", evaluation=None, n_strips=24)
    assert (tmp_path / "p.png").stat().st_size > 10_000
    assert drawn["evaluation"] == 2                      # the trial (3) has a lower CD but misses the lift
    assert drawn["twist"] == pytest.approx([0.4 - 0.25 * j for j in range(9)])
    assert drawn["stations"] == pytest.approx(list(np.linspace(0, S + 1e-5, 9)))
    assert drawn["design"]["e_load"] == pytest.approx(1.0, abs=1e-4)
    assert drawn["baseline"]["e_load"] < 0.9             # a uniform load is far from the ellipse
    h = drawn["history"]
    assert h["evaluation"] == [1, 2, 3] and h["accepted"] == [True, True, False]
    assert h["e_load"][1] == pytest.approx(1.0, abs=1e-4) and h["e_load"][0] == pytest.approx(h["e_load"][2])


def test_an_evaluation_asked_for_is_drawn_and_a_missing_one_is_one_line(run, tmp_path, capsys):
    drawn = run_plot(run, tmp_path / "p.png", evaluation=3, n_strips=24)
    assert drawn["evaluation"] == 3 and drawn["twist"] == [1.0] * 9
    assert main(["--run", str(run), "--out", str(tmp_path / "o"), "--evaluation", "7"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--evaluation 7" in err[0]
    assert not (tmp_path / "o" / "adodg_case3_run.png").exists()


def test_an_evaluation_without_its_mesh_is_one_line_and_no_picture(run, tmp_path, capsys):
    (run / "evals" / "0003" / "mesh.su2").unlink()              # a trial's files half gone
    assert main(["--run", str(run), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "0003" in err[0] and "Traceback" not in err[0]
    assert not (tmp_path / "o" / "adodg_case3_run.png").exists()
