"""``box.refine`` and knot insertion (issue 31): more control points, the same map.

Inserting knots must not move the surface (1e-12 of the chord), the refined box's sections keep
their meaning (trailing-edge reference points, stations), the cache key includes ``refine``, and
the shape variables of a refined lattice have exact derivatives.
"""

from __future__ import annotations

import numpy as np
import pytest
from test_derivatives import assert_matches_fd

from ffdcli.box.box import Box, fit_box
from ffdcli.box.refine import apply_refine, refine_box, region_knots
from ffdcli.design import refine_regions
from ffdcli.errors import InputError
from ffdcli.lattice.lattice import Lattice, evaluate
from ffdcli.lattice.spline import basis, insertion_matrix, refinement_matrix
from ffdcli.mesh import CellBlock
from ffdcli.parameterization.changes import Shape, Twist, changes_from_spec
from ffdcli.settings import BoxSettings
from ffdcli.testing.wings import Planform, wing_surface


@pytest.fixture(scope="module")
def wing():
    pf = Planform(le_sweep_deg=30, taper=0.4, twist_tip_deg=-5, dihedral_deg=4, root_airfoil="2412")
    pts, quads = wing_surface(pf, n_chord=41, n_span=21)
    box, emb, _ = fit_box(pts, [CellBlock("quad", quads)], BoxSettings(points=(6, 8, 2)), dim=3)
    return pts, box, emb


@pytest.mark.parametrize("p", [1, 2, 3, 4])
def test_knot_insertion_is_the_same_spline(p):
    rng = np.random.default_rng(p)
    n = 7
    knots = Lattice(rng.normal(size=(n, 3, 2, 3)), (p, 2, 1)).knots[0]
    P = rng.normal(size=(n, 3))
    t = np.linspace(0, 1, 301)
    first, vals = basis(knots, p, t)
    before = np.einsum("na,nad->nd", vals, P[first[:, None] + np.arange(p + 1)])
    new = [0.1, 0.5, 0.5, 0.77, 0.9]
    new = [u for u in new if np.count_nonzero(knots == u) < p][:4]
    k2, A = refinement_matrix(knots, p, new)
    Q = A @ P
    first, vals = basis(k2, p, t)
    after = np.einsum("na,nad->nd", vals, Q[first[:, None] + np.arange(p + 1)])
    assert np.abs(after - before).max() < 1e-14
    assert np.allclose(A.sum(axis=1), 1.0) and (A >= 0).all()       # convex combinations
    with pytest.raises(ValueError):
        insertion_matrix(knots, p, 0.0)


def test_refined_box_is_the_same_map(wing):
    pts, box, emb = wing
    chord = np.linalg.norm(box.te_points - box.le_points, axis=1).max()
    rbox, Av = refine_box(box, chord=[0.05, 0.9, 0.95], span=[0.3, 0.31, 0.75])
    assert rbox.shape == (9, 11, 2) and Av.shape == (11, 8)
    before = evaluate(box.lattice(), emb.params)
    after = evaluate(rbox.lattice(), emb.params)
    assert np.abs(after - before).max() < 1e-12 * chord
    # every section's trailing-edge reference point is its te point; root and tip unchanged
    np.testing.assert_allclose(rbox.frame.ref_points(rbox.control_points), rbox.te_points, atol=1e-12)
    np.testing.assert_array_equal(rbox.stations[[0, -1]], box.stations[[0, -1]])
    np.testing.assert_allclose(rbox.le_rows @ rbox.control_points.reshape(-1, 3),
                               box.le_rows @ box.control_points.reshape(-1, 3), atol=1e-12 * chord)
    # stored and read back (the cache)
    back = Box.from_arrays(rbox.to_arrays())
    np.testing.assert_array_equal(back.base_sections, rbox.base_sections)


def test_regions_add_the_points_asked_for(wing):
    pts, box, emb = wing
    regions = refine_regions([{"span": [0.7, 1.0], "sections": 4}, {"chord": [0.0, 0.15], "points": 2}])
    assert regions == (("span", 0.7, 1.0, 4), ("chord", 0.0, 0.15, 2))
    u, v = region_knots(box, regions)
    assert len(u) == 2 and len(v) == 4
    rbox, remb = apply_refine(box, emb, regions)
    assert rbox.shape == (8, 12, 2)
    s = (rbox.stations - rbox.stations[0]) / (rbox.stations[-1] - rbox.stations[0])
    assert (s > 0.6).sum() == (((box.stations - box.stations[0]) / np.ptp(box.stations)) > 0.6).sum() + 4
    chord = np.linalg.norm(box.te_points - box.le_points, axis=1).max()
    np.testing.assert_allclose(remb.evaluate(rbox.control_points), emb.evaluate(box.control_points),
                               atol=1e-12 * chord)


def test_refined_shape_variables_have_exact_derivatives(wing):
    pts, box, emb = wing
    rbox, _ = apply_refine(box, emb, (("span", 0.6, 1.0, 3), ("chord", 0.0, 0.2, 2)))
    n, m, l = rbox.shape
    rng = np.random.default_rng(3)
    items = [{"twist": {"tip": 6}}, {"shape": {"upper": rng.uniform(-0.01, 0.01, n).tolist(),
                                               "lower": rng.uniform(-0.01, 0.01, n).tolist(),
                                               "sections": [m - 3, m - 2]}}]
    changes = changes_from_spec(items, n, m, l, 3, box=rbox, surface=pts)
    assert isinstance(changes[0], Twist) and isinstance(changes[1], Shape)
    # {tip: } is linear in the refined sections' span fractions (they are not evenly spaced)
    s = (rbox.stations - rbox.stations[0]) / (rbox.stations[-1] - rbox.stations[0])
    np.testing.assert_allclose(changes[0].values, 6 * s, atol=1e-12)
    assert_matches_fd(rbox.control_points, rbox.frame, changes)


def test_settings_and_cache_key():
    plain = BoxSettings(points=(6, 8, 2))
    assert "refine" not in plain.as_dict()                     # unrefined boxes keep their cache keys
    ref = BoxSettings(points=(6, 8, 2), refine=(("span", 0.7, 1.0, 4),))
    assert ref.get_cache_key() != plain.get_cache_key()
    assert BoxSettings.from_dict(ref.as_dict()) == ref
    with pytest.raises(InputError, match="refine"):
        BoxSettings(points=(6, 8, 2), refine=(("span", 0.9, 0.2, 4),)).checked(3)
    with pytest.raises(InputError, match="2D box has no span"):
        BoxSettings(points=(6, 2), refine=(("span", 0.1, 0.2, 4),)).checked(2)
