"""ffdcli.testing.wings: NACA sections, planforms, the quad wing surface, the O-grid and the extruded hex mesh.

Most checks are against closed forms the construction must meet to rounding: 1e-12 (a few hundred
ulps of coordinates of order 1-30) unless a comment says why another tolerance.
"""

from __future__ import annotations

import numpy as np
import pytest

from ffdcli.mesh import Mesh
from ffdcli.testing import wings

TOL = 1e-12


# -- NACA 4-digit -----------------------------------------------------------------------------


def test_parse_naca4_and_errors():
    assert wings.parse_naca4("NACA 2412") == wings.Naca4(0.02, 0.4, 0.12)
    assert wings.parse_naca4("0012").symmetric
    for bad in ("012", "abcd", "2012", "0400", "0000"):
        with pytest.raises(ValueError):
            wings.parse_naca4(bad)


@pytest.mark.parametrize("n", [5, 101, 160])
def test_naca4_selig_order_and_edges(n):
    xy = wings.naca4("0012", n)
    assert xy.shape == (n, 2)
    assert np.array_equal(xy[0], [1.0, 0.0]) and np.array_equal(xy[-1], [1.0, 0.0])  # sharp TE, exact
    if n % 2:
        assert np.array_equal(xy[(n - 1) // 2], [0.0, 0.0])
    half = (n + 1) // 2                    # odd: the LE point ends the upper side; even: the LE is
    assert np.all(np.diff(xy[:half, 0]) < 0) and np.all(np.diff(xy[n // 2:, 0]) > 0)   # between two
    assert wings.polygon_area(xy) > 0                                   # counter-clockwise
    assert np.all(xy[1:half - 1, 1] > 0)                                 # upper side first


def test_naca4_thickness_values():
    # open trailing edge: y_t(1) = 5 t (0.2969 - 0.1260 - 0.3516 + 0.2843 - 0.1015) = 0.6 * 0.0021
    xy = wings.naca4("0012", 101, closed_te=False)
    assert xy[0, 1] == pytest.approx(0.00126, abs=TOL) and xy[-1, 1] == pytest.approx(-0.00126, abs=TOL)
    # the 4-digit polynomial has its maximum thickness t at x = 0.3 to within 1e-4 of t
    x = np.linspace(0, 1, 100001)
    t = 2 * wings.naca4_thickness("0012", x, closed_te=False)
    assert t.max() == pytest.approx(0.12, abs=1e-4) and abs(x[np.argmax(t)] - 0.3) < 0.01


def test_naca4_area_converges_to_closed_form():
    exact = wings.naca4_symmetric_area("0012")
    # the inscribed polygon converges at second order: 10x the points, 100x smaller error
    err = [exact - wings.polygon_area(wings.naca4("0012", n)) for n in (401, 4001, 40001)]
    assert 0 < err[2] < err[1] < err[0] and abs(err[2]) < 1e-9
    assert 70 < err[0] / err[1] < 130 and 70 < err[1] / err[2] < 130
    assert exact == pytest.approx(0.0821, abs=5e-4)                     # the known ~0.685 t chord^2


def test_naca4_cambered_surfaces_are_consistent():
    xc = np.linspace(0.01, 0.99, 57)
    up, low = wings.naca4_points("2412", xc)
    yu, _ = wings.naca4_surfaces("2412", up[:, 0])
    _, yl = wings.naca4_surfaces("2412", low[:, 0])
    # bisection to 1 ulp of the camber station, slopes O(1): 1e-12
    np.testing.assert_allclose(yu, up[:, 1], atol=TOL)
    np.testing.assert_allclose(yl, low[:, 1], atol=TOL)
    yc, _ = wings.naca4_camber("2412", np.array([0.4]))
    assert yc[0] == pytest.approx(0.02, abs=1e-15)                       # maximum camber m at p


# -- Planform ---------------------------------------------------------------------------------


def test_planform_lines_chord_twist():
    pf = wings.Planform(semi_span=4.0, root_chord=2.0, taper=0.5, le_sweep_deg=30.0, dihedral_deg=6.0,
                        twist_root_deg=3.0, twist_tip_deg=-4.0, sections="xy")
    eta = np.linspace(0, 1, 9)
    le, te = pf.leading_edge(eta), pf.trailing_edge(eta)
    s = 4.0 * eta
    expected_le = np.stack([s * np.tan(np.radians(30)), s * np.tan(np.radians(6)), s], axis=1)
    np.testing.assert_allclose(le, expected_le, atol=TOL)               # twist about the LE
    np.testing.assert_allclose(np.linalg.norm(te - le, axis=1), 2.0 * (1 - 0.5 * eta), atol=TOL)
    twist = np.degrees(np.arctan2(le[:, 1] - te[:, 1], te[:, 0] - le[:, 0]))   # nose up positive
    np.testing.assert_allclose(twist, 3.0 - 7.0 * eta, atol=1e-10)       # arctan2 of O(1) values
    np.testing.assert_allclose(te[:, 2], s, atol=TOL)                    # sections normal to span


def test_planform_axes_and_kink():
    pf = wings.crm_planform()
    assert pf.axes == (0, 2, 1) and pf.handedness == -1
    assert pf.chord(0.0) == pytest.approx(9.93 + 3.69, abs=TOL)
    assert pf.chord(pf.kink_eta) == pytest.approx(9.93 * (1 - 0.725 * 0.37), abs=TOL)
    assert pf.chord(1.0) == pytest.approx(9.93 * 0.275, abs=TOL)
    eta = pf.stations(11)
    assert eta[0] == 0 and eta[-1] == 1 and pf.kink_eta in eta
    with pytest.raises(ValueError):
        wings.Planform(kink_te_extension=1.0)
    with pytest.raises(ValueError):
        wings.Planform(sections="xx")


# -- wing surface -----------------------------------------------------------------------------


def _divergence_volume(points, quads):
    """Volume enclosed by planar faces: sum of p0 . A / 3 with A = (p2 - p0) x (p3 - p1) / 2."""
    p = points[quads]
    area = 0.5 * np.cross(p[:, 2] - p[:, 0], p[:, 3] - p[:, 1])
    return float(np.sum(np.einsum("ij,ij->i", p[:, 0], area)) / 3.0)


def _edge_counts(quads):
    e = np.concatenate([quads[:, [0, 1]], quads[:, [1, 2]], quads[:, [2, 3]], quads[:, [3, 0]]])
    e = np.sort(e[e[:, 0] != e[:, 1]], axis=1)                            # drop collapsed edges
    _, counts = np.unique(e, axis=0, return_counts=True)
    return counts


def test_rect_wing_surface_closed_is_an_exact_prism():
    pf = wings.rect_wing_planform()
    pts, quads = wings.wing_surface(pf, n_chord=31, n_span=7, tip="closed", root="closed")
    assert pts.shape == (7 * 60, 3) and quads.dtype == np.int64 and quads.shape[1] == 4
    assert np.all(_edge_counts(quads) == 2)                              # watertight
    section = wings.naca4("0012", 61)
    # all faces are planar (rectangles and flat caps): the divergence theorem is exact to rounding
    assert _divergence_volume(pts, quads) == pytest.approx(3.0 * wings.polygon_area(section), abs=TOL)
    le = wings.leading_edge_ids(31, 7)
    np.testing.assert_array_equal(pts[le][:, :2], 0.0)
    np.testing.assert_allclose(pts[le][:, 2], np.linspace(0, 3, 7), atol=TOL)


def test_default_surface_is_open_at_the_root_only():
    pts, quads = wings.wing_surface(wings.rect_wing_planform(), n_chord=21, n_span=5)
    counts = _edge_counts(quads)
    assert np.sum(counts == 1) == 40 and np.all(counts <= 2)             # the 40 root-section edges
    p = pts[quads]
    normal = np.cross(p[:, 2] - p[:, 0], p[:, 3] - p[:, 1])
    tip = np.all(p[:, :, 2] == 3.0, axis=1)
    assert tip.sum() > 0 and np.all(normal[tip, 2] > 0)                  # tip cap faces +z (outwards)


@pytest.mark.parametrize("pf", [wings.crm_planform(), wings.crm_planform(span_sign=-1.0),
                                wings.rect_wing_planform(sections="zy", closed_te=False, twist_tip_deg=5)])
def test_surface_orientation_outwards_any_axes(pf):
    pts, quads = wings.wing_surface(pf, n_chord=25, n_span=9, tip="closed", root="closed")
    assert np.all(_edge_counts(quads) == 2)
    assert _divergence_volume(pts, quads) > 0     # outward normals give +volume (inward would be -)


def test_surface_mesh_blocks():
    pf = wings.rect_wing_planform()
    m = wings.surface_mesh(pf, n_chord=21, n_span=5, root="closed")
    assert isinstance(m, Mesh) and m.dim == 3 and m.cells == []
    assert list(m.markers) == ["wing", "root"]
    assert [b.type for b in m.markers["wing"]] == ["quad", "triangle"]
    pts, quads = wings.wing_surface(pf, n_chord=21, n_span=5, root="closed")
    np.testing.assert_array_equal(m.points, pts)
    assert sum(len(b) for v in m.markers.values() for b in v) == len(quads)
    assert len(m.markers["wing"][1]) == 2 and len(m.markers["root"][1]) == 2    # LE and TE triangles


# -- O-grid -----------------------------------------------------------------------------------


def test_airfoil_ogrid_structure():
    n_around, n_radial, radius = 81, 21, 10.0
    xy, quads, foil, far = wings.airfoil_ogrid("0012", n_around, n_radial, radius)
    m = n_around - 1                                                       # sharp TE: one point
    assert xy.shape == (m * n_radial, 2) and quads.shape == ((n_radial - 1) * m, 4)
    assert wings.quad_areas(xy, quads).min() > 0
    np.testing.assert_array_equal(xy[:m], wings.naca4("0012", n_around)[:-1])
    r = np.linalg.norm(xy[-m:] - [0.5, 0.0], axis=1)
    np.testing.assert_allclose(r, radius, atol=TOL)                        # far field is the circle
    # fluid on the left of every boundary line: the airfoil is run clockwise, the far field ccw

    def loop_area(lines):
        a, b = xy[lines[:, 0]], xy[lines[:, 1]]
        return 0.5 * float(np.sum(a[:, 0] * b[:, 1] - b[:, 0] * a[:, 1]))

    assert loop_area(foil) == pytest.approx(-wings.polygon_area(xy[:m]), abs=TOL)
    assert loop_area(far) == pytest.approx(0.5 * m * radius**2 * np.sin(2 * np.pi / m), rel=TOL)
    # every interior edge shared by two quads, the boundary edges once: a structured annulus
    e = np.sort(np.concatenate([quads[:, [0, 1]], quads[:, [1, 2]], quads[:, [2, 3]], quads[:, [3, 0]]]), 1)
    u, c = np.unique(e, axis=0, return_counts=True)
    boundary = np.unique(np.sort(np.concatenate([foil, far]), 1), axis=0)
    np.testing.assert_array_equal(u[c == 1], boundary)


def test_airfoil_ogrid_from_coordinates_and_mesh():
    sel = wings.naca4("4415", 121, closed_te=False)                         # blunt, cambered
    xy, quads, foil, far = wings.airfoil_ogrid(sel, 97, 17, 8.0)
    assert wings.quad_areas(xy, quads).min() > 0 and len(foil) == len(far) == 97
    m = wings.airfoil_ogrid_mesh("2412", 65, 13, 6.0)
    assert m.dim == 2 and np.all(m.points[:, 2] == 0) and list(m.markers) == ["airfoil", "farfield"]


# -- extruded hex mesh --------------------------------------------------------------------------


def _hex_faces(hexes):
    idx = [[0, 3, 2, 1], [4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]]
    return np.concatenate([hexes[:, i] for i in idx])


@pytest.mark.parametrize("pf", [None, wings.crm_planform(), wings.crm_planform(span_sign=-1.0)])
def test_extruded_wing_mesh_valid_and_closed(pf):
    m = wings.extruded_wing_mesh(pf)
    assert m.dim == 3 and [b.type for b in m.cells] == ["hexahedron"]
    assert list(m.markers) == ["wing", "farfield", "symmetry", "side"]
    hexes = m.cells[0].data
    assert wings.hex_volumes(m.points, hexes).min() > 0
    # the faces used once by the hexahedra are exactly the marker faces: all boundary is marked
    f = np.sort(_hex_faces(hexes), axis=1)
    u, c = np.unique(f, axis=0, return_counts=True)
    marked = np.sort(np.concatenate([b.data for v in m.markers.values() for b in v]), axis=1)
    assert len(np.unique(marked, axis=0)) == len(marked)
    np.testing.assert_array_equal(u[c == 1], np.unique(marked, axis=0))
    planform = pf or wings.rect_wing_planform()
    span = planform.axes[2]
    sym = m.points[m.marker_point_ids("symmetry"), span]
    side = m.points[m.marker_point_ids("side"), span]
    np.testing.assert_allclose(sym, 0.0, atol=TOL)
    np.testing.assert_allclose(side, planform.span_sign * planform.semi_span, atol=TOL)
    # marker normals point out of the fluid: symmetry towards -span, side towards +span
    for name, sign in (("symmetry", -1), ("side", 1)):
        p = m.points[m.markers[name][0].data]
        n = np.cross(p[:, 2] - p[:, 0], p[:, 3] - p[:, 1])[:, span] * planform.span_sign
        assert np.all(np.sign(n) == sign)


def test_extruded_wing_surface_is_the_wing():
    pf = wings.rect_wing_planform(twist_tip_deg=-3.0, taper=0.6, le_sweep_deg=10.0)
    m = wings.extruded_wing_mesh(pf, n_around=41, n_span=5)
    ids = m.marker_point_ids("wing")
    eta = pf.stations(5)
    expected = pf.section_points(eta, wings.naca4("0012", 41)[:-1]).reshape(-1, 3)
    np.testing.assert_allclose(np.sort(m.points[ids], axis=0), np.sort(expected, axis=0), atol=TOL)


@pytest.mark.parametrize("name", ["s1223.dat", "sc20714.dat", "rae2822.dat"])
def test_airfoil_ogrid_real_sections(name):
    # cusped (S1223) and blunt, aft-loaded (SC(2)-0714) trailing edges: the corner points must not
    # slide round the corner in the first layers (these folded the wall cells before)
    from conftest import shared_file

    from ffdcli.io.formats.airfoil import read_airfoil

    coords = read_airfoil(shared_file(f"airfoils/{name}")).coords
    for n in (65, 97, 161):
        xy, quads, foil, far = wings.airfoil_ogrid(coords, n, 33, 10.0)
        assert wings.quad_areas(xy, quads).min() > 0
        np.testing.assert_array_equal(xy[0], coords[0])                   # the TE point is kept


def test_twist_about_trailing_edge_is_the_spec_rotation():
    # SPEC: twist rotates a section about its trailing-edge point, nose up positive; a planform with
    # twist_axis=1 is that rotation applied to the untwisted wing, exactly (one rotation matrix)
    flat = wings.rect_wing_planform()
    twisted = wings.rect_wing_planform(twist_root_deg=0.0, twist_tip_deg=12.0, twist_axis=1.0)
    eta = np.linspace(0, 1, 5)
    coords = wings.naca4("0012", 41)
    p0, p1 = flat.section_points(eta, coords), twisted.section_points(eta, coords)
    np.testing.assert_allclose(twisted.trailing_edge(eta), flat.trailing_edge(eta), atol=TOL)
    for j, th in enumerate(np.radians(12.0 * eta)):
        te = flat.trailing_edge(eta[j:j + 1])[0]
        rot = np.array([[np.cos(th), np.sin(th)], [-np.sin(th), np.cos(th)]])   # x' = x cos + y sin
        d = (p0[j, :, :2] - te[:2]) @ rot.T + te[:2]
        np.testing.assert_allclose(p1[j, :, :2], d, atol=TOL)
        assert p1[j, 20, 1] >= te[1]                                         # LE up: nose up
