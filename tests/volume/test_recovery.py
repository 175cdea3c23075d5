"""Recovery before refusal (ffdcli.volume.recovery): a longer reach, then the design in increments."""

from __future__ import annotations

import json

import numpy as np
import pytest
import yaml
from conftest import REPO, run_ffd

from ffdcli.app.deformation import deform
from ffdcli.app.run import load_run
from ffdcli.design import load_design
from ffdcli.settings import WarpSettings
from ffdcli.volume.recovery import attempts, incremental_warp
from ffdcli.volume.warp import prepare_mesh_warp, warp


def crm_design(tmp_path, changes, volume=None, name="d.yaml"):
    data = {"mesh": str(REPO / "samples" / "crm_wing.su2"), "surface": "wing",
            "box": {"points": [6, 8, 2], "sections": "xz"}, "changes": changes,
            "output": {"mesh": str(tmp_path / "out.su2"), "lattice": str(tmp_path / "out_lattice.vtk")}}
    if volume:
        data["volume"] = volume
    p = tmp_path / name
    p.write_text(yaml.safe_dump(data))
    return p


def test_attempts_are_a_longer_reach_then_the_rotation_then_increments():
    got = attempts(WarpSettings(alpha=0.5, wall_layer="none"))
    assert [(st.alpha, st.carry, st.rotation_reach, n) for _, st, n in got] == [
        (2.0, "gradient", 0.5, 1), (0.5, "rotation", 0.5, 1), (0.5, "rotation", None, 1), (2.0, "gradient", 0.5, 4)]
    assert "alpha: 2" in got[0][0] and "carry: rotation" in got[1][0] and "rotation_reach: null" in got[2][0]
    assert "4 increments" in got[3][0]
    assert len(attempts(WarpSettings(rotation_reach=None, wall_layer="none"))) == 3
    assert len(attempts(WarpSettings(carry="rotation", rotation_reach=None, wall_layer="none"))) == 2


def test_with_a_wall_layer_the_warp_alone_comes_first_then_the_same_attempts_without_it():
    for kw in ({}, {"rotation_reach": None}, {"carry": "rotation", "alpha": 2.0}):
        got = attempts(WarpSettings(**kw))
        assert "wall_layer: none" in got[0][0] and got[0][2] == 1
        assert all(st.wall_layer == "none" for _, st, _ in got)
        alone = attempts(WarpSettings(**kw, wall_layer="none"))
        assert [(w, st, n) for w, st, n in got[1:]] == alone


@pytest.mark.slow
def test_one_increment_is_the_plain_warp_and_the_surface_is_exact(tmp_path):
    run = load_run(load_design(crm_design(tmp_path, [{"twist": {"tip": 8}}, {"sweep": 4}])), cache_dir=tmp_path)
    P1 = run.lattice_after()
    st = WarpSettings()
    model, _ = prepare_mesh_warp(run.prep.mesh, "wing", st)
    plain = run.prep.mesh.points + warp(model, run.surface_displacement(P1), run.surface_frames(P1))
    one = incremental_warp(run.chain, P1, st, 1)
    np.testing.assert_allclose(one, plain, rtol=0, atol=1e-13)
    four = incremental_warp(run.chain, P1, st, 4)
    sid = run.prep.surface.ids
    assert np.array_equal(four[sid], run.prep.mesh.points[sid] + run.surface_displacement(P1))
    # the increments really move the volume differently (the warp is rebuilt on each step's mesh)
    assert np.abs(four - plain).max() > 1e-6


@pytest.mark.slow
def test_a_failing_setting_is_recovered_and_reported(tmp_path):
    """CRM sweep +10 with IDWarp's short reach (alpha 0.25) inverts cells behind the tip; the
    longer reach recovers it, and deform says so (text and --json)."""
    design = crm_design(tmp_path, [{"sweep": 10}], volume={"alpha": 0.25})
    run = load_run(load_design(design), cache_dir=tmp_path)
    res = deform(run)
    assert res.quality.ok
    assert res.recovery[0]["attempt"] == "the design's volume settings" and res.recovery[0]["failed"] > 0
    assert res.recovered_with == res.recovery[-1]["attempt"] and res.recovery[-1]["ok"]
    bare = deform(run, recover=False)
    assert not bare.quality.ok and bare.recovery == []
    proc = run_ffd("deform", str(design), "--json", "--cache-dir", str(tmp_path))
    assert proc.returncode == 0, proc.stderr
    s = json.loads(proc.stdout)
    assert s["recovered_with"] == res.recovered_with and s["recovery"][0]["failed"] > 0
    proc = run_ffd("deform", str(design), "--cache-dir", str(tmp_path))
    assert "recovered: longer reach" in proc.stdout


@pytest.mark.slow
def test_a_large_twist_is_recovered_without_the_fade(tmp_path):
    """configs/rect_twist_linear.yaml (45 degrees at the tip) passes with the defaults: directly since
    the gate judges cells made worse only below 0.01 (it made 2 cells markedly worse with the faded
    rotation before), else by carrying the surface frame's rotation (whole or faded), never by more."""
    run = load_run(load_design(REPO / "configs" / "rect_twist_linear.yaml"), cache_dir=tmp_path)
    res = deform(run)
    assert res.quality.ok and res.quality.n_inverted == 0
    assert res.recovered_with is None or "rotation" in res.recovered_with, res.recovered_with


@pytest.mark.slow
def test_refusal_says_what_was_tried(tmp_path):
    """A tenth of the tip chord inverts cells behind the tip (a quarter now passes: the cells on the
    tip's own faces are squeezed as the design's own map squeezes them, which the gate accepts): every
    attempt fails, and the refusal lists them and what to try next."""
    design = crm_design(tmp_path, [{"chord": {"tip": 0.1}}])
    proc = run_ffd("deform", str(design), "--cache-dir", str(tmp_path))
    assert proc.returncode == 3, proc.stderr
    assert "tried: the design's volume settings" in proc.stderr and "increments" in proc.stderr
    assert "try next" in proc.stderr
    assert not (tmp_path / "out.su2").exists()
