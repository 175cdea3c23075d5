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
    from ffdcli.app.deformation import deform
    from ffdcli.app.run import load_run
    from ffdcli.design import load_design
    from ffdcli.viz.plot import section_curves

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


# --------------------------------------------------------------------------------------------------
# Issue 19: outlines, the change panel, labels, target, gate note, 3D from deform --plot
# --------------------------------------------------------------------------------------------------

def _run(tmp_path, changes, **planform):
    from ffdcli.app.deformation import deform
    from ffdcli.app.run import load_run
    from ffdcli.design import load_design

    mesh = write_surface_wing(tmp_path, **planform)
    run = load_run(load_design(write_design(tmp_path, mesh, changes)))
    return run, deform(run)


def test_outline_of_a_swept_tapered_planform_follows_its_edges():
    from ffdcli.testing.wings import Planform, wing_surface
    from ffdcli.viz.plot import outline

    pf = Planform(semi_span=3.0, root_chord=1.5, taper=0.4, le_sweep_deg=30.0, sections="xz")
    X = wing_surface(pf, n_chord=41, n_span=31)[0]
    o = outline(X, 1, 0, bins=30)                 # along span y, across chord x
    span, x = o[:, 0], o[:, 1]
    le = np.tan(np.radians(30.0)) * span
    half = len(o) // 2
    # the leading-edge half of the loop is the minimum chord coordinate per span slice
    assert np.abs(x[:half] - le[:half]).max() < 0.12          # within a slice's LE drift
    assert x[half:-1].max() == X[:, 0].max() or np.isclose(x[half:-1].max(), X[:, 0].max())
    assert o[0, 0] == X[:, 1].min() and np.isclose(o[:, 0].max(), X[:, 1].max())
    np.testing.assert_array_equal(o[0], o[-1])                   # closed


def test_change_panel_is_the_exact_rigid_rotation_for_a_uniform_twist(tmp_path):
    """Every section twisted by the same angle about the straight trailing edge: the lattice and
    the surface rotate rigidly, so each panel's Delta is the rotation of its own points."""
    from ffdcli.viz.plot import section_change, section_curves

    theta = 4.0
    run, result = _run(tmp_path, [{"twist": [theta] * 8}])
    box = run.box
    c, t = box.axes.chord, box.axes.thickness
    th = np.radians(theta)
    for label, (_value, j, q0, q1) in section_curves(run, result).items():
        te = box.te_points[j][[c, t]]
        le = box.le_points[j][[c, t]]
        chord = np.hypot(*(te - le))
        r = q0 - te
        # nose up positive: the leading edge (chord-axis coordinate below the TE's) goes up
        sgn = box.chord_sign
        rot_t = -np.sin(th) * r[:, 0] * sgn + np.cos(th) * r[:, 1]
        np.testing.assert_allclose(q1[:, 1] - te[1], rot_t, atol=1e-9)
        xc, d, up = section_change(box, j, q0, q1)
        assert xc.min() == 0.0 and np.isclose(xc.max(), 1.0)       # the cut's own LE and TE
        assert np.isclose(np.ptp(q0[:, 0]), chord, rtol=0.02)
        np.testing.assert_allclose(np.sort(d), np.sort(100 * (q1[:, 1] - q0[:, 1]) / np.ptp(q0[:, 0])),
                                   rtol=1e-6)
        assert 0.9 * 100 * np.sin(th) < d.max() < 1.1 * 100 * np.sin(th), label   # LE: c sin(theta)


def test_a_one_percent_shape_change_shows_as_about_one_percent(tmp_path):
    from ffdcli.viz.plot import section_change, section_curves

    run, result = _run(tmp_path, [{"shape": {"upper": [0, 0.01, 0.01, 0.01, 0.01, 0]}}])
    for label, (_value, j, q0, q1) in section_curves(run, result).items():
        xc, d, up = section_change(run.box, j, q0, q1)
        assert 0.5 < d[up].max() <= 1.0 + 1e-9, label      # chord 1: 0.01 is 1 %
        assert d.min() >= -1e-12, label                     # nothing moves down
        assert d[~up].max() < 0.6 * d[up].max(), label      # the lower side (linear in l = 2) less


def test_change_panel_chord_fraction_is_the_cut_own_on_a_swept_tapered_tip(tmp_path):
    """Twist about the quarter chord on a swept, tapered wing: in every panel (the tip cut lies
    inboard of the tip section, where LE and chord differ) the thickness-wise change crosses zero
    near x/c = 0.25 of that cut."""
    from ffdcli.viz.plot import section_change, section_curves

    run, result = _run(tmp_path, [{"twist": {"values": [4.0] * 8, "axis": 0.25}}], taper=0.3,
                       le_sweep_deg=35.0, sections="xz")
    for label, (_v, j, q0, q1) in section_curves(run, result).items():
        xc, d, up = section_change(run.box, j, q0, q1)
        zero = xc[up][np.argmin(np.abs(d[up]))]
        assert abs(zero - 0.25) < 0.03, (label, zero)


def test_section_labels_are_lattice_index_and_span_fraction(tmp_path):
    from ffdcli.viz.plot import section_curves, span_fraction

    run, result = _run(tmp_path, [{"twist": {"tip": 3}}])
    curves = section_curves(run, result)
    assert [v[1] for v in curves.values()] == [0, 3, 7]
    assert span_fraction(run.box, curves["root"][0]) == 0.0
    assert np.isclose(span_fraction(run.box, curves["mid-span"][0]), 3 / 7)
    assert 0.95 < span_fraction(run.box, curves["tip"][0]) < 1.0


def test_plot_draws_the_target_airfoil(tmp_path):
    png = tmp_path / "fit.png"
    proc = run_ffd("plot", REPO / "configs" / "naca0012_s1223.yaml", "-o", png, "--target",
                   REPO / "samples" / "s1223.dat")
    assert proc.returncode == 0, proc.stderr
    rgb = read_png(png)[..., :3]
    violet = (rgb[..., 0] > 0.4) & (rgb[..., 0] < 0.75) & (rgb[..., 1] < 0.2) & (rgb[..., 2] > 0.65)
    assert violet.sum() > 300
    proc = run_ffd("plot", REPO / "configs" / "naca0012_s1223.yaml", "-o", tmp_path / "n.png")
    rgb = read_png(tmp_path / "n.png")[..., :3]
    violet0 = (rgb[..., 0] > 0.4) & (rgb[..., 0] < 0.75) & (rgb[..., 1] < 0.2) & (rgb[..., 2] > 0.65)
    assert violet0.sum() < 20


def test_plot_says_when_the_gate_would_refuse(tmp_path):
    import json

    design = REPO / "configs" / "rect_twist_linear.yaml"
    # the tip section turned by 150 degrees over one section's span: the design's own map folds the
    # cells at the tip, which no recovery of the volume can undo (with volume.method: none the gate does
    # not judge the volume at all: another tool moves it)
    proc = run_ffd("plot", design, "-o", tmp_path / "r.png", "--no-3d", "--json",
                   "--set", "changes.0.twist=[0, 0, 0, 0, 0, 0, 0, 150]")
    assert proc.returncode == 0, proc.stderr
    assert "quality gate would refuse" in proc.stderr
    assert json.loads(proc.stdout)["refused"] is True
    proc = run_ffd("plot", REPO / "configs" / "rect_twist_linear.yaml", "-o", tmp_path / "ok.png",
                   "--no-3d", "--json", "--set", "changes.0.twist=[0, 0.5, 1, 1.5, 2, 2.5, 3, 3.5]")
    assert "quality gate" not in proc.stderr and json.loads(proc.stdout)["refused"] is False


def test_deform_plot_writes_the_3d_view_too(tmp_path):
    import json

    import pytest

    pytest.importorskip("pyvista")
    mesh = write_surface_wing(tmp_path)
    design = write_design(tmp_path, mesh, [{"twist": {"tip": 10}}])
    proc = run_ffd("deform", design, "--plot", "--json")
    assert proc.returncode == 0, proc.stderr
    s = json.loads(proc.stdout)
    if s.get("plot_3d") is None:        # no off-screen OpenGL here: said so
        assert "no 3D view" in proc.stderr
        return
    rgb = read_png(s["plot_3d"])[..., :3]
    reddish = rgb[..., 0] - rgb[..., 1:].max(-1) > 0.2      # the translucent deformed surface
    grey = (np.ptp(rgb, axis=-1) < 0.05) & (rgb.mean(-1) > 0.45) & (rgb.mean(-1) < 0.8)
    black = rgb.sum(-1) < 0.3
    assert reddish.sum() > 20000 and grey.sum() > 2000 and black.sum() > 200


def test_plot_parts_draws_several_components(tmp_path):
    """The hook for several components: two parts (a wing and a shifted copy) in one picture."""
    from dataclasses import replace

    from ffdcli.viz.plot import plot_parts, run_parts

    run, result = _run(tmp_path, [{"dihedral": 5}])
    (wing,) = run_parts(run, result)
    shift = np.array([4.0, 0.0, 0.0])
    tail = replace(wing, name="tail", X0=wing.X0 + shift, X1=wing.X1 + shift, P0=wing.P0 + shift,
                   P1=wing.P1 + shift)
    one = plot_parts([wing], tmp_path / "one.png", title="one")
    two = plot_parts([wing, tail], tmp_path / "two.png", title="two")
    r1, b1 = red_and_black(read_png(one))
    r2, b2 = red_and_black(read_png(two))
    assert b2.sum() > b1.sum() + 300 and r2.sum() > r1.sum()


def test_root_cut_of_a_root_open_at_a_noisy_symmetry_plane(tmp_path):
    """A half-wing's root nodes lie on the symmetry plane only to rounding (the ONERA M6 mesh: span
    coordinates -3e-11 to 0): a cut on the lattice's first section, which the box puts at the lowest
    of them, met only that node's edges (four points in one place, an empty root panel). The root cut
    then moves 2 % of the span outboard, and the panel says "near"."""
    from ffdcli.app.deformation import deform
    from ffdcli.app.run import load_run
    from ffdcli.design import load_design
    from ffdcli.io.formats import read_mesh, write_mesh
    from ffdcli.viz.plot import section_curves, span_fraction

    src = read_mesh(write_surface_wing(tmp_path))
    pts = src.points.copy()
    s = int(np.argmax(np.ptp(pts, axis=0)))                    # the span axis
    root = np.flatnonzero(pts[:, s] == pts[:, s].min())
    pts[root, s] += np.random.default_rng(0).uniform(-3e-11, 0.0, len(root))
    mesh = tmp_path / "noisy.su2"
    write_mesh(src, mesh, pts)
    run = load_run(load_design(write_design(tmp_path, mesh, [{"twist": {"tip": 5}}], name="noisy.yaml")))
    value, j, q0, q1 = section_curves(run, deform(run))["root"]
    assert j == 0 and len(q0) > 20 and np.ptp(q0[:, 0]) > 0.5 * np.ptp(pts[:, 0]) / 2
    assert np.isclose(span_fraction(run.box, value), 0.02)
