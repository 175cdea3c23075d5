"""Twist about a chord fraction (``twist: {tip: 5, axis: 0.25}``): exact oracles and derivatives."""

from __future__ import annotations

import math

import numpy as np
import pytest
import yaml
from conftest import SAMPLES
from test_changes import wing_lattice
from test_derivatives import assert_matches_fd, skewed_lattice
from wingcase import write_design, write_surface_wing

from ffdcli.design import changes_from_spec, load_design
from ffdcli.errors import InputError
from ffdcli.parameterization.changes import Chord, LatticeFrame, SectionLaw, Twist, apply_changes


def rotate_about(X, p, theta_deg, c, t):
    """Rotation by theta (nose up: the point ahead, lower chord coordinate, rises) about p, in the
    (chord c, thickness t) columns; X (..., 3), p (..., 3) broadcastable."""
    th = math.radians(theta_deg)
    r = X - p
    out = X.copy()
    out[..., c] = p[..., c] + math.cos(th) * r[..., c] + math.sin(th) * r[..., t]
    out[..., t] = p[..., t] - math.sin(th) * r[..., c] + math.cos(th) * r[..., t]
    return out


@pytest.mark.parametrize("axis", [0.0, 0.25, 0.5, 1.0, 1.3])
def test_the_axis_point_stays_and_each_section_rotates_rigidly_about_it(axis):
    P, frame = skewed_lattice()
    theta = np.linspace(-4.0, 12.0, 8)
    Q = apply_changes(P, frame, [Twist(theta, axis=axis)])
    te, le = frame.ref_points(P), np.einsum("jik,ijkd->jd", frame.le_weights, P)
    p = le + axis * (te - le)                                          # chord fraction on LE -> TE
    np.testing.assert_allclose(frame.chord_points(P, axis), p, atol=1e-12)
    np.testing.assert_allclose(frame.chord_points(Q, axis), p, atol=1e-12)   # does not move
    for j in range(8):
        want = rotate_about(P[:, j], p[j], theta[j], 0, 1)
        np.testing.assert_allclose(Q[:, j], want, atol=1e-12)
    # leading and trailing edge points rotate about it: distances kept, angle theta
    le1, te1 = np.einsum("jik,ijkd->jd", frame.le_weights, Q), frame.ref_points(Q)
    np.testing.assert_allclose(np.linalg.norm(le1 - p, axis=1), np.linalg.norm(le - p, axis=1), atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(te1 - p, axis=1), np.linalg.norm(te - p, axis=1), atol=1e-12)


def test_default_axis_is_the_trailing_edge_bit_for_bit():
    P, frame = skewed_lattice()
    law = SectionLaw.root_tip(8, tip=7.0)
    np.testing.assert_array_equal(apply_changes(P, frame, [Twist(law)]),
                                  apply_changes(P, frame, [Twist(law, axis=1.0)]))
    assert not np.array_equal(apply_changes(P, frame, [Twist(law)]),
                              apply_changes(P, frame, [Twist(law, axis=0.25)]))


@pytest.mark.parametrize("axis", [0.0, 0.25, 0.7])
@pytest.mark.parametrize("theta", [0.0, 30.0])
def test_derivatives_match_central_differences(axis, theta):
    P, frame = skewed_lattice()
    assert_matches_fd(P, frame, [Twist(np.full(8, theta), axis=axis)])
    assert_matches_fd(P, frame, [Twist(SectionLaw.root_tip(8, tip=theta, root=-2.0), axis=axis)])
    # through the input lattice too (the axis points follow an earlier chord change)
    assert_matches_fd(P, frame, [Chord(SectionLaw.root_tip(8, tip=0.7)),
                                 Twist(SectionLaw.root_tip(8, tip=theta + 3.0), axis=axis)])


def test_from_lattice_frame_has_the_midpoint_leading_edge():
    P, frame = wing_lattice()
    assert isinstance(frame, LatticeFrame)
    np.testing.assert_allclose(frame.chord_points(P, 0.0), 0.5 * (P[0, :, 0] + P[0, :, -1]))
    np.testing.assert_allclose(frame.chord_points(P, 0.25),
                               0.5 * (0.75 * (P[0, :, 0] + P[0, :, -1]) + 0.25 * (P[-1, :, 0] + P[-1, :, -1])))


# --------------------------------------------------------------------------------------------------
# On meshes, through the design file
# --------------------------------------------------------------------------------------------------

def _deform(tmp_path, changes, **planform):
    from ffdcli.app.deformation import deform
    from ffdcli.app.run import load_run

    mesh = write_surface_wing(tmp_path, **planform)
    run = load_run(load_design(write_design(tmp_path, mesh, changes)))
    res = deform(run)
    return run, run.prep.surface.points, res.points[run.prep.surface.ids]


@pytest.mark.parametrize("axis", [0.25, 0.5])
@pytest.mark.parametrize("planform", [dict(sections="xy"), dict(sections="xz", taper=0.5, le_sweep_deg=25.0),
                                      dict(sections="zy", dihedral_deg=4.0)])
def test_a_uniform_twist_rotates_the_wing_about_its_chord_fraction_line(tmp_path, axis, planform):
    """Every section by the same angle about a straight line (an untwisted wing's axis line at one
    chord fraction): the whole surface rotates rigidly about that line."""
    theta = 6.0
    run, X0, X1 = _deform(tmp_path, [{"twist": {"values": [theta] * 8, "axis": axis}}], **planform)
    box = run.box
    c, t, s = box.axes.chord, box.axes.thickness, box.axes.span
    p = box.le_points + axis * (box.te_points - box.le_points)         # (m, 3): on one line
    # the line through the root and tip points, evaluated at each surface point's span coordinate
    w = (X0[:, s] - p[0, s]) / (p[-1, s] - p[0, s])
    line = p[0] + w[:, None] * (p[-1] - p[0])
    want = rotate_about(X0, line, theta * box.chord_sign, c, t)
    scale = np.ptp(X0[:, c])
    assert np.abs(X1 - want).max() < 1e-9 * scale
    # the leading edge rose and the trailing edge fell, by the chord fraction's lever arms
    i_le, i_te = np.argmin(box.chord_sign * X0[:, c]), np.argmax(box.chord_sign * X0[:, c])
    assert X1[i_le, t] > X0[i_le, t] and X1[i_te, t] < X0[i_te, t]


def test_tip_section_rotates_about_its_quarter_chord_and_the_root_stays(tmp_path):
    theta = 8.0
    run, X0, X1 = _deform(tmp_path, [{"twist": {"tip": theta, "axis": 0.25}}], taper=0.6)
    box = run.box
    c, t, s = box.axes.chord, box.axes.thickness, box.axes.span
    root = np.isclose(X0[:, s], X0[:, s].min())
    np.testing.assert_array_equal(X1[root], X0[root])
    tip = np.isclose(X0[:, s], X0[:, s].max())
    p = box.le_points[-1] + 0.25 * (box.te_points[-1] - box.le_points[-1])
    want = rotate_about(X0[tip], p, theta, c, t)
    assert np.abs(X1[tip] - want).max() < 1e-9


def test_2d_twist_about_the_quarter_chord(tmp_path):
    from ffdcli.app.deformation import deform
    from ffdcli.app.run import load_run

    src = SAMPLES / "naca0012_2d.su2"
    d = tmp_path / "a.yaml"
    d.write_text(yaml.safe_dump({"mesh": str(src), "changes": [{"twist": {"angle": 3.0, "axis": 0.25}}],
                                 "volume": {"method": "none"}, "output": {"mesh": str(tmp_path / "o.su2")}}))
    run = load_run(load_design(d))
    res = deform(run, check=False)
    box = run.box
    X0, X1 = run.prep.surface.points, res.points[run.prep.surface.ids]
    p = box.le_points[0] + 0.25 * (box.te_points[0] - box.le_points[0])
    want = rotate_about(X0, p, 3.0 * box.chord_sign, box.axes.chord, box.axes.thickness)
    assert np.abs(X1 - want).max() < 1e-9


def test_design_file_forms_and_names():
    names = {"tip": ["twist.tip"], "values": [f"twist[{j}]" for j in range(4)]}
    for spec, want in (({"tip": 5, "axis": 0.25}, names["tip"]),
                       ({"root": 1, "tip": 5, "axis": 0.25}, ["twist.root", "twist.tip"]),
                       ({"values": [0, 1, 2, 3], "axis": 0.25}, names["values"]),
                       ([0, 1, 2, 3], names["values"])):
        (ch,) = changes_from_spec([{"twist": spec}], 6, 4, 2, 3)
        assert [n for n, _ in ch.variables()] == want
        assert ch.axis == (0.25 if isinstance(spec, dict) else 1.0)
    (ch,) = changes_from_spec([{"twist": {"angle": 2, "axis": 0.3}}], 6, 1, 2, 2)
    assert [n for n, _ in ch.variables()] == ["twist"] and ch.axis == 0.3
    with pytest.raises(InputError, match="2D form"):
        changes_from_spec([{"twist": {"angle": 2}}], 6, 4, 2, 3)
    with pytest.raises(InputError, match="4 sections"):
        changes_from_spec([{"twist": {"values": [1, 2], "axis": 0.25}}], 6, 4, 2, 3)


@pytest.mark.parametrize("spec, words", [
    ("{values: [0, 1], tip: 3}", "two forms"),
    ("{axis: 0.25}", "missing key 'tip'"),
    ("{tip: 3, axis: quarter}", "expected a number"),
    ("{tip: 3, axis: 0.25, about: te}", "unknown key 'about'"),
])
def test_bad_twist_axis_forms_name_the_key(tmp_path, spec, words):
    (tmp_path / "w.su2").write_text("")
    d = tmp_path / "d.yaml"
    d.write_text(f"mesh: w.su2\nchanges:\n  - twist: {spec}\n")
    with pytest.raises(InputError) as e:
        load_design(d)
    assert words in e.value.message and e.value.line == 3


def test_api_derivatives_with_an_axis_match_central_differences(tmp_path):
    from ffdcli.api import DesignModel

    mesh = write_surface_wing(tmp_path, sections="xz", taper=0.5, le_sweep_deg=20.0)
    design = write_design(tmp_path, mesh, [{"chord": {"tip": 0.8}},
                                           {"twist": {"root": 1.0, "tip": 6.0, "axis": 0.25}}])
    model = DesignModel.from_file(design)
    v0 = model.values.copy()
    rng = np.random.default_rng(1)
    dv = rng.normal(size=model.n_vars)
    jv = model.surface_jvp(dv)
    h = 1e-5
    model.set_values(v0 + h * dv)
    plus = model.surface_points().copy()
    model.set_values(v0 - h * dv)
    minus = model.surface_points().copy()
    fd = (plus - minus) / (2 * h)
    assert np.abs(jv - fd).max() <= 1e-6 * np.abs(fd).max()
