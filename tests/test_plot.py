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
    proc = run_ffd("plot", str(design), "-o", str(png))
    assert proc.returncode == 0, proc.stderr
    img = read_png(png)
    assert img.shape[0] > 500 and img.shape[1] > 800
    red, black = red_and_black(img)
    assert red.sum() > 1000 and black.sum() > 1000


def test_plot_no_change_red_covers_black(tmp_path):
    """With no change the deformed (red, drawn on top) hides the original (black) curves."""
    mesh = write_surface_wing(tmp_path)
    d0 = write_design(tmp_path, mesh, [{"twist": {"tip": 0}}], name="zero.yaml")
    d1 = write_design(tmp_path, mesh, [{"dihedral": 10}], name="dih.yaml")
    run_ffd("plot", str(d0), "-o", str(tmp_path / "zero.png"))
    run_ffd("plot", str(d1), "-o", str(tmp_path / "dih.png"))
    _, black0 = red_and_black(read_png(tmp_path / "zero.png"))
    _, black1 = red_and_black(read_png(tmp_path / "dih.png"))
    assert black1.sum() > 1.5 * black0.sum()


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
