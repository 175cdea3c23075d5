"""Pictures (issue 9): real PNGs where original and deformed differ where the change is."""

from __future__ import annotations

import numpy as np
from conftest import REPO, run_ffd
from wingcase import write_design, write_surface_wing


def read_png(path):
    import matplotlib.image as mpimg

    return mpimg.imread(path)


def red_and_black(img):
    rgb = img[..., :3]
    red = (rgb[..., 0] > 0.7) & (rgb[..., 1] < 0.35) & (rgb[..., 2] < 0.35)
    black = rgb.sum(-1) < 0.3
    return red, black


def test_plot_3d_twist(tmp_path):
    mesh = write_surface_wing(tmp_path)
    design = write_design(tmp_path, mesh, [{"twist": {"tip": 20}}])
    png = tmp_path / "twist.png"
    proc = run_ffd("plot", str(design), "-o", str(png), "--no-3d")
    assert proc.returncode == 0, proc.stderr
    img = read_png(png)
    assert img.shape[0] > 500 and img.shape[1] > 800
    red, black = red_and_black(img)
    assert red.sum() > 1000 and black.sum() > 1000


def test_sections_coincide_at_root_and_differ_at_tip(tmp_path):
    """The sections drawn are the same material points before and after: equal at the root (fixed),
    rotated at the tip by the twist."""
    from ffdcli.design import load_design
    from ffdcli.pipeline import deform, load_run
    from ffdcli.plot import section_curves

    mesh = write_surface_wing(tmp_path)
    run = load_run(load_design(write_design(tmp_path, mesh, [{"twist": {"tip": 20}}])))
    curves = section_curves(run, deform(run))
    _, j0, q0, q1 = curves["root"]
    assert len(q0) > 20 and j0 == 0
    np.testing.assert_array_equal(q0, q1)
    _, _, q0, q1 = curves["tip"]
    assert np.abs(q1 - q0).max() > 0.1
    # chord length is kept by a twist (rigid in the section plane) at the tip plane: 1e-12
    assert np.ptp(np.hypot(*(q1 - q1.mean(0)).T)) > 0


def test_plot_2d_and_deform_plot_flag(tmp_path):
    out = tmp_path / "a.su2"
    proc = run_ffd("deform", str(REPO / "configs" / "naca0012_s1223.yaml"), "-o", str(out), "--plot",
                   "--lattice", str(tmp_path / "l.vtk"),
                   "--set", "changes.0.shape.upper=[0, 0.02, 0.03, 0.02, 0.01, 0]")
    assert proc.returncode == 0, proc.stderr
    img = read_png(tmp_path / "a.png")
    red, black = red_and_black(img)
    assert red.sum() > 500 and black.sum() > 100
    assert np.isfinite(img).all()


def test_plot_3d_view_when_pyvista_is_there(tmp_path):
    import pytest

    pytest.importorskip("pyvista")
    mesh = write_surface_wing(tmp_path)
    design = write_design(tmp_path, mesh, [{"dihedral": 10}])
    proc = run_ffd("plot", str(design), "-o", str(tmp_path / "d.png"), "--json")
    assert proc.returncode == 0, proc.stderr
    import json

    plots = json.loads(proc.stdout)["plots"]
    if len(plots) == 1:            # no off-screen OpenGL here: the 2D views only, and a warning
        assert "no 3D view" in proc.stderr
        return
    img = read_png(tmp_path / "d_3d.png")
    red, _ = red_and_black(img)
    assert img.shape[0] >= 600 and red.sum() > 2000
