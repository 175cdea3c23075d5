"""Cell quality (scaled Jacobian) and the quality gate."""

from __future__ import annotations

import numpy as np
import pytest

from ffdcli.mesh import CellBlock, Mesh
from ffdcli.quality.gate import QualityReport, check_quality
from ffdcli.quality.metrics import cell_orientation, cell_quality

UNIT_TET = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1.0]])
REGULAR_TET = np.array([[1, 1, 1], [-1, 1, -1], [1, -1, -1], [-1, -1, 1.0]])   # det > 0 in this order
CUBE = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1.0]])
S3 = np.sqrt(3) / 2
PRISM = np.array([[0, 0, 0], [1, 0, 0], [0.5, S3, 0], [0, 0, 1], [1, 0, 1], [0.5, S3, 1.0]])
PYRAMID = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0.5, 0.5, np.sqrt(0.5)]])


def q1(points, ctype, dim=3, order=None):
    n = len(points)
    return cell_quality(points, [CellBlock(ctype, [list(range(n)) if order is None else order])], dim)[0]


def with_good(good, bad, ctype):
    """Quality of ``bad`` in a block that also holds the ``good`` cell."""
    n = len(good)
    blk = CellBlock(ctype, [list(range(n)), list(range(n, 2 * n))])
    return cell_quality(np.vstack([good, bad]), [blk])[1]


# 1e-15: a handful of products and square roots of exact numbers, rounding only.
def test_ideal_cells_have_quality_one():
    for pts, ctype in [(REGULAR_TET, "tetra"), (CUBE, "hexahedron"), (PRISM, "wedge"), (PYRAMID, "pyramid")]:
        assert q1(pts, ctype) == pytest.approx(1.0, abs=1e-15), ctype
    assert q1(np.array([[0, 0, 0], [1, 0, 0], [0.5, S3, 0]]), "triangle", 2) == pytest.approx(1, abs=1e-15)
    assert q1(CUBE[:4], "quad", 2) == pytest.approx(1.0, abs=1e-15)


def test_known_values_and_stretching():
    # unit right tet: the worst corner is at (1,0,0): det 1 / (1 * sqrt2 * sqrt2) * sqrt2 = 1/sqrt2
    assert q1(UNIT_TET, "tetra") == pytest.approx(1 / np.sqrt(2), abs=1e-15)
    # a boundary-layer hexahedron 1000:1 with right angles is still perfect (angles, not aspect)
    assert q1(CUBE * [1, 1, 1e-3], "hexahedron") == pytest.approx(1.0, abs=1e-15)
    # shear the top face by 1 along x: every corner angle between the x and slanted edges is 45 deg
    sheared = CUBE + np.outer(CUBE[:, 2], [1.0, 0, 0])
    assert q1(sheared, "hexahedron") == pytest.approx(1 / np.sqrt(2), abs=1e-15)


def test_inverted_and_degenerate_cells():
    # the fourth node pushed through the opposite face inverts the tet
    flipped = UNIT_TET * [1, 1, -1]
    two = np.vstack([UNIT_TET, flipped])
    q = cell_quality(two, [CellBlock("tetra", [[0, 1, 2, 3], [4, 5, 6, 7], [0, 1, 2, 3]])])
    assert q[0] > 0 and q[2] == q[0] and q[1] == -1.0      # clipped: the mirror's worst corner is -sqrt2
    flat = UNIT_TET * [1, 1, 0]                                   # all four nodes in a plane
    assert q1(flat, "tetra") == 0.0
    collapsed = UNIT_TET.copy()
    collapsed[3] = collapsed[0]                                   # an edge of zero length
    assert q1(collapsed, "tetra") == 0.0
    # next to a good cell of the same block (a block that is mostly negative would be read as
    # written in the mirrored convention, see cell_orientation)
    apex_under = PYRAMID * [1, 1, -1]
    assert with_good(PYRAMID, apex_under, "pyramid") < 0
    folded = CUBE.copy()
    folded[6] = [0.2, 0.2, 0.2]                                   # a corner pushed inside out
    assert with_good(CUBE, folded, "hexahedron") < 0
    prism = PRISM.copy()
    prism[3:] = prism[3:] * [1, 1, -1]                            # top face pushed under the base
    assert with_good(PRISM, prism, "wedge") < 0


def test_quads_2d_and_plane_orientation():
    # a 2 x 1 strip of quads in the x-z plane (y constant), counter-clockwise seen from +y
    pts = np.array([[0, 5, 0], [0, 5, 1], [1, 5, 1], [1, 5, 0], [2, 5, 1], [2, 5, 0.0]])
    quads = CellBlock("quad", [[0, 1, 2, 3], [3, 2, 4, 5]])
    o = cell_orientation(pts, [quads], 2)
    assert np.array_equal(o.normal, [0, 1, 0])
    np.testing.assert_allclose(cell_quality(pts, [quads], 2), [1, 1], atol=1e-15)
    moved = pts.copy()
    moved[4, 0] = 0.5                                             # second quad's corner folded over
    q = cell_quality(moved, [quads], 2, orientation=o)
    assert q[0] == pytest.approx(1) and q[1] < 0
    # the same mesh judged on its own (majority orientation still from the first cell: a tie
    # of areas is not possible here since the folded cell's area is smaller)
    assert cell_quality(moved, [quads], 2)[1] < 0


def test_mirrored_blocks_are_judged_in_their_own_convention():
    # a block of wedges written in mirrored order (0,2,1,3,5,4): all negative in VTK order
    mirrored = CellBlock("wedge", [[0, 2, 1, 3, 5, 4]] * 3)
    o = cell_orientation(PRISM, [mirrored])
    assert o.signs.tolist() == [-1.0]
    assert cell_quality(PRISM, [mirrored]) == pytest.approx([1, 1, 1], abs=1e-15)


def _hex_grid(n=4):
    g = np.linspace(0, 1, n + 1)
    X, Y, Z = np.meshgrid(g, g, g, indexing="ij")
    pts = np.column_stack([X.ravel(), Y.ravel(), Z.ravel()])
    idx = np.arange((n + 1) ** 3).reshape(n + 1, n + 1, n + 1)
    i, j, k = (a.ravel() for a in np.meshgrid(*[np.arange(n)] * 3, indexing="ij"))
    hexes = np.column_stack([idx[i, j, k], idx[i + 1, j, k], idx[i + 1, j + 1, k], idx[i, j + 1, k],
                             idx[i, j, k + 1], idx[i + 1, j, k + 1], idx[i + 1, j + 1, k + 1],
                             idx[i, j + 1, k + 1]])
    return Mesh(points=pts, dim=3, cells=[CellBlock("hexahedron", hexes)])


def test_check_quality_gate():
    mesh = _hex_grid()
    ok = check_quality(mesh, mesh.points + 0.01)                  # a translation: nothing changes
    assert isinstance(ok, QualityReport) and ok.ok and ok.count == 64
    assert ok.min_before == pytest.approx(1) and ok.min_after == pytest.approx(1)
    bad = mesh.points.copy()
    centre = np.flatnonzero(np.all(np.isclose(mesh.points, 0.5), axis=1))[0]
    bad[centre] += [0.3, 0.3, 0.3]                                # the centre node pushed through 7 cells
    r = check_quality(mesh, bad)
    assert not r.ok and r.n_inverted >= 1 and r.min_after < 0
    has_centre = np.any(mesh.cells[0].data == centre, axis=1)
    q = cell_quality(bad, mesh.cells)
    assert r.n_inverted == np.count_nonzero(q <= 0) and np.all(has_centre[q <= 0])
    w = r.worst[0]
    assert w["failed"] and w["quality"] == r.min_after and w["quality_before"] == pytest.approx(1)
    assert np.allclose(w["centroid"], bad[mesh.cells[0].data[w["cell"]]].mean(axis=0))
    d = r.to_dict()
    assert d["inverted"] == r.n_inverted and d["ok"] is False and len(d["worst"]) == 10
    assert f"{r.n_inverted} inverted" in r.summary() and f"cell {w['cell']}" in r.describe_worst()


def test_already_poor_cells_do_not_block_unless_they_get_much_worse():
    # one hexahedron whose top face is sheared by s along x: q = 1 / sqrt(1 + s^2)
    def sheared(s):
        return CUBE + np.outer(CUBE[:, 2], [s, 0, 0])

    poor = Mesh(points=sheared(30), dim=3, cells=[CellBlock("hexahedron", [list(range(8))])])
    assert cell_quality(poor.points, poor.cells)[0] == pytest.approx(1 / np.sqrt(901), rel=1e-14)
    r = check_quality(poor, sheared(31), threshold=0.05)      # 0.0333 -> 0.0322: below 0.05, not halved
    # (orthogonality 4.66 -> 4.52 deg: below 20 but lost less than 10)
    assert r.ok and r.n_worse == 0 and r.n_below == 1 and r.n_below_before == 1 and r.min_after < 0.05
    r = check_quality(poor, sheared(70), threshold=0.05)      # 0.0333 -> 0.0143: halved, not under 0.01
    assert r.ok and r.n_worse == 0 and r.n_below == 1
    r = check_quality(poor, sheared(150), threshold=0.05)     # 0.0333 -> 0.0067: halved, under 0.01
    assert not r.ok and r.n_inverted == 0 and r.n_worse == 1 and r.n_failed == 1
    assert "1 cells made worse" in r.failure_message() and "below 0.5 x its value before" in r.failure_message()
    # without a "before" the threshold alone counts (ffd check)
    r = check_quality(poor, threshold=0.05)
    assert r.n_below == 1 and r.min_before is None and r.ok


def _two_hexes(top_shift):
    """Two hexahedra side by side: the first sheared by 30 (q 0.0333, the input's worst), the second a
    unit cube whose top face moves by ``top_shift`` along x (its own nodes only)."""
    a = CUBE + np.outer(CUBE[:, 2], [30.0, 0, 0])
    b = CUBE + [40.0, 0, 0]
    pts = np.vstack([a, b])
    mesh = Mesh(points=pts, dim=3, cells=[CellBlock("hexahedron", [list(range(8)), list(range(8, 16))])])
    moved = pts.copy()
    moved[12:16, 0] += top_shift
    return mesh, moved


def test_a_mesh_whose_worst_cell_did_not_get_worse_is_not_refused():
    # the good cube sheared by 20: q = 1/sqrt(401) = 0.0499 (< 0.05, < half of 1) but still above the
    # input's worst cell (0.0333) and 0.01: the solver already ran on worse, so the scaled Jacobian does not
    # refuse it (its orthogonality does, 90 -> 3 deg: checked apart here)
    mesh, moved = _two_hexes(20.0)
    r = check_quality(mesh, moved, orthogonality=False)
    assert r.min_after == pytest.approx(1 / np.sqrt(901)) and r.min_after == r.min_before
    assert r.n_below == 2 and r.n_below_before == 1 and r.n_worse == 0 and r.ok
    # shift 40 (0.025): counted below 0.05 but above 0.01, not refused; shift 120 (0.0083): refused
    mesh, moved = _two_hexes(40.0)
    assert check_quality(mesh, moved, orthogonality=False).ok
    mesh, moved = _two_hexes(120.0)
    r = check_quality(mesh, moved, orthogonality=False)
    assert r.n_worse == 1 and not r.ok and r.worst[0]["cell"] == 1 and r.worst[0]["failed"]


def test_a_cell_degenerate_in_the_input_is_an_input_problem():
    from ffdcli.errors import InputError, QualityError
    from ffdcli.quality.gate import Remedies, enforce

    mesh = _hex_grid(3)
    pts = mesh.points.copy()
    corner = np.flatnonzero(np.all(np.isclose(pts, [1, 1, 1]), axis=1))[0]
    pts[corner] = pts[np.flatnonzero(np.all(np.isclose(pts, [2 / 3, 1, 1]), axis=1))[0]]   # a zero edge
    bad_mesh = mesh.with_points(pts)
    r = check_quality(bad_mesh, pts + 0.01)                  # the design (a translation) changes nothing
    assert r.n_input_bad == 1 and r.n_inverted == 1 and r.n_new_inverted == 0 and r.ok
    w = r.input_bad[0]
    assert w["cell"] == len(bad_mesh.cells[0]) - 1 and w["quality"] == 0.0
    with pytest.raises(InputError) as e:
        enforce(r, mesh_path="m.su2", design_path="d.yaml")
    msg = str(e.value)
    assert e.value.exit_code == 2 and "m.su2" in msg and f"cell {w['cell']} (hexahedron)" in msg
    assert "degenerate in the input mesh" in msg and "at (0.791667, 0.833333, 0.833333)" in msg
    assert "--force" not in msg and "ffd check" not in msg     # the library states the rule, not the CLI's flags
    with pytest.raises(InputError) as e:                        # the caller adds how to override it
        enforce(r, remedies=Remedies(deform_anyway=", or give --force to deform it anyway"))
    assert str(e.value).endswith("repair or regenerate the mesh, or give --force to deform it anyway")
    assert len(enforce(r, force=True)) == 1
    # a cell the design inverts is exit 3, with the rule in the message
    moved = mesh.points.copy()
    moved[corner] = [0.5, 0.5, 0.5]
    r = check_quality(mesh, moved)
    assert r.n_new_inverted >= 1 and r.n_input_bad == 0
    with pytest.raises(QualityError) as e:
        enforce(r, design_path="d.yaml")
    assert "inverted by the design" in str(e.value) and "a cell fails when the design inverts it" in str(e.value)
    assert "nothing was written" in str(e.value) and e.value.report["inverted_by_design"] == r.n_new_inverted
    assert "--force" not in str(e.value)


# ---------------------------------------------------------------------------------------------
# Orthogonality (SU2's dual-grid measure)


def _sheared_grid(n, s):
    """A hexahedral grid of n^3 unit cells whose z-layers slide along x by s per unit z."""
    mesh = _hex_grid(n)
    pts = mesh.points * n
    return mesh.with_points(pts + np.outer(pts[:, 2], [s, 0, 0]))


@pytest.mark.parametrize("s", [0.0, 0.3, 1.0, 2.5])
def test_orthogonality_of_a_sheared_grid_is_known_exactly(s):
    from ffdcli.quality.orthogonality import edge_orthogonality, node_orthogonality

    mesh = _sheared_grid(3, s)
    theta = np.degrees(np.arctan(s))
    ortho, area, topo = edge_orthogonality(mesh.points, mesh.cells)
    d = np.abs(mesh.points[topo.edges[:, 1]] - mesh.points[topo.edges[:, 0]])
    along_y = d[:, 1] > 0.5
    # the dual face of an x edge is turned by the shear, a z edge is turned against its dual face,
    # y edges keep 90 degrees (1e-12: arccos near 1 loses half the digits)
    np.testing.assert_allclose(ortho[along_y], 90.0, atol=1e-6)
    np.testing.assert_allclose(ortho[~along_y], 90.0 - theta, atol=1e-6)
    # an interior node: area-weighted mean over 2 x, 2 y, 2 z edges; x faces have area sqrt(1 + s^2)
    o = node_orthogonality(mesh.points, mesh.cells)
    inner = np.flatnonzero(np.all(np.isclose(mesh.points[:, 1:], [1, 1]), axis=1)
                           & np.isclose(mesh.points[:, 0], 1 + mesh.points[:, 2] * s))[0]
    ax = np.sqrt(1 + s * s)
    expected = (ax * (90 - theta) + 90 + (90 - theta)) / (ax + 2)
    assert o[inner] == pytest.approx(expected, abs=1e-6)
    # every node of a uniformly sheared grid sees the same proportions (corners and faces too)
    np.testing.assert_allclose(o, expected, atol=1e-6)


def test_orthogonality_is_invariant_under_similarity_and_mirrored_order():
    from ffdcli.quality.orthogonality import node_orthogonality

    rng = np.random.default_rng(3)
    mesh = _sheared_grid(2, 0.7)
    pts = mesh.points + rng.uniform(-0.15, 0.15, mesh.points.shape)
    o = node_orthogonality(pts, mesh.cells)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    q *= np.sign(np.linalg.det(q))
    moved = 3.7 * pts @ q.T + [10.0, -4.0, 2.0]
    np.testing.assert_allclose(node_orthogonality(moved, mesh.cells), o, atol=1e-9)
    # the same cells written in the mirrored node order (a mirrored mesh of mirrored cells)
    mirror = pts * [1, 1, -1]
    flipped = [CellBlock("hexahedron", mesh.cells[0].data[:, [4, 5, 6, 7, 0, 1, 2, 3]])]
    np.testing.assert_allclose(node_orthogonality(mirror, flipped), o, atol=1e-9)
    np.testing.assert_allclose(node_orthogonality(mirror, mesh.cells), o, atol=1e-9)


def test_orthogonality_numba_matches_numpy_on_mixed_cells():
    from ffdcli.quality.orthogonality import edge_topology, node_orthogonality

    rng = np.random.default_rng(5)
    # a hex grid, each hex also cut into 2 wedges and into 5 tets (a mixed mesh with shared edges)
    mesh = _hex_grid(3)
    pts = mesh.points + rng.uniform(-0.03, 0.03, mesh.points.shape)
    h = mesh.cells[0].data
    wedges = np.concatenate([h[:, [0, 1, 3, 4, 5, 7]], h[:, [1, 2, 3, 5, 6, 7]]])
    tets = np.concatenate([h[:, [0, 1, 3, 4]], h[:, [1, 2, 3, 6]], h[:, [1, 4, 5, 6]], h[:, [3, 6, 7, 4]],
                           h[:, [1, 3, 4, 6]]])
    pyr = h[:, [0, 1, 2, 3, 4]]
    for cells in ([CellBlock("wedge", wedges)], [CellBlock("tetra", tets)], [CellBlock("pyramid", pyr)],
                  [CellBlock("hexahedron", h)]):
        assert cell_quality(pts, cells).min() > 0
        a = node_orthogonality(pts, cells)
        b = node_orthogonality(pts, cells, use_numba=False)
        np.testing.assert_allclose(a, b, atol=1e-9)
        t1, t2 = edge_topology(cells, len(pts)), edge_topology(cells, len(pts), use_numba=False)
        assert {tuple(e) for e in t1.edges.tolist()} == {tuple(e) for e in t2.edges.tolist()}
        assert np.nanmin(a) > 0 and np.nanmax(a) <= 90.0
    # a node no cell uses has no orthogonality
    assert np.isnan(node_orthogonality(np.vstack([pts, [[9, 9, 9]]]), [CellBlock("tetra", tets)])[-1])


def test_orthogonality_in_2d():
    from ffdcli.quality.orthogonality import node_orthogonality

    g = np.arange(4.0)
    X, Y = np.meshgrid(g, g, indexing="ij")
    pts = np.column_stack([X.ravel(), Y.ravel(), np.zeros(16)])
    idx = np.arange(16).reshape(4, 4)
    i, j = (a.ravel() for a in np.meshgrid(np.arange(3), np.arange(3), indexing="ij"))
    quads = CellBlock("quad", np.column_stack([idx[i, j], idx[i + 1, j], idx[i + 1, j + 1], idx[i, j + 1]]))
    np.testing.assert_allclose(node_orthogonality(pts, [quads], 2), 90.0, atol=1e-9)
    s = 0.5
    sheared = pts + np.outer(pts[:, 1], [s, 0, 0])
    # 2D: x edges (dual face length sqrt(1+s^2)... turned) and y edges both at 90 - atan(s)
    np.testing.assert_allclose(node_orthogonality(sheared, [quads], 2), 90 - np.degrees(np.arctan(s)), atol=1e-9)


def test_the_gate_refuses_a_node_that_loses_orthogonality():
    # a sheared stack of thin cells keeps its scaled Jacobian above the threshold but its dual grid
    # turns: the node value (see the sheared-grid oracle) goes 90 -> 15.4 deg (below 20, lost 74.6)
    mesh = _hex_grid(2)
    moved = _sheared_grid(2, 8.0).points / 2
    r = check_quality(mesh, moved)
    assert r.n_new_inverted == 0 and r.n_worse == 0 and r.min_after == pytest.approx(1 / np.sqrt(65))
    assert r.n_ortho_failed == r.n_nodes == 27 and not r.ok
    assert r.ortho_before == pytest.approx(90) and r.ortho_after < 20 and r.ortho_loss > 70
    assert "27 nodes lost orthogonality" in r.failure_message() and "node " in r.describe_worst()
    # thresholds are parameters: a looser gate passes it
    assert check_quality(mesh, moved, ortho_min=10.0).ok


def test_surface_only_mesh_passes():
    mesh = Mesh(points=CUBE, dim=3, cells=[])
    r = check_quality(mesh, CUBE)
    assert r.ok and r.count == 0 and r.min_after is None


# ---------------------------------------------------------------------------------------------
# ffd check


def _run_check(monkeypatch, capsys, mesh, *args):
    """``ffd check`` in this process with ``read_mesh`` returning ``mesh`` (no reader needed)."""
    import ffdcli.io.formats
    from ffdcli.cli import main

    monkeypatch.setattr(ffdcli.io.formats, "read_mesh", lambda path, progress=None: mesh)
    with pytest.raises(SystemExit) as e:
        main(["check", "mesh.vtu", *args])
    out = capsys.readouterr()
    return e.value.code, out.out, out.err


def test_ffd_check_exit_codes(monkeypatch, capsys):
    import json

    mesh = _hex_grid(2)
    code, out, err = _run_check(monkeypatch, capsys, mesh, "--json")
    assert code == 0, err
    summary = json.loads(out)
    assert summary["cells"] == 8 and summary["inverted"] == 0 and summary["min_after"] == pytest.approx(1)
    bad = mesh.points.copy()
    centre = np.flatnonzero(np.all(np.isclose(bad, 0.5), axis=1))[0]
    bad[centre] += 0.3
    code, out, err = _run_check(monkeypatch, capsys, mesh.with_points(bad))
    assert code == 3 and "inverted" in err and "Traceback" not in err
    assert err.startswith("ffd: error: mesh.vtu:")
    code, out, err = _run_check(monkeypatch, capsys, mesh.with_points(bad), "--json")
    assert code == 3 and json.loads(out)["report"]["inverted"] >= 1
    # below a threshold: counted, and a failure only when --threshold is given
    sheared = CUBE + np.outer(CUBE[:, 2], [30.0, 0, 0])
    poor = Mesh(points=sheared, dim=3, cells=[CellBlock("hexahedron", [list(range(8))])])
    code, out, err = _run_check(monkeypatch, capsys, poor)
    assert code == 0 and "1 below 0.05" in out
    code, out, err = _run_check(monkeypatch, capsys, poor, "--threshold", "0.1")
    assert code == 3 and "1 below 0.1" in err
    code, out, err = _run_check(monkeypatch, capsys, poor, "--threshold", "7")
    assert code == 2 and "--threshold" in err


def test_ffd_check_reads_a_vtu(tmp_path):
    """End to end through the real reader (skipped until the VTK reader is on this branch)."""
    pytest.importorskip("ffdcli.io.formats.vtk")
    import meshio
    from conftest import run_ffd

    mesh = _hex_grid(2)
    path = tmp_path / "grid.vtu"
    meshio.write(path, meshio.Mesh(mesh.points, [("hexahedron", mesh.cells[0].data)]))
    proc = run_ffd("check", path, "--json")
    assert proc.returncode == 0, proc.stderr
    bad = mesh.points.copy()
    bad[np.flatnonzero(np.all(np.isclose(bad, 0.5), axis=1))[0]] += 0.3
    meshio.write(path, meshio.Mesh(bad, [("hexahedron", mesh.cells[0].data)]))
    proc = run_ffd("check", path)
    assert proc.returncode == 3 and "inverted" in proc.stderr


def test_scaled_jacobian_kernel_matches_its_numpy_reference():
    from ffdcli.quality.metrics import raw_quality

    rng = np.random.default_rng(11)
    shapes = {"tetra": REGULAR_TET, "hexahedron": CUBE, "wedge": PRISM, "pyramid": PYRAMID}
    for ctype, ref in shapes.items():
        k = len(ref)
        pts = np.concatenate([ref + rng.normal(scale=0.4 * np.ptp(ref), size=ref.shape) for _ in range(300)])
        data = np.arange(300 * k).reshape(300, k)
        data[7] = data[7][0]                                     # a fully collapsed cell: q = 0
        a = raw_quality(pts, data, ctype, None)
        b = raw_quality(pts, data, ctype, None, use_numba=False)
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-14)
        assert a[7] == 0.0 and (a < 0).any() and (a > 0).any()
    pts = np.concatenate([CUBE[:4] + rng.normal(scale=0.3, size=(4, 3)) * [1, 1, 0] for _ in range(50)])
    data = np.arange(200).reshape(50, 4)
    n = np.array([0.0, 0.0, 1.0])
    np.testing.assert_allclose(raw_quality(pts, data, "quad", n), raw_quality(pts, data, "quad", n, use_numba=False),
                               atol=1e-14)
