"""``ffd optimize`` through the solver interface with the ANALYTIC STAND-IN solver
(:mod:`ffdcli.optimize.solvers.analytic`: smooth functions of the wall points with exact dJ/dX, no
flow solver): convergence, resume, failures, max_failures, the gradient check, the design file's
``optimize:`` section and the command line's exit codes. The real SU2 loop: tests/test_optimize_su2.py."""

from __future__ import annotations

import csv
import json
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st

from ffdcli.api import DesignModel
from ffdcli.cli import main
from ffdcli.design import load_design
from ffdcli.design.optimize import optimize_settings, select_variables
from ffdcli.errors import InputError
from ffdcli.optimize.problem import OptimizationProblem
from ffdcli.optimize.solvers.analytic import AnalyticSolver
from ffdcli.optimize.workflow import run_optimize

ROOT = Path(__file__).resolve().parents[2]
MESH = ROOT / "samples" / "naca0012_2d.su2"
VARIABLES = ["c0", "c1.shape.upper[1]", "c1.shape.upper[2]", "c1.shape.upper[3]", "c1.shape.upper[4]",
             "c1.shape.lower[1]", "c1.shape.lower[2]", "c1.shape.lower[3]", "c1.shape.lower[4]"]


def write_case(tmp_path: Path, analytic: dict | None = None, **optimize) -> Path:
    """A 2D design (6 x 2 box: twist + 8 shape variables, t/c >= baseline at 30 % chord) solved by the
    analytic stand-in: minimise DRAG = mean(y^2) with LIFT = 10 mean(y) >= 0.1."""
    (tmp_path / "analytic.yaml").write_text(yaml.safe_dump({"marker": "airfoil", **(analytic or {})}))
    opt = {"solver": "analytic", "config": "analytic.yaml", "objective": "DRAG",
           "functions": [{"name": "LIFT", "lower": 0.1}], "variables": VARIABLES, "iterations": 12,
           "folder": "opt", **optimize}
    design = {"mesh": str(MESH), "surface": "airfoil", "box": {"points": [6, 2]},
              "changes": [{"twist": 0}, {"shape": {"upper": [0] * 6, "lower": [0] * 6}}],
              "bounds": {"c0.twist": [-3, 3], "c1.shape": [-0.03, 0.03]},
              "constraints": [{"thickness_to_chord": {"chord": [0.3], "lower": 1.0}}], "optimize": opt}
    path = tmp_path / "design.yaml"
    path.write_text(yaml.safe_dump(design, sort_keys=False))
    return path


def solver_for(path: Path) -> AnalyticSolver:
    return AnalyticSolver(Path(path).parent / "analytic.yaml")


def history(path: Path) -> list[dict]:
    with open(path) as fh:
        return list(csv.DictReader(fh))


def test_converges_feasible_with_outputs(tmp_path):
    path = write_case(tmp_path, iterations=40)
    solver = solver_for(path)
    out = run_optimize(path, solver=solver)
    assert out["status"] == "converged", out["message"]
    assert out["constraints_satisfied"]
    assert out["objective"]["best"] < out["objective"]["initial"] - 5e-5
    assert out["functions"]["LIFT"] >= 0.1 - 1e-6
    assert out["iterations"] >= 3
    # one flow per evaluation, the adjoints (DRAG, LIFT) only at the accepted iterates
    assert out["flow_solves"] == solver.flows == out["evaluations"]
    assert out["adjoint_solves"] == solver.adjoints <= 2 * (out["iterations"] + 1)
    assert solver.adjoints >= 2 * out["iterations"]
    folder = tmp_path / "opt"
    rows = history(folder / "history.csv")
    assert len(rows) == out["evaluations"]
    assert {"evaluation", "iteration", "norm", "objective", "LIFT", "k0.thickness_to_chord[0]", "violation", "step",
            "solver_seconds", "ffd_seconds", "optimizer_seconds", "folder", "failed"} <= set(rows[0])
    # the optimiser's own time (its QPs, the constraints' Jacobian) is counted, and summed in the summary
    spent = [float(r["optimizer_seconds"]) for r in rows]
    assert spent[0] == 0.0 and sum(spent[1:]) > 0.0
    assert sum(spent) <= out["seconds"]["optimizer"] + 1e-3 <= out["seconds"]["wall"]
    assert (folder / "history.png").stat().st_size > 10_000
    for row in rows:
        assert (folder / row["folder"] / "mesh.su2").is_file()
    # best.yaml: the design file with the best values; loading it gives those values
    best = load_design(folder / "best.yaml")
    model = DesignModel.from_file(folder / "best.yaml")
    assert model.names[0] == "c0.twist"
    ev = json.loads((folder / "evals" / f"{out['best_evaluation']:04d}" / "result.json").read_text())
    assert np.array_equal(model.values, np.array(ev["values"]))
    assert best.mesh == MESH.resolve()
    assert (folder / "best.su2").read_bytes() == (folder / "evals" / f"{out['best_evaluation']:04d}" /
                                                  "mesh.su2").read_bytes()


def test_history_is_written_after_every_evaluation(tmp_path):
    """A long run can be watched: history.csv holds every finished evaluation when the next one starts."""
    path = write_case(tmp_path, iterations=3)
    seen = []

    class Watched(AnalyticSolver):
        def flow(self, folder, mesh, start=None):
            csv_path = tmp_path / "opt" / "history.csv"
            seen.append(len(history(csv_path)) if csv_path.is_file() else 0)
            return super().flow(folder, mesh, start)

    out = run_optimize(path, solver=Watched(tmp_path / "analytic.yaml"))
    assert out["evaluations"] >= 3
    assert seen == list(range(out["evaluations"]))


def test_screening_skips_the_adjoint_of_a_far_constraint(tmp_path):
    far = [{"name": "LIFT", "lower": 0.1}, {"name": "MOMENT_Z", "lower": -10.0}]
    path = write_case(tmp_path, functions=far, iterations=4)
    solver = solver_for(path)
    out = run_optimize(path, solver=solver)
    rows = history(tmp_path / "opt" / "history.csv")
    grads = [json.loads((tmp_path / "opt" / r["folder"] / "result.json").read_text())["gradients"] for r in rows]
    with_grad = [g for g in grads if g]
    assert set(with_grad[0]) == {"DRAG", "LIFT", "MOMENT_Z"}          # the baseline: every adjoint
    assert all(set(g) == {"DRAG", "LIFT"} for g in with_grad[1:])      # then MOMENT_Z (margin 1.0) screened
    assert out["adjoint_solves"] == solver.adjoints == 2 * len(with_grad) + 1
    # screen: null runs every adjoint at every iterate
    (tmp_path / "b").mkdir()
    path = write_case(tmp_path / "b", functions=far, iterations=4, screen=None)
    out = run_optimize(path, solver=solver_for(path))
    assert out["adjoint_solves"] == 3 * sum(1 for r in history(tmp_path / "b" / "opt" / "history.csv")
                                            if int(r["adjoint_solves"]))


@pytest.mark.parametrize("method", ["SLSQP", "SQP"])
def test_resume_reuses_every_finished_evaluation(tmp_path, method):
    path = write_case(tmp_path, iterations=3, method=method)
    first = solver_for(path)
    a = run_optimize(path, solver=first)
    again = solver_for(path)
    b = run_optimize(path, resume=True, solver=again)
    assert again.flows == 0 and again.adjoints == 0            # nothing run twice
    assert b["reused"] == a["evaluations"] and b["objective"] == a["objective"]
    # a longer run continues where the first stopped: the first evaluations are the same designs
    more = solver_for(path)
    c = run_optimize(path, ["optimize.iterations=6"], resume=True, solver=more)
    assert c["evaluations"] > a["evaluations"]
    assert more.flows == c["evaluations"] - a["evaluations"]
    assert c["reused"] == a["evaluations"]


def test_resume_says_when_the_folder_holds_evaluations_of_other_inputs(tmp_path):
    """A solver configuration changed since (here a comment) makes every evaluation another problem's: the
    resumed run says how many it does not reuse instead of silently solving them all again."""
    path = write_case(tmp_path, iterations=2)
    a = run_optimize(path, solver=solver_for(path))
    config = tmp_path / "analytic.yaml"
    config.write_text(config.read_text() + "noise: 0.0\n")
    warnings = []
    again = solver_for(path)
    b = run_optimize(path, resume=True, solver=again, warn=warnings.append)
    assert b["reused"] == 0 and again.flows == b["evaluations"]
    assert any(f"{a['evaluations']} finished evaluations" in w and "other inputs" in w for w in warnings), warnings


class _NewStateForm(AnalyticSolver):
    """The analytic stand-in whose ``state`` changed form in a new version, the old form kept as legacy."""

    def state(self):
        return "form 2\n" + super().state()

    def legacy_states(self):
        return (super().state(),)


def test_resume_reuses_the_evaluations_keyed_by_an_earlier_version_s_state(tmp_path):
    """A run made when ``state`` had another form (SU2's, before comments were left out) is found all the
    same by a resumed run: nothing solved again, no warning; without the legacy form it would not be."""
    path = write_case(tmp_path, iterations=2)
    a = run_optimize(path, solver=solver_for(path))
    warnings = []
    again = _NewStateForm(tmp_path / "analytic.yaml")
    b = run_optimize(path, resume=True, solver=again, warn=warnings.append)
    assert again.flows == 0 and again.adjoints == 0 and b["reused"] == a["evaluations"]
    assert b["objective"] == a["objective"] and not any("other inputs" in w for w in warnings)

    class Forgot(_NewStateForm):                 # the same new form with no legacy
        def legacy_states(self):
            return ()

    # the resumed run moved its evaluations to the new form: a version without the legacy finds them
    forgot = Forgot(tmp_path / "analytic.yaml")
    assert run_optimize(path, resume=True, solver=forgot)["reused"] == a["evaluations"] and forgot.flows == 0
    # a run never resumed under the new form is another problem's for it
    (tmp_path / "c").mkdir()
    path_c = write_case(tmp_path / "c", iterations=2)
    run_optimize(path_c, solver=solver_for(path_c))
    forgot = Forgot(tmp_path / "c" / "analytic.yaml")
    c = run_optimize(path_c, resume=True, solver=forgot, warn=warnings.append)
    assert c["reused"] == 0 and forgot.flows == c["evaluations"]


class _Forgetful(AnalyticSolver):
    """The analytic stand-in with a flow "solution" that a cleaned folder has lost."""

    lost: set = set()

    def has_flow(self, folder):
        return Path(folder).name not in self.lost


@pytest.mark.parametrize("files_lost", [False, True])
def test_resume_of_an_evaluation_stopped_before_its_adjoints(tmp_path, files_lost):
    """A run stopped between a design's flow and its adjoints, resumed: the adjoints run; when the
    folder also lost its mesh and flow solution (a record restored elsewhere), one more flow first."""
    path = write_case(tmp_path, iterations=3, method="SQP")
    run_optimize(path, solver=solver_for(path))
    folder = tmp_path / "opt" / "evals"
    withgrad = [p for p in sorted(folder.glob("*/result.json")) if json.loads(p.read_text())["gradients"]]
    last = withgrad[-1]
    data = json.loads(last.read_text())
    data["gradients"], data["solves"]["adjoint"] = {}, 0
    last.write_text(json.dumps(data))
    if files_lost:
        (last.parent / "mesh.su2").unlink()
    again = _Forgetful(tmp_path / "analytic.yaml")
    again.lost = {last.parent.name} if files_lost else set()
    run_optimize(path, resume=True, solver=again)
    assert again.adjoints == 2                        # DRAG's and LIFT's, of that design only
    assert again.flows == (1 if files_lost else 0)
    redone = json.loads(last.read_text())
    assert set(redone["gradients"]) == {"DRAG", "LIFT"}
    assert redone["solves"] == {"flow": 2 if files_lost else 1, "adjoint": 2}
    assert (last.parent / "mesh.su2").is_file()
    assert redone["functions"] == pytest.approx(data["functions"], rel=1e-12)


def test_best_mesh_made_again_when_the_folders_lost_their_meshes(tmp_path):
    path = write_case(tmp_path, iterations=3, method="SQP")
    run_optimize(path, solver=solver_for(path))
    best = tmp_path / "opt" / "best.su2"
    before = best.read_bytes()
    best.unlink()
    for mesh in (tmp_path / "opt" / "evals").glob("*/mesh.su2"):
        mesh.unlink()
    again = solver_for(path)
    run_optimize(path, resume=True, solver=again)
    assert again.flows == 0 and again.adjoints == 0
    assert best.read_bytes() == before


def test_a_design_within_same_design_of_a_finished_one_is_answered_by_it(tmp_path):
    """A resumed run's optimiser may reach its designs again only to the last digits (another version's
    arithmetic): within SAME_DESIGN of every variable the evaluation answers; beyond it, it does not."""
    from ffdcli.optimize.store import SAME_DESIGN, EvaluationStore
    store = EvaluationStore(tmp_path, "inputs", resume=False)
    x = np.array([0.01, -0.02, 1.5])
    ev = store.save(store.new(x, 0).with_(functions={"DRAG": 0.01}))
    again = EvaluationStore(tmp_path, "inputs", resume=True)
    assert again.find(x).index == ev.index
    assert again.find(x + np.array([0.0, 0.5, -0.9]) * SAME_DESIGN).index == ev.index
    assert again.find(x + np.array([0.0, 2.0, 0.0]) * SAME_DESIGN) is None
    assert again.find(x[:2]) is None                                   # another problem's length
    assert EvaluationStore(tmp_path, "other inputs", resume=True).find(x) is None


def test_folder_of_another_run_needs_resume(tmp_path):
    path = write_case(tmp_path, iterations=1)
    run_optimize(path, solver=solver_for(path))
    with pytest.raises(InputError, match="--resume"):
        run_optimize(path, solver=solver_for(path))


def test_failure_recorded_and_stepped_back(tmp_path):
    path = write_case(tmp_path, analytic={"fail_calls": [3]})
    out = run_optimize(path, solver=solver_for(path))
    rows = history(tmp_path / "opt" / "history.csv")
    failed = [r for r in rows if r["failed"]]
    assert len(failed) == 1 and "failure injected" in failed[0]["failed"] and "flow.log" in failed[0]["failed"]
    assert out["constraints_satisfied"] and out["status"] in ("converged", "iterations")
    # the next design lies between the last accepted design and the failed one (a shorter step back)
    evs = {int(r["evaluation"]): json.loads((tmp_path / "opt" / r["folder"] / "result.json").read_text())
           for r in rows}
    k = int(failed[0]["evaluation"])
    anchor = max((i for i, e in evs.items() if i < k and e["gradients"]), key=int)
    x0, xf, xn = (np.array(evs[i]["values"]) for i in (anchor, k, k + 1))
    t = np.dot(xn - x0, xf - x0) / np.dot(xf - x0, xf - x0)
    assert 0.05 < t < 0.95
    assert np.linalg.norm(xn - x0 - t * (xf - x0)) < 1e-9 * max(1.0, np.linalg.norm(xf - x0))


def test_max_failures_exit_1_with_best_written(tmp_path):
    # every flow after the baseline's fails
    path = write_case(tmp_path, analytic={"fail_calls": list(range(2, 30))}, max_failures=2)
    out = run_optimize(path, solver=solver_for(path))
    assert out["status"] == "failures" and out["exit_code"] == 1
    rows = history(tmp_path / "opt" / "history.csv")
    assert sum(bool(r["failed"]) for r in rows) == 3
    assert (tmp_path / "opt" / "best.yaml").is_file() and (tmp_path / "opt" / "best.su2").is_file()
    code = run_cli([str(path), "--resume", "--json", "-q"])
    assert code == 1


def test_check_gradient_agrees(tmp_path):
    path = write_case(tmp_path)
    out = run_optimize(path, check=["c0.twist", "c1.shape.upper[2]", "c1.shape.lower[3]"], solver=solver_for(path))
    rows = out["gradient_check"]
    # the solver's functions, then the geometric constraint (t/c at 30 % chord), from the same two flows each
    cons = [r for r in rows if r["function"] not in ("DRAG", "LIFT")]
    assert len(rows) - len(cons) == 6 and len(cons) == 3 and len({r["function"] for r in cons}) == 1
    assert "thickness_to_chord" in cons[0]["function"]
    for r in rows:
        assert r["relative"] < 1e-5 or abs(r["finite_difference"]) < 1e-10, r
        assert r["step"] == pytest.approx(6e-3 if r["variable"] == "c0.twist" else 6e-5)
    # the shape moves change t/c and the constraint's exact Jacobian says by how much
    moved = [r for r in cons if r["variable"] != "c0.twist"]
    assert all(abs(r["finite_difference"]) > 1e-3 for r in moved), moved


def run_cli(argv) -> int:
    with pytest.raises(SystemExit) as e:
        main(["optimize", *argv])
    return e.value.code


def test_cli_json_and_exit_codes(tmp_path, capsys, monkeypatch):
    path = write_case(tmp_path, iterations=2)
    assert run_cli([str(path), "--json", "-q"]) == 0
    out = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    for key in ("status", "iterations", "evaluations", "flow_solves", "adjoint_solves", "objective", "functions",
                "constraints_satisfied", "best", "seconds"):
        assert key in out
    assert set(out["objective"]) == {"initial", "best"} and set(out["seconds"]) >= {"solver", "ffd"}
    assert run_cli([str(path), "--check-gradient", "c0.twist", "--json", "-q", "--set", "optimize.folder=chk"]) == 0
    rows = json.loads(capsys.readouterr().out.strip().splitlines()[-1])["gradient_check"]
    assert set(rows[0]) >= {"function", "variable", "adjoint", "finite_difference", "relative"}
    # a missing solver configuration: exit 2 before any work
    sub = tmp_path / "b"
    sub.mkdir()
    bad = write_case(sub, config="nope.cfg")
    assert run_cli([str(bad)]) == 2
    assert "optimize.config" in capsys.readouterr().err
    assert not (bad.parent / "opt").exists()
    # SU2 nowhere: exit 2 naming SU2_RUN, before any work
    (bad.parent / "su2.cfg").write_text("SOLVER= EULER\n")
    su2 = write_case(bad.parent, solver="su2", config="su2.cfg", folder="su2run")
    monkeypatch.setenv("PATH", "/nonexistent")
    monkeypatch.delenv("SU2_RUN", raising=False)
    assert run_cli([str(su2)]) == 2
    assert "SU2_RUN" in capsys.readouterr().err
    assert not (bad.parent / "su2run").exists()


@pytest.mark.parametrize("change, key, words", [
    ({"objective": "LIFT"}, "optimize.functions[0].name", "also optimize.objective"),
    ({"functions": [{"name": "LIFT"}]}, "optimize.functions[0]", "neither lower nor upper"),
    ({"functions": [{"name": "LIFT", "lower": 2, "upper": 1}]}, "optimize.functions[0].lower", "above upper"),
    ({"method": "BFGS"}, "optimize.method", "SLSQP"),
    ({"launch": "mpirun -n 'x"}, "optimize.launch", "quotes"),
    ({"iterations": -1}, "optimize.iterations", "at least 0"),
    ({"colour": 1}, "optimize.colour", "unknown key"),
    ({"variables": ["c7"]}, "optimize.variables[0]", "names no design variable"),
])
def test_optimize_section_errors_name_the_key(tmp_path, change, key, words):
    path = write_case(tmp_path, **change)
    with pytest.raises(InputError) as e:
        design = load_design(path)
        settings = optimize_settings(design)
        names = ["c0.twist", "c1.shape.upper[0]"]
        select_variables(names, settings.variables, error=design.error)
    assert e.value.key == key and words in str(e.value)


def test_optimize_settings_paths_and_launch(tmp_path):
    path = write_case(tmp_path, launch="mpirun -n 8 --bind-to 'core x'")
    s = optimize_settings(load_design(path))
    assert s.launch == ("mpirun", "-n", "8", "--bind-to", "core x")
    assert s.config == (tmp_path / "analytic.yaml").resolve() and s.folder == (tmp_path / "opt").resolve()
    assert s.function_names == ["DRAG", "LIFT"] and s.method == "SLSQP" and s.max_failures == 3
    assert select_variables(["c0.twist", "c1.shape.upper[1]", "c10.span"], ["c1"]) == [1]


def test_trust_constr_runs_feasible(tmp_path):
    path = write_case(tmp_path, method="trust-constr", iterations=15)
    out = run_optimize(path, solver=solver_for(path))
    assert out["status"] in ("converged", "iterations")
    assert out["constraints_satisfied"] and out["objective"]["best"] < out["objective"]["initial"]


def test_sqp_with_move_limits_converges_feasible_with_adjoints_only_at_accepted_steps(tmp_path):
    path = write_case(tmp_path, method="SQP", iterations=40)
    solver = solver_for(path)
    out = run_optimize(path, solver=solver)
    assert out["status"] == "converged", out["message"]
    assert out["constraints_satisfied"] and out["functions"]["LIFT"] >= 0.1 - 1e-6
    (tmp_path / "slsqp").mkdir()
    other = write_case(tmp_path / "slsqp", iterations=40)
    reference = run_optimize(other, solver=solver_for(other))
    assert out["objective"]["best"] == pytest.approx(reference["objective"]["best"], rel=1e-3)
    assert out["flow_solves"] == solver.flows == out["evaluations"]
    assert out["adjoint_solves"] == solver.adjoints == 2 * (out["iterations"] + 1)
    rows = history(tmp_path / "opt" / "history.csv")
    # the first step moves no variable by more than move_limit (0.1) of its bound range
    first = json.loads((tmp_path / "opt" / rows[1]["folder"] / "result.json").read_text())["values"]
    base = json.loads((tmp_path / "opt" / rows[0]["folder"] / "result.json").read_text())["values"]
    model = DesignModel.from_file(path)
    r = model.upper - model.lower
    assert np.max(np.abs(np.subtract(first, base)) / np.where(np.isfinite(r), r, 1.0)) <= 0.1 + 1e-12
    # each trial's verdict: accepted where the adjoints were run, rejected (with its ratio) elsewhere
    assert rows[0]["trial"] == ""
    for row in rows[1:]:
        word = "accepted" if int(row["adjoint_solves"]) else "rejected"
        assert row["trial"].startswith(word) and "of the predicted" in row["trial"], row["trial"]


def test_sqp_steps_back_from_a_failed_design(tmp_path):
    path = write_case(tmp_path, method="SQP", analytic={"fail_calls": [3]}, iterations=40)
    lines = []
    out = run_optimize(path, solver=solver_for(path), report=lines.append)
    # each trial's verdict is said as it happens, after its flow's line
    trials = [ln for ln in lines if " trial " in ln]
    assert len(trials) == out["evaluations"] - 1
    assert any(" trial failed" in ln for ln in trials) and any(" trial accepted" in ln for ln in trials)
    replayed = []
    run_optimize(path, resume=True, solver=solver_for(path), report=replayed.append)
    assert not any(" trial " in ln for ln in replayed)             # a replay does not say them again
    rows = history(tmp_path / "opt" / "history.csv")
    failed = [r for r in rows if r["failed"]]
    assert len(failed) == 1 and "failure injected" in failed[0]["failed"]
    assert failed[0]["trial"].startswith("failed")
    assert out["constraints_satisfied"] and out["status"] == "converged"
    evs = [json.loads((tmp_path / "opt" / r["folder"] / "result.json").read_text()) for r in rows]
    k = rows.index(failed[0])
    anchor = max(i for i in range(k) if evs[i]["gradients"])       # the accepted design before it
    model = DesignModel.from_file(path)
    r = np.where(np.isfinite(model.upper - model.lower), model.upper - model.lower, 1.0)
    x = [np.array(e["values"]) / r for e in evs]                   # the optimiser's scaled variables
    assert np.abs(x[k + 1] - x[anchor]).max() <= 0.25 * np.abs(x[k] - x[anchor]).max() + 1e-12


class _SlowAdjoints(AnalyticSolver):
    """The analytic stand-in whose adjoints take 0.3 s each and record when they ran (and fail for
    ``fail``): what ``concurrent_adjoints`` changes is when they run, never what they give."""

    def __init__(self, config, fail=None):
        super().__init__(config)
        self.spans, self.fail = [], fail

    def adjoint(self, folder, mesh, function, start=None):
        import time

        t0 = time.perf_counter()
        time.sleep(0.3)
        self.spans.append((t0, time.perf_counter()))
        if function == self.fail:
            from ffdcli.optimize.solvers.base import SolverFailure
            raise SolverFailure(f"the adjoint of {function} diverged (a test)", None)
        return super().adjoint(folder, mesh, function, start)


def test_concurrent_adjoints_give_the_same_run_and_overlap(tmp_path):
    runs = {}
    for n in (1, 2):
        (tmp_path / f"c{n}").mkdir()
        path = write_case(tmp_path / f"c{n}", iterations=3, concurrent_adjoints=n)
        solver = _SlowAdjoints(path.parent / "analytic.yaml")
        out = run_optimize(path, solver=solver)
        runs[n] = (out, history(path.parent / "opt" / "history.csv"), solver.spans)
    (a, ha, sa), (b, hb, sb) = runs[1], runs[2]
    assert a["adjoint_solves"] == b["adjoint_solves"] > 2
    assert [r["objective"] for r in ha] == [r["objective"] for r in hb]       # the same run, value for value
    assert a["objective"]["best"] == b["objective"]["best"]

    def overlapping(spans):
        spans = sorted(spans)
        return sum(s1 < e0 for (_, e0), (s1, _) in zip(spans, spans[1:]))
    assert overlapping(sa) == 0 and overlapping(sb) >= 1                     # two at once with 2


def test_a_failed_concurrent_adjoint_is_recorded(tmp_path):
    path = write_case(tmp_path, iterations=2, concurrent_adjoints=2, max_failures=0)
    out = run_optimize(path, solver=_SlowAdjoints(path.parent / "analytic.yaml", fail="LIFT"))
    rows = history(tmp_path / "opt" / "history.csv")
    assert "adjoint of LIFT" in rows[0]["failed"] and "diverged" in rows[0]["failed"]
    assert out["status"] != "converged"


class _Ev:
    """A finished evaluation as the store keeps it (what the warm start reads)."""

    def __init__(self, name, values, gradients=()):
        self.folder = Path(name)
        self.values = np.asarray(values, dtype=float)
        self.failed = None
        self.functions = {"DRAG": 0.01}
        self.gradients = {g: np.zeros(len(self.values)) for g in gradients}


class _Store:
    def __init__(self, evs):
        self.evs = evs

    def all(self):
        return list(self.evs)


def _problem(evs, warm_start=True):
    model = SimpleNamespace(design=SimpleNamespace(mesh="m.su2"))
    return OptimizationProblem(model, solver=None, store=_Store(evs), functions=["DRAG"], warm_start=warm_start)


@settings(max_examples=25, deadline=None)
@given(st.integers(2, 6), st.floats(0.05, 0.95), st.integers(0, 2**31 - 1))
def test_a_trial_starts_from_the_nearest_accepted_design_not_a_nearer_rejected_trial(n, frac, seed):
    """The warm start of a flow: the nearest evaluation with gradients (an accepted design) even when a
    rejected trial (no gradients) is nearer; with no gradients anywhere, the nearest; an adjoint's start
    needs that adjoint; none when warm starts are off."""
    rng = np.random.default_rng(seed)
    x = rng.normal(size=n)
    d = rng.normal(size=n)
    accepted = _Ev("accepted", x, gradients=["DRAG"])
    far = _Ev("far_accepted", x + 10 * d, gradients=["DRAG"])
    rejected = _Ev("rejected", x + frac * d)                  # nearer to the new trial than x is
    trial = x + d
    p = _problem([far, accepted, rejected])
    assert p._nearest(trial) == Path("accepted")
    assert p._nearest(trial, "DRAG") == Path("accepted")
    assert _problem([rejected, _Ev("other", x)])._nearest(trial) == Path("rejected")
    assert _problem([accepted, rejected], warm_start=False)._nearest(trial) is None
    assert _problem([rejected])._nearest(trial, "DRAG") is None
