"""The C-mesh generator (:mod:`ffdcli.testing.cmesh`): on several airfoils and sizes, no inverted cell,
the wall cells exactly ``first_cell`` high and orthogonal, the wake cut conforming (its two sides the
same points, no marker on it), the trailing edge one point, the far field where asked, the boundary
markers closing the domain; and the trailing-edge closure."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ffdcli.quality.gate import check_quality
from ffdcli.testing.cells import quad_areas
from ffdcli.testing.cmesh import TE_BLEND, c_grid, close_trailing_edge, cmesh, read_airfoil
from ffdcli.testing.naca import naca4, polygon_area

DATA = Path(__file__).resolve().parents[3] / "shared" / "data" / "airfoils"
AIRFOILS = [DATA / f"{n}.dat" for n in ("rae2822", "naca0012", "sc20714")]


def _airfoils():
    out = [("naca2412", naca4("2412", 161)), ("naca0012", naca4("0012", 121))]
    out += [(p.stem, read_airfoil(p)) for p in AIRFOILS if p.is_file()]
    return out


@pytest.mark.parametrize("name, xy", _airfoils(), ids=lambda v: v if isinstance(v, str) else "")
@pytest.mark.parametrize("size", [(65, 17, 33, 1e-5), (129, 33, 65, 2e-6), (257, 49, 81, 1e-6)])
def test_a_valid_conforming_c_mesh(name, xy, size):
    n_around, n_wake, n_normal, first = size
    grid, ids, pts, quads, lines = c_grid(xy, n_around, n_wake, n_normal, first, 100.0)
    assert quad_areas(pts, quads).min() > 0                                   # no inverted cell
    n_lines = grid.shape[0]
    assert n_lines == (n_around | 1) + 2 * n_wake
    assert len(pts) == n_lines * n_normal - (n_wake + 1)                      # the cut and TE shared once
    w0, w1 = n_wake, n_lines - 1 - n_wake
    assert np.array_equal(ids[w1:, 0], ids[w0::-1, 0])                        # one point on both sides
    assert np.allclose(grid[w1:, 0], grid[w0::-1, 0], atol=0)
    h = np.linalg.norm(grid[w0:w1 + 1, 1] - grid[w0:w1 + 1, 0], axis=1)
    assert np.allclose(h, first, rtol=1e-3)                                   # the first cell as asked
    tang = np.gradient(grid[w0 + 1:w1, 0], axis=0)
    off = grid[w0 + 1:w1, 1] - grid[w0 + 1:w1, 0]
    cosang = np.abs(np.sum(tang * off, axis=1)) / np.linalg.norm(tang, axis=1) / np.linalg.norm(off, axis=1)
    angle = np.degrees(np.arcsin(cosang))
    te_x = grid[w0, 0, 0]
    away = grid[w0 + 1:w1, 0, 0] < te_x - 10 * TE_BLEND * (te_x - grid[w0:w1 + 1, 0, 0].min())
    assert angle[away].max() < 1.0 and angle.max() < 12.0      # orthogonal off the wall; near the TE averaged
    te = grid[w0, 0]
    far = 100.0 * (te[0] - grid[w0:w1 + 1, 0, 0].min())                       # 100 chords
    r = np.linalg.norm(pts - te, axis=1)
    assert np.isclose(np.abs(pts[:, 1] - te[1]).max(), far) and np.isclose(pts[:, 0].max() - te[0], far)
    assert r.max() <= far * np.sqrt(2) * (1 + 1e-12)
    # every boundary edge (used by one quad) is on a marker, and no marker edge is interior: no cut marker
    edges = np.sort(np.concatenate([quads[:, [0, 1]], quads[:, [1, 2]], quads[:, [2, 3]], quads[:, [3, 0]]]), axis=1)
    uniq, count = np.unique(edges, axis=0, return_counts=True)
    boundary = {tuple(e) for e in uniq[count == 1]}
    marked = {tuple(sorted(e)) for seg in lines.values() for e in seg}
    assert boundary == marked
    assert len(lines["airfoil"]) == (n_around | 1) - 1


def test_the_boundary_lines_have_the_fluid_on_their_left():
    grid, ids, pts, quads, lines = c_grid(read_airfoil(AIRFOILS[0]) if AIRFOILS[0].is_file() else naca4("2412"),
                                         97, 25, 41, 1e-5, 100.0)
    for name, seg in lines.items():
        a, b = pts[seg[:, 0]], pts[seg[:, 1]]
        d = b - a
        left = np.stack([-d[:, 1], d[:, 0]], axis=1)
        # each segment's quad: the one holding both ends
        owner = {}
        for q, quad in enumerate(quads):
            for k in range(4):
                owner[(quad[k], quad[(k + 1) % 4])] = q
        cells = np.array([owner[(i, j)] for i, j in seg])
        centre = pts[quads[cells]].mean(axis=1)
        assert np.all(np.sum((centre - 0.5 * (a + b)) * left, axis=1) > 0), name


def test_cmesh_is_a_2d_mesh_that_ffd_checks_clean():
    mesh = cmesh(naca4("2412", 161), 97, 25, 41, 1e-5, 100.0)
    assert mesh.dim == 2 and set(mesh.markers) == {"airfoil", "farfield"}
    report = check_quality(mesh)
    assert report.n_inverted == 0 and report.n_below == 0 and report.min_after > 0.2
    assert report.n_ortho_low == 0


@settings(max_examples=25, deadline=None)
@given(dy_up=st.floats(1e-4, 5e-3), dy_lo=st.floats(1e-4, 5e-3))
def test_a_blunt_trailing_edge_is_closed_to_its_mid_point(dy_up, dy_lo):
    xy = naca4("2412", 81, closed_te=True)
    blunt = xy.copy()
    blunt[0, 1] += dy_up
    blunt[-1, 1] -= dy_lo
    closed = close_trailing_edge(blunt)
    mid = 0.5 * (blunt[0] + blunt[-1])
    assert np.array_equal(closed[0], closed[-1]) and np.allclose(closed[0], mid)
    le = int(np.argmin(xy[:, 0]))
    assert np.allclose(closed[le], blunt[le])                                  # the leading edge stays
    assert np.allclose(closed[:, 0], blunt[:, 0])                              # a shear in y only
    assert polygon_area(closed) > 0
    assert np.array_equal(close_trailing_edge(xy), xy)                         # sharp: unchanged


@settings(max_examples=12, deadline=None)
@given(growth=st.sampled_from([0.0, 1e-4, 1e-3, 3e-3]), first=st.sampled_from([1e-6, 1e-5]),
       n_wake=st.integers(17, 41))
def test_the_wake_cuts_cells_grow_downstream_as_asked(growth, first, n_wake):
    """On the cut the first cell is ``first + growth * x`` (x behind the trailing edge), on both sides,
    the wall's lines keep ``first``, the far field does not move, and no cell inverts or shears."""
    xy = naca4("2412", 121)
    grid, ids, pts, quads, _ = c_grid(xy, 97, n_wake, 49, first, 100.0, wake_growth=growth)
    ref, *_ = c_grid(xy, 97, n_wake, 49, first, 100.0, wake_growth=0.0)
    w0, w1 = n_wake, grid.shape[0] - 1 - n_wake
    for side in (slice(0, w0 + 1), slice(w1, None)):
        x = grid[side, 0, 0] - grid[w0, 0, 0]
        h = np.linalg.norm(grid[side, 1] - grid[side, 0], axis=1)
        assert np.allclose(h, first + growth * x, rtol=2e-3)
    assert np.allclose(np.linalg.norm(grid[w0:w1 + 1, 1] - grid[w0:w1 + 1, 0], axis=1), first, rtol=1e-3)
    assert np.array_equal(grid[:, -1], ref[:, -1])                            # the far field as before
    assert quad_areas(pts, quads).min() > 0
    assert np.all(np.diff(np.abs(grid[:w0, :, 1] - grid[w0, 0, 1]), axis=1) > 0)   # monotone up each line


def test_the_default_c_mesh_grows_its_wake_cut():
    """The default: 1e-3 of the distance behind the trailing edge, not the wall's first cell carried down
    the cut (on which SU2's multigrid diverged, docs/adodg-case2.md)."""
    grid, *_ = c_grid(naca4("2412", 121), 97, 25, 49, 1e-6, 100.0)
    x = grid[0, 0, 0] - grid[25, 0, 0]
    assert x > 50 and np.isclose(abs(grid[0, 1, 1] - grid[0, 0, 1]), 1e-6 + 1e-3 * x, rtol=2e-3)
