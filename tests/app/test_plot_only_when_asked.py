"""``ffd deform`` draws pictures only with ``--plot`` (found here: whenever the design file named
``output.plot``, which ``ffd init`` always does, a ``--set`` loop paid 2.4x for pictures nobody asked
for). ``output.plot`` says where the picture goes: ``ffd plot``'s, and ``ffd deform --plot``'s."""

from __future__ import annotations

import json

import pytest
import yaml
from hostile import ffd_inproc
from wingcase import write_design, write_volume_wing


@pytest.fixture(scope="module")
def ws(tmp_path_factory):
    d = tmp_path_factory.mktemp("plotwhen")
    mesh = write_volume_wing(d)
    write_design(d, mesh, [{"twist": {"tip": 3}}], name="named.yaml",
                 extra={"output": {"mesh": "o/named.su2", "lattice": "o/named_lattice.vtk", "plot": "o/pic.png"}})
    write_design(d, mesh, [{"twist": {"tip": 3}}], name="unnamed.yaml")
    (d / "o").mkdir()
    return d


def _pngs(d):
    return sorted(p.relative_to(d).as_posix() for p in d.rglob("*.png"))


@pytest.mark.parametrize("design", ["named.yaml", "unnamed.yaml"])
@pytest.mark.parametrize("output", [None, "o/run.su2"])
@pytest.mark.parametrize("tip", [2, -4])
def test_no_picture_without_plot(ws, design, output, tip):
    for p in ws.rglob("*.png"):
        p.unlink()
    args = ["deform", design, "--set", f"changes.0.twist.tip={tip}", "--json"] + (["-o", output] if output else [])
    proc = ffd_inproc(*args, cwd=ws)
    assert proc.returncode == 0, proc.stderr
    s = json.loads(proc.stdout)
    assert s["plot"] is None and s["plot_3d"] is None and _pngs(ws) == []


@pytest.mark.parametrize("output, where", [(None, "o/pic.png"), ("o/run.su2", "o/run.png")])
def test_plot_puts_the_picture_where_the_file_says(ws, output, where):
    for p in ws.rglob("*.png"):
        p.unlink()
    args = ["deform", "named.yaml", "--plot", "--json"] + (["-o", output] if output else [])
    proc = ffd_inproc(*args, cwd=ws)
    assert proc.returncode == 0, proc.stderr
    assert json.loads(proc.stdout)["plot"].endswith(where) and (ws / where).is_file()


def test_ffd_plot_uses_output_plot(ws):
    proc = ffd_inproc("plot", "named.yaml", "--no-3d", cwd=ws)
    assert proc.returncode == 0 and (ws / "o" / "pic.png").is_file(), proc.stderr


def test_the_starter_says_what_output_plot_means(ws):
    proc = ffd_inproc("init", "vwing.su2", "--surface", "wing", "-o", "started.yaml", cwd=ws)
    assert proc.returncode == 0, proc.stderr
    text = (ws / "started.yaml").read_text()
    assert "ffd deform draws none without --plot" in text and yaml.safe_load(text)["output"]["plot"]
