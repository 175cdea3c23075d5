"""CGNS NGON_n/NFACE_n sections read into the polyhedral cell model shared with OpenFOAM (issue 29,
defect 2): the volume moves, the gate runs, and what cannot be read is refused naming the section."""

from __future__ import annotations

import h5py
import numpy as np
import pytest
from conftest import run_ffd

from ffdcli.errors import InputError
from ffdcli.io.formats import read_mesh
from ffdcli.io.formats.openfoam_case import polymesh_of
from ffdcli.quality.polyhedral import poly_figures
from ffdcli.testing.cgns_poly import write_ngon_cgns
from ffdcli.testing.wings import extruded_wing_mesh, rect_wing_planform


@pytest.fixture(scope="module")
def wing():
    mesh = extruded_wing_mesh(rect_wing_planform(semi_span=2.0), n_around=25, n_radial=7, n_span=4)
    poly, patches = polymesh_of(mesh, wall=("wing",))
    return mesh, poly, patches


@pytest.mark.parametrize("signed,counted", [(True, False), (False, False), (True, True)],
                         ids=["signed", "unsigned", "cgns3-counted"])
def test_ngon_nface_read_as_the_same_polyhedra(tmp_path, wing, signed, counted):
    mesh, poly, patches = wing
    f = write_ngon_cgns(tmp_path / "m.cgns", mesh.points, poly, patches, signed=signed, counted=counted)
    got = read_mesh(f)
    assert got.polyhedra is not None and got.n_cells == poly.n_cells and not got.cells
    a, b = poly_figures(mesh.points, poly), poly_figures(got.points, got.polyhedra)
    assert np.allclose(a.volumes, b.volumes, rtol=1e-12) and (b.volumes > 0).all()
    assert np.allclose(a.non_orth, b.non_orth, atol=1e-9) and np.allclose(a.skew, b.skew, atol=1e-9)
    for name in mesh.markers:
        assert np.array_equal(got.marker_point_ids(name), mesh.marker_point_ids(name))


def test_deform_moves_the_volume_and_gates_it(tmp_path, wing):
    mesh, poly, patches = wing
    write_ngon_cgns(tmp_path / "m.cgns", mesh.points, poly, patches)
    design = tmp_path / "d.yaml"
    design.write_text("mesh: m.cgns\nsurface: wing\nbox: {points: [5, 4, 2]}\nchanges:\n  - twist: {tip: 3}\n")
    r = run_ffd("deform", design, "--json", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert "Warning" not in r.stderr and '"polyhedral"' in r.stdout
    got = read_mesh(tmp_path / "out" / "d.cgns")
    on_markers = np.concatenate([mesh.marker_point_ids(n) for n in mesh.markers])
    inner = np.setdiff1d(np.arange(mesh.n_points), on_markers)
    assert np.abs(got.points[inner] - mesh.points[inner]).max() > 1e-4       # the volume moved
    r = run_ffd("check", tmp_path / "out" / "d.cgns")
    assert r.returncode == 0 and "no volume cells" not in r.stdout and "checkMesh's figures" in r.stdout


def _edit(path, fn):
    with h5py.File(path, "r+") as h5:
        fn(h5["Base/Zone"])


@pytest.mark.parametrize("case", ["no nface", "unknown type", "missing face", "same sign"])
def test_unreadable_cells_are_refused_naming_the_section(tmp_path, wing, case):
    mesh, poly, patches = wing
    f = write_ngon_cgns(tmp_path / "m.cgns", mesh.points, poly, patches)
    if case == "no nface":
        _edit(f, lambda z: z.__delitem__("Cells"))
        words, key = "without an NFACE_n", "Faces"
    elif case == "unknown type":
        def retype(z):
            z["Cells"][" data"][0] = 99
        _edit(f, retype)
        words, key = "element type code 99", "Cells"
    elif case == "missing face":
        def big(z):
            z["Cells/ElementConnectivity"][" data"][0] = 10 ** 7
        _edit(f, big)
        words, key = "no NGON_n section holds", "Cells"
    else:
        def flip(z):
            d = z["Cells/ElementConnectivity"][" data"]
            vals = d[()]
            vals[vals < 0] *= -1                 # every neighbour claims the face as its own
            vals[0] = -vals[0]
            d[...] = vals
        _edit(f, flip)
        words, key = "same orientation", "Cells"
    with pytest.raises(InputError) as e:
        read_mesh(f)
    assert words in str(e.value) and key in str(e.value)
    r = run_ffd("check", f)
    assert r.returncode == 2 and words in r.stderr and "Warning" not in r.stderr and "Traceback" not in r.stderr
