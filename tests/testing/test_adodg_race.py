"""``benchmarks.adodg.race``: the solves each run spent to reach a drag, counted the same way for ffd's
``history.csv`` and SU2's ``shape_optimization.py`` folder; synthetic run folders, no solver."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest

from benchmarks.adodg import race, su2_side, su2_side_case2

HEAD = ["evaluation", "iteration", "objective", "LIFT", "violation", "flow_solves", "adjoint_solves", "folder",
        "failed"]


def ffd_run(folder: Path, rows: list[tuple]) -> Path:
    """An ffd run folder: rows (evaluation, objective, violation, flows, adjoints, failed), written out of order."""
    folder.mkdir(parents=True)
    with open(folder / "history.csv", "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(HEAD)
        for ev, obj, viol, fl, adj, failed in reversed(rows):
            w.writerow([ev, 0, "" if failed else obj, 0.375, "" if failed else viol, fl, adj, f"evals/{ev:04d}",
                        "diverged" if failed else ""])
    return folder


def su2_run(folder: Path, rows: list[dict], adjoints: list[int], area: float = 0.0778,
            residuals: list[float] | None = None) -> Path:
    """An SU2 shape_optimization.py folder: history_project.csv rows, DESIGNS/DSN_k with ``adjoints[k]``
    finished gradient files (and one unfinished adjoint folder on the last design); with ``residuals``,
    ``CONV_RESIDUAL_MINVAL= -8`` and each design's flow history ending at that rms[Rho]."""
    folder.mkdir(parents=True)
    conv = "CONV_RESIDUAL_MINVAL= -8\n" if residuals else ""
    (folder / "config.cfg").write_text("MESH_FILENAME= mesh.su2\n" + conv)
    (folder / "baseline_geometry.json").write_text(json.dumps({"AIRFOIL_AREA": area}))
    head = list(rows[0])
    lines = [",".join(f'"{h}"' for h in head)] + [",".join(repr(float(r[h])) for h in head) for r in rows]
    (folder / "history_project.csv").write_text("\n".join(lines) + "\n")
    for k, n in enumerate(adjoints):
        dsn = folder / "DESIGNS" / f"DSN_{k + 1:03d}"
        dsn.mkdir(parents=True)
        for f in ("DRAG", "LIFT", "MOMENT_Z")[:n]:
            (dsn / f"ADJOINT_{f}").mkdir()
            (dsn / f"ADJOINT_{f}" / "of_grad.csv").write_text('"VARIABLE","GRADIENT"\n0, 1.0\n')
        if residuals:
            (dsn / "DIRECT").mkdir()
            (dsn / "DIRECT" / "history_direct.csv").write_text(
                f'"Inner_Iter","rms[Rho]","CD"\n0, -2.0, 0.1\n240, {residuals[k]!r}, 0.02\n')
    (folder / "DESIGNS" / f"DSN_{len(adjoints):03d}" / "ADJOINT_EXTRA").mkdir()      # running: no gradient yet
    return folder


def test_a_design_stands_at_the_solves_before_it_plus_its_flow():
    t = race.trace_of("x", [1, 1, 1, 1], [2, 0, 2, 0], [5.0, 6.0, 4.0, 3.0], [False, True, True, True])
    np.testing.assert_array_equal(t.solves, [1, 4, 5, 8])        # 1; 1+2+1; 4+1 (a trial: no adjoint); 5+2+1
    assert t.total == 8
    np.testing.assert_array_equal(race.best_so_far(t), [np.inf, 6.0, 4.0, 3.0])
    assert race.best(t) == (3.0, 8)
    assert race.solves_to_reach(t, 4.5) == 5 and race.solves_to_reach(t, 2.0) is None


@pytest.mark.parametrize("seed", range(20))
def test_the_best_is_reached_where_best_says_and_never_before(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 30))
    t = race.trace_of("r", [1] * n, rng.integers(0, 4, n).tolist(), rng.uniform(1, 2, n).tolist(),
                      (rng.random(n) < 0.6).tolist())
    b = race.best(t)
    if not t.feasible.any():
        assert b is None
        return
    assert b[0] == t.objective[t.feasible].min()
    assert race.solves_to_reach(t, b[0]) == b[1]
    assert all(race.solves_to_reach(t, b[0]) <= s for s in t.solves[t.feasible & (t.objective == b[0])])
    assert np.all(np.diff(t.solves) >= 1) and t.total >= t.solves[-1]


def test_ffd_history_in_evaluation_order_with_a_failed_row(tmp_path):
    run = ffd_run(tmp_path / "run", [(1, 0.0078, 3e-4, 1, 2, False), (2, 0.0077, 1e-7, 1, 2, False),
                                     (3, None, None, 1, 0, True), (4, 0.0076, 2e-4, 1, 0, False),
                                     (5, 0.00765, 0.0, 1, 2, False)])
    t = race.ffd_trace(run, 1e-4)
    np.testing.assert_array_equal(t.solves, [1, 4, 7, 8, 9])
    np.testing.assert_array_equal(t.feasible, [False, True, False, False, True])
    assert np.isnan(t.objective[2]) and t.total == 11
    assert race.best(t) == (0.00765, 9)


def test_su2_case3_counts_only_finished_adjoints_and_judges_the_lift(tmp_path):
    rows = [{"DRAG": 0.00779, "LIFT": 0.375317}, {"DRAG": 0.007774, "LIFT": 0.37501},
            {"DRAG": 0.00776, "LIFT": 0.3750002}]
    run = su2_run(tmp_path / "su2", rows, [2, 2, 1])
    t = race.su2_trace(3, run, "SU2")
    np.testing.assert_array_equal(t.solves, [1, 4, 7])
    np.testing.assert_array_equal(t.feasible, [False, True, True])
    assert t.total == 8


def test_su2_case2_uses_the_case_s_constraints(tmp_path):
    rows = [{"DRAG": 0.0194, "LIFT": 0.805, "MOMENT_Z": 0.096, "AIRFOIL_AREA": 0.0778},
            {"DRAG": 0.0130, "LIFT": 0.82405, "MOMENT_Z": 0.0919, "AIRFOIL_AREA": 0.0778},
            {"DRAG": 0.0120, "LIFT": 0.82405, "MOMENT_Z": 0.0925, "AIRFOIL_AREA": 0.0778},     # the moment
            {"DRAG": 0.0125, "LIFT": 0.8240, "MOMENT_Z": 0.0900, "AIRFOIL_AREA": 0.0776}]     # the area
    t = race.su2_trace(2, su2_run(tmp_path / "su2", rows, [3, 3, 0, 0]), "SU2")
    np.testing.assert_array_equal(t.feasible, [False, True, False, False])
    ffd = race.trace_of("ffd", [1, 1], [3, 3], [0.0194, 0.0125], [False, True])
    text = race.summary([ffd, t], 0.0194)
    assert "SU2: 4 designs, 10 solves; best feasible 0.013 after 5 solves (33.0 % below 0.0194)" in text
    assert "ffd reaches SU2's best (0.013): after 5 solves" in text
    assert "SU2 reaches ffd's best (0.0125): not reached in 10 solves" in text


def test_the_command_draws_and_prints_and_a_missing_folder_is_exit_2(tmp_path, capsys):
    run = ffd_run(tmp_path / "run", [(1, 0.0078, 3e-4, 1, 2, False), (2, 0.0077, 1e-7, 1, 2, False)])
    su2 = su2_run(tmp_path / "su2", [{"DRAG": 0.00779, "LIFT": 0.375317}, {"DRAG": 0.00778, "LIFT": 0.375}], [2, 2])
    png = tmp_path / "pics" / "race.png"
    assert race.main(["--case", "3", "--ffd", str(run), "--su2", str(su2), "--out", str(png)]) == 0
    out = capsys.readouterr().out
    assert "ffd run: 2 designs, 6 solves; best feasible 0.0077 after 4 solves (1.3 % below 0.0078)" in out
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    missing = tmp_path / "nothing"
    assert race.main(["--case", "3", "--ffd", str(missing), "--out", str(tmp_path / "no.png")]) == 2
    err = capsys.readouterr().err
    assert "history.csv: no such file" in err and "Traceback" not in err and not (tmp_path / "no.png").exists()


def test_only_runs_of_the_two_tools_are_paired():
    a = race.trace_of("ffd 16", [1, 1], [1, 1], [2.0, 1.0], [True, True])
    b = race.trace_of("ffd 32", [1, 1], [1, 1], [2.0, 0.5], [True, True])
    c = race.trace_of("SU2", [1, 1], [1, 1], [2.0, 1.5], [True, True], tool="SU2")
    lines = race.summary([a, b, c]).splitlines()
    assert "ffd 16 reaches ffd 32's best" not in "\n".join(lines)
    assert "ffd 32 reaches SU2's best (1.5): after 3 solves" in lines
    assert "SU2 reaches ffd 16's best (1): not reached in 4 solves" in lines
    assert len(lines) == 3 + 4


def test_the_picture_s_range_is_the_feasible_designs_and_the_baseline_not_an_outlier():
    ffd = race.trace_of("ffd", [1, 1, 1], [2, 2, 2], [7.8e-3, 7.7e-3, 7.66e-3], [False, True, True])
    su2 = race.trace_of("SU2", [1, 1, 1], [2, 2, 1], [7.8e-3, 7.76e-3, 1.7e-3], [False, True, False], tool="SU2")
    lo, hi = race.y_limits([ffd, su2], baseline=7.8e-3)
    assert lo < 7.66e-3 and hi > 7.8e-3 and lo > 1.7e-3          # the stalled flow's 0.0017 is off the scale
    assert hi - lo == pytest.approx((7.8e-3 - 7.66e-3) * 1.16)
    trial = race.trace_of("ffd", [1, 1], [2, 0], [7.8e-3, 7.9e-3], [True, False])   # a trial just above: shown
    lo, hi = race.y_limits([trial], baseline=7.8e-3)
    assert lo < 7.8e-3 < 7.9e-3 < hi


def test_an_su2_flow_stopped_short_of_its_residual_is_no_result(tmp_path):
    rows = [{"DRAG": 0.0194, "LIFT": 0.805, "MOMENT_Z": 0.096, "AIRFOIL_AREA": 0.0778},
            {"DRAG": 0.0130, "LIFT": 0.82405, "MOMENT_Z": 0.0919, "AIRFOIL_AREA": 0.0778},
            {"DRAG": 0.0100, "LIFT": 0.8240, "MOMENT_Z": 0.0900, "AIRFOIL_AREA": 0.0778}]     # stalled at -4.9
    run = su2_run(tmp_path / "su2", rows, [3, 3, 0], residuals=[-8.01, -8.0000000001, -4.92])
    assert su2_side.flow_converged(run, 3) == [True, True, False]
    t = race.su2_trace(2, run, "SU2")
    np.testing.assert_array_equal(t.feasible, [False, True, False])
    assert t.unconverged == 1 and race.best(t) == (0.0130, 5)
    assert "SU2: 3 designs, 9 solves (1 flows not converged: counted infeasible)" in race.summary([t])
    rep = su2_side_case2.report(run)                       # the case's own report says the same
    assert [r["converged"] for r in rep["designs"]] == [True, True, False]
    assert rep["best"]["design"] == "DSN_002"               # DSN_003's lower drag is no result
    assert "DSN_003" in su2_side_case2.summary(rep) and "FLOW NOT CONVERGED" in su2_side_case2.summary(rep)


def test_a_config_converged_on_a_coefficient_is_not_judged_by_the_residual(tmp_path):
    rows = [{"DRAG": 0.0194, "LIFT": 0.805, "MOMENT_Z": 0.096, "AIRFOIL_AREA": 0.0778}]
    run = su2_run(tmp_path / "su2", rows, [3], residuals=[-4.9])
    assert su2_side.flow_converged(run, 1) == [False]
    cfg = run / "config.cfg"
    cfg.write_text(cfg.read_text() + "CONV_FIELD= DRAG\n")                # a Cauchy criterion on CD
    assert su2_side.flow_converged(run, 1) == [True]
    assert su2_side.finished_adjoints(run / "DESIGNS" / "DSN_001") == 3
