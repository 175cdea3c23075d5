"""ADODG Case 2's evaluation of an optimum on the finer C-mesh (benchmarks/adodg/case2_evaluate.py) and
its SU2 solves' set-up and reading (benchmarks/adodg/case2_solve.py), without a solver but for one short
test marked ``solver``.

A run is faked on a coarse C-mesh of a cambered section (``ffdcli.testing.cmesh``; its history and
evaluation folders written as ``ffd optimize`` writes them, the design's mesh by ``ffd deform`` with the
automatic 13 x 2 box of ``configs/adodg/case2.yaml``) and evaluated on a finer C-mesh of the same section,
whose wall shares only a few nodes with the coarse one, as ``rae2822_s1`` with SU2's mesh."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest
import yaml

from benchmarks.adodg import case2_evaluate as c2
from benchmarks.adodg import case2_solve
from benchmarks.adodg.case2_evaluate import (
    area_ratio,
    evaluate,
    pick_row,
    project,
    shape_check,
    wall,
)
from benchmarks.adodg.case2_meshes import wall_section
from benchmarks.adodg.case2_solve import CAUCHY_EPS, read_solve, run_solve, solve_config
from benchmarks.adodg.evaluate import design_data, ffd, write_yaml
from ffdcli.io.formats import read_mesh, write_mesh
from ffdcli.optimize.solvers.base import find_program
from ffdcli.optimize.solvers.su2 import config_value, read_config
from ffdcli.testing.cmesh import cmesh
from ffdcli.testing.naca import naca4

ROOT = Path(__file__).resolve().parents[2]
DESIGN = ROOT / "configs" / "adodg" / "case2.yaml"


@pytest.fixture(scope="module")
def meshes(tmp_path_factory):
    """A coarse C-mesh of the NACA 2412 with a sharp trailing edge (the run's: 192 wall nodes, as SU2's
    RAE2822 mesh) and a finer one of its wall section (384 wall nodes, as ``rae2822_s1`` is made)."""
    folder = tmp_path_factory.mktemp("meshes")
    coarse, fine = folder / "coarse.su2", folder / "fine.su2"
    write_mesh(cmesh(naca4("2412", 121), 193, 9, 13, 1e-4, 20.0), coarse)
    write_mesh(cmesh(wall_section(coarse, "airfoil"), 385, 17, 17, 1e-4, 20.0), fine)
    return coarse, fine


def design_file(folder: Path, mesh: Path) -> Path:
    """case2.yaml on ``mesh`` (marker ``airfoil``; its run folder ``opt``)."""
    data = yaml.safe_load(DESIGN.read_text())
    data.update(mesh=str(mesh), surface="airfoil", output={"mesh": str(folder / "unused.su2")})
    data["optimize"].update(folder=str(folder / "opt"), config=str(DESIGN.parent / "case2.cfg"))
    return write_yaml(folder / "design.yaml", data)


def names_of(design: Path) -> list[str]:
    return [v["name"] for v in ffd("vars", str(design))["variables"]]


def fake_run(folder: Path, design: Path, mesh: Path, designs: list[tuple[list[float], float, float]]) -> Path:
    """A run folder as ``ffd optimize`` writes it: history.csv and evals/NNNN/{result.json, mesh.su2},
    each mesh made by ``ffd deform`` with the automatic box, as the run's evaluations are."""
    run, names, rows = folder / "opt", names_of(design), []
    for k, (values, cd, violation) in enumerate(designs, start=1):
        ev = run / "evals" / f"{k:04d}"
        ev.mkdir(parents=True)
        yml = write_yaml(ev / "design.yaml", design_data(design, mesh, values=values, names=names, box_file=None,
                                                          output=ev / "mesh.su2"))
        ffd("deform", str(yml), "--cache-dir", str(folder / "cache"))
        (ev / "result.json").write_text(json.dumps({"index": k, "values": values}))
        rows.append({"evaluation": k, "iteration": k - 1, "objective": cd, "LIFT": 0.82, "MOMENT_Z": 0.09,
                     "k0.volume": 1.0, "violation": violation, "folder": f"evals/{k:04d}", "failed": ""})
    with open(run / "history.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    return run


def moves(rng, scale: float) -> list[float]:
    """Random moves of the 12 columns ahead of the trailing edge of both rows (the trailing edge's 0)."""
    up, lo = rng.uniform(-scale, scale, 12), rng.uniform(-scale, scale, 12)
    return [*up, 0.0, *lo, 0.0]


@pytest.fixture(scope="module")
def evaluated(meshes, tmp_path_factory):
    """A run of three evaluations (the baseline, a feasible design, a lower-drag infeasible one)
    evaluated on the finer mesh without a solver."""
    coarse, fine = meshes
    folder = tmp_path_factory.mktemp("run")
    design = design_file(folder, coarse)
    rng = np.random.default_rng(3)
    good, bad = moves(rng, 4e-3), moves(rng, 4e-3)
    run = fake_run(folder, design, coarse, [([0.0] * 26, 0.0194, 0.019), (good, 0.0130, 5e-5), (bad, 0.0120, 3e-3)])
    out = evaluate(design, run, fine, folder / "work", run_solve=False)
    return {"out": out, "design": design, "run": run, "work": folder / "work", "good": good, "bad": bad,
            "meshes": meshes}


def test_the_best_feasible_evaluation_is_taken_and_its_lattice_rebuilds_the_run_mesh_exactly(evaluated):
    out = evaluated["out"]
    assert out["evaluation"] == 2 and out["feasible"]          # 3 has the lower CD but breaks a constraint
    assert out["lattice_error"] <= 1e-12                        # the Plot3D file is the run's lattice
    assert list(out["values"].values()) == pytest.approx(evaluated["good"], abs=0)
    assert out["run_result"]["cd"] == 0.0130 and out["run_result"]["cm"] == -0.09    # CM nose-up: SU2's CMz negated
    assert out["reduction_run"]["alpha"] == pytest.approx(1 - 0.0130 / 0.0194)
    assert "solves" not in out                                   # no solver asked


def test_the_finer_wall_carries_the_optimum_s_displacement(evaluated):
    out = evaluated["out"]
    assert out["shape_ok"] and out["shape_error"] <= out["shape_tolerance"] <= 1e-5
    assert out["max_displacement"] > 1e-3                       # the check compares a real move
    assert out["common_nodes"] >= 1 and out["common_error"] <= 1e-12   # the trailing edge at least
    assert out["wall_nodes"] == 384 and out["section_gap"] <= 1e-12   # on the run wall's spline
    # the area ratio on the finer mesh is the run mesh's, to the sections' resolution
    assert out["area_ratio"] == pytest.approx(out["area_ratio_run_mesh"], abs=2e-3)
    assert out["area_ratio"] != pytest.approx(1.0, abs=1e-4)


def test_the_shape_check_sees_a_wrong_design_on_the_finer_mesh(evaluated, tmp_path):
    """The finer mesh deformed by the *other* design: the displacements disagree far beyond the tolerance."""
    coarse, fine = evaluated["meshes"]
    design, names = evaluated["design"], names_of(evaluated["design"])
    xyz = evaluated["work"] / "e0002" / "lattice.xyz"
    wrong = tmp_path / "wrong.su2"
    ffd("deform", str(write_yaml(tmp_path / "wrong.yaml",
                                 c2.fine_design(design, fine, "airfoil", evaluated["bad"], names, xyz, wrong))),
        "--cache-dir", str(tmp_path / "cache"))
    ids_r, base_r = wall(coarse, "airfoil")
    des_r = wall(evaluated["run"] / "evals" / "0002" / "mesh.su2", "airfoil")[1]
    ids_f, base_f = wall(fine, "airfoil")
    got = shape_check(base_r, des_r, base_f, wall(wrong, "AIRFOIL")[1])
    assert not got["shape_ok"] and got["shape_error"] > 1e-3


def test_a_run_restored_without_its_meshes_is_evaluated_the_same(evaluated, tmp_path):
    """A record keeps each evaluation's result.json but not its mesh: the evaluation's mesh is made again
    from its values with the run's automatic lattice, and every figure is the one from the kept mesh."""
    src = evaluated["run"]
    run = tmp_path / "opt"
    run.mkdir()
    (run / "history.csv").write_text((src / "history.csv").read_text())
    for k in ("0001", "0002", "0003"):                          # what `record restore` writes
        (run / "evals" / k).mkdir(parents=True)
        (run / "evals" / k / "result.json").write_text((src / "evals" / k / "result.json").read_text())
    out = evaluate(evaluated["design"], run, evaluated["meshes"][1], tmp_path / "work", evaluation=2,
                   run_solve=False)
    kept = evaluated["out"]
    assert out["run_mesh_rebuilt"] and not kept["run_mesh_rebuilt"]
    rebuilt = tmp_path / "work" / "e0002" / "run_mesh_0002.su2"
    assert rebuilt.is_file() and not (run / "evals" / "0002" / "mesh.su2").exists()   # the run folder untouched
    ids = wall(evaluated["meshes"][0], "airfoil")[0]
    assert np.abs(read_mesh(rebuilt).points[ids] - read_mesh(src / "evals" / "0002" / "mesh.su2").points[ids]).max() \
        <= 1e-14
    assert out["lattice_error"] <= 1e-12
    for key in ("shape_error", "area_ratio", "area_ratio_run_mesh", "common_error"):
        assert out[key] == pytest.approx(kept[key], abs=1e-14), key


@pytest.mark.parametrize("seed", range(4))
def test_shape_check_on_a_smooth_field_and_a_bump(meshes, seed):
    """Any smooth displacement field sampled on both walls passes; one node moved by 1e-5 fails there."""
    coarse, fine = meshes
    rng = np.random.default_rng(seed)
    c = rng.uniform(-3e-3, 3e-3, (4, 2))

    def field(xy):
        x, y = xy[:, 0], xy[:, 1]
        return np.column_stack([np.zeros_like(x), c[0, 0] + c[1, 0] * x + c[2, 0] * np.sin(3 * x) + c[3, 0] * y])

    base_r, base_f = wall(coarse, "airfoil")[1], wall(fine, "airfoil")[1]
    got = shape_check(base_r, base_r + field(base_r), base_f, base_f + field(base_f))
    assert got["shape_ok"], got
    bumped = base_f + field(base_f)
    node = int(rng.integers(1, len(base_f) - 1))
    bumped[node, 1] += 1e-5
    bad = shape_check(base_r, base_r + field(base_r), base_f, bumped)
    assert got["shape_tolerance"] < 1e-6 and bad["shape_error"] >= 1e-5 - got["shape_error"] and not bad["shape_ok"]
    assert bad["worst_at"] == pytest.approx(base_f[node].tolist())


def test_projection_on_a_closed_loop(meshes):
    base_r = wall(meshes[0], "airfoil")[1]
    k, t, d = project(base_r, base_r)                            # every node is on the loop
    assert d.max() <= 1e-15
    mid = 0.5 * (base_r + np.roll(base_r, -1, axis=0))
    k, t, d = project(mid, base_r)
    assert d.max() <= 1e-15 and np.allclose(t, 0.5) and np.array_equal(k, np.arange(len(base_r)))


def test_area_ratio_of_a_uniformly_thickened_section(meshes):
    base = wall(meshes[0], "airfoil")[1]
    assert area_ratio(base, base * [1.0, 1.1]) == pytest.approx(1.1, rel=1e-12)
    assert area_ratio(base, base + [0.0, 0.01]) == pytest.approx(1.0, rel=1e-12)   # a shift adds no area


def test_evaluation_json_has_the_fields(evaluated):
    saved = json.loads((evaluated["work"] / "e0002" / "evaluation.json").read_text())
    for key in ("design", "run", "evaluation", "feasible", "violation", "run_mesh", "mesh", "lattice_file",
                "values", "run_result", "lattice_error", "shape_error", "shape_tolerance", "shape_ok",
                "common_nodes", "common_error", "section_gap", "wall_nodes", "deform", "check", "area_ratio",
                "area_ratio_run_mesh", "reduction_run"):
        assert key in saved, key
    q = saved["deform"]["quality"]
    assert q["inverted"] == 0 and q["ok"] and q["min_after"] > 0.1
    wl = saved["deform"]["wall_layer"]                          # the first cells move rigidly with the wall
    assert wl is not None and abs(wl["ratio_min"] - 1) < 1e-3 and abs(wl["ratio_max"] - 1) < 1e-3
    assert saved["check"]["wall_layer"]["height_min"] == pytest.approx(1e-4, rel=0.05)
    assert Path(saved["lattice_file"]).is_file()


def test_evaluation_n_is_taken_when_asked_and_refused_when_absent(evaluated):
    run = evaluated["run"]
    assert int(pick_row(run, 1e-4, 3)["evaluation"]) == 3 and not pick_row(run, 1e-4, 3)["feasible"]
    with pytest.raises(c2.EvaluationError, match="--evaluation 9: not a finished evaluation"):
        pick_row(run, 1e-4, 9)


@pytest.mark.parametrize("case", ["run", "mesh", "evaluation", "design", "files"])
def test_a_missing_input_is_one_line_and_exit_2(evaluated, tmp_path, capsys, case):
    run, fine = evaluated["run"], evaluated["meshes"][1]
    args = {"design": str(evaluated["design"]), "run": str(run), "mesh": str(fine), "evaluation": None}
    said = {"run": "no history.csv", "mesh": "no such file", "evaluation": "not a finished evaluation",
            "design": "no such file", "files": "no result.json"}[case]
    if case == "run":
        args["run"] = str(tmp_path / "none")
    elif case == "mesh":
        args["mesh"] = str(tmp_path / "none.su2")
    elif case == "evaluation":
        args["evaluation"] = "7"
    elif case == "design":
        args["design"] = str(tmp_path / "none.yaml")
    else:                                                        # an evaluation folder without its files
        broken = tmp_path / "opt"
        (broken / "evals" / "0001").mkdir(parents=True)
        (broken / "history.csv").write_text((run / "history.csv").read_text().splitlines()[0] + "\n"
                                            + (run / "history.csv").read_text().splitlines()[1] + "\n")
        args["run"] = str(broken)
    argv = ["--design", args["design"], "--run", args["run"], "--mesh", args["mesh"], "--work", str(tmp_path / "w")]
    argv += ["--evaluation", args["evaluation"]] if args["evaluation"] else []
    code = c2.main(argv + ["--no-solve"])
    err = capsys.readouterr().err
    assert code == 2 and said in err and len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert not (tmp_path / "w").exists()                        # nothing half-written


def test_solve_config_at_alpha_and_at_the_lift(meshes, tmp_path):
    fine = meshes[1]
    a = solve_config(fine, "alpha").splitlines()
    assert config_value(a, "MESH_FILENAME") == str(fine.resolve()) and config_value(a, "AOA") == "2.79"
    assert config_value(a, "MARKER_HEATFLUX") == "( airfoil, 0.0 )" and config_value(a, "FIXED_CL_MODE") is None
    assert config_value(a, "CONV_RESIDUAL_MINVAL") == "-8" and config_value(a, "RESTART_SOL") == "NO"
    c = solve_config(fine, "cl", restart=tmp_path / "r.dat", iterations=50).splitlines()
    assert config_value(c, "FIXED_CL_MODE") == "YES" and config_value(c, "TARGET_CL") == "0.824"
    assert float(config_value(c, "CONV_CAUCHY_EPS")) == CAUCHY_EPS
    assert config_value(c, "RESTART_SOL") == "YES" and config_value(c, "SOLUTION_FILENAME") == str(tmp_path / "r.dat")
    assert config_value(c, "CONV_RESIDUAL_MINVAL") == "-9" and config_value(c, "ITER") == "50"
    assert config_value(a, "MGLEVEL") == "3" and config_value(solve_config(fine, "alpha", multigrid=1).splitlines(),
                                                              "MGLEVEL") == "1"
    assert config_value(a, "CFL_ADAPT") == "YES"                           # case2.cfg's adapted CFL by default
    for cfl in (20.0, 50.0):
        f = solve_config(fine, "cl", restart=tmp_path / "r.dat", cfl=cfl).splitlines()
        assert config_value(f, "CFL_ADAPT") == "NO" and float(config_value(f, "CFL_NUMBER")) == cfl
    with pytest.raises(ValueError, match="expected 'alpha' or 'cl'"):
        solve_config(fine, "mach")


def write_solve(folder: Path, mode: str, rows: list[tuple[int, float, float, float, float]], iterations: int = 3000,
                log: str = "", rc: int = 0, target: int = -8) -> Path:
    """A finished solve's folder: flow.cfg, history.csv (Inner_Iter, rms[Rho], CD, CL, CMz), log, run.json."""
    folder.mkdir(parents=True)
    keys = [f"ITER= {iterations}", f"CONV_RESIDUAL_MINVAL= {target}", "AOA= 2.79"]
    if mode == "cl":
        keys += ["FIXED_CL_MODE= YES", f"CONV_CAUCHY_EPS= {CAUCHY_EPS}"]
    (folder / "flow.cfg").write_text("\n".join(keys) + "\n")
    head = '"Time_Iter","Outer_Iter","Inner_Iter","rms[Rho]","CD","CL","CMz"\n'
    (folder / "history.csv").write_text(head + "".join(f"0,0,{i},{r},{d},{lift},{m}\n" for i, r, d, lift, m in rows))
    (folder / "log.txt").write_text(log)
    (folder / "run.json").write_text(json.dumps({"mesh": "m.su2", "mode": mode, "rc": rc, "restart": None,
                                                 "wall": 10.0, "cpu": 9.0}))
    return folder


def test_read_solve_judges_convergence_by_the_stated_criterion(tmp_path):
    rows = [(0, -4.0, 0.03, 0.5, 0.1), (245, -8.01, 0.0194, 0.805, 0.0961)]
    a = read_solve(write_solve(tmp_path / "a", "alpha", rows))
    assert a["converged"] and a["iterations"] == 246 and a["cd"] == 0.0194 and a["cm"] == -0.0961
    assert a["criterion"] == "rms[Rho] <= -8" and a["alpha"] == 2.79 and a["cpu"] == 9.0
    stalled = read_solve(write_solve(tmp_path / "b", "alpha", [(2999, -7.5, 0.02, 0.8, 0.09)]))
    assert not stalled["converged"]
    log = "|Previous AOA                            |2.91799                       |\n" \
          "|Changed AoA by                          |0.00226738                    |\n"
    cl = read_solve(write_solve(tmp_path / "c", "cl", [(700, -9.2, 0.0209, 0.824004, 0.0962)], log=log, target=-9))
    assert cl["converged"] and cl["alpha"] == pytest.approx(2.92025738) and "fixed-CL" in cl["criterion"]
    off = read_solve(write_solve(tmp_path / "d", "cl", [(700, -9.2, 0.0209, 0.82402, 0.0962)], log=log, target=-9))
    assert not off["converged"]                                   # the lift 2e-5 off the target
    capped = read_solve(write_solve(tmp_path / "e", "cl", [(2999, -9.2, 0.0209, 0.824, 0.0962)], log=log,
                                    iterations=3000, target=-9))
    assert not capped["converged"]                                # stopped by ITER, not by SU2's test
    failed = read_solve(write_solve(tmp_path / "f", "alpha", [(245, -8.01, 0.0194, 0.805, 0.0961)], rc=1))
    assert not failed["converged"]
    assert c2.finished(a) and c2.finished(stalled) and not c2.finished(failed)     # diverged: rc 1


@pytest.mark.parametrize("aoa", [2.74112662988105, 3.1, 1.95])
def test_a_fixed_cl_solve_without_su2_s_aoa_lines_reads_the_angle_from_flow_meta(tmp_path, aoa):
    folder = write_solve(tmp_path / "c", "cl", [(551, -7.1, 0.02114, 0.824069, 0.10416)], target=-9)
    assert read_solve(folder)["alpha"] is None                   # neither in the log nor a flow.meta
    (folder / "flow.meta").write_text(f"ITER= 551\nAOA= {aoa!r}\nSIDESLIP_ANGLE= 0\nDCD_DCL_VALUE= 0.1\n")
    assert read_solve(folder)["alpha"] == aoa


def test_a_design_whose_alpha_solve_diverged_starts_its_fixed_cl_solve_from_the_baseline(evaluated, tmp_path,
                                                                                        monkeypatch):
    """Four solves faked: the design's alpha solve diverged (rc 1), so its restart is not the fixed-CL
    solve's start (the baseline's alpha solution is), and no drag reduction is taken from it."""
    calls = {}

    def fake(mesh, mode, folder, **kw):
        calls[(Path(folder).parent.name, mode)] = kw.get("restart")
        diverged = Path(folder).parent.name.startswith("e") and mode == "alpha"
        return read_solve(write_solve(tmp_path / "f" / f"{Path(folder).parent.name}_{mode}", mode,
                                      [(700, 3.0 if diverged else -8.5, 0.02, 0.824, 0.1)], rc=1 if diverged else 0))
    monkeypatch.setattr(c2, "reuse_or_solve", fake)
    work = tmp_path / "w"
    out = c2.evaluate(evaluated["design"], evaluated["run"], evaluated["meshes"][1], work, evaluation=2)
    start = work / "baseline" / "alpha" / "restart_flow.dat"
    assert calls[("e0002", "alpha")] == start and calls[("e0002", "cl")] == start
    assert calls[("baseline", "cl")] == start and calls[("baseline", "alpha")] is None
    assert set(out["reduction"]) == {"cl"}                       # none from the diverged alpha solve


def su2_missing() -> str | None:
    found = find_program("SU2_CFD", "SU2_RUN", (ROOT.parent / "shared" / "su2" / "bin",))
    return None if found else "SU2_CFD not found"


@pytest.mark.solver
@pytest.mark.skipif(su2_missing() is not None, reason=str(su2_missing()))
def test_a_few_su2_iterations_on_the_coarse_mesh_are_read_back(meshes, tmp_path):
    """Three SU2_CFD iterations in fixed-CL mode: the folder's files are SU2's own and read back
    (CD, CL, CMz's sign, the iteration count, CPU seconds), not converged at the iteration cap."""
    s = run_solve(meshes[0], "cl", tmp_path / "cl", iterations=3, nice=0)
    assert s["iterations"] == 3 and not s["converged"] and s["cpu"] > 0
    assert np.isfinite([s["cd"], s["cl"], s["cm"]]).all() and s["rc"] == 0
    assert (tmp_path / "cl" / "history.csv").is_file() and (tmp_path / "cl" / "restart_flow.dat").is_file()


def test_a_stopped_solve_is_continued_from_its_last_restart_and_its_pieces_counted(meshes, tmp_path, monkeypatch):
    """A solve stopped after 120 iterations (history, restart, no run.json) runs on from its restart with
    the same configuration and target; stopped again after 70, then finished after 80: all count."""
    mesh, folder = meshes[1], tmp_path / "alpha"
    folder.mkdir()
    (folder / "flow.cfg").write_text(solve_config(mesh, "alpha", iterations=3000))
    first = read_config(folder / "flow.cfg")
    head = '"Time_Iter","Outer_Iter","Inner_Iter","Time(sec)","rms[Rho]","CD","CL","CMz"\n'

    def stop_after(n: int, rms: float) -> None:
        (folder / "history.csv").write_text(head + "".join(f"0,0,{i},1.5,{rms},0.02,0.8,0.09\n" for i in range(n)))
        (folder / "restart_flow.dat").write_bytes(b"restart")

    runs = []

    def fake_su2(cmd, cwd, stdout, stderr):
        runs.append(config_value(read_config(Path(cwd) / "flow.cfg"), "SOLUTION_FILENAME"))
        if len(runs) == 1:
            stop_after(70, -7.0)
            raise KeyboardInterrupt                  # stopped again, before run.json
        stop_after(80, -8.2)
        return 0

    monkeypatch.setattr(case2_solve.subprocess, "call", fake_su2)
    monkeypatch.setattr(case2_solve, "find_program", lambda *a: Path("SU2_CFD"))
    stop_after(120, -6.0)
    assert case2_solve.stopped(folder, mesh, "alpha") and not case2_solve.stopped(folder, mesh, "cl")
    with pytest.raises(KeyboardInterrupt):
        case2_solve.reuse_or_solve(mesh, "alpha", folder)
    assert not (folder / "run.json").exists()
    s = case2_solve.reuse_or_solve(mesh, "alpha", folder)
    assert runs == [str((folder / f"restart_part{k}.dat").resolve()) for k in (1, 2)]
    assert s["iterations"] == 120 + 70 + 80 and s["converged"] and s["pieces"] == 3
    assert s["wall_su2_pieces"] == pytest.approx((120 + 70) * 1.5)
    cfg = read_config(folder / "flow.cfg")
    assert config_value(cfg, "CONV_RESIDUAL_MINVAL") == config_value(first, "CONV_RESIDUAL_MINVAL") == "-8"
    assert config_value(cfg, "RESTART_SOL") == "YES" and (folder / "flow_part1.cfg").read_text().splitlines() == first
    again = case2_solve.reuse_or_solve(mesh, "alpha", folder)        # finished: read back, not run again
    assert len(runs) == 2 and again["iterations"] == s["iterations"]


def test_a_stopped_solve_that_was_diverging_is_not_continued(meshes, tmp_path):
    """Its restart is no starting point: refused in one line, the folder left as it is."""
    mesh, folder = meshes[1], tmp_path / "alpha"
    folder.mkdir()
    (folder / "flow.cfg").write_text(solve_config(mesh, "alpha"))
    head = '"Time_Iter","Outer_Iter","Inner_Iter","Time(sec)","rms[Rho]","CD","CL","CMz"\n'
    (folder / "history.csv").write_text(head + "0,0,0,1.5,-4.3,0.9,0.5,0.1\n0,0,1,1.5,-5.9,0.02,0.82,0.09\n"
                                        "0,0,2,1.5,6.2,-1e8,2e9,9e8\n")
    (folder / "restart_flow.dat").write_bytes(b"restart")
    with pytest.raises(case2_solve.SolveError, match="was diverging"):
        case2_solve.reuse_or_solve(mesh, "alpha", folder)
    assert sorted(p.name for p in folder.iterdir()) == ["flow.cfg", "history.csv", "restart_flow.dat"]


def test_summary_prints_the_solves_and_the_reductions(evaluated, tmp_path):
    """The text of an evaluation with its four solves (here read from written folders)."""
    rows = [(245, -8.01, 0.0200, 0.805, 0.0961)]
    solves = {name: read_solve(write_solve(tmp_path / name, mode, [(r[0], r[1], cd, *r[3:]) for r in rows],
                                           target=-8 if mode == "alpha" else -9))
              for name, mode, cd in (("ba", "alpha", 0.0200), ("bc", "cl", 0.0210), ("da", "alpha", 0.0130),
                                     ("dc", "cl", 0.0135))}
    out = {**evaluated["out"], "baseline": {"alpha": solves["ba"], "cl": solves["bc"]},
           "solves": {"alpha": solves["da"], "cl": solves["dc"]},
           "reduction": {"alpha": 1 - 0.0130 / 0.0200, "cl": 1 - 0.0135 / 0.0210}}
    text = c2.summary(out)
    assert "CD   130.0 counts" in text and "alpha ?" in text and "35.7 % at cl" in text
    assert "NOT converged" in text                     # the fixed-CL rows miss the lift: 0.805, not 0.824
