"""SU2's own optimiser beside ffd on ADODG Case 3 (benchmarks/adodg/case3_su2_side.py).

Without a solver: the configuration it writes (9 ``FFD_TWIST`` variables about the trailing-edge line, the
B-spline box around the wing, the lift equality, the bounds in SU2's tangent units, case3.cfg's flow
untouched) and the report's bookkeeping (solves, the best design meeting the lift, twists in degrees, the
span load of a ``DIRECT`` folder). With SU2 (marked ``solver``): the box embedded into the coarsest level's
mesh with every wing node mapped, and ``SU2_DEF`` with one ``FFD_TWIST`` value against an independent
oracle: every wing node turned about the trailing-edge line by atan(value), weighted by the clamped cubic
B-spline basis of its control section (the root section turned rigidly by the whole angle)."""

from __future__ import annotations

import importlib.util
import json
import math
import re
import shutil
import subprocess

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.interpolate import BSpline

from benchmarks.adodg.case3_meshes import levels, make_level
from benchmarks.adodg.case3_su2_side import (
    BOUND_DEG,
    CL_TARGET,
    CONFIG,
    SECTIONS,
    angle_to_value,
    config_keys,
    ffd_definition,
    gradient_per_degree,
    mapped_nodes,
    report,
    setup,
    stations,
    table_row,
    twist_variables,
    value_to_angle,
    wing_box,
    write_configs,
)
from benchmarks.adodg.su2_side import su2_bin, su2_env
from ffdcli.io.formats import read_mesh, write_mesh
from ffdcli.mesh import CellBlock, Mesh
from ffdcli.optimize.solvers.su2 import config_value, read_config, with_keys
from ffdcli.testing.naca import naca4

DV = re.compile(r"\(\s*15,\s*1\.0\s*\|\s*wing\s*\|\s*BOX,\s*(\d+),\s*([^)]*)\)")


def su2_missing() -> str | None:
    if importlib.util.find_spec("gmsh") is None:
        return "gmsh is not installed (the [test] extra)"
    try:
        su2_bin()
    except RuntimeError as e:
        return str(e)
    return None


def naca_wing(chord: float, span: float, x0: float, z0: float, n_span: int = 7) -> np.ndarray:
    """(W, 3) points of an untwisted rectangular NACA 0012 wing: chord x from x0, span y from 0, z about z0."""
    xz = naca4("0012", 61, closed_te=True) * chord
    return np.concatenate([np.column_stack([xz[:, 0] + x0, np.full(len(xz), y), xz[:, 1] + z0])
                           for y in np.linspace(0.0, span, n_span)])


@settings(max_examples=25, deadline=None)
@given(chord=st.floats(0.2, 5.0), span=st.floats(0.5, 20.0), x0=st.floats(-3.0, 3.0), z0=st.floats(-1.0, 1.0))
def test_the_box_encloses_the_wing_with_ffds_margin_and_its_planes_are_ffds_stations(chord, span, x0, z0):
    pts = naca_wing(chord, span, x0, z0)
    box = wing_box(pts)
    m = 0.02 * chord
    assert box["chord"] == pytest.approx(chord, rel=1e-9)
    assert box["x"] == pytest.approx((pts[:, 0].min() - m, pts[:, 0].max() + m), abs=1e-12 * (1 + abs(x0) + chord))
    assert box["z"] == pytest.approx((pts[:, 2].min() - m, pts[:, 2].max() + m), abs=1e-12 * (1 + abs(z0) + chord))
    assert box["y"] == (0.0, pytest.approx(span + 1e-5 * chord))  # root on the symmetry plane, tip face at the tip
    assert box["te"] == pytest.approx((x0 + chord, z0), abs=1e-9 * (1 + abs(x0) + chord + abs(z0)))
    ys = stations(box)
    assert len(ys) == SECTIONS and np.allclose(np.diff(ys), (span + 1e-5 * chord) / (SECTIONS - 1))
    dvs = DV.findall(twist_variables(box))
    assert [int(j) for j, _ in dvs] == list(range(SECTIONS))
    for _, axis in dvs:
        xa, ya, za, xb, yb, zb = (float(v) for v in axis.split(","))
        assert (xa, za) == pytest.approx(box["te"]) and (xb, zb) == pytest.approx(box["te"])   # the trailing-edge line
        assert ya < ys[0] and yb > ys[-1]                                # it crosses every control plane


def test_ffd_definition_orders_the_corners_chord_span_thickness():
    box = {"x": (-0.02, 1.02), "y": (0.0, 3.06), "z": (-0.08, 0.08), "te": (1.0, 0.0), "chord": 1.0}
    text = ffd_definition(box)
    assert text.startswith("(BOX, ")
    c = np.array([float(v) for v in text[6:-1].split(",")]).reshape(8, 3)
    np.testing.assert_allclose(c[1] - c[0], [1.04, 0, 0])          # i: chord
    np.testing.assert_allclose(c[3] - c[0], [0, 3.06, 0])          # j: span
    np.testing.assert_allclose(c[4] - c[0], [0, 0, 0.16])          # k: thickness
    np.testing.assert_allclose(c[:4, 2], -0.08)
    np.testing.assert_allclose(c[4:, :2], c[:4, :2])


@pytest.mark.parametrize("deg", [-8.0, -1.5, 0.0, 0.3, 5.0, 8.0])
def test_su2_twist_values_are_tangents_of_the_angle(deg):
    v = angle_to_value(deg)
    assert v == pytest.approx(math.tan(math.radians(deg)), abs=1e-15)
    assert float(value_to_angle(v)) == pytest.approx(deg, abs=1e-12)
    assert angle_to_value(deg, ref_length=2.0) == pytest.approx(2.0 * v)


def test_the_optimisation_keys_state_ffds_problem():
    box = wing_box(naca_wing(1.0, 3.0, 0.0, 0.0))
    keys = config_keys("mesh_ffd.su2", box)
    assert keys["OPT_CONSTRAINT"] == "( LIFT = 0.375 ) * 1.0"                  # an equality, unscaled
    assert keys["OPT_OBJECTIVE"].startswith("DRAG *")
    assert float(keys["OPT_BOUND_UPPER"]) == pytest.approx(math.tan(math.radians(BOUND_DEG)))
    assert float(keys["OPT_BOUND_LOWER"]) == -float(keys["OPT_BOUND_UPPER"])
    assert keys["OPT_ITERATIONS"] == "20"
    assert keys["FFD_DEGREE"] == "(3, 8, 1)" and keys["FFD_BLENDING"] == "BSPLINE_UNIFORM"
    assert keys["FFD_BSPLINE_ORDER"] == "(4, 4, 2)" and keys["FFD_CONTINUITY"] == "USER_INPUT"
    assert keys["CONV_FIELD"] == "(RMS_DENSITY, RMS_ADJ_DENSITY)"
    assert len(DV.findall(keys["DEFINITION_DV"])) == SECTIONS == len(keys["DEFINITION_DV"].split(";"))


def tiny_mesh(points: np.ndarray) -> Mesh:
    """A mesh whose wing marker is ``points`` (triangles of consecutive nodes; enough for the box)."""
    n = len(points)
    tris = np.stack([np.arange(n - 2), np.arange(1, n - 1), np.arange(2, n)], axis=1)
    return Mesh(points=points, dim=3, cells=[CellBlock("tetra", np.array([[0, 1, 2, 3]]))],
                markers={"wing": [CellBlock("triangle", tris)]})


def test_write_configs_keeps_case3s_flow_and_runs_nothing(tmp_path):
    write_mesh(tiny_mesh(naca_wing(1.0, 3.0, 0.0, 0.0)), tmp_path / "w.su2")
    info = write_configs(tmp_path / "w.su2", tmp_path / "run")
    run = tmp_path / "run"
    assert sorted(p.name for p in run.iterdir()) == ["box.cfg", "box.json", "config.cfg", "mesh.su2"]
    base, cfg, box = read_config(CONFIG), read_config(run / "config.cfg"), read_config(run / "box.cfg")
    for key in ("MACH_NUMBER", "AOA", "REF_AREA", "REF_LENGTH", "MARKER_EULER", "MARKER_SYM", "MARKER_FAR",
                "CONV_NUM_METHOD_FLOW", "JST_SENSOR_COEFF", "MGLEVEL", "CFL_NUMBER", "CONV_RESIDUAL_MINVAL",
                "ITER", "OBJECTIVE_FUNCTION"):
        assert config_value(cfg, key) == config_value(base, key), key
    assert config_value(cfg, "MESH_FILENAME") == "mesh_ffd.su2"
    assert config_value(box, "MESH_FILENAME") == "mesh.su2" and config_value(box, "MESH_OUT_FILENAME") == "mesh_ffd.su2"
    assert config_value(box, "DV_KIND") == "FFD_SETTING"
    assert info["alpha"] == float(config_value(base, "AOA")) and info["wing_nodes"] == len(naca_wing(1, 3, 0, 0))
    assert json.loads((run / "box.json").read_text())["stations"] == pytest.approx(list(np.linspace(0, 3 + 1e-5, 9)))


def test_write_configs_takes_the_hybrid_familys_flow_settings_when_asked(tmp_path):
    hybrid = CONFIG.parent / "case3_hybrid.cfg"
    write_mesh(tiny_mesh(naca_wing(1.0, 3.0, 0.0, 0.0)), tmp_path / "w.su2")
    info = write_configs(tmp_path / "w.su2", tmp_path / "run", hybrid)
    cfg = read_config(tmp_path / "run" / "config.cfg")
    aoa = config_value(read_config(hybrid), "AOA")
    assert config_value(cfg, "AOA") == aoa != config_value(read_config(CONFIG), "AOA")
    assert info["alpha"] == float(config_value(read_config(hybrid), "AOA")) and info["flow_config"] == str(hybrid)
    assert config_value(cfg, "MESH_FILENAME") == "mesh_ffd.su2"


@pytest.mark.parametrize("stiffness", ["INVERSE_VOLUME", "WALL_DISTANCE"])
def test_the_stiffness_model_goes_to_both_configs_and_box_json(tmp_path, stiffness):
    write_mesh(tiny_mesh(naca_wing(1.0, 3.0, 0.0, 0.0)), tmp_path / "w.su2")
    info = write_configs(tmp_path / "w.su2", tmp_path / "run", CONFIG, stiffness)
    for name in ("config.cfg", "box.cfg"):
        assert config_value(read_config(tmp_path / "run" / name), "DEFORM_STIFFNESS_TYPE") == stiffness
    assert info["stiffness"] == stiffness
    with pytest.raises(ValueError, match="stiffness 'SOFT'"):
        write_configs(tmp_path / "w.su2", tmp_path / "run2", CONFIG, "SOFT")
    assert not (tmp_path / "run2").exists()                       # refused before anything is written


def test_write_configs_refuses_a_mesh_without_the_wing(tmp_path):
    m = tiny_mesh(naca_wing(1.0, 3.0, 0.0, 0.0))
    m = Mesh(points=m.points, dim=3, cells=m.cells, markers={"body": m.markers["wing"]})
    write_mesh(m, tmp_path / "b.su2")
    with pytest.raises(ValueError, match="wing"):
        write_configs(tmp_path / "b.su2", tmp_path / "run")
    assert not (tmp_path / "run").exists()


def test_mapped_nodes_reads_su2_defs_count():
    log = "x\n  Number of vertices (Total, Inside FFD, Mapped to FFD): 4071, 4071, 4070\n"
    assert mapped_nodes(log) == (4071, 4071, 4070)
    with pytest.raises(RuntimeError):
        mapped_nodes("nothing here")


def plate(s: float = 3.0, n_chord: int = 6, n_span: int = 96):
    """A flat double-sided plate wing, chord 1, span [0, s]: points and triangles (normals into the body)."""
    x, y = np.linspace(0, 1, n_chord + 1), np.linspace(0, s, n_span + 1)
    X, Y = np.meshgrid(x, y, indexing="ij")
    grid = np.stack([X.ravel(), Y.ravel(), np.zeros(X.size)], axis=1)
    ids = np.arange(X.size).reshape(X.shape)
    a, b, c, d = ids[:-1, :-1].ravel(), ids[1:, :-1].ravel(), ids[1:, 1:].ravel(), ids[:-1, 1:].ravel()
    up = np.concatenate([np.stack([a, c, b], 1), np.stack([a, d, c], 1)])
    lo = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)]) + len(grid)
    return np.concatenate([grid, grid]), np.concatenate([up, lo])


def write_plate_flow(folder, mesh_name: str, history_name: str, jump, cl: float, cd: float, s: float = 3.0) -> None:
    """A flow on :func:`plate` as SU2 leaves it in ``folder``: the mesh, ``surface_flow.csv`` (Cp = -/+
    jump(y)/2 on the two sides: the pressure jump is ``jump``) and a one-row history with CL and CD."""
    pts, tris = plate(s)
    write_mesh(Mesh(points=pts, dim=3, cells=[CellBlock("tetra", np.array([[0, 1, 2, 3]]))],
                    markers={"wing": [CellBlock("triangle", tris)]}), folder / mesh_name)
    j = jump(pts[: len(pts) // 2, 1])
    cp = np.concatenate([-0.5 * j, 0.5 * j])
    rows = "\n".join(f"{i},{pts[i, 0]},{pts[i, 1]},{pts[i, 2]},{cp[i]}" for i in range(len(pts)))
    (folder / "surface_flow.csv").write_text('"PointID","x","y","z","Pressure_Coefficient"\n' + rows + "\n")
    (folder / history_name).write_text('"Inner_Iter","CL","CD"\n' + f"1,{cl},{cd}\n")


def grad_of(name: str, j: int) -> float:
    return (0.05 if name == "DRAG" else 0.6) * (1 + 0.1 * j)


def fake_design(folder, k: int, twist_deg, adjoints: dict, jump=None, cl: float = 0.0, cd: float = 0.0):
    """DESIGNS/DSN_00k as SU2's scripts leave it: config_DSN.cfg, ADJOINT_<F> folders (a gradient file
    when finished), and with ``jump`` a DIRECT folder (mesh, surface_flow.csv, history_direct.csv)."""
    dsn = folder / "DESIGNS" / f"DSN_{k:03d}"
    dsn.mkdir(parents=True)
    values = ", ".join(repr(angle_to_value(t)) for t in twist_deg)
    (dsn / "config_DSN.cfg").write_text(f"DV_KIND= FFD_TWIST\nDV_VALUE_NEW= {values}\n")
    for name, done in adjoints.items():
        (dsn / f"ADJOINT_{name}").mkdir()
        if done:   # SU2_DOT_AD's file: d(function)/d(value) per variable
            rows = "".join(f"{j}, {grad_of(name, j)}, 0.001\n" for j in range(len(twist_deg)))
            (dsn / f"ADJOINT_{name}" / f"of_grad_{name.lower()}.csv").write_text(
                '"VARIABLE", "GRADIENT", "FINDIFF_STEP"\n' + rows)
    if jump is not None:
        direct = dsn / "DIRECT"
        direct.mkdir()
        write_plate_flow(direct, "mesh_ffd_deform.su2", "history_direct.csv", jump, cl, cd)


def test_report_counts_solves_picks_the_best_design_meeting_the_lift_and_reads_its_load(tmp_path):
    s = 3.0
    (tmp_path / "box.json").write_text(json.dumps({"alpha": 0.0, "stations": list(np.linspace(0, s, 9))}))
    rows = [(0.3955, 0.00190), (0.37502, 0.00046), (0.3600, 0.00030), (0.37499, 0.00045)]
    (tmp_path / "history_project.csv").write_text(
        '"EVALUATION", "DRAG", "LIFT"\n' + "".join(f"{k + 1}, {cd}, {cl}\n" for k, (cl, cd) in enumerate(rows)))
    c0 = 4 * 0.375 * s / (np.pi * s)
    uniform = lambda y: np.full_like(y, 0.375)                                    # noqa: E731
    ellipse = lambda y: c0 * np.sqrt(np.clip(1 - (y / s) ** 2, 0, None))          # noqa: E731
    twists = [[0.0] * 9, [-0.1 * j for j in range(9)], [1.0] * 9, [0.5 - 0.2 * j for j in range(9)]]
    fake_design(tmp_path, 1, twists[0], {"DRAG": True, "LIFT": True}, uniform, *rows[0])
    fake_design(tmp_path, 2, twists[1], {"DRAG": True, "LIFT": True})
    fake_design(tmp_path, 3, twists[2], {})                                       # a rejected trial: flow only
    fake_design(tmp_path, 4, twists[3], {"DRAG": True, "LIFT": False}, ellipse, *rows[3])   # LIFT's unfinished
    rep = report(tmp_path)
    assert (rep["flow_solves"], rep["adjoint_solves"]) == (4, 5)
    assert not rep["finished"] and rep["wall"] is None
    assert [r["feasible"] for r in rep["designs"]] == [False, True, False, True]
    assert rep["best"]["design"] == "DSN_004"                      # least CD among CL within 1e-4 of 0.375
    for r, t in zip(rep["designs"], twists, strict=True):
        assert r["twist_deg"] == pytest.approx(t, abs=1e-12)
        assert r["twist_rel_root_deg"] == pytest.approx(np.array(t) - t[0], abs=1e-12)
    base, best = rep["baseline_load"], rep["best_load"]
    assert base["CL"] == rows[0][0] and best["CD"] == rows[3][1]   # read from DIRECT/history_direct.csv
    assert best["CL_strips"] == pytest.approx(CL_TARGET, rel=2e-3)
    assert best["e_load"] == pytest.approx(1.0, abs=2e-3) and best["rms_pct"] < 1.0
    assert base["e_load"] < 0.95 and base["rms_pct"] > 5.0
    per_deg = math.pi / 180                                          # d tan(theta) / d deg at theta = 0
    for name in ("DRAG", "LIFT"):
        assert rep["baseline_gradient_per_deg"][name] == pytest.approx([grad_of(name, j) * per_deg for j in range(9)])
    # at a twisted design, d(value)/d(deg) = (1 + value^2) pi / 180
    g = gradient_per_degree(tmp_path / "DESIGNS" / "DSN_002", "DRAG", [angle_to_value(t) for t in twists[1]])
    assert g == pytest.approx([grad_of("DRAG", j) * per_deg / math.cos(math.radians(t)) ** 2
                               for j, t in enumerate(twists[1])], rel=1e-12)
    assert gradient_per_degree(tmp_path / "DESIGNS" / "DSN_003", "DRAG", [0.0] * 9) is None
    row = table_row(rep)
    assert "| 4 + 5 | 0.000450 | 0.374990 |" in row and f"{best['e_load']:.4f}" in row and "running" in row


# --- with SU2 ---------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def embedded(tmp_path_factory):
    folder = tmp_path_factory.mktemp("case3_su2")
    write_mesh(make_level(levels()[0]), folder / "case3_L0.su2")
    setup(folder / "case3_L0.su2", folder / "run")
    return folder / "run"


def clamped_basis(v: np.ndarray, n: int = SECTIONS, p: int = 3) -> np.ndarray:
    """(len(v), n) clamped uniform B-spline basis of degree p (scipy: independent of SU2's and ffd's code)."""
    t = np.r_[np.zeros(p), np.linspace(0, 1, n - p + 1), np.ones(p)]
    return np.stack([np.nan_to_num(BSpline(t, np.eye(n)[j], p, extrapolate=False)(v)) for j in range(n)], axis=1)


def span_parameter(y: np.ndarray, ys: np.ndarray) -> np.ndarray:
    """The box's span parameter of each y: y(v) = sum_j N_j(v) y_j inverted on a fine table (monotone)."""
    vv = np.linspace(0.0, 1.0, 40001)
    return np.interp(y, clamped_basis(vv) @ ys, vv)


@pytest.mark.solver
@pytest.mark.skipif(su2_missing() is not None, reason=str(su2_missing()))
def test_setup_maps_every_wing_node_into_the_box(embedded):
    info = json.loads((embedded / "box.json").read_text())
    assert mapped_nodes((embedded / "box.log").read_text()) == (info["wing_nodes"],) * 3
    assert "FFD_NBOX= 1" in (embedded / "mesh_ffd.su2").read_text()
    assert config_value(read_config(embedded / "config.cfg"), "MESH_FILENAME") == "mesh_ffd.su2"


@pytest.mark.solver
@pytest.mark.skipif(su2_missing() is not None, reason=str(su2_missing()))
@pytest.mark.parametrize("plane,deg", [(0, 2.5), (4, -3.0), (7, 4.0)])
def test_one_ffd_twist_turns_the_wing_about_the_trailing_edge_line(embedded, tmp_path, plane, deg):
    shutil.copyfile(embedded / "mesh_ffd.su2", tmp_path / "mesh_ffd.su2")
    cfg = read_config(embedded / "config.cfg")
    dv = config_value(cfg, "DEFINITION_DV").split(";")[plane]
    param = dv.split("|")[2].strip().rstrip(")").strip()
    assert param.startswith(f"BOX, {plane},")
    (tmp_path / "def.cfg").write_text(with_keys(cfg, {"DV_KIND": "FFD_TWIST", "DV_PARAM": f"( {param} )",
                                                      "DV_VALUE": repr(angle_to_value(deg)),
                                                      "MESH_OUT_FILENAME": "out.su2"}))
    subprocess.run([str(su2_bin() / "SU2_DEF"), "def.cfg"], cwd=tmp_path, env=su2_env(), check=True,
                   capture_output=True)
    info = json.loads((embedded / "box.json").read_text())
    base, moved = read_mesh(embedded / "mesh.su2"), read_mesh(tmp_path / "out.su2")
    ids = np.unique(base.markers["wing"][0].data)
    p, q = base.points[ids], moved.points[ids]
    # the oracle: a turn about the span-wise line through the trailing edge (x_te, z_te), nose up for a
    # positive angle, of the plane's share N_plane(v) of the displacement (SU2 moves control points)
    th = math.radians(deg)
    rot = np.array([[math.cos(th), math.sin(th)], [-math.sin(th), math.cos(th)]])
    rel = p[:, [0, 2]] - np.array(info["te"])
    share = clamped_basis(span_parameter(p[:, 1], np.array(info["stations"])))[:, plane]
    expect = p.copy()
    expect[:, [0, 2]] += share[:, None] * (rel @ rot.T - rel)
    scale = np.abs(q - p).max()
    assert scale > 0.2 * math.radians(abs(deg))                           # it moved (a share of the angle)
    np.testing.assert_allclose(q, expect, atol=1e-7)
    assert np.abs(q[:, 1] - p[:, 1]).max() < 1e-8                        # sections stay in their planes
    if plane == 0:                                                       # the root section turns whole
        root = np.abs(p[:, 1]) < 1e-12
        le = np.argmin(np.where(root, p[:, 0], np.inf))
        d = q[le] - np.array([info["te"][0], 0.0, info["te"][1]])
        assert math.degrees(math.atan2(d[2], -d[0])) == pytest.approx(deg, abs=1e-6)
        sym = np.abs(base.points[:, 1]) < 1e-12
        assert np.abs(moved.points[sym, 1]).max() < 1e-10                  # the symmetry plane stays flat
