"""samples/make_samples.py rebuilds the bundled meshes with the fixtures' one generator (gmsh_wings)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

SAMPLES = Path(__file__).resolve().parents[2] / "samples"


def _make_samples():
    spec = importlib.util.spec_from_file_location("make_samples", SAMPLES / "make_samples.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_the_2d_sample_is_rebuilt_node_for_node():
    ms = _make_samples()
    assert ms.differences(ms.naca0012_2d(), SAMPLES / "naca0012_2d.su2") == ([], [])


@pytest.mark.slow
@pytest.mark.parametrize("name", ["rect_wing", "wing_tail_fin"])
def test_gmsh_samples_are_rebuilt_node_for_node(name):
    pytest.importorskip("gmsh")
    ms = _make_samples()
    assert ms.differences(ms.MESHES[name](), SAMPLES / f"{name}.su2") == ([], [])


def test_a_changed_mesh_is_reported(tmp_path):
    ms = _make_samples()
    m = ms.naca0012_2d()
    m.points[5, 0] += 1e-9
    diff, notes = ms.differences(m, SAMPLES / "naca0012_2d.su2")
    assert diff == ["coordinates of 1 points differ, by up to 1e-09"] and notes == []
