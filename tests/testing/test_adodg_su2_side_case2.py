"""SU2's own optimiser beside ffd on ADODG Case 2 (benchmarks/adodg/su2_side_case2.py): the configuration
it writes (24 FFD control points, bounds, the CL equality, the moment bound and the area, the flow of
``case2.cfg`` but for the fixed CFL) checked against ffd's own Case 2 files without a solver, the box
against ffd's lattice on the same mesh, the report's feasibility rule; and with SU2 (marked ``solver``)
the set-up on SU2's RAE2822 RANS mesh: SU2_GEO's baseline area, SU2_DEF's box with every wall node
mapped into it, and one control point moved by SU2_DEF exactly as the Bezier box says."""

from __future__ import annotations

import csv
import json
import re
import subprocess
from math import comb
from pathlib import Path

import numpy as np
import pytest
import yaml

from benchmarks.adodg import race, su2_side
from benchmarks.adodg.su2_side import su2_bin, su2_env
from benchmarks.adodg.su2_side_case2 import (
    BOUND,
    BOX,
    CONFIG,
    FFD_COLUMNS,
    MARKER,
    config_keys,
    feasible,
    report,
    setup,
    summary,
)
from ffdcli.api import DesignModel
from ffdcli.io.formats import read_mesh
from ffdcli.optimize.solvers.su2 import config_value, read_config, with_keys

ROOT = Path(__file__).resolve().parents[2]
MESH = ROOT.parent / "shared" / "data" / "su2" / "optimization_rans__steady_rae2822__mesh_RAE2822_turb.su2"
DESIGN = yaml.safe_load((ROOT / "configs" / "adodg" / "case2.yaml").read_text())


def su2_missing() -> str | None:
    try:
        su2_bin()
    except RuntimeError as e:
        return str(e)
    return None if MESH.is_file() else f"{MESH} not found"


def parse_constraints(text: str) -> dict[str, tuple[str, float, float]]:
    """``OPT_CONSTRAINT`` as SU2's parser reads it: {function: (sign, value, scale)}."""
    out = {}
    for item in filter(None, (t.strip() for t in text.split(";"))):
        body, scale = item.split("*")
        name, sign, value = re.match(r"\(\s*(\w+)\s*([<>=])\s*([-\d.eE+]+)\s*\)", body.strip()).groups()
        out[name] = (sign, float(value), float(scale))
    return out


def test_variables_are_ffd_files_24_control_points_with_its_bounds():
    keys = config_keys("mesh.su2", 0.0777)
    dvs = [d.strip() for d in keys["DEFINITION_DV"].split(";")]
    assert len(dvs) == len(DESIGN["optimize"]["variables"]) == 24
    got = [tuple(int(v) for v in re.search(r"BOX, (\d+), (\d+), 0\.0, 1\.0 \)$", d).groups()) for d in dvs]
    # ffd's order: upper row (j = 1) at columns 0..11, then the lower row; the trailing-edge column stays put
    assert got == [(i, 1) for i in range(12)] + [(i, 0) for i in range(12)]
    names = DESIGN["optimize"]["variables"]
    assert names == [f"c0.shape.{side}[{i}]" for side in ("upper", "lower") for i in range(12)]
    assert all(d.startswith(f"( 19, 1.0 | {MARKER} |") for d in dvs)          # FFD_CONTROL_POINT_2D, moving in y
    assert keys["FFD_DEGREE"] == f"({FFD_COLUMNS - 1}, 1, 0)" and FFD_COLUMNS == DESIGN["box"]["points"][0]
    lo, hi = DESIGN["bounds"]["c0.shape"]
    assert (float(keys["OPT_BOUND_LOWER"]), float(keys["OPT_BOUND_UPPER"])) == (lo, hi) == (-BOUND, BOUND)


@pytest.mark.parametrize("area", [0.0777, 0.081234567, 0.07])
def test_constraints_are_ffd_files_functions_and_the_baseline_area(area):
    cons = parse_constraints(config_keys("mesh.su2", area)["OPT_CONSTRAINT"])
    assert set(cons) == {"LIFT", "MOMENT_Z", "AIRFOIL_AREA"}
    funcs = {f["name"]: f for f in DESIGN["optimize"]["functions"]}
    assert funcs["LIFT"]["lower"] == funcs["LIFT"]["upper"]                  # ffd's file: an equality
    assert cons["LIFT"][:2] == ("=", funcs["LIFT"]["lower"])
    assert cons["MOMENT_Z"][:2] == ("<", funcs["MOMENT_Z"]["upper"]) and "lower" not in funcs["MOMENT_Z"]
    assert cons["AIRFOIL_AREA"][0] == ">" and cons["AIRFOIL_AREA"][1] == pytest.approx(area, rel=1e-7)
    assert DESIGN["constraints"] == [{"volume": {"lower": 1.0}}]              # ffd: area >= the baseline's
    assert {c[2] for c in cons.values()} == {0.001}


def test_flow_is_case2_cfg_but_for_the_fixed_cfl():
    base = read_config(CONFIG)
    keys = config_keys("mesh.su2", 0.0777)
    cfg = with_keys(base, keys).splitlines()
    assert (config_value(cfg, "CFL_ADAPT"), config_value(cfg, "CFL_NUMBER")) == ("NO", "50")
    assert config_value(base, "CFL_ADAPT") == "YES"                            # what was changed, and why: docstring
    physics = ["SOLVER", "KIND_TURB_MODEL", "MACH_NUMBER", "AOA", "REYNOLDS_NUMBER", "FREESTREAM_TEMPERATURE",
               "REF_ORIGIN_MOMENT_X", "REF_LENGTH", "REF_AREA", "CONV_NUM_METHOD_FLOW", "JST_SENSOR_COEFF",
               "CONV_NUM_METHOD_TURB", "MGLEVEL", "MGCYCLE", "NUM_METHOD_GRAD", "FROZEN_VISC_DISC",
               "MARKER_HEATFLUX", "MARKER_FAR", "ITER"]
    for key in physics:
        assert config_value(cfg, key) == config_value(base, key), key
        assert key not in keys
    assert config_value(cfg, "CONV_RESIDUAL_MINVAL") == config_value(base, "CONV_RESIDUAL_MINVAL") == "-8"
    assert config_value(cfg, "RESTART_SOL") == "NO" and config_value(cfg, "OPT_OBJECTIVE") == "DRAG * 0.001"


def test_box_holds_ffds_lattice_on_the_same_mesh(tmp_path):
    if not MESH.is_file():
        pytest.skip(f"{MESH} not found")
    (tmp_path / "rae.su2").write_bytes(MESH.read_bytes())
    design = {k: v for k, v in DESIGN.items() if k not in ("optimize", "output")}
    design["mesh"] = "rae.su2"
    (tmp_path / "d.yaml").write_text(yaml.safe_dump(design))
    P = np.asarray(DesignModel.from_file(tmp_path / "d.yaml", use_cache=False).lattice()).reshape(-1, 3)[:, :2]
    x0, x1, y0, y1 = BOX
    assert P[:, 0].min() >= x0 - 1e-9 and P[:, 0].max() <= x1 + 1e-9
    assert P[:, 1].min() >= y0 - 1e-9 and P[:, 1].max() <= y1 + 1e-9
    assert P[:, 0].min() - x0 < 1e-3 and x1 - P[:, 0].max() < 1e-3            # the same extent, within 1e-3 chord
    assert P[:, 1].min() - y0 < 1e-3 and y1 - P[:, 1].max() < 1e-3


@pytest.mark.parametrize("row,ok", [
    ({"LIFT": 0.824, "MOMENT_Z": 0.092, "AIRFOIL_AREA": 0.0777}, True),
    ({"LIFT": 0.82409, "MOMENT_Z": 0.09209, "AIRFOIL_AREA": 0.07761}, True),
    ({"LIFT": 0.82411, "MOMENT_Z": 0.05, "AIRFOIL_AREA": 0.08}, False),          # lift above the equality's tolerance
    ({"LIFT": 0.82389, "MOMENT_Z": 0.05, "AIRFOIL_AREA": 0.08}, False),          # and below it
    ({"LIFT": 0.824, "MOMENT_Z": 0.0922, "AIRFOIL_AREA": 0.08}, False),          # too much nose-down moment
    ({"LIFT": 0.824, "MOMENT_Z": -0.2, "AIRFOIL_AREA": 0.0775}, False),          # area lost
    ({"LIFT": 0.824, "MOMENT_Z": 0.0}, False),                                   # no area evaluated
])
def test_feasibility_is_the_cases_rule_at_its_tolerance(row, ok):
    assert feasible(row, 0.0777) is ok


def test_report_counts_solves_and_picks_the_best_feasible(tmp_path):
    (tmp_path / "config.cfg").write_text("% x\n")
    (tmp_path / "baseline_geometry.json").write_text(json.dumps({"AIRFOIL_AREA": 0.0777}))
    rows = [(0.0194, 0.805, 0.096, 0.0777), (0.0150, 0.8240, 0.0915, 0.0778), (0.0120, 0.83, 0.09, 0.078),
            (0.0160, 0.82405, 0.0920, 0.0777)]
    with open(tmp_path / "history_project.csv", "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(['"DRAG"', '"LIFT"', '"MOMENT_Z"', '"AIRFOIL_AREA"'])
        w.writerows(rows)
    for k, adj in enumerate((3, 3, 0, 0)):
        for a in range(adj):
            d = tmp_path / "DESIGNS" / f"DSN_{k + 1:03d}" / f"ADJOINT_{a}"
            d.mkdir(parents=True)
            (d / "of_grad.csv").write_text("x\n")
    rep = report(tmp_path)
    assert (rep["flow_solves"], rep["adjoint_solves"]) == (4, 6) and not rep["finished"]
    assert [r["feasible"] for r in rep["designs"]] == [False, True, False, True]
    assert rep["best"]["design"] == "DSN_002" and rep["baseline_CD"] == 0.0194


def test_a_design_su2s_restart_made_again_is_not_counted(tmp_path):
    """SU2's restart replays SLSQP, whose designs can come back different in the last bit; SU2 makes them
    again. Such a design (and its solves) is marked and not counted; one that differs more is a design."""
    (tmp_path / "config.cfg").write_text("% x\n")
    (tmp_path / "baseline_geometry.json").write_text(json.dumps({"AIRFOIL_AREA": 0.0777}))
    x2 = [0.00013409235885957207, -2.6532190493191143e-05, 5.8e-05]
    designs = [[0.0, 0.0, 0.0], x2, [0.0007, -0.0008, 0.0016],
               [0.00013409235885957207, -2.653219049319115e-05, 5.8e-05],    # x2 but for the last bit
               [0.00013409235885957207, -2.6532190493191143e-05, 5.8e-05 + 1e-9]]
    rows = [(0.0194, 0.805, 0.096, 0.0777), (0.0191, 0.805, 0.0955, 0.0777), (0.0177, 0.805, 0.0927, 0.0777),
            (0.0191, 0.805, 0.0955, 0.0777), (0.0190, 0.805, 0.0955, 0.0777)]
    with open(tmp_path / "history_project.csv", "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(['"DRAG"', '"LIFT"', '"MOMENT_Z"', '"AIRFOIL_AREA"'])
        w.writerows(rows)
    for k, x in enumerate(designs):
        dsn = tmp_path / "DESIGNS" / f"DSN_{k + 1:03d}"
        for a in range(3):
            (dsn / f"ADJOINT_{a}").mkdir(parents=True)
            (dsn / f"ADJOINT_{a}" / "of_grad.csv").write_text("x\n")
        (dsn / "config_DSN.cfg").write_text("DV_VALUE_NEW= " + ", ".join(repr(v) for v in x) + "\n")
    assert su2_side.repeats(tmp_path, 5) == [False, False, False, True, False]
    rep = report(tmp_path)
    assert (rep["flow_solves"], rep["adjoint_solves"], rep["repeated_designs"]) == (4, 12, 1)
    assert [r["repeat"] for r in rep["designs"]] == [False, False, False, True, False]
    assert "not counting 1 design SU2's restart made again" in summary(rep)
    trace = race.su2_trace(2, tmp_path, "SU2")
    assert trace.total == 4 * (1 + 3) and len(trace.objective) == 4 and 0.0191 in trace.objective


def bezier(u: np.ndarray, i: int, n: int) -> np.ndarray:
    return comb(n, i) * u**i * (1.0 - u) ** (n - i)


@pytest.mark.solver
@pytest.mark.skipif(su2_missing() is not None, reason=str(su2_missing()))
def test_setup_embeds_the_box_and_su2_def_moves_one_control_point_as_the_box_says(tmp_path):
    folder = tmp_path / "su2"
    cfg = setup(MESH, folder)
    lines = read_config(cfg)
    assert config_value(lines, "MESH_FILENAME") == "mesh_ffd.su2"
    log = (folder / "box.log").read_text()
    assert re.search(r"Mapped to FFD\): 192, 192, 192", log), log[-2000:]       # every wall node in the box
    geo = json.loads((folder / "baseline_geometry.json").read_text())
    assert 0.07 < geo["AIRFOIL_AREA"] < 0.09                                      # the RAE2822's (t/c 0.121)
    assert f"AIRFOIL_AREA > {geo['AIRFOIL_AREA']:.7g}" in config_value(lines, "OPT_CONSTRAINT")
    # SU2_DEF moves the upper control point of column 4 by 1e-3 chord: every wall node moves in y by the
    # Bezier weight of that point at its box coordinates (u along the chord, v through the thickness)
    value, i = 1e-3, 4
    keys = {"DV_KIND": "FFD_CONTROL_POINT_2D", "DV_PARAM": f"( BOX, {i}, 1, 0.0, 1.0 )", "DV_VALUE": f"{value:g}",
            "MESH_FILENAME": "mesh_ffd.su2", "MESH_OUT_FILENAME": "moved.su2"}
    (folder / "move.cfg").write_text(with_keys(lines, keys))
    subprocess.run(["nice", "-n", "5", str(su2_bin() / "SU2_DEF"), "move.cfg"], cwd=folder, env=su2_env(),
                   check=True, capture_output=True)
    base, moved = read_mesh(folder / "mesh.su2"), read_mesh(folder / "moved.su2")
    wall = np.unique(np.concatenate([b.data for b in base.markers[MARKER]]).ravel())
    x, y = base.points[wall, 0], base.points[wall, 1]
    x0, x1, y0, y1 = BOX
    u, v = (x - x0) / (x1 - x0), (y - y0) / (y1 - y0)
    expected = value * bezier(u, i, FFD_COLUMNS - 1) * v
    d = moved.points[wall, :2] - base.points[wall, :2]
    np.testing.assert_allclose(d[:, 0], 0.0, atol=1e-10)
    np.testing.assert_allclose(d[:, 1], expected, atol=1e-3 * value)
    assert d[:, 1].max() > 0.5 * value * bezier(np.array(i / 12), i, 12)        # the move is there, not zero
    assert moved.points.shape == base.points.shape
