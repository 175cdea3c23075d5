"""Numbers on the command line are finite (found here: ``ffd grad --tolerance nan`` was accepted:
``FloatRange(min=0)`` lets NaN through), a lattice given with ``ffd box --from`` away from the wing is
refused in words (found here: a raw NumPy RuntimeWarning, then a box that moved nothing), and a Python
warning that reaches the command line is one ``ffd: warning:`` line."""

from __future__ import annotations

import warnings

import click
import numpy as np
import pytest
from hostile import ffd_inproc
from wingcase import write_volume_wing

from ffdcli.cli import _register, cli
from ffdcli.io.formats import read_mesh
from ffdcli.io.formats.plot3d import write_plot3d

_register()

#: Every option of every command that takes a float (``optimize --step`` is left to the optimiser's owners).
FLOAT_OPTIONS = [(name, p.opts[0]) for name, cmd in cli.commands.items() for p in cmd.params
                 if isinstance(p, click.Option) and isinstance(p.type, click.types.FloatParamType)
                 and name != "optimize"]


def test_the_float_options_are_found():
    assert {("grad", "--tolerance"), ("box", "--margin"), ("check", "--threshold")} <= set(FLOAT_OPTIONS)


@pytest.mark.parametrize("value", ["nan", "NaN", "inf", "-inf", "1e999", "-Infinity"])
@pytest.mark.parametrize("command, option", FLOAT_OPTIONS)
def test_non_finite_numbers_are_refused(tmp_path, command, option, value):
    cmd = cli.commands[command]
    args = [f"{p.name}.yaml" for p in cmd.params if isinstance(p, click.Argument) and p.required]
    args += [x for p in cmd.params if isinstance(p, click.Option) and p.required for x in (p.opts[0], "x.csv")]
    proc = ffd_inproc(command, *args, f"{option}={value}", cwd=tmp_path)
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr.startswith("ffd: error: invalid value for") and "finite number" in proc.stderr, proc.stderr


@pytest.fixture(scope="module")
def wing(tmp_path_factory):
    d = tmp_path_factory.mktemp("away")
    mesh = read_mesh(write_volume_wing(d))
    pts = mesh.points[mesh.marker_point_ids("wing")]
    return d, pts.min(axis=0), pts.max(axis=0)


@pytest.mark.parametrize("axis", [0, 1, 2])
@pytest.mark.parametrize("shift", [1.5, 4.0, -2.0])
def test_box_from_a_lattice_away_from_the_wing(wing, axis, shift):
    d, lo, hi = wing
    move = np.zeros(3)
    move[axis] = shift * (hi - lo)[axis]
    grid = np.stack(np.meshgrid(*(np.linspace(lo[a], hi[a], n) for a, n in enumerate((5, 3, 4))),
                                indexing="ij"), axis=-1) + move
    name = f"away{axis}_{shift}.xyz"
    write_plot3d(d / name, [grid])
    with warnings.catch_warnings():
        warnings.simplefilter("error")           # no NumPy warning on the way
        proc = ffd_inproc("box", "vwing.su2", "--surface", "wing", "--from", name, "--lattice", "l.vtk",
                          "--no-cache" if False else "--rebuild", cwd=d)
    assert proc.returncode == 2, proc.stderr
    assert f"ffd: error: {name}: none of the" in proc.stderr and "inside the imported lattice" in proc.stderr
    assert "Warning" not in proc.stderr and not (d / "l.vtk").exists()


def test_a_stray_python_warning_is_one_line(tmp_path, monkeypatch):
    import ffdcli.app.inspection as inspection

    real = inspection.inspect_mesh

    def noisy(*args, **kwargs):
        np.float64(0.0) / np.float64(0.0)        # NumPy: "invalid value encountered in scalar divide"
        return real(*args, **kwargs)

    monkeypatch.setattr(inspection, "inspect_mesh", noisy)
    write_volume_wing(tmp_path)
    with warnings.catch_warnings():
        warnings.simplefilter("always")
        proc = ffd_inproc("inspect", "vwing.su2", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    lines = proc.stderr.splitlines()
    assert lines == ["ffd: warning: RuntimeWarning: invalid value encountered in scalar divide"], proc.stderr
