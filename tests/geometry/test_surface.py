"""Surface extraction, vertex normals and areas, and the default wing marker."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import shared_file

from ffdcli.errors import InputError
from ffdcli.geometry.surface import default_surface, extract_surface, vertex_areas, vertex_normals
from ffdcli.io.formats import read_mesh
from ffdcli.mesh import CellBlock, Mesh

# Unit cube corners and its six faces as outward-oriented quads (right-hand rule).
CUBE = np.array([[x, y, z] for z in (0, 1) for y in (0, 1) for x in (0, 1)], dtype=float)
CUBE_QUADS = np.array([[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]])


def cube_mesh(offset=100, triangles=False) -> Mesh:
    """The cube's points placed after ``offset`` unused points, so global != local ids."""
    pts = np.vstack([np.full((offset, 3), 9.0), CUBE])
    q = CUBE_QUADS + offset
    face = CellBlock("triangle", np.vstack([q[:, [0, 1, 2]], q[:, [0, 2, 3]]])) if triangles \
        else CellBlock("quad", q)
    return Mesh(points=pts, dim=3, markers={"wing": [face], "farfield": [CellBlock("quad", q[:1])]})


def reference_normals_areas(points, faces):
    """Plain per-face loop (the definition), to check the vectorised scatter against."""
    n = np.zeros((len(points), 3))
    a = np.zeros(len(points))
    for b in faces:
        for f in b.data:
            p = points[f]
            if b.type == "line":
                d = p[1] - p[0]
                v = np.array([d[1], -d[0], 0.0])
            elif b.type == "triangle":
                v = 0.5 * np.cross(p[1] - p[0], p[2] - p[0])
            else:
                v = 0.5 * np.cross(p[2] - p[0], p[3] - p[1])
            for i in f:
                n[i] += v
                a[i] += np.linalg.norm(v) / len(f)
    norm = np.linalg.norm(n, axis=1)
    return np.where(norm[:, None] > 0, n / np.where(norm > 0, norm, 1)[:, None], 0), a


@pytest.mark.parametrize("triangles", [False, True])
def test_cube_normals_and_areas(triangles):
    s = extract_surface(cube_mesh(triangles=triangles), "wing")
    np.testing.assert_array_equal(s.ids, np.arange(100, 108))
    np.testing.assert_array_equal(s.points, CUBE)
    # exact arithmetic on 0/1 coordinates: sums of halves and quarters, so the tolerance is 1e-15
    assert abs(s.areas.sum() - 6.0) < 1e-15
    np.testing.assert_allclose(s.face_vectors.sum(axis=0), 0, atol=1e-15)       # closed surface
    outward = (CUBE - 0.5) / np.linalg.norm(CUBE - 0.5, axis=1)[:, None]
    if not triangles:        # each corner touches three unit faces: normal exactly along the diagonal
        np.testing.assert_allclose(s.normals, outward, atol=1e-15)
    assert np.all(np.einsum("ij,ij->i", s.normals, outward) > 0.5)


def test_local_faces_map_back_to_global():
    m = cube_mesh()
    s = extract_surface(m, ["wing", "farfield", "wing"])      # duplicates ignored
    assert s.names == ("wing", "farfield")
    assert [s.ids[b.data].tolist() for b in s.faces] == [b.data.tolist() for b in m.markers["wing"]] + \
        [b.data.tolist() for b in m.markers["farfield"]]


def test_circle_2d_normals_radial_and_lengths():
    n = 64
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    pts = np.column_stack([np.cos(t), np.sin(t), np.zeros(n)])
    lines = CellBlock("line", np.column_stack([np.arange(n), (np.arange(n) + 1) % n]))
    nrm, area = vertex_normals(pts, [lines]), vertex_areas(pts, [lines])
    # counter-clockwise travel: the right-hand normal points outward; a regular polygon's vertex
    # normal is exactly radial up to rounding of cos/sin (1e-14)
    np.testing.assert_allclose(nrm, pts, atol=1e-14)
    np.testing.assert_allclose(area.sum(), 2 * n * np.sin(np.pi / n), rtol=1e-14)


def test_vectorised_matches_loop_on_random_mixed_faces():
    rng = np.random.default_rng(5)
    pts = rng.random((40, 3))
    faces = [CellBlock("triangle", rng.integers(0, 40, (30, 3))),
             CellBlock("quad", rng.integers(0, 40, (20, 4))), CellBlock("vertex", [[3]])]
    n_ref, a_ref = reference_normals_areas(pts, [f for f in faces if f.type != "vertex"])
    # same sums in a different order: agreement to a few ulps of values of order 1
    np.testing.assert_allclose(vertex_normals(pts, faces), n_ref, atol=1e-13)
    np.testing.assert_allclose(vertex_areas(pts, faces), a_ref, atol=1e-13)


def test_missing_marker_message(tmp_path):
    m = cube_mesh()
    m.path = tmp_path / "wing.su2"
    with pytest.raises(InputError) as err:
        extract_surface(m, ["wing", "Wing2"])
    text = str(err.value)
    assert str(m.path) in text and "'Wing2'" in text and "wing, farfield" in text


def _with_markers(*names):
    blk = [CellBlock("line", [[0, 1]])]
    return Mesh(points=np.zeros((2, 3)), dim=2, markers={n: blk for n in names})


@pytest.mark.parametrize("names,expect", [
    (["anything"], ["anything"]),
    (["WING", "FARFIELD", "SYMMETRY"], ["WING"]),
    (["airfoil", "Far_Field", "inlet", "OUTFLOW", "freestream", "FFD_box", "sym_plane"], ["airfoil"]),
    (["AIRFOIL", "FARFIELD"], ["AIRFOIL"]),
])
def test_default_surface(names, expect):
    assert default_surface(_with_markers(*names)) == expect


@pytest.mark.parametrize("names", [["airfoil_upper", "airfoil_lower", "farfield"],
                                   ["farfield", "symmetry"], []])
def test_default_surface_ambiguous(names):
    with pytest.raises(InputError) as err:
        default_surface(_with_markers(*names))
    text = str(err.value)
    for n in names:
        assert n in text
    if names:
        assert "--surface NAME" in text and "surface:" in text


def test_real_airfoil_closed_and_wing_area():
    m = read_mesh(shared_file("su2/deformation__rae2822__mesh_RAE2822_turb_ffd.su2"))
    s = extract_surface(m, default_surface(m))
    assert s.names == ("AIRFOIL",) and s.n_points == 192
    # a closed curve's vector lengths cancel; coordinates of order 1 -> rounding of order 1e-15
    np.testing.assert_allclose(s.face_vectors.sum(axis=0), 0, atol=1e-13)
    assert 2.0 < s.areas.sum() < 2.1                      # perimeter of a unit-chord airfoil
    n_ref, a_ref = reference_normals_areas(s.points, s.faces)
    np.testing.assert_allclose(s.normals, n_ref, atol=1e-13)
    m3 = read_mesh(shared_file("oneram6/mesh_ONERAM6_gmsh_coarse.su2"))
    w = extract_surface(m3, default_surface(m3))
    assert w.names == ("WING",)
    np.testing.assert_allclose(w.areas.sum(), np.linalg.norm(w.face_vectors, axis=1).sum(), rtol=1e-12)
