"""SU2's own optimiser beside ffd on ADODG Case 1 (benchmarks/adodg/su2_side.py): the configurations
it writes (variables, bounds, constraints, the FFD box) without a solver, and with SU2 (marked
``solver``) the set-up on the coarsest level: SU2_GEO's baseline functions and SU2_DEF's box with every
wall node mapped into it; and a Hicks-Henne bump of positive amplitude adds material on either side
(what makes the bounds [0, 0.1] the add-material rule)."""

from __future__ import annotations

import json
import re
import shutil
import subprocess

import numpy as np
import pytest

from benchmarks.adodg import su2_side as side
from benchmarks.adodg.meshes import family, level_mesh
from benchmarks.adodg.su2_side import (
    BOUND,
    CONFIG,
    HH_STATIONS,
    config_keys,
    ffd_definition,
    geometry,
    setup,
    su2_bin,
    su2_env,
)
from benchmarks.adodg.surface import add_material, wall_nodes
from ffdcli.io.formats import read_mesh, write_mesh
from ffdcli.optimize.solvers.su2 import config_value, read_config, with_keys


def su2_missing() -> str | None:
    try:
        su2_bin()
    except RuntimeError as e:
        return str(e)
    return None


def test_ffd_configuration_has_16_control_points_bounds_and_the_geometric_constraints():
    keys = config_keys("ffd", "mesh.su2", 0.120012, 0.0816978)
    dvs = keys["DEFINITION_DV"].split(";")
    assert len(dvs) == 16
    got = {tuple(int(v) for v in re.search(r"BOX, (\d+), (\d+), 0\.0, 1\.0", d).groups()) for d in dvs}
    assert got == {(i, j) for i in range(8) for j in (0, 1)}        # the trailing-edge column (8) stays put
    assert all(d.strip().startswith("( 19,") for d in dvs)          # FFD_CONTROL_POINT_2D, moving in y
    assert keys["FFD_DEGREE"] == "(8, 1, 0)" and keys["DV_KIND"] == "FFD_SETTING"
    assert (keys["OPT_BOUND_LOWER"], keys["OPT_BOUND_UPPER"]) == (f"{-BOUND:g}", f"{BOUND:g}")
    assert "AIRFOIL_THICKNESS > 0.120012" in keys["OPT_CONSTRAINT"]
    assert "AIRFOIL_AREA > 0.0816978" in keys["OPT_CONSTRAINT"]
    assert keys["CONV_FIELD"] == "(RMS_DENSITY, RMS_ADJ_DENSITY)"
    numbers = [float(v) for v in re.findall(r"-?\d+\.?\d*", ffd_definition().split(",", 1)[1])]
    corners = np.array(numbers[:12]).reshape(4, 3)
    np.testing.assert_allclose(corners[:, :2], [[-0.02, -0.08], [1.02, -0.08], [1.02, 0.08], [-0.02, 0.08]])
    assert not any(numbers[12:])


def test_hicks_henne_configuration_is_outward_only_and_unconstrained():
    keys = config_keys("hh", "mesh.su2", 0.12, 0.08)
    dvs = keys["DEFINITION_DV"].split(";")
    assert len(dvs) == 2 * len(HH_STATIONS) == 18
    sides = [int(re.search(r"\| (\d), ", d).group(1)) for d in dvs]
    assert sides.count(0) == sides.count(1) == 9
    assert keys["OPT_BOUND_LOWER"] == "0.0" and float(keys["OPT_BOUND_UPPER"]) == BOUND
    assert keys["OPT_CONSTRAINT"] == "NONE"
    with pytest.raises(ValueError):
        config_keys("cst", "mesh.su2", 0.12, 0.08)


@pytest.fixture(scope="module")
def l0(tmp_path_factory):
    folder = tmp_path_factory.mktemp("l0")
    write_mesh(level_mesh(family(levels=1, finest=(64, 16))[0]), folder / "adodg_L0.su2")
    return folder / "adodg_L0.su2"


@pytest.mark.solver
@pytest.mark.skipif(su2_missing() is not None, reason=str(su2_missing()))
def test_setup_embeds_the_box_and_measures_the_baseline(tmp_path, l0):
    cfg = setup("ffd", l0, tmp_path / "ffd")
    lines = read_config(cfg)
    assert config_value(lines, "MESH_FILENAME") == "mesh_ffd.su2"
    log = (tmp_path / "ffd" / "box.log").read_text()
    assert re.search(r"Mapped to FFD\): 64, 64, 64", log), log[-2000:]
    assert "FFD_NBOX= 1" in (tmp_path / "ffd" / "mesh_ffd.su2").read_text()
    geo = geometry(tmp_path / "ffd", "mesh.su2")
    assert geo["AIRFOIL_THICKNESS"] == pytest.approx(0.12, abs=2e-4)
    assert f"AIRFOIL_THICKNESS > {geo['AIRFOIL_THICKNESS']:.6g}" in config_value(lines, "OPT_CONSTRAINT")


@pytest.mark.solver
@pytest.mark.skipif(su2_missing() is not None, reason=str(su2_missing()))
@pytest.mark.parametrize("side,x", [(0, 0.3), (1, 0.5), (0, 0.8)])
def test_a_positive_hicks_henne_bump_adds_material_on_its_side(tmp_path, l0, side, x):
    shutil.copyfile(l0, tmp_path / "mesh.su2")
    keys = config_keys("hh", "mesh.su2", 0.12, 0.08)
    keys.update(DV_KIND="HICKS_HENNE", DV_PARAM=f"( {side}, {x} )", DV_VALUE="0.01", MESH_OUT_FILENAME="out.su2")
    (tmp_path / "def.cfg").write_text(with_keys(read_config(CONFIG), keys))
    subprocess.run([str(su2_bin() / "SU2_DEF"), "def.cfg"], cwd=tmp_path, env=su2_env(), check=True,
                   capture_output=True)
    base, moved = read_mesh(tmp_path / "mesh.su2"), read_mesh(tmp_path / "out.su2")
    ids = wall_nodes(base)
    m = add_material(base.points[ids, :2], moved.points[ids, :2])
    assert m.margin >= -1e-12                                  # nothing moved inward
    y0, dy = base.points[ids, 1], moved.points[ids, 1] - base.points[ids, 1]
    own, other = (y0 > 0, y0 < 0) if side == 1 else (y0 < 0, y0 > 0)
    outward = dy[own] if side == 1 else -dy[own]
    assert outward.max() == pytest.approx(0.01, rel=0.05)      # the bump's crest, outward on its side
    assert np.abs(dy[other]).max() <= 1e-12                    # the other side stays put


def test_run_resume_passes_su2_restart_and_keeps_the_pieces(tmp_path, monkeypatch):
    """``run --resume`` hands SU2 its own project file (``-r project.pkl``) and adds the piece's wall
    time to the earlier pieces'; a first run, or one without a project file, starts afresh."""
    calls = []

    class Done:
        returncode = 0

    def fake_run(cmd, **kw):
        calls.append(cmd)
        return Done()

    monkeypatch.setattr(side.subprocess, "run", fake_run)
    monkeypatch.setattr(side, "su2_bin", lambda: tmp_path)
    side.run(tmp_path, resume=True)                      # no project.pkl yet: a fresh start
    assert "-r" not in calls[-1]
    (tmp_path / "project.pkl").write_bytes(b"x")
    side.run(tmp_path, resume=False)
    assert "-r" not in calls[-1]
    first = json.loads((tmp_path / "run.json").read_text())
    assert len(first["pieces"]) == 1
    side.run(tmp_path, resume=True)
    assert calls[-1][-2:] == ["-r", "project.pkl"]
    meta = json.loads((tmp_path / "run.json").read_text())
    assert len(meta["pieces"]) == 2
    assert meta["wall"] == pytest.approx(sum(p["wall"] for p in meta["pieces"]))


@pytest.mark.parametrize("argv, said", [(["setup", "--mesh", "{tmp}/none.su2", "--folder", "{tmp}/f"], "--mesh"),
                                        (["run", "{tmp}/empty"], "has no config.cfg"),
                                        (["report", "{tmp}/empty"], "has no config.cfg")])
def test_a_missing_mesh_or_folder_is_one_line_and_exit_2(tmp_path, capsys, argv, said):
    (tmp_path / "empty").mkdir()
    code = side.main([a.format(tmp=tmp_path) for a in argv] + (["--baseline", "b.su2"] if argv[0] == "report" else [])
                     + (["ffd"] if argv[0] == "setup" else []))
    err = capsys.readouterr().err
    assert code == 2 and said in err and len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert not (tmp_path / "f").exists()
