"""Flap and slat (issue 31): the oracles of the issue on a fitted box, and exact derivatives.

- points behind the hinge's transition and inside the device's span range (clear of its blends)
  turn rigidly about the hinge line (1e-10 of the chord);
- points ahead of the hinge, and outside the device plus its blends, do not move (1e-12);
- a 0 degree device is no change; flap then twist is the composition of the two maps;
- angle, hinge fractions and the input lattice against central differences.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from test_derivatives import assert_matches_fd

from ffdcli.api import DesignModel
from ffdcli.app.deform import device_line
from ffdcli.box.box import fit_box
from ffdcli.box.refine import edges_at, span_fractions
from ffdcli.errors import InputError
from ffdcli.lattice.lattice import evaluate
from ffdcli.lattice.spline import basis
from ffdcli.mesh import CellBlock
from ffdcli.parameterization.changes import Twist, apply_changes, changes_from_spec, design_variables
from ffdcli.parameterization.changes.control_surfaces import refine_for_devices, rodrigues
from ffdcli.parameterization.changes.devices import BLEND_INTERVALS, MAX_ANGLE, section_weights
from ffdcli.settings import BoxSettings
from ffdcli.testing.wings import Planform, crm_planform, naca4, rect_wing_planform, wing_surface


@pytest.fixture(scope="module")
def rect():
    pts, faces = wing_surface(rect_wing_planform(), n_chord=61, n_span=31)
    box, emb, _ = fit_box(pts, [CellBlock("quad", faces)], BoxSettings(points=(6, 8, 2)))
    return pts, box, emb


@pytest.fixture(scope="module")
def crm():
    pts, faces = wing_surface(crm_planform(), n_chord=61, n_span=41)
    box, emb, _ = fit_box(pts, [CellBlock("quad", faces)], BoxSettings(points=(6, 8, 2)))
    return pts, box, emb


@pytest.fixture(scope="module")
def left():
    pf = Planform(le_sweep_deg=25, taper=0.5, dihedral_deg=4, sections="yz", span_sign=-1.0, root_airfoil="2412")
    pts, faces = wing_surface(pf, n_chord=61, n_span=31)
    box, emb, _ = fit_box(pts, [CellBlock("quad", faces)], BoxSettings(points=(6, 8, 2)))
    return pts, box, emb


def test_left_wing_span_along_minus_x(left):
    assert left[1].span_dir @ np.array([1.0, 0, 0]) == -1.0
    check_oracles(left, {"flap": {"span": [0.2, 0.6], "hinge": 0.7, "angle": 20}})
    check_oracles(left, {"slat": {"span": [0.1, 0.9], "hinge": 0.15, "angle": 15}})


def build(case, items):
    """(refined box, embedding, changes) of a ``changes`` list on a fitted wing."""
    pts, box, emb = case
    box, emb = refine_for_devices(box, emb, pts, items)
    n, m, l = box.shape
    return box, emb, changes_from_spec(items, n, m, l, box.dim, box=box, surface=pts)


def surface_after(box, emb, P):
    return emb.evaluate(box.core_control_points(P)) if box.dim == 3 else \
        box.mesh_vectors(emb.evaluate(box.core_control_points(P)))


def local_coords(box, X):
    """(span fraction, chord fraction) of points X (the baseline chord at their station)."""
    f = span_fractions(box, X)
    edges = np.array([edges_at(box, x) for x in np.clip(f, 0, 1)])
    le, te = edges[:, 0], edges[:, 1]
    cf = np.einsum("ij,ij->i", X - le, te - le) / np.einsum("ij,ij->i", te - le, te - le)
    return f, cf


def check_oracles(case, item, rigid=1e-10, still=1e-12):
    """``rigid``, ``still``: how closely (in chords) points behind the transition turn rigidly and
    points ahead of the hinge stay (1e-10, 1e-12); a variable hinge on a tapered hinge line turns
    each section by its own share, and the sections a point 0.01 chord from the hinge or the
    transition's end depends on see the line a little further aft or forward (1e-5)."""
    pts, _, _ = case
    box, emb, (dev,) = build(case, [item])
    X = pts
    P0 = box.control_points
    P = apply_changes(P0, box.frame, [dev])
    disp = surface_after(box, emb, P) - surface_after(box, emb, P0)
    chord = np.linalg.norm(box.te_points - box.le_points, axis=1).max()
    f, cf = local_coords(box, X)
    a, b = dev.spec.span
    H = dev.hinge_line(P0)
    # the hinge line's chord fraction at each point's station (a straight line: not linear in the
    # fraction on a tapered wing)
    sa, sb = span_fractions(box, H)
    Hs = H[0] + np.clip((f - sa) / (sb - sa), -1, 2)[:, None] * (H[1] - H[0])
    h = local_coords(box, Hs)[1]
    omega, _, _ = dev._axis(H, box.frame)
    R = rodrigues(omega, np.array([np.radians(dev.angle)]))[0]
    rigid_motion = H[0] + (X - H[0]) @ R.T - X
    tr = dev.geometry.transition.max() + 0.01
    if dev.kind == "flap":
        turning = (f >= a) & (f <= b) & (cf > h + tr)
        still_points = (cf < h - 0.01) | (f < a - dev.spec.blend) | (f > b + dev.spec.blend)
    else:
        turning = (f >= a) & (f <= b) & (cf < h - tr)
        still_points = (cf > h + 0.01) | (f < a - dev.spec.blend) | (f > b + dev.spec.blend)
    turning &= emb.inside
    still_points &= emb.inside
    assert turning.sum() > 50 and still_points.sum() > 500
    assert np.abs(disp[turning] - rigid_motion[turning]).max() < rigid * chord
    assert np.abs(disp[still_points]).max() < still * chord
    return dev, disp, box


@pytest.mark.parametrize("angle", [10.0, 30.0, -15.0])
def test_flap_rotates_rigidly_and_leaves_the_rest(rect, angle):
    dev, disp, box = check_oracles(rect, {"flap": {"span": [0.2, 0.6], "hinge": 0.75, "angle": angle}})
    f, cf = local_coords(box, rect[0])
    te = (f > 0.25) & (f < 0.55) & (cf > 0.99)
    down = disp[te] @ box.thickness_dir
    assert np.all(np.sign(down) == -np.sign(angle))        # positive: trailing edge down
    assert np.allclose(down, -0.25 * np.sin(np.radians(angle)), rtol=0.05)


def test_slat_and_tapered_hinge_on_a_swept_wing(crm):
    check_oracles(crm, {"slat": {"span": [0.1, 0.9], "hinge": 0.15, "angle": 15}})
    dev, disp, box = check_oracles(crm, {"flap": {"span": [0.4, 0.95], "hinge": [0.75, 0.7], "angle": 20,
                                                  "blend": 0.03}}, rigid=1e-5, still=1e-5)
    assert dev.variables()[1][0] == "flap.hinge[0]"


def test_slat_nose_goes_down(rect):
    dev, disp, box = check_oracles(rect, {"slat": {"span": [0.1, 0.9], "hinge": 0.15, "angle": 15}})
    f, cf = local_coords(box, rect[0])
    le = (f > 0.2) & (f < 0.8) & (cf < 0.005)
    assert np.all(disp[le] @ box.thickness_dir < 0)


def test_knots_do_not_move_the_surface(rect, crm):
    for case in (rect, crm):
        pts, box, emb = case
        item = {"flap": {"span": [0.3, 0.7], "hinge": [0.7, 0.8], "angle": 10}}
        rbox, remb, _ = build(case, [item])
        assert rbox.shape[0] > box.shape[0] and rbox.shape[1] > box.shape[1]
        chord = np.linalg.norm(box.te_points - box.le_points, axis=1).max()
        before = evaluate(box.lattice(), emb.params)
        after = evaluate(rbox.lattice(), emb.params)
        assert np.abs(after - before).max() < 1e-12 * chord
        assert np.abs(surface_after(rbox, remb, rbox.control_points) - before).max() < 1e-12 * chord


def test_blend_weights_make_a_linear_ramp_between_full_and_none():
    """Sections inside the device's span turn fully, those reaching past a blend not at all, and
    the angle's share along the span, sum_j w_j N_j(v), is 1 in the device, 0 past the blends,
    monotone, and exactly the linear ramp across the middle of each blend (B-splines reproduce
    linear functions)."""
    q, n = 3, BLEND_INTERVALS * 3
    inner = 0.1 + 0.2 * np.arange(n + 1) / n          # inner blend 0.1 .. 0.3, device 0.3 .. 0.55
    outer = 0.55 + 0.3 * np.arange(n + 1) / n         # outer blend 0.55 .. 0.85
    v = np.concatenate([np.zeros(q + 1), [0.05], inner, [0.42], outer, [0.93], np.ones(q + 1)])
    w = section_weights(v, q, (0.3, 0.55), (0.1, 0.85))
    t = np.linspace(0.0, 1.0, 4001)
    first, vals = basis(v, q, t)
    share = np.einsum("ik,ik->i", vals, w[first[:, None] + np.arange(q + 1)])
    assert np.all((w >= 0) & (w <= 1)) and np.count_nonzero((w > 0) & (w < 1)) == 2 * (n - q) > 0
    assert np.allclose(share[(t >= 0.3) & (t <= 0.55)], 1.0, atol=1e-14)
    assert np.abs(share[(t <= 0.1) | (t >= 0.85)]).max() < 1e-15
    rising, falling = t < 0.42, t > 0.42
    assert np.all(np.diff(share[rising]) >= -1e-15) and np.all(np.diff(share[falling]) <= 1e-15)
    # between the Greville abscissae of the last full and first still section (a knot interval
    # inside each end of the blend), a straight line across the middle
    h = 0.3 / n
    mid = (t > 0.55 + 2 * h) & (t < 0.85 - 2 * h)
    line = (0.85 - h - t[mid]) / (0.3 - 2 * h)
    assert np.abs(share[mid] - line).max() < 1e-13
    # never steeper than that line (the control polygon's slope): 1.5 times the blend's mean slope
    slope = np.abs(np.diff(share[falling])) / np.diff(t[falling])
    assert slope.max() <= (1 + 1e-9) / (0.3 - 2 * h) and (0.3 - 2 * h) == pytest.approx(0.3 / 1.5)
    h = 0.2 / n
    mid = (t > 0.1 + 2 * h) & (t < 0.3 - 2 * h)
    assert np.abs(share[mid] - (t[mid] - 0.1 - h) / (0.2 - 2 * h)).max() < 1e-13


def test_the_flap_fades_along_the_span_no_steeper_than_its_blend(rect):
    """On the rectangular wing the trailing edge's drop falls from its full value to 0 across the
    blend at most 1.7 times as steeply as a straight ramp over the blend would (the spanwise
    parameter is not proportional to the span fraction)."""
    pts = rect[0]
    dev, disp, box = check_oracles(rect, {"flap": {"span": [0.2, 0.6], "hinge": 0.75, "angle": 20}})
    f, cf = local_coords(box, pts)
    te = (cf > 0.995) & (f > 0.55) & (f < 0.85)
    order = np.argsort(f[te])
    f_te, drop = f[te][order], -(disp[te] @ box.thickness_dir)[order]
    full = 0.25 * np.sin(np.radians(20.0))
    assert drop.max() == pytest.approx(full, rel=0.05) and drop.min() < 1e-12
    keep = np.diff(f_te) > 1e-3
    slope = np.abs(np.diff(drop))[keep] / np.diff(f_te)[keep]
    assert slope.max() < 1.7 * full / dev.spec.blend          # 1.55 here; 2.9 before the ramp


def test_zero_angle_is_no_change(rect):
    box, _, (dev,) = build(rect, [{"flap": {"span": [0.2, 0.6], "hinge": 0.75, "angle": 0}}])
    P0 = box.control_points
    assert np.array_equal(apply_changes(P0, box.frame, [dev]), P0)


def test_flap_then_twist_is_the_composition(rect):
    items = [{"flap": {"span": [0.2, 0.6], "hinge": 0.75, "angle": 12}}, {"twist": {"tip": 5}}]
    box, _, (dev, tw) = build(rect, items)
    assert isinstance(tw, Twist)
    P0 = box.control_points
    both = apply_changes(P0, box.frame, [dev, tw])
    assert np.allclose(both, tw.apply(dev.apply(P0, box.frame), box.frame), atol=1e-14, rtol=0)
    # twist first: the hinge line follows the twisted lattice (it is read off the input lattice)
    box2, _, (tw2, dev2) = build(rect, items[::-1])
    P1 = tw2.apply(box2.control_points, box2.frame)
    H = dev2.hinge_line(P1)
    H0 = dev2.hinge_line(box2.control_points)
    assert not np.allclose(H, H0)


@pytest.mark.parametrize("item", [
    {"flap": {"span": [0.2, 0.6], "hinge": [0.75, 0.7], "angle": 17}},
    {"slat": {"span": [0.0, 0.5], "hinge": [0.12, 0.18], "angle": -8, "blend": 0.1}},
    {"flap": {"span": [0.5, 1.0], "hinge": 0.7, "angle": 25}},
])
def test_derivatives_against_central_differences(crm, item):
    box, _, changes = build(crm, [{"twist": {"tip": 3}}, item, {"dihedral": 2}])
    names, _ = design_variables(changes)
    assert any(".angle" in n for n in names)
    assert_matches_fd(box.control_points, box.frame, changes)


def test_2d_flap_turns_the_whole_aft_part():
    xy = naca4("0012", 101)
    pts = np.column_stack([xy, np.zeros(len(xy))])
    box, emb, _ = fit_box(pts, (), BoxSettings(points=(6, 2)), dim=2)
    case = (pts, box, emb)
    for kind in ("flap", "slat"):
        item = {kind: {"hinge": [0.7] if kind == "flap" else 0.2, "angle": 10}}
        rbox, remb, (dev,) = build(case, [item])
        P = apply_changes(rbox.control_points, rbox.frame, [dev])
        disp = surface_after(rbox, remb, P) - pts
        cf = pts[:, 0]
        h = dev.spec.hinge[0]
        still = cf < h - 0.01 if kind == "flap" else cf > h + 0.01
        assert np.abs(disp[still]).max() < 1e-12
        end = cf > 0.995 if kind == "flap" else cf < 0.002
        assert np.all(disp[end, 1] < 0)
        assert_matches_fd(rbox.control_points, rbox.frame, [dev])


@pytest.mark.parametrize("item, words", [
    ({"flap": {"hinge": 0.75, "angle": 10}}, "needs span"),
    ({"flap": {"span": [0.6, 0.2], "hinge": 0.75, "angle": 10}}, "inner < outer"),
    ({"flap": {"span": [0.2, 0.6], "hinge": 0.995, "angle": 10}}, "between 0.02 and 0.98"),
    ({"flap": {"span": [0.2, 0.6], "hinge": [0.7, 0.7, 0.7], "angle": 10}}, "list of 2"),
    ({"flap": {"span": [0.2, 0.6], "hinge": [0.5, 0.7], "angle": 10}}, "default hinge_range of a flap"),
    ({"slat": {"span": [0.2, 0.6], "hinge": [0.15, 0.35], "angle": 10}}, "default hinge_range of a slat"),
    ({"flap": {"span": [0.2, 0.6], "hinge": [0.7, 0.7], "hinge_range": [0.72, 0.9], "angle": 10}},
     "inside hinge_range"),
    ({"flap": {"span": [0.2, 0.6], "hinge": [0.7, 0.7], "hinge_range": [0.8, 0.6], "angle": 10}}, "lo < hi"),
    ({"flap": {"span": [0.2, 0.6], "hinge": 0.7, "hinge_range": [0.6, 0.8], "angle": 10}}, "give hinge as a list"),
    ({"slat": {"span": [0.2, 0.6], "hinge": 0.15, "angle": 80}}, "within [-60, 60]"),
    ({"flap": {"span": [0.2, 0.6], "hinge": 0.75, "angle": 5, "transition": 0.5}}, "transition"),
])
def test_bad_devices_are_input_errors(rect, item, words):
    with pytest.raises(InputError, match=words.replace("[", r"\[")) as e:
        build(rect, [item])
    assert e.value.key.startswith("changes[0].")


def test_edges_at_interpolates_the_baseline_chord(rect):
    _, box, _ = rect
    le, te = edges_at(box, 0.5)
    assert np.allclose(np.linalg.norm(te - le), 1.0, atol=1e-3)


def test_the_optimisers_bound_on_a_device_angle_is_what_a_design_file_may_give():
    model = DesignModel.from_file(Path(__file__).resolve().parents[2] / "configs" / "rect_flap.yaml")
    k = [i for i, n in enumerate(model.names) if n.endswith("flap.angle")]
    assert k and np.all(model.lower[k] == -MAX_ANGLE) and np.all(model.upper[k] == MAX_ANGLE)


def test_ffd_deform_says_when_the_root_or_tip_squeezes_a_blend(rect):
    """A device 0.05 from the root has only 0.05 of span to fade over, not the 0.2 set: the printed
    line says so (its rotation fades four times as fast there); a device clear of both ends, or
    reaching the tip, prints the setting alone."""
    near = build(rect, [{"flap": {"span": [0.05, 0.45], "hinge": 0.72, "angle": 20}}])[2][0].describe()
    assert near["blends"] == [0.05, 0.2]
    assert "(blend 0.2; inner only 0.05, the root is nearer)" in device_line("c0", near)
    clear = build(rect, [{"flap": {"span": [0.3, 0.7], "hinge": 0.72, "angle": 20}}])[2][0].describe()
    assert clear["blends"] == [0.2, 0.2] and "(blend 0.2)," in device_line("c0", clear)
    tip = build(rect, [{"slat": {"span": [0.5, 1.0], "hinge": 0.15, "angle": 10}}])[2][0].describe()
    assert tip["blends"] == [0.2, None] and "(blend 0.2)," in device_line("c0", tip)
