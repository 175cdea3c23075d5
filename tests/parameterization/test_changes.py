"""SPEC oracles of each change on explicit lattices (no mesh, no box): the meaning of every change.

Tolerances: every change is a handful of float64 operations on O(1) coordinates, so results agree
with the direct formulas to a few ulp; 1e-12 (absolute, coordinates of order 1-10) leaves room for
the rounding of sin/cos/tan and of the 4x4 products without hiding any modelling error (those are
of the order of the changes themselves, 1e-3 and above).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from ffdcli.errors import InputError
from ffdcli.parameterization.changes import (
    Chord,
    Dihedral,
    LatticeFrame,
    SectionLaw,
    Shape,
    Span,
    Sweep,
    Twist,
    apply_changes,
    design_variables,
    set_design_variables,
)

TOL = 1e-12
AXES = {  # name -> (chord, thickness, span) columns
    "rect": (0, 1, 2),   # rectangular wing: chord x, thickness y, span z
    "crm": (0, 2, 1),    # CRM: chord x, span y, thickness z
}


def unit(col, sign=1.0):
    e = np.zeros(3)
    e[col] = sign
    return e


def wing_lattice(n=6, m=8, l=2, chord=1.0, thick=0.12, semi_span=4.0, sweep_deg=0.0, dihedral_deg=0.0,
                 axes="rect", root_at=0.0):
    """A box lattice of a straight wing: P[i, j, k] at chord x_i, thickness y_k, span z_j (in the
    columns of ``axes``), leading edge swept by ``sweep_deg`` and raised by ``dihedral_deg``."""
    c, t, s = AXES[axes]
    x = np.linspace(0.0, chord, n)
    y = np.linspace(-thick / 2, thick / 2, l)
    z = np.linspace(0.0, semi_span, m)
    P = np.zeros((n, m, l, 3))
    P[..., c] = x[:, None, None] + math.tan(math.radians(sweep_deg)) * z[None, :, None]
    P[..., t] = y[None, None, :] + math.tan(math.radians(dihedral_deg)) * z[None, :, None]
    P[..., s] = z[None, :, None] + root_at
    frame = LatticeFrame.from_lattice((n, m, l), unit(c), unit(t), unit(s))
    return P, frame


def coords(P, frame):
    """(..., 3) chord, thickness, span components."""
    return np.stack([P @ frame.chord_dir, P @ frame.thickness_dir, P @ frame.span_dir], axis=-1)


def le_angle(P, frame, along):
    le = frame.le_points(P)
    v = le[1] - le[0]
    return math.atan2(v @ along, v @ frame.span_dir)


# ------------------------------------------------------------------------------------------- twist

@pytest.mark.parametrize("axes", ["rect", "crm"])
def test_twist_rotates_each_section_about_its_trailing_edge_nose_up(axes):
    P, frame = wing_lattice(axes=axes)
    theta = np.array([0, 10, 10, 12, 15, 15, 16, -22], float)
    Q = Twist(theta).apply(P, frame)
    c0, c1 = coords(P, frame), coords(Q, frame)
    te_c, te_t = 1.0, 0.0                          # trailing-edge point: chord 1, thickness 0
    for j, th in enumerate(np.radians(theta)):
        dc, dt = c0[:, j, :, 0] - te_c, c0[:, j, :, 1] - te_t
        # SPEC: P' = T(p) R(theta) T(-p) P with c' = c cos + t sin, t' = -c sin + t cos
        np.testing.assert_allclose(c1[:, j, :, 0], te_c + dc * math.cos(th) + dt * math.sin(th), atol=TOL)
        np.testing.assert_allclose(c1[:, j, :, 1], te_t - dc * math.sin(th) + dt * math.cos(th), atol=TOL)
        np.testing.assert_allclose(c1[:, j, :, 2], c0[:, j, :, 2], atol=TOL)
    # nose up: a positive angle moves the leading-edge row up, a negative one down
    assert np.all(c1[0, 1:7, :, 1] > c0[0, 1:7, :, 1])
    assert np.all(c1[0, 7, :, 1] < c0[0, 7, :, 1])
    # the root section (theta_0 = 0) is bit for bit unchanged
    np.testing.assert_array_equal(Q[:, 0], P[:, 0])


def test_twist_tip_law_is_linear_in_section_index_and_root_moves_only_when_named():
    P, frame = wing_lattice()
    tip = Twist(SectionLaw.root_tip(8, tip=15.0))
    np.testing.assert_allclose(tip.values, 15.0 * np.arange(8) / 7, atol=TOL)
    np.testing.assert_array_equal(tip.apply(P, frame)[:, 0], P[:, 0])
    both = Twist(SectionLaw.root_tip(8, tip=3.0, root=-2.0))
    np.testing.assert_allclose(both.values, -2.0 + 5.0 * np.arange(8) / 7, atol=TOL)
    assert not np.allclose(both.apply(P, frame)[:, 0], P[:, 0])
    assert [n for n, _ in tip.variables()] == ["twist.tip"]
    assert [n for n, _ in both.variables()] == ["twist.root", "twist.tip"]


def test_twist_about_the_frame_reference_point_not_the_lattice_corner():
    """The trailing-edge point comes from ref_weights: a different reference point is honoured."""
    P, frame = wing_lattice(n=4, m=3)
    w = np.zeros((3, 4, 2))
    w[:, 2, :] = 0.5                                   # reference at the third chordwise row
    fr = LatticeFrame(frame.chord_dir, frame.thickness_dir, frame.span_dir, w, frame.le_rows)
    Q = Twist([0.0, 30.0, 60.0]).apply(P, fr)
    p = fr.ref_points(P)
    np.testing.assert_allclose(fr.ref_points(Q), p, atol=TOL)      # the axis points stay put


# -------------------------------------------------------------------------------------------- span

@pytest.mark.parametrize("axes,root_at", [("rect", 0.0), ("crm", 2.5)])
def test_span_scales_the_semi_span_exactly_and_keeps_the_root(axes, root_at):
    P, frame = wing_lattice(axes=axes, sweep_deg=25.0, root_at=root_at)
    Q = Span(1.1).apply(P, frame)
    c0, c1 = coords(P, frame), coords(Q, frame)
    np.testing.assert_allclose(c1[..., 2] - root_at, 1.1 * (c0[..., 2] - root_at), atol=TOL, rtol=0)
    np.testing.assert_allclose(c1[..., :2], c0[..., :2], atol=TOL, rtol=0)   # chords unchanged
    np.testing.assert_allclose(Q[:, 0], P[:, 0], atol=TOL, rtol=0)


# ---------------------------------------------------------------------------------- sweep/dihedral

@pytest.mark.parametrize("axes", ["rect", "crm"])
@pytest.mark.parametrize("lam0,delta", [(0.0, 10.0), (20.0, 5.0), (35.0, -12.0)])
def test_sweep_makes_the_leading_edge_angle_exactly_lambda_plus_delta(axes, lam0, delta):
    P, frame = wing_lattice(axes=axes, sweep_deg=lam0, dihedral_deg=4.0)
    assert le_angle(P, frame, frame.chord_dir) == pytest.approx(math.radians(lam0), abs=TOL)
    Q = Sweep(delta).apply(P, frame)
    # 1e-12 rad: atan2 of O(1) differences, a few ulp
    assert le_angle(Q, frame, frame.chord_dir) == pytest.approx(math.radians(lam0 + delta), abs=TOL)
    D = coords(Q, frame) - coords(P, frame)
    np.testing.assert_allclose(D[..., 1:], 0.0, atol=TOL)          # moves only along the chord
    np.testing.assert_allclose(Q[:, 0], P[:, 0], atol=TOL)          # root fixed
    # a shear: the shift is proportional to the span distance from the root
    k = math.tan(math.radians(lam0 + delta)) - math.tan(math.radians(lam0))
    np.testing.assert_allclose(D[..., 0], k * coords(P, frame)[..., 2], atol=TOL)


@pytest.mark.parametrize("axes", ["rect", "crm"])
@pytest.mark.parametrize("gam0,delta", [(0.0, 5.0), (0.0, -5.0), (6.0, 3.0)])
def test_dihedral_makes_the_leading_edge_angle_exactly_gamma_plus_delta_tip_up(axes, gam0, delta):
    P, frame = wing_lattice(axes=axes, sweep_deg=30.0, dihedral_deg=gam0)
    Q = Dihedral(delta).apply(P, frame)
    assert le_angle(Q, frame, frame.thickness_dir) == pytest.approx(math.radians(gam0 + delta), abs=TOL)
    D = coords(Q, frame) - coords(P, frame)
    np.testing.assert_allclose(D[..., [0, 2]], 0.0, atol=TOL)      # only along thickness
    np.testing.assert_allclose(Q[:, 0], P[:, 0], atol=TOL)
    tip_rise = D[0, -1, 0, 1]
    assert (tip_rise > 0) == (delta > 0)                           # positive raises the tip


def test_sweep_beyond_85_degrees_is_an_input_error():
    P, frame = wing_lattice(sweep_deg=30.0)
    with pytest.raises(InputError, match="within"):
        Sweep(60.0).apply(P, frame)


def test_sweep_and_dihedral_offsets_move_whole_sections():
    P, frame = wing_lattice(m=4)
    off = np.array([0.0, 0.01, 0.03, 0.06])
    D = coords(Sweep(offsets=off).apply(P, frame), frame) - coords(P, frame)
    np.testing.assert_allclose(D[..., 0], np.broadcast_to(off[None, :, None], D.shape[:3]), atol=TOL)
    np.testing.assert_allclose(D[..., 1:], 0.0, atol=TOL)
    D = coords(Dihedral(offsets=off).apply(P, frame), frame) - coords(P, frame)
    np.testing.assert_allclose(D[..., 1], np.broadcast_to(off[None, :, None], D.shape[:3]), atol=TOL)
    assert [n for n, _ in Sweep(offsets=off).variables()][1] == "sweep.offsets[1]"


# ------------------------------------------------------------------------------------------- chord

def test_chord_scales_about_the_trailing_edge_in_plane_keeping_thickness_to_chord():
    P, frame = wing_lattice(sweep_deg=10.0)
    ch = Chord(SectionLaw.root_tip(8, tip=0.6, default_root=1.0))
    Q = ch.apply(P, frame)
    c0, c1 = coords(P, frame), coords(Q, frame)
    for j, f in enumerate(ch.values):
        chord0 = c0[-1, j, 0, 0] - c0[0, j, 0, 0]
        chord1 = c1[-1, j, 0, 0] - c1[0, j, 0, 0]
        thick0 = c0[0, j, -1, 1] - c0[0, j, 0, 1]
        thick1 = c1[0, j, -1, 1] - c1[0, j, 0, 1]
        assert chord1 == pytest.approx(f * chord0, abs=TOL)
        assert thick1 / chord1 == pytest.approx(thick0 / chord0, abs=TOL)
    assert ch.values[-1] == pytest.approx(0.6, abs=TOL)
    np.testing.assert_allclose(frame.ref_points(Q), frame.ref_points(P), atol=TOL)   # TE points fixed
    np.testing.assert_allclose(c1[..., 2], c0[..., 2], atol=TOL)                      # in-plane
    np.testing.assert_array_equal(Q[:, 0], P[:, 0])                                  # root factor 1


# ------------------------------------------------------------------------------------------- shape

def test_shape_moves_only_the_named_points_only_along_thickness():
    P, frame = wing_lattice(n=6, m=8, l=3)
    up = np.array([0, 0.01, 0.015, 0.01, 0.005, 0])
    lo = np.array([0, -0.005, -0.01, -0.005, 0, 0])
    Q = Shape(up, lo, sections=[2, 5]).apply(P, frame)
    D = coords(Q, frame) - coords(P, frame)
    np.testing.assert_allclose(D[..., [0, 2]], 0.0, atol=TOL)
    expected = np.zeros(P.shape[:3])
    expected[:, [2, 5], -1] = up[:, None]
    expected[:, [2, 5], 0] = lo[:, None]
    np.testing.assert_allclose(D[..., 1], expected, atol=TOL)
    # per-point form (a random shape expanded at load time)
    rng = np.random.default_rng(7)
    U, L = rng.uniform(-0.015, 0.015, (2, 6, 8))
    D = coords(Shape(U, L).apply(P, frame), frame) - coords(P, frame)
    np.testing.assert_allclose(D[:, :, -1, 1], U, atol=TOL)
    np.testing.assert_allclose(D[:, :, 0, 1], L, atol=TOL)
    np.testing.assert_allclose(D[:, :, 1, 1], 0.0, atol=TOL)
    with pytest.raises(InputError, match="shape.upper"):
        Shape(up[:5]).apply(P, frame)
    with pytest.raises(InputError, match="section indices"):
        Shape(up, sections=[8]).apply(P, frame)


# ------------------------------------------------------------------------------------- composition

def test_twist_and_span_commute_and_both_match_the_direct_computation():
    """Twist acts in the section planes, span along their normal: they commute (checked), and both
    orders equal the direct formula."""
    P, frame = wing_lattice(sweep_deg=15.0)
    theta = np.linspace(0, 45, 8)
    a = apply_changes(P, frame, [Twist(theta), Span(1.1)])
    b = apply_changes(P, frame, [Span(1.1), Twist(theta)])
    C = coords(P, frame)
    te = C[-1, :, 0, 0]                                  # TE chord coordinate per section
    th = np.radians(theta)[None, :, None]
    dc, dt = C[..., 0] - te[None, :, None], C[..., 1]
    direct = np.stack([te[None, :, None] + dc * np.cos(th) + dt * np.sin(th),
                       -dc * np.sin(th) + dt * np.cos(th), 1.1 * C[..., 2]], axis=-1)
    np.testing.assert_allclose(coords(a, frame), direct, atol=TOL)
    np.testing.assert_allclose(coords(b, frame), direct, atol=TOL)


def test_twist_then_sweep_differs_from_sweep_then_twist_and_both_match_direct():
    """Sweep reads the leading-edge line, which twist moves: the order matters."""
    P, frame = wing_lattice(sweep_deg=0.0)
    theta = np.linspace(0, 45, 8)
    a = apply_changes(P, frame, [Twist(theta), Sweep(10.0)])
    b = apply_changes(P, frame, [Sweep(10.0), Twist(theta)])
    assert np.abs(a - b).max() > 1e-3
    C = coords(P, frame)
    th = np.radians(theta)
    z = C[0, :, 0, 2]
    # twist first: LE of section j (chord 0, thickness 0) goes to chord 1 - cos(theta_j)
    T = coords(Twist(theta).apply(P, frame), frame)
    lam = math.atan2((1 - math.cos(th[-1])) - 0.0, z[-1] - z[0])
    k = math.tan(lam + math.radians(10)) - math.tan(lam)
    direct_a = T.copy()
    direct_a[..., 0] += k * T[..., 2]
    np.testing.assert_allclose(coords(a, frame), direct_a, atol=TOL)
    # sweep first (Lambda = 0): section j shifts by z_j tan 10, then rotates about its shifted TE
    S = C.copy()
    S[..., 0] += math.tan(math.radians(10)) * C[..., 2]
    te = S[-1, :, 0, 0]
    dc, dt = S[..., 0] - te[None, :, None], S[..., 1]
    thb = th[None, :, None]
    direct_b = np.stack([te[None, :, None] + dc * np.cos(thb) + dt * np.sin(thb),
                         -dc * np.sin(thb) + dt * np.cos(thb), S[..., 2]], axis=-1)
    np.testing.assert_allclose(coords(b, frame), direct_b, atol=TOL)


def test_no_changes_is_the_identity_bit_for_bit():
    P, frame = wing_lattice()
    np.testing.assert_array_equal(apply_changes(P, frame, []), P)
    np.testing.assert_array_equal(Twist(np.zeros(8)).apply(P, frame), P)


# ---------------------------------------------------------------------------------------------- 2D

def airfoil_lattice(n=6, l=5):
    x = np.linspace(0, 1, n)
    y = np.linspace(-0.06, 0.06, l)
    P = np.zeros((n, 1, l, 3))
    P[..., 0] = x[:, None, None]
    P[..., 1] = y[None, None, :]
    frame = LatticeFrame.from_lattice((n, 1, l), [1, 0, 0], [0, 1, 0], [0, 0, 1], dim=2)
    return P, frame


def test_2d_twist_and_chord_take_one_number_about_the_trailing_edge():
    P, frame = airfoil_lattice()
    Q = Twist(SectionLaw.scalar(5.0)).apply(P, frame)
    th = math.radians(5.0)
    dc = P[..., 0] - 1.0
    np.testing.assert_allclose(Q[..., 0], 1.0 + dc * math.cos(th) + P[..., 1] * math.sin(th), atol=TOL)
    np.testing.assert_allclose(Q[..., 1], -dc * math.sin(th) + P[..., 1] * math.cos(th), atol=TOL)
    np.testing.assert_array_equal(Q[..., 2], P[..., 2])
    assert Twist(SectionLaw.scalar(5.0)).variables() == [("twist", 5.0)]
    R = Chord(SectionLaw.scalar(0.5)).apply(P, frame)
    np.testing.assert_allclose(R[..., 0], 1.0 + 0.5 * dc, atol=TOL)
    np.testing.assert_allclose(R[..., 1], 0.5 * P[..., 1], atol=TOL)


@pytest.mark.parametrize("change", [Span(1.1), Sweep(5.0), Dihedral(2.0), Sweep(offsets=[0.1])])
def test_2d_span_sweep_dihedral_are_input_errors(change):
    P, frame = airfoil_lattice()
    with pytest.raises(InputError, match="2D"):
        change.apply(P, frame)


def test_twist_list_length_must_match_the_lattice():
    P, frame = wing_lattice(m=8)
    with pytest.raises(InputError, match="8 sections"):
        Twist([0, 1, 2]).apply(P, frame)


# ----------------------------------------------------------------------------------- variables

def test_design_variable_names_values_and_setting_them():
    changes = [Twist(np.arange(8.0)), Span(1.1), Twist(SectionLaw.root_tip(8, tip=3.0, root=-2.0)),
               Sweep(5.0), Shape([0, 1, 2], [3, 4, 5]),
               Chord(SectionLaw.root_tip(8, tip=0.6, default_root=1))]
    names, values = design_variables(changes)
    assert names[:2] == ["c0.twist[0]", "c0.twist[1]"]
    assert names[7:11] == ["c0.twist[7]", "c1.span", "c2.twist.root", "c2.twist.tip"]
    assert names[11:] == ["c3.sweep", "c4.shape.upper[0]", "c4.shape.upper[1]", "c4.shape.upper[2]",
                          "c4.shape.lower[0]", "c4.shape.lower[1]", "c4.shape.lower[2]", "c5.chord.tip"]
    np.testing.assert_array_equal(values, [*range(8), 1.1, -2, 3, 5, 0, 1, 2, 3, 4, 5, 0.6])
    new = set_design_variables(changes, values + 1)
    names2, values2 = design_variables(new)
    assert names2 == names
    np.testing.assert_array_equal(values2, values + 1)
    with pytest.raises(ValueError):
        set_design_variables(changes, values[:-1])
    U = np.zeros((2, 3))
    assert [n for n, _ in Shape(U).variables()][:4] == ["shape.upper[0,0]", "shape.upper[0,1]",
                                                          "shape.upper[0,2]", "shape.upper[1,0]"]


def test_nose_up_and_tip_up_follow_the_frame_directions_not_the_mesh_axes():
    """Chord along -x, thickness along -z, span along -y (a mirrored wing): the meaning holds."""
    P, frame = wing_lattice(axes="crm")
    P = -P
    fr = LatticeFrame.from_lattice(P.shape[:3], -frame.chord_dir, -frame.thickness_dir, -frame.span_dir)
    Q = Twist(np.full(8, 10.0)).apply(P, fr)
    rise = (Q - P)[0, 1:] @ fr.thickness_dir                   # leading-edge row, all but the root
    assert np.all(rise > 0)
    Q = Dihedral(5.0).apply(P, fr)
    assert le_angle(Q, fr, fr.thickness_dir) == pytest.approx(math.radians(5.0), abs=TOL)
    assert ((Q - P)[0, -1, 0] @ fr.thickness_dir) > 0
    Q = Span(1.1).apply(P, fr)
    np.testing.assert_allclose(Q @ fr.span_dir, 1.1 * (P @ fr.span_dir), atol=TOL)
