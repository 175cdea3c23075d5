"""The hybrid mesh family of ADODG Case 3 (benchmarks/adodg/case3_hybrid.py), without a solver: the
coarsest level (H0) is a closed, valid, conforming mesh of tetrahedra and prisms with the case's
markers, its wall on the NACA 0012 wing and its tip cap, its leading edge resolved chordwise; the
surface and the layers hold on varied sizes (hypothesis) without gmsh."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from benchmarks.adodg.case3_hybrid import (
    CHORD,
    LE_RADIUS,
    SEMISPAN,
    HybridLevel,
    box,
    chord_stations,
    graded,
    hybrid_levels,
    hybrid_mesh,
    prism_layers,
    section_grid,
    wing_surface,
)
from ffdcli.mesh import CellBlock
from ffdcli.mesh.idsets import unique_ids
from ffdcli.quality.metrics import cell_quality
from ffdcli.quality.orthogonality import node_orthogonality
from ffdcli.testing.cells import tet_volumes
from ffdcli.testing.naca import naca4_thickness

pytest.importorskip("gmsh")


@pytest.fixture(scope="module")
def h0():
    return hybrid_mesh(hybrid_levels()[0])


def _block(blocks, kind):
    return np.concatenate([b.data for b in blocks if b.type == kind]) if any(b.type == kind for b in blocks) \
        else np.zeros((0, 3 if kind == "triangle" else 4), dtype=np.int64)


def _wedge_volumes(points, wedges):
    """Volumes (W,) of wedges as the sum of three tetrahedra of one split (the quadrilateral sides are
    nearly flat here, so the split's choice changes the total by far less than the test's tolerance)."""
    a, b, c, d, e, f = (wedges[:, i] for i in range(6))
    parts = [np.stack(t, 1) for t in ((a, b, c, d), (b, c, d, e), (c, d, e, f))]
    return sum(np.abs(tet_volumes(points, t)) for t in parts)


def test_markers_cells_and_no_inverted_cell(h0):
    assert set(h0.markers) == {"wing", "symmetry", "farfield"}
    assert [c.type for c in h0.cells] == ["tetra", "wedge"]
    q = cell_quality(h0.points, h0.cells)
    assert q.min() > 0.005, q.min()
    # the layers' stations move along the offset curves only near the edges: no skewed dual faces
    assert node_orthogonality(h0.points, h0.cells).min() > 20.0
    sym = unique_ids(*[b.data for b in h0.markers["symmetry"]])
    assert np.all(h0.points[sym, 1] == 0.0)
    far = unique_ids(*[b.data for b in h0.markers["farfield"]])
    lo, hi = box(25.0)
    on_face = np.isclose(h0.points[far], lo, atol=1e-9) | np.isclose(h0.points[far], hi, atol=1e-9)
    assert np.all(on_face.any(axis=1))


def test_the_mesh_is_closed_and_conforming(h0):
    """Every cell face is shared by two cells or lies on exactly one marker face (the prisms' top
    meets gmsh's tetrahedra node to node; the layers' sides in the root plane are the symmetry quads)."""
    tets, wedges = h0.cells[0].data, h0.cells[1].data
    tri_faces = np.concatenate([tets[:, [0, 1, 2]], tets[:, [0, 1, 3]], tets[:, [0, 2, 3]], tets[:, [1, 2, 3]],
                                wedges[:, [0, 1, 2]], wedges[:, [3, 4, 5]]])
    quad_faces = np.concatenate([wedges[:, [0, 1, 4, 3]], wedges[:, [1, 2, 5, 4]], wedges[:, [2, 0, 3, 5]]])
    for faces, kind in ((tri_faces, "triangle"), (quad_faces, "quad")):
        keys, counts = np.unique(np.sort(faces, axis=1), axis=0, return_counts=True)
        assert counts.max() <= 2
        once = keys[counts == 1]
        marked = np.concatenate([_block(blocks, kind) for blocks in h0.markers.values()])
        assert len(np.unique(np.sort(marked, axis=1), axis=0)) == len(marked)
        assert np.array_equal(np.unique(np.sort(marked, axis=1), axis=0), once)
    # and the cells fill the box less the wing, without overlap
    xs, yt = chord_stations(hybrid_levels()[0])
    area = 2.0 * np.trapezoid(yt, xs)
    cap = 0.5 * np.pi * np.trapezoid(yt ** 2, xs)
    lo, hi = box(25.0)
    total = tet_volumes(h0.points, tets).sum() + _wedge_volumes(h0.points, wedges).sum()
    assert abs(total - (np.prod(hi - lo) - area * SEMISPAN - cap)) < 2e-3 * (area * SEMISPAN + cap)


def test_wall_is_the_wing_and_its_cap(h0):
    wall = unique_ids(*[b.data for b in h0.markers["wing"]])
    p = h0.points[wall]
    t = naca4_thickness("0012", p[:, 0] / CHORD) * CHORD
    side = p[:, 1] <= SEMISPAN
    assert np.max(np.abs(np.abs(p[side, 2]) - t[side])) < 1e-12
    tip = ~side
    assert tip.sum() > 0
    r = np.hypot(p[tip, 1] - SEMISPAN, p[tip, 2])
    assert np.max(np.abs(r - t[tip])) < 1e-12
    assert p[:, 1].max() == pytest.approx(SEMISPAN + t.max(), rel=2e-2)


def test_leading_edge_resolved_chordwise(h0):
    """The wall edges at the leading edge are about a tenth of its radius along the chord, and each
    wing triangle's chordwise edge grows by at most the level's ratio from the leading edge on."""
    level = hybrid_levels()[0]
    wall = unique_ids(*[b.data for b in h0.markers["wing"]])
    p = h0.points[wall]
    root = p[(p[:, 1] == 0.0) & (p[:, 2] >= 0.0)]
    root = root[np.argsort(root[:, 0])]
    ds = np.hypot(np.diff(root[:, 0]), np.diff(root[:, 2]))
    assert ds[0] == pytest.approx(0.1 * LE_RADIUS, rel=0.15)
    arc_to_radius = np.cumsum(ds) < LE_RADIUS
    assert np.all(ds[arc_to_radius] < 0.25 * LE_RADIUS)            # several edges round the nose
    assert np.all(ds[1:] / ds[:-1] < level.growth * 1.1)
    assert ds[-1] == pytest.approx(level.ds_te, rel=0.15)
    assert ds.max() <= level.ds_max * 1.1


levels = st.builds(
    lambda le, te, mx, dy, tip, g, first, layers, lg: HybridLevel(
        "t", ds_le=le, ds_te=te, ds_max=mx, dy_max=dy, dy_tip=tip, growth=g, first=first, layers=layers,
        layer_growth=lg, h_near=0.03, h_far=10.0),
    st.floats(0.0008, 0.004), st.floats(0.002, 0.008), st.floats(0.04, 0.1), st.floats(0.08, 0.3),
    st.floats(0.02, 0.06), st.floats(1.1, 1.3), st.floats(0.0008, 0.003), st.integers(2, 10),
    st.floats(1.2, 1.7))


@settings(max_examples=15, deadline=None)
@given(levels)
def test_surface_and_layers_are_valid_on_varied_sizes(level):
    wall, tris, ids = wing_surface(level)
    pts, wedges, quads = prism_layers(wall, tris, ids, level)
    assert cell_quality(pts, [CellBlock("wedge", wedges)]).min() > 0
    assert np.all(pts[quads.ravel(), 1] == 0.0)
    nw = len(wall)
    p = pts[ids["root"]]
    ds = np.hypot(p[1, 0] - p[0, 0], p[1, 2] - p[0, 2])
    assert ds == pytest.approx(level.ds_le, rel=0.15)
    # the layers are nested offsets: layer k at distance h_k from the section (off the trailing edge's arc)
    gx, gz = section_grid(level)
    assert np.all(np.diff(gx, axis=1)[:, : gx.shape[1] // 2] > 0)
    assert np.all(gz[:, [0, -1]] == 0.0) and np.all(gz[:, 1:-1] > 0)
    top = pts[level.layers * nw:]
    assert np.all(np.linalg.norm(top - wall, axis=1) >= level.first * 0.999)


@settings(max_examples=30, deadline=None)
@given(st.floats(0.5, 5.0), st.floats(1e-3, 0.05), st.floats(1e-3, 0.05), st.floats(0.06, 0.5),
       st.floats(1.05, 1.5))
def test_graded_spacing(length, d0, d1, dmax, growth):
    assume(abs(d0 - d1) < 0.5 * (growth - 1.0) * length)       # both ends reachable by the growth
    s = graded(length, d0, d1, dmax, growth)
    ds = np.diff(s)
    assert s[0] == 0.0 and s[-1] == length and np.all(ds > 0)
    if len(ds) > 8:
        assert ds[0] == pytest.approx(min(d0, dmax), rel=0.25)
        assert ds[-1] == pytest.approx(min(d1, dmax), rel=0.25)
        assert np.all(ds <= dmax * 1.3)
        assert np.all(ds[1:] / ds[:-1] < growth * 1.15) and np.all(ds[:-1] / ds[1:] < growth * 1.15)
