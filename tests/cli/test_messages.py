"""Messages that say what is true (issue: round 4, item 16): ``ffd plot --target`` on a 3D design is
refused (it was ignored), the count of sections after a flap says where they came from, the advice on a
root at the wrong end names what to give, an SU2_CFD that cannot run is not "not found"."""

from __future__ import annotations

import os
from types import SimpleNamespace

import pytest
from conftest import SAMPLES
from hostile import ffd_inproc
from wingcase import write_design, write_volume_wing

from ffdcli.optimize.solvers.base import find_program, missing_program
from ffdcli.parameterization.components import root_advice


@pytest.fixture(scope="module")
def ws(tmp_path_factory):
    d = tmp_path_factory.mktemp("messages")
    mesh = write_volume_wing(d)
    write_design(d, mesh, [{"twist": {"tip": 3}}], name="w.yaml")
    (d / "s1223.dat").write_bytes((SAMPLES / "s1223.dat").read_bytes())
    (d / "rect_wing.su2").write_bytes((SAMPLES / "rect_wing.su2").read_bytes())
    return d


@pytest.mark.parametrize("changes", [[{"twist": {"tip": 3}}], [{"span": 1.1}], []])
def test_plot_target_on_a_3d_design_is_refused(ws, changes):
    write_design(ws, ws / "vwing.su2", changes, name="p.yaml")
    proc = ffd_inproc("plot", "p.yaml", "--target", "s1223.dat", "-o", "p.png", cwd=ws)
    assert proc.returncode == 2 and "--target" in proc.stderr and "3D" in proc.stderr, proc.stderr
    assert not (ws / "p.png").exists()


DEVICES = [{"flap": {"span": [0.2, 0.8], "hinge": 0.7, "angle": 10}},
           {"slat": {"span": [0.3, 0.9], "hinge": 0.15, "angle": 8}},
           {"flap": {"span": [0.0, 0.5], "hinge": [0.7, 0.75], "angle": 5}}]


@pytest.mark.parametrize("device", DEVICES, ids=lambda d: next(iter(d)))
@pytest.mark.parametrize("second", ["twist", "chord", "sweep"])
def test_sections_after_a_device_say_where_they_came_from(ws, device, second):
    values = [1.0] * 8
    item = {"sweep": {"offsets": values}} if second == "sweep" else {second: values}
    text = ("mesh: rect_wing.su2\nsurface: wing\nbox: {points: [6, 8, 2]}\nchanges:\n"
            f"  - {device}\n  - {item}\n").replace("'", "")
    (ws / "dev.yaml").write_text(text)
    proc = ffd_inproc("vars", "dev.yaml", cwd=ws)
    if proc.returncode == 0:
        pytest.skip("this device inserted no sections")
    line = proc.stderr.strip().splitlines()[-1]      # after the compile notice of a first run, if any
    assert "has 8 values" in line and "8 of box.points[1]" in line and "inserted by" in line, line
    assert "sections (box.points[1])" not in line


@pytest.mark.parametrize("given, detected", [(None, "min"), (None, "max"), ("min", "min"), ("max", "max")])
def test_root_advice_names_what_to_give(given, detected):
    comp = SimpleNamespace(spec=SimpleNamespace(box=SimpleNamespace(root=given)),
                           box=SimpleNamespace(axes=SimpleNamespace(root=detected)))
    text = root_advice(comp)
    other = "max" if detected == "min" else "min"
    assert f"box.root: {other}" in text
    if given is None:
        assert "leave it out" not in text and "detected" in text
    else:
        assert "leave it out" in text and f"box.root: {given}" in text


@pytest.mark.parametrize("how", ["not executable", "folder"])
@pytest.mark.parametrize("where", ["SU2_RUN", "extra"])
def test_a_solver_that_cannot_run_is_not_not_found(tmp_path, monkeypatch, how, where):
    folder = tmp_path / "bin"
    folder.mkdir()
    if how == "folder":
        (folder / "SU2_CFD").mkdir()
    else:
        (folder / "SU2_CFD").write_text("#!/bin/sh\n")
        os.chmod(folder / "SU2_CFD", 0o644)
    monkeypatch.setenv("PATH", str(tmp_path / "nothing"))
    if where == "SU2_RUN":
        monkeypatch.setenv("SU2_RUN", str(folder))
        extra = ()
    else:
        monkeypatch.delenv("SU2_RUN", raising=False)
        extra = (folder,)
    assert find_program("SU2_CFD", "SU2_RUN", extra) is None
    why = missing_program("SU2_CFD", "SU2_RUN", extra)
    assert str(folder / "SU2_CFD") in why and ("not executable" in why if how != "folder" else "folder" in why)
    monkeypatch.setenv("SU2_RUN", str(tmp_path / "empty"))
    assert missing_program("SU2_CFD", "SU2_RUN", ()) == "not found"
