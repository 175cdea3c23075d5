"""pyGeo/DAFoam Plot3D lattices import without ``box.points``: the file's size, in box.points order.

Every single-block lattice of ../shared/data/reference-ffd is imported around a wing built inside it
(a NACA0012 wing placed in the lattice's own parameter space, so that it is inside by construction),
and the real pairs (the MACH tutorial wing and its pyGeo lattices) on their own mesh.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import SHARED_DATA, assert_clean_failure, run_ffd, shared_file

from ffdcli.io.formats import write_mesh
from ffdcli.io.formats.plot3d import read_plot3d
from ffdcli.lattice.lattice import Lattice, evaluate
from ffdcli.lattice.spline import clamped_knots
from ffdcli.testing.wings import Planform, surface_mesh

REF = "reference-ffd"
SINGLE = ["CRM_Wing__FFD__wingFFD.xyz", "MACH_Tutorial_Wing__FFD__wingFFD.xyz",
          "Onera_M6_Wing__FFD__wingFFD.xyz", "mach_wing__ffd.xyz", "stw__wing-ffd-advanced-coarse.xyz"]


def _roles(blk):
    """File axes of (chord, span, thickness) by the lattice's extent along each: span the longest,
    thickness the shortest."""
    ext = []
    for a in range(3):
        first = np.take(blk, 0, axis=a)
        last = np.take(blk, -1, axis=a)
        ext.append(float(np.linalg.norm(last - first, axis=-1).mean()))
    span, thick = int(np.argmax(ext)), int(np.argmin(ext))
    return 3 - span - thick, span, thick


def wing_inside(blk, path):
    """A NACA0012 wing surface mesh (marker ``wing``) inside the B-spline volume of ``blk``."""
    mesh = surface_mesh(Planform(semi_span=1.0, root_chord=1.0, sections="xy"), n_chord=25, n_span=9)
    x, y, z = mesh.points.T                       # chord 0..1, thickness +-0.06, span 0..1
    c, s, t = _roles(blk)
    u = np.zeros((len(x), 3))
    u[:, c] = 0.05 + 0.9 * x
    u[:, s] = 0.03 + 0.94 * z
    u[:, t] = 0.5 + 3.0 * y
    deg = tuple(min(3, k - 1) for k in blk.shape[:3])
    lat = Lattice(control_points=blk, degree=deg,
                  knots=tuple(clamped_knots(k, d) for k, d in zip(blk.shape[:3], deg, strict=True)))
    X = evaluate(lat, u)
    # flat sections: every station at one span coordinate (the lattice's own stations may lean)
    span_axis = int(np.argmax(np.ptp(X, axis=0)))
    _, station = np.unique(z, return_inverse=True)
    mean = np.bincount(station, weights=X[:, span_axis]) / np.bincount(station)
    X[:, span_axis] = mean[station]
    mesh.points = X
    write_mesh(mesh, path)
    return (blk.shape[c], blk.shape[s], blk.shape[t])


@pytest.mark.parametrize("name", SINGLE)
def test_every_single_block_reference_lattice_imports_without_points(tmp_path, name):
    import json

    xyz = shared_file(f"{REF}/{name}")
    (blk,) = read_plot3d(xyz)
    mesh = tmp_path / "w.su2"
    want = wing_inside(blk, mesh)
    proc = run_ffd("box", mesh, "--from", xyz, "--json", "--lattice", tmp_path / "l.vtk")
    assert proc.returncode == 0, proc.stderr
    s = json.loads(proc.stdout)
    assert tuple(s["lattice"]) == want                    # (chord, span, thickness) = box.points order
    assert s["outside"] == 0 and s["residual"] < 1e-8
    # and through a design file without box.points
    d = tmp_path / "d.yaml"
    d.write_text(f"mesh: w.su2\nsurface: wing\nbox: {{file: {xyz}}}\nchanges:\n  - twist: {{tip: 2}}\n"
                 f"output: {{mesh: o.su2, lattice: o.vtk}}\n")
    proc = run_ffd("deform", d, "--json")
    assert proc.returncode == 0, proc.stderr
    assert json.loads(proc.stdout)["lattice"] == list(want)


def test_a_wrong_points_names_the_sizes_in_box_points_order(tmp_path):
    xyz = shared_file(f"{REF}/CRM_Wing__FFD__wingFFD.xyz")
    (blk,) = read_plot3d(xyz)
    mesh = tmp_path / "w.su2"
    want = wing_inside(blk, mesh)
    proc = run_ffd("box", mesh, "--from", xyz, "--points", "6,8,2", "--lattice", tmp_path / "l.vtk")
    assert_clean_failure(proc, 2, "box.points [6, 8, 2]", " x ".join(map(str, want)))
    proc = run_ffd("box", mesh, "--from", xyz, "--points", ",".join(map(str, want)),
                   "--lattice", tmp_path / "l.vtk")
    assert proc.returncode == 0, proc.stderr


@pytest.mark.parametrize("name", ["mach_wing__ffd.xyz", "MACH_Tutorial_Wing__FFD__wingFFD.xyz"])
def test_the_mach_wing_and_its_pygeo_lattice(tmp_path, name):
    import json

    mesh = shared_file("cgns/aero__meshing__volume__wing.cgns")
    xyz = shared_file(f"{REF}/{name}")
    proc = run_ffd("box", mesh, "--from", xyz, "--json", "--cache-dir", tmp_path, "--lattice",
                   tmp_path / "l.vtk")
    assert proc.returncode == 0, proc.stderr
    s = json.loads(proc.stdout)
    assert s["lattice"] == [6, 8, 2] and s["outside"] == 0


def test_the_multi_block_wing_and_tail_lattice_is_a_clear_error(tmp_path):
    xyz = shared_file(f"{REF}/DPW4_Aircraft__FFD__wingTailFFD.xyz")
    blocks = read_plot3d(xyz)
    assert len(blocks) == 2
    mesh = tmp_path / "w.su2"
    wing_inside(blocks[0], mesh)
    proc = run_ffd("box", mesh, "--from", xyz, "--lattice", tmp_path / "l.vtk")
    assert_clean_failure(proc, 2, "2 blocks")


if SHARED_DATA is None:  # pragma: no cover
    pytestmark = pytest.mark.skip("../shared/data is not present")
