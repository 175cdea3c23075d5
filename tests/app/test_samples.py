"""The bundled samples in samples/: present, well formed and valid meshes.

A tiny vectorised SU2 reader lives here so that these checks do not depend on ffdcli.io.formats.su2.
"""

from __future__ import annotations

from functools import cache

import numpy as np
import pytest
from conftest import SAMPLES, shared_file

from ffdcli.testing import wings
from ffdcli.testing.cells import tet_volumes

NODES = {3: 2, 5: 3, 9: 4, 10: 4, 12: 8, 13: 6, 14: 5}


@cache
def read_su2(name: str) -> dict:
    """NDIME, points, elements by VTK id and markers (VTK id -> faces) of a single-zone ASCII SU2 file
    whose element and marker blocks each hold one element type."""
    lines = (SAMPLES / name).read_text().splitlines()
    out = {"markers": {}}
    i = 0

    def block(start, n):
        rows = np.array(" ".join(lines[start:start + n]).split(), dtype=np.float64)
        return rows.reshape(n, -1)

    while i < len(lines):
        key, _, val = lines[i].partition("=")
        key = key.strip()
        if key == "NDIME":
            out["ndime"] = int(val)
        elif key == "NELEM":
            n = int(val)
            rows = block(i + 1, n).astype(np.int64)
            assert np.all(rows[:, 0] == rows[0, 0]) and np.array_equal(rows[:, -1], np.arange(n))
            out["cells"] = (int(rows[0, 0]), rows[:, 1:1 + NODES[int(rows[0, 0])]])
            i += n
        elif key == "NPOIN":
            n = int(val.split()[0])
            rows = block(i + 1, n)
            assert np.array_equal(rows[:, -1], np.arange(n))
            out["points"] = rows[:, :out["ndime"]]
            i += n
        elif key == "MARKER_TAG":
            name_ = val.strip()
            n = int(lines[i + 1].partition("=")[2])
            rows = block(i + 2, n).astype(np.int64)
            assert np.all(rows[:, 0] == rows[0, 0])
            out["markers"][name_] = (int(rows[0, 0]), rows[:, 1:])
            i += n + 1
        i += 1
    return out


WINGS = {"rect_wing.su2": (wings.rect_wing_planform(), (15_000, 40_000)),
         "crm_wing.su2": (wings.crm_planform(semi_span=3.0, root_chord=1.0, kink_te_extension=0.37),
                          (20_000, 50_000))}


@pytest.mark.parametrize("name", list(WINGS))
def test_wing_samples(name):
    planform, (lo, hi) = WINGS[name]
    m = read_su2(name)
    pts = m["points"]
    assert m["ndime"] == 3 and lo <= len(pts) <= hi
    kind, tets = m["cells"]
    assert kind == 10
    assert set(m["markers"]) == {"wing", "symmetry", "farfield"}
    assert tet_volumes(pts, tets).min() > 0                                # VTK/SU2 orientation
    assert np.array_equal(np.unique(tets), np.arange(len(pts)))           # no unused point
    # the boundary faces of the tetrahedra (used once) are exactly the marker triangles
    faces = np.concatenate([tets[:, [0, 1, 2]], tets[:, [0, 1, 3]], tets[:, [0, 2, 3]], tets[:, [1, 2, 3]]])
    u, c = np.unique(np.sort(faces, axis=1), axis=0, return_counts=True)
    assert c.max() == 2
    marked = np.concatenate([f for k, f in m["markers"].values() if k == 5])
    assert len(marked) == sum(len(f) for _, f in m["markers"].values())  # all triangles
    np.testing.assert_array_equal(u[c == 1], np.unique(np.sort(marked, axis=1), axis=0))
    # marker normals point out of the fluid, e.g. the symmetry plane towards -span
    span = planform.axes[2]
    sym = pts[m["markers"]["symmetry"][1]]
    assert np.all(sym[..., span] == 0.0)
    assert np.all(np.cross(sym[:, 1] - sym[:, 0], sym[:, 2] - sym[:, 0])[:, span] < 0)
    # the wing is where the planform says: root at span 0, tip at the semi-span, LE at x = 0
    w = pts[np.unique(m["markers"]["wing"][1])]
    assert w[:, span].min() == 0.0 and w[:, span].max() == pytest.approx(planform.semi_span, abs=1e-9)
    assert w[:, planform.axes[0]].min() == pytest.approx(0.0, abs=1e-9)
    tip_te = planform.trailing_edge(1.0)[0]
    assert w[:, planform.axes[0]].max() == pytest.approx(max(tip_te[0], planform.chord(0.0)), abs=1e-6)


def test_rect_wing_surface_lies_on_naca0012():
    m = read_su2("rect_wing.su2")
    w = m["points"][np.unique(m["markers"]["wing"][1])]
    side = (w[:, 2] > 1e-9) & (w[:, 2] < 3 - 1e-9)                         # not on the tip cap
    x, y = w[side, 0], w[side, 1]
    yu, _ = wings.naca4_surfaces("0012", np.clip(x, 0, 1))
    # the OCC loft interpolates the 81 sections points with a cubic spline: 1e-5 chord is its error
    np.testing.assert_allclose(np.abs(y), yu, atol=1e-5)


def test_naca0012_2d_sample():
    m = read_su2("naca0012_2d.su2")
    assert m["ndime"] == 2 and 5_000 <= len(m["points"]) <= 10_000
    kind, quads = m["cells"]
    assert kind == 9 and set(m["markers"]) == {"airfoil", "farfield"}
    assert wings.quad_areas(m["points"], quads).min() > 0
    xy, q, foil, far = wings.airfoil_ogrid("0012", 161, 41, 15.0)
    np.testing.assert_allclose(m["points"], xy, rtol=1e-14, atol=1e-15)   # written with %.15g
    np.testing.assert_array_equal(quads, q)
    np.testing.assert_array_equal(m["markers"]["airfoil"][1], foil)
    np.testing.assert_array_equal(m["markers"]["farfield"][1], far)


def test_airfoil_files():
    from ffdcli.io.formats.airfoil import read_airfoil

    assert read_airfoil(SAMPLES / "naca0012.dat").coords.shape == (133, 2)
    assert (SAMPLES / "s1223.dat").read_bytes() == shared_file("airfoils/s1223.dat").read_bytes()


def test_readme_lists_every_sample():
    text = (SAMPLES / "README.md").read_text()
    for f in SAMPLES.iterdir():
        if f.suffix in (".su2", ".dat", ".py"):
            assert f.name in text
