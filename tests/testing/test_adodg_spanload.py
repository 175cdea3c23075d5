"""ADODG Case 3's span load and span efficiency (benchmarks/adodg/spanload.py) on analytic loads and
on a synthetic wall whose pressures carry a known load: no solver."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from scipy.spatial import ConvexHull

from benchmarks.adodg.spanload import (
    SpanLoad,
    drag_by_region,
    ellipse_difference,
    ellipse_strips,
    fourier_coefficients,
    load_efficiency,
    span_efficiency,
    strip_loads,
    wall_stations,
)


def exact_strips(edges: np.ndarray, s: float, coef) -> np.ndarray:
    """Strip means of sum A_n sin(n theta), y = s cos(theta), by dense quadrature (independent of the
    module's closed form)."""
    out = []
    for y0, y1 in zip(edges[:-1], edges[1:], strict=True):
        y = np.linspace(y0, y1, 20001)
        th = np.arccos(np.clip(y / s, 0, 1))
        f = sum(a * np.sin((2 * k + 1) * th) for k, a in enumerate(coef))
        out.append(np.trapezoid(f, y) / (y1 - y0))
    return np.array(out)


@settings(max_examples=15, deadline=None)
@given(cl=st.floats(0.1, 3.0), s=st.floats(0.5, 10.0), n=st.integers(4, 60))
def test_an_exact_ellipse_has_e_one_and_no_difference(cl, s, n):
    edges = np.linspace(0.0, s, n + 1)
    load = SpanLoad(edges=edges, ccl=ellipse_strips(edges, cl, s), cl_total=cl)
    assert np.isclose(np.sum(load.ccl * load.widths), cl, rtol=1e-12)
    d = ellipse_difference(load, s)
    assert d.rms < 1e-10 and d.max_abs < 1e-10
    assert load_efficiency(fourier_coefficients(load, s)) == pytest.approx(1.0, abs=1e-12)


@settings(max_examples=10, deadline=None)
@given(a3=st.floats(-0.3, 0.3), a5=st.floats(-0.2, 0.2), s=st.floats(1.0, 5.0))
def test_a_load_with_known_harmonics_gives_the_lifting_line_efficiency(a3, a5, s):
    coef = [1.0, a3, a5]
    edges = np.linspace(0.0, s, 41)
    ccl = exact_strips(edges, s, coef)
    load = SpanLoad(edges=edges, ccl=ccl, cl_total=float(np.sum(ccl * np.diff(edges))))
    fit = fourier_coefficients(load, s, n_terms=5)
    assert np.allclose(fit, coef + [0, 0], atol=1e-6)
    assert load_efficiency(fit) == pytest.approx(1.0 / (1.0 + 3 * a3 ** 2 + 5 * a5 ** 2), abs=1e-6)


def test_a_rectangular_load_differs_from_its_ellipse_by_the_known_amounts():
    s, n, cl = 3.0, 20000, 1.2
    edges = np.linspace(0.0, s, n + 1)
    load = SpanLoad(edges=edges, ccl=np.full(n, cl / s), cl_total=cl)
    d = ellipse_difference(load, s)
    # constant load cl/s against the ellipse c0 sqrt(1 - t^2), c0 = 4 cl / (pi s): difference / c0
    # = pi/4 - sqrt(1 - t^2); at the tip pi/4, RMS over t: sqrt(pi^2/16 - pi/4 * pi/2 + 2/3)
    assert d.max_abs == pytest.approx(100 * np.pi / 4, rel=2e-2)
    assert d.rms == pytest.approx(100 * np.sqrt(np.pi ** 2 / 16 - np.pi ** 2 / 8 + 2 / 3), rel=1e-3)
    # its induced drag is unbounded (the tip vortex): the truncated series' e falls as terms are added
    es = [load_efficiency(fourier_coefficients(load, s, n_terms=k)) for k in (3, 6, 12)]
    assert es[0] > es[1] > es[2] and es[2] < 0.9


def test_span_efficiency_from_drag():
    cl, ar, e = 0.375, 6.0, 0.97
    cd0 = 1.3e-3
    cd = cd0 + cl * cl / (np.pi * ar * e)
    assert span_efficiency(cl, cd, cd0, ar) == pytest.approx(e, rel=1e-12)


def plate_wing(n_chord: int, n_span: int, s: float):
    """A flat double-sided plate wing (upper z = +0, lower z = -0), chord 1 along x, span [0, s] along y:
    points (P, 3) and triangles with normals into the body (upper: -z, lower: +z)."""
    x, y = np.linspace(0, 1, n_chord + 1), np.linspace(0, s, n_span + 1)
    X, Y = np.meshgrid(x, y, indexing="ij")
    grid = np.stack([X.ravel(), Y.ravel(), np.zeros(X.size)], axis=1)
    ids = np.arange(X.size).reshape(X.shape)
    a, b, c, d = ids[:-1, :-1].ravel(), ids[1:, :-1].ravel(), ids[1:, 1:].ravel(), ids[:-1, 1:].ravel()
    up = np.concatenate([np.stack([a, c, b], 1), np.stack([a, d, c], 1)])      # normal -z (into body)
    lo = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)]) + len(grid)   # normal +z
    return np.concatenate([grid, grid]), np.concatenate([up, lo])


@pytest.mark.parametrize("alpha", [0.0, 3.0])
def test_strip_loads_integrate_a_known_pressure_jump(alpha):
    s, cl = 3.0, 1.1
    points, tris = plate_wing(8, 120, s)
    n = len(points) // 2
    y = points[:n, 1]
    jump = 4 * cl / (np.pi * s) * np.sqrt(np.clip(1 - (y / s) ** 2, 0, None))    # c cl (chord 1) = Cp_l - Cp_u
    cp = np.concatenate([-0.5 * jump, 0.5 * jump])
    load = strip_loads(points, tris, cp, n_strips=12, alpha_deg=alpha)
    # the plate's normal force is the lift times cos(alpha)
    ca = np.cos(np.radians(alpha))
    ell = ellipse_strips(load.edges, cl, s)
    assert np.allclose(load.ccl, ca * ell, rtol=2e-3, atol=2e-3 * ell[0])
    assert load.cl_total == pytest.approx(ca * cl, rel=1e-3)
    d = ellipse_difference(SpanLoad(load.edges, load.ccl / ca, load.cl_total / ca), s)
    assert d.rms < 0.5


@settings(max_examples=20, deadline=None)
@given(seed=st.integers(0, 10_000), n_span=st.integers(3, 60), alpha=st.floats(0.0, 6.0))
def test_station_strips_hold_each_row_of_a_wall_meshed_in_rows(seed, n_span, alpha):
    """Strips between the wall's own spanwise stations (irregular) hold each row of triangles whole:
    the strip load of a jump that varies along the span is its trapezoid mean over the row, exactly,
    where equal strips that cut the rows would alias."""
    rng = np.random.default_rng(seed)
    s = 3.0
    y = np.concatenate([[0.0], np.sort(rng.uniform(0.0, s, n_span - 1)), [s]])
    assume(bool(np.all(np.diff(y) > 1e-6)))
    points, tris = plate_wing(6, n_span, s)
    n = len(points) // 2
    rows = np.rint(points[:n, 1] / s * n_span).astype(int)
    points[:n, 1] = y[rows]
    points[n:, 1] = y[rows]
    f = 0.3 + np.sin(2.0 * y / s) + 0.2 * rng.standard_normal(len(y))      # c cl at each station
    cp = np.concatenate([-0.5 * f[rows], 0.5 * f[rows]])
    edges = wall_stations(points, tris, s)
    assert np.array_equal(edges, y)
    load = strip_loads(points, tris, cp, n_strips=0, alpha_deg=alpha, edges=edges)
    ca = np.cos(np.radians(alpha))
    assert np.allclose(load.ccl, ca * 0.5 * (f[1:] + f[:-1]), rtol=1e-12, atol=1e-12)


def test_wall_stations_refuse_an_unstructured_wall():
    rng = np.random.default_rng(1)
    points = np.stack([rng.uniform(0, 1, 2000), rng.uniform(0, 3, 2000), np.zeros(2000)], axis=1)
    points[0, 1], points[1, 1] = 0.0, 3.0
    tris = np.arange(1998).reshape(-1, 3)
    assert wall_stations(points, np.concatenate([tris, [[0, 1, 2]]]), 3.0) is None


@settings(max_examples=20, deadline=None)
@given(seed=st.integers(0, 10_000), n_span=st.integers(3, 40), noise=st.sampled_from([1e-15, 1e-13, 1e-11]))
def test_wall_stations_take_rows_moved_with_round_off_as_one_row_each(seed, n_span, noise):
    """A wall whose rows another program moved (SU2_DEF: span coordinates off by 1e-14) keeps its rows:
    the same stations as the exact wall, 0 and the span exactly, and the same strip loads."""
    rng = np.random.default_rng(seed)
    s = 3.0
    points, tris = plate_wing(6, n_span, s)
    exact = wall_stations(points, tris, s)
    moved = points.copy()
    moved[:, 1] += noise * s * rng.uniform(-1.0, 1.0, len(points))
    edges = wall_stations(moved, tris, s)
    assert edges is not None and len(edges) == len(exact) == n_span + 1
    assert edges[0] == 0.0 and edges[-1] == s and np.allclose(edges, exact, rtol=0, atol=2 * noise * s)
    cp = np.concatenate([-np.ones(len(points) // 2), np.ones(len(points) // 2)])
    a = strip_loads(points, tris, cp, n_strips=0, alpha_deg=2.0, edges=exact)
    b = strip_loads(moved, tris, cp, n_strips=0, alpha_deg=2.0, edges=edges)
    assert np.allclose(a.ccl, b.ccl, rtol=1e-6)


def closed_polyhedron(rng, n: int = 200) -> tuple[np.ndarray, np.ndarray, float]:
    """Random points on an ellipsoid, their convex hull's triangles oriented into the body (the mesh's
    convention), and the hull's volume."""
    u = rng.normal(size=(n, 3))
    pts = u / np.linalg.norm(u, axis=1)[:, None] * rng.uniform(0.2, 1.5, 3) + rng.uniform(-1, 1, 3)
    hull = ConvexHull(pts)
    tris = hull.simplices.copy()
    c = pts.mean(axis=0)
    p = pts[tris]
    n_out = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    flip = np.einsum("ij,ij->i", n_out, p.mean(axis=1) - c) > 0        # outward: flip to inward
    tris[flip] = tris[flip][:, ::-1]
    return pts, tris, float(hull.volume)


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), alpha=st.floats(-10.0, 10.0), b=st.floats(-2, 2), c=st.floats(-2, 2))
def test_drag_by_region_of_a_linear_pressure_on_a_closed_body_is_its_gradient_times_the_volume(seed, alpha, b, c):
    rng = np.random.default_rng(seed)
    pts, tris, volume = closed_polyhedron(rng)
    cp = 0.3 + b * pts[:, 0] + c * pts[:, 2]                     # linear: each triangle's mean is exact
    x = np.sort(rng.uniform(pts[:, 0].min(), pts[:, 0].max(), 3))
    span = float(rng.uniform(pts[:, 1].min(), pts[:, 1].max()))
    parts, cap = drag_by_region(pts, tris, cp, alpha_deg=alpha, x_edges=x, span=span)
    a = np.radians(alpha)
    # closed surface, normals inward: sum of cp n dA = -grad(cp) V (the divergence theorem)
    assert parts.sum() + cap == pytest.approx(-(b * np.cos(a) + c * np.sin(a)) * volume, abs=1e-10)
    # each triangle in exactly one place: the cap by its centroid's span, the rest by its centroid's x
    p = pts[tris]
    cen = p.mean(axis=1)
    f = cp[tris].mean(axis=1)[:, None] * 0.5 * np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    d = f[:, 0] * np.cos(a) + f[:, 2] * np.sin(a)
    on_cap = cen[:, 1] > span
    assert cap == pytest.approx(d[on_cap].sum(), abs=1e-12)
    last = ~on_cap & (cen[:, 0] >= x[1])                  # the last region takes every centroid beyond x[1]
    assert len(parts) == 2 and parts[1] == pytest.approx(d[last].sum(), abs=1e-12)
