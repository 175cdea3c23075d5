"""Issue 15: geometric constraints: exact oracles of affine changes, Jacobians vs central differences."""

from __future__ import annotations

import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from wingcase import write_design, write_surface_wing

from ffdcli.api import DesignModel
from ffdcli.errors import InputError

GRID = {"chord": [0.1, 0.3, 0.5, 0.7, 0.9], "span": [0.0, 0.3, 0.6, 1.0]}
ALL = [{"thickness": dict(GRID)}, {"thickness_to_chord": {"chord": [0.3, 0.6], "span": [0.0, 0.5, 1.0]}},
       {"volume": {"lower": 1.0}}, {"le_te": {}}, {"fold_free": {"lower": 0.2}}]

# Wings with variety: span along z / y / x, a left wing, taper, sweep, dihedral, a blunt trailing edge.
WINGS = {
    "rect_z": dict(sections="xy"),
    "tapered_swept_y": dict(sections="xz", taper=0.5, le_sweep_deg=25, dihedral_deg=4),
    "left_y": dict(sections="xz", span_sign=-1, taper=0.7, le_sweep_deg=10),
    "span_x_blunt": dict(sections="yz", closed_te=False, taper=0.8),
    "kinked_crm_like": dict(sections="xz", taper=0.3, le_sweep_deg=30, dihedral_deg=5, kink_eta=0.4,
                            kink_te_extension=0.4, root_airfoil="2414", tip_airfoil="2410"),
}


def model_for(tmp_path, wing, changes, points=(6, 8, 2)):
    mesh = write_surface_wing(tmp_path, **WINGS[wing])
    m = DesignModel.from_file(write_design(tmp_path, mesh, changes, points=points))
    m.set_constraints(ALL)
    return m


def by_kind(m, kind):
    names = m.constraint_names
    v = m.constraint_values()
    return np.array([x for n, x in zip(names, v) if n.split(".")[1].split("[")[0] == kind])


@pytest.mark.parametrize("wing", list(WINGS))
def test_baseline_is_one_and_names(tmp_path, wing):
    m = model_for(tmp_path, wing, [{"twist": {"tip": 0}}, {"shape": {"upper": [0] * 6, "lower": [0] * 6}}])
    v = m.constraint_values()
    names = m.constraint_names
    assert len(v) == len(names)
    assert names[0] == "k0.thickness[0]" and names[19] == "k0.thickness[19]" and names[20] == "k1.thickness_to_chord[0]"
    assert "k2.volume" in names and "k4.fold_free" in names and "k3.le_te[0]" in names
    assert len([n for n in names if n.startswith("k3.")]) == 16        # LE and TE of 8 sections
    for kind in ("thickness", "thickness_to_chord", "volume", "fold_free"):
        np.testing.assert_allclose(by_kind(m, kind), 1.0, atol=1e-12)
    np.testing.assert_array_equal(by_kind(m, "le_te"), 0.0)
    lo, hi = m.constraint_lower, m.constraint_upper
    assert lo[names.index("k2.volume")] == 1.0 and hi[names.index("k2.volume")] == np.inf
    assert lo[names.index("k3.le_te[0]")] == 0.0 and hi[names.index("k3.le_te[0]")] == 0.0


@pytest.mark.parametrize("wing", list(WINGS))
def test_affine_oracles(tmp_path, wing):
    m = model_for(tmp_path, wing, [{"span": 1.0}, {"chord": [1.0] * 8}, {"sweep": 0}, {"dihedral": 0}])
    span, chord, sweep, dihedral = (m.names.index(n) for n in ("c0.span", "c1.chord[0]", "c2.sweep", "c3.dihedral"))
    v = m.values.copy()
    v[span] = 1.1
    m.set_values(v)
    np.testing.assert_allclose(by_kind(m, "volume"), 1.1, rtol=1e-12)
    np.testing.assert_allclose(by_kind(m, "thickness"), 1.0, rtol=1e-12)
    np.testing.assert_allclose(by_kind(m, "thickness_to_chord"), 1.0, rtol=1e-12)
    np.testing.assert_allclose(by_kind(m, "fold_free"), 1.1, rtol=1e-12)
    c = 0.8
    v = m.values.copy()
    v[span] = 1.0
    v[[m.names.index(f"c1.chord[{j}]") for j in range(8)]] = c
    m.set_values(v)
    np.testing.assert_allclose(by_kind(m, "thickness"), c, rtol=1e-12)
    np.testing.assert_allclose(by_kind(m, "thickness_to_chord"), 1.0, rtol=1e-12)
    np.testing.assert_allclose(by_kind(m, "volume"), c * c, rtol=1e-12)
    np.testing.assert_allclose(by_kind(m, "fold_free"), c * c, rtol=1e-12)
    v = m.values.copy()
    v[[m.names.index(f"c1.chord[{j}]") for j in range(8)]] = 1.0
    v[sweep], v[dihedral] = 12.0, -7.0
    m.set_values(v)
    for kind in ("thickness", "volume", "fold_free"):
        np.testing.assert_allclose(by_kind(m, kind), 1.0, rtol=1e-12, err_msg=kind)


def test_volume_is_the_closed_volume(tmp_path):
    """The half wing closed by its symmetry plane: the same volume as the wing with its root capped."""
    from ffdcli.constraints.base import surface_triangles
    from ffdcli.constraints.volume import _enclosed, enclosed_volume
    from ffdcli.testing.wings import Planform, surface_mesh

    m = model_for(tmp_path, "tapered_swept_y", [{"span": 1.0}])
    closed = surface_mesh(Planform(**WINGS["tapered_swept_y"]), n_chord=31, n_span=13, root="closed")
    faces = list(closed.markers["wing"]) + list(closed.markers["root"])
    tri = surface_triangles(faces)
    vol, _ = _enclosed(closed.points, tri, np.array([5.0, -3.0, 2.0]), 3, False)    # any point: closed
    (c,) = [c for c in m.constraints if c.kind == "volume"]
    assert c.base == pytest.approx(vol, rel=1e-12)
    # the compiled kernel against the NumPy reference, value and gradient
    X = closed.points + np.random.default_rng(0).normal(scale=1e-3, size=closed.points.shape)
    ref_v, ref_g = _enclosed(X, tri, np.array([0.1, 0.2, 0.3]), 3, True)
    v, g = enclosed_volume(X, tri, np.array([0.1, 0.2, 0.3]), grad=True)
    assert v == pytest.approx(ref_v, rel=1e-13)
    np.testing.assert_allclose(g, ref_g, rtol=1e-12, atol=1e-15)


def central(m, k, h):
    v0 = m.values.copy()
    vp, vm = v0.copy(), v0.copy()
    vp[k] += h
    vm[k] -= h
    m.set_values(vp)
    fp = m.constraint_values().copy()
    m.set_values(vm)
    fm = m.constraint_values().copy()
    m.set_values(v0)
    return (fp - fm) / (2 * h)


DESIGN = [{"twist": {"root": 1, "tip": 6}}, {"span": 1.1}, {"sweep": 5}, {"dihedral": -3},
          {"chord": {"tip": 0.7}}, {"shape": {"upper": [0.002, 0.01, 0.02, 0.01, 0.005, -0.001],
                                              "lower": [-0.001, -0.01, 0, 0, 0, 0.001]}},
          {"twist": [0, 1, 2, 3, 4, 5, 6, 7]}, {"dihedral": {"offsets": [0, .01, .02, .03, .04, .05, .06, .07]}}]


@pytest.mark.parametrize("wing", ["tapered_swept_y", "left_y", "rect_z", "kinked_crm_like"])
def test_jacobian_matches_central_differences(tmp_path, wing):
    m = model_for(tmp_path, wing, DESIGN)
    J = m.constraint_jacobian()
    assert J.shape == (len(m.constraint_names), m.n_vars)
    scale = np.abs(J).max(axis=1)
    for k, name in enumerate(m.names):
        h = 1e-4 * max(1.0, abs(m.values[k])) if m.units[k] != "length" else 1e-5
        fd = central(m, k, h)
        np.testing.assert_allclose(J[:, k], fd, rtol=1e-6, atol=1e-6 * max(scale.max(), 1e-3), err_msg=name)
    # le_te is linear in the shape values: exactly A @ v
    names = m.constraint_names
    rows = [i for i, n in enumerate(names) if ".le_te[" in n]
    np.testing.assert_allclose(m.constraint_values()[rows], J[rows] @ m.values, atol=1e-15)


def test_le_te_value(tmp_path):
    m = model_for(tmp_path, "rect_z", [{"shape": {"upper": [0.01, 0, 0, 0, 0, 0.02], "lower": [-0.01, 0, 0, 0, 0, 0]}}])
    v = by_kind(m, "le_te")
    np.testing.assert_allclose(v.reshape(8, 2), [[0.0, 0.02]] * 8, atol=1e-15)


# set_constraints speaks as the command line does for a design file (issue 29: the schema's words)
@pytest.mark.parametrize("spec, words", [
    ({"thickness": {"chord": [0.5], "span": [1.2]}}, "span.0.: must be at least 0 and at most 1"),
    ({"thickness": {"chord": [-0.1], "span": [0.5]}}, "chord.0.: must be greater than 0"),
    ({"thickness": {"chord": [1.0], "span": [0.5]}}, "chord.0.: must be greater than 0 and less than 1"),
    ({"thickness": {"span": [0.5]}}, "missing key 'chord'"),
    ({"thickness": {"chord": [0.5]}}, "needs span"),
    ({"thickness": {"chord": [0.999999999], "span": [0.5]}}, "misses the surface"),
    ({"wobble": {}}, "unknown key 'wobble'"),
    ({"volume": {"lower": 2, "upper": 1}}, "above"),
])
def test_bad_constraints(tmp_path, spec, words):
    m = model_for(tmp_path, "rect_z", [{"span": 1.0}])
    with pytest.raises(InputError, match=words):
        m.set_constraints([spec])


def test_fold_free_sees_a_fold(tmp_path):
    """Twist of one inner section far enough folds the box: fold_free goes below 0."""
    m = model_for(tmp_path, "rect_z", [{"shape": {"upper": [0, 0, 0, 0, 0, 0], "lower": [0] * 6,
                                                  "sections": [3]}}])
    v = m.values.copy()
    v[m.names.index("c0.shape.lower[2]")] = 0.5          # lower point pushed far above the upper one
    m.set_values(v)
    assert by_kind(m, "fold_free")[0] < 0


def test_2d_airfoil_constraints(tmp_path):
    from ffdcli.io.formats import write_mesh
    from ffdcli.testing.wings import airfoil_ogrid_mesh

    mesh = airfoil_ogrid_mesh("0012", n_around=65, n_radial=9)
    path = tmp_path / "foil.su2"
    write_mesh(mesh, path)

    design = tmp_path / "foil.yaml"
    design.write_text(yaml.safe_dump({"mesh": "foil.su2", "box": {"points": [6, 2]},
                                      "changes": [{"chord": 1.0}, {"twist": 0.0},
                                                  {"shape": {"upper": [.001, .01, .02, .01, .003, .002],
                                                             "lower": [-.002, -.01, .001, .002, .001, -.001]}}]}))
    m = DesignModel.from_file(design)
    names = sorted(mesh.markers)
    assert names
    m.set_constraints([{"thickness": {"chord": [0.2, 0.5]}}, {"thickness_to_chord": {"chord": [0.3]}},
                       {"volume": {}}, {"le_te": {}}, {"fold_free": {}}])
    v = m.values.copy()
    v[0] = 0.9
    m.set_values(v)
    vals = m.constraint_values()
    assert vals[m.constraint_names.index("k2.volume")] > 0
    J = m.constraint_jacobian()
    rows = [i for i, n in enumerate(m.constraint_names) if "fold_free" not in n]   # a 2-point thickness
    for k in range(m.n_vars):                                                      # direction: samples tie
        fd = central(m, k, 1e-5)
        np.testing.assert_allclose(J[rows, k], fd[rows], rtol=1e-6, atol=1e-7, err_msg=m.names[k])
    with pytest.raises(InputError, match="no meaning on a 2D"):
        m.set_constraints([{"thickness": {"chord": [0.5], "span": [0.5]}}])


@settings(max_examples=4, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(taper=st.floats(0.3, 1.0), sweep=st.floats(-10, 35), dihedral=st.floats(-5, 8),
       sections=st.sampled_from(["xy", "xz", "yz", "zx"]), left=st.booleans(),
       s=st.floats(0.7, 1.4), c=st.floats(0.6, 1.3))
def test_affine_oracles_on_random_wings(tmp_path_factory, taper, sweep, dihedral, sections, left, s, c):
    """Generated wings of any axes and side: span s and uniform chord c give volume s c^2, thickness c,
    t/c 1 and fold-free s c^2, to rounding."""
    tmp = tmp_path_factory.mktemp("rand")
    mesh = write_surface_wing(tmp, taper=taper, le_sweep_deg=sweep, dihedral_deg=dihedral, sections=sections,
                              span_sign=-1 if left else 1)
    m = DesignModel.from_file(write_design(tmp, mesh, [{"span": s}, {"chord": [c] * 8}]))
    m.set_constraints(ALL)
    np.testing.assert_allclose(by_kind(m, "volume"), s * c * c, rtol=1e-11)
    np.testing.assert_allclose(by_kind(m, "thickness"), c, rtol=1e-11)
    np.testing.assert_allclose(by_kind(m, "thickness_to_chord"), 1.0, rtol=1e-11)
    np.testing.assert_allclose(by_kind(m, "fold_free"), s * c * c, rtol=1e-11)


@pytest.mark.data
def test_onera_m6_oracles(tmp_path):
    """The real ONERA M6 mesh (shared data): span 1.1, uniform chord 0.8 and sweep 5 give volume
    1.1 x 0.64, thickness 0.8, t/c 1 and fold-free 0.704, exactly; root station 0 is found."""
    from conftest import shared_file

    mesh = shared_file("oneram6/mesh_ONERAM6_gmsh_coarse.su2")
    design = tmp_path / "m6.yaml"
    design.write_text(yaml.safe_dump({
        "mesh": str(mesh), "surface": "WING",
        "changes": [{"span": 1.1}, {"chord": [0.8] * 8}, {"sweep": 5}],
        "output": {"mesh": "out.su2", "lattice": "out_lattice.vtk"}}))
    m = DesignModel.from_file(design, cache_dir=tmp_path)
    m.set_constraints([{"thickness": {"chord": [0.1, 0.5, 0.9], "span": [0.0, 0.5, 0.95]}},
                       {"thickness_to_chord": {"chord": [0.3], "span": [0.0, 0.5, 0.95]}},
                       {"volume": {}}, {"fold_free": {}}])
    np.testing.assert_allclose(by_kind(m, "volume"), 1.1 * 0.64, rtol=1e-10)
    np.testing.assert_allclose(by_kind(m, "thickness"), 0.8, rtol=1e-10)
    np.testing.assert_allclose(by_kind(m, "thickness_to_chord"), 1.0, rtol=1e-10)
    np.testing.assert_allclose(by_kind(m, "fold_free"), 1.1 * 0.64, rtol=1e-10)
