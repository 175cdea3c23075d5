"""``add_material`` (ADODG Case 1, "the shape may only add material"): its Jacobian against central
differences, and oracles of where it is negative, on the NACA0012 and on 3D wings."""

from __future__ import annotations

import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from wingcase import write_design, write_surface_wing

from ffdcli.api import DesignModel
from ffdcli.io.formats import write_mesh
from ffdcli.testing.wings import airfoil_ogrid_mesh

N = 8          # chordwise control points of the airfoil's box


@pytest.fixture(scope="module")
def foil(tmp_path_factory):
    """The NACA0012 O-grid and a design of its upper and lower shape rows."""
    tmp = tmp_path_factory.mktemp("foil")
    write_mesh(airfoil_ogrid_mesh("0012", n_around=97, n_radial=9), tmp / "foil.su2")
    design = tmp / "foil.yaml"
    design.write_text(yaml.safe_dump({"mesh": "foil.su2", "box": {"points": [N, 2]},
                                      "changes": [{"shape": {"upper": [0.0] * N, "lower": [0.0] * N}}],
                                      "constraints": [{"add_material": None}]}))
    return DesignModel.from_file(design)


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


def shape_values(upper, lower):
    return np.concatenate([upper, lower])


def test_baseline_names_bounds_and_sides(foil):
    m = foil
    m.set_values(np.zeros(m.n_vars))
    c = m.constraints[0]
    assert c.kind == "add_material" and m.constraint_names[0] == "k0.add_material[0]"
    np.testing.assert_array_equal(m.constraint_values(), 0.0)
    assert np.all(m.constraint_lower == 0.0) and np.all(np.isinf(m.constraint_upper))
    y = c.X0[:, 1]
    # a symmetric section: the upper side is y > 0, the lower y < 0 (sides from the outward normals),
    # and the leading- and trailing-edge points (normal along the chord) have no item
    np.testing.assert_array_equal(c.side, np.sign(y))
    assert len(c.ids) == len(m.surface_points()) - 2


@settings(max_examples=6, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(u=st.lists(st.floats(0.0, 0.02), min_size=N, max_size=N))
def test_a_design_that_only_thickens_is_nonnegative(foil, u):
    """Upper row up and lower row down by the same amounts (the box is symmetric about the chord): every
    node moves outward, so every value is >= 0, and each is the node's outward move along y."""
    m = foil
    u = np.array(u)
    m.set_values(shape_values(u, -u))
    vals = m.constraint_values()
    c = m.constraints[0]
    moved = m.surface_points()[c.ids] - c.X0
    assert np.all(vals >= 0.0)
    np.testing.assert_allclose(vals, np.abs(moved[:, 1]), atol=1e-15)
    m.set_values(np.zeros(m.n_vars))


@pytest.mark.parametrize("point", range(N))
def test_a_design_that_thins_somewhere_is_negative_exactly_there(foil, point):
    """One upper control point moved down: the values are negative exactly at the upper nodes (y > 0) that
    moved, by their move; the lower nodes it drags down gain material (values > 0)."""
    m = foil
    v = np.zeros(m.n_vars)
    v[point] = -0.01                                           # c0.shape.upper[point]
    m.set_values(v)
    vals = m.constraint_values()
    c = m.constraints[0]
    dy = (m.surface_points()[c.ids] - c.X0)[:, 1]
    upper, moved = c.X0[:, 1] > 0, np.abs(dy) > 0
    np.testing.assert_array_equal(vals < 0, upper & moved)
    np.testing.assert_array_equal(vals > 0, ~upper & moved)
    np.testing.assert_allclose(vals[upper], dy[upper], atol=1e-15)
    assert (vals < 0).any()
    m.set_values(np.zeros(m.n_vars))


def test_jacobian_is_exact_and_constant_on_the_airfoil(tmp_path):
    """With twist and chord before the shape (the chain is nonlinear in the values), the Jacobian matches
    central differences; with shape alone it is constant and the values are J @ v exactly."""
    write_mesh(airfoil_ogrid_mesh("0012", n_around=65, n_radial=9), tmp_path / "foil.su2")
    design = tmp_path / "foil.yaml"
    shape = {"upper": [.001, .01, .02, .01, .003, .002], "lower": [-.002, -.01, .001, .002, .001, -.001]}
    design.write_text(yaml.safe_dump({"mesh": "foil.su2", "box": {"points": [6, 2]},
                                      "changes": [{"chord": 1.05}, {"twist": 2.0}, {"shape": shape}],
                                      "constraints": [{"add_material": {}}]}))
    m = DesignModel.from_file(design)
    J = m.constraint_jacobian()
    assert J.shape == (len(m.constraint_names), m.n_vars) and np.abs(J).max() > 0
    for k in range(m.n_vars):
        h = 1e-4 if m.units[k] != "length" else 1e-5
        np.testing.assert_allclose(J[:, k], central(m, k, h), rtol=1e-6, atol=1e-9, err_msg=m.names[k])
    m.set_values(np.r_[1.0, 0.0, m.values[2:]])                # chord 1, twist 0: the shape alone is linear
    J0 = m.constraint_jacobian()
    m.set_values(np.r_[1.0, 0.0, -3 * m.values[2:]])
    np.testing.assert_allclose(m.constraint_jacobian(), J0, atol=1e-15)
    np.testing.assert_allclose(m.constraint_values(), J0[:, 2:] @ m.values[2:], atol=1e-15)


@pytest.mark.parametrize("wing", [dict(sections="xy"), dict(sections="xz", taper=0.5, le_sweep_deg=25, dihedral_deg=4),
                                  dict(sections="xz", span_sign=-1, taper=0.7, le_sweep_deg=10)])
def test_jacobian_matches_central_differences_on_wings(tmp_path, wing):
    mesh = write_surface_wing(tmp_path, **wing)
    changes = [{"twist": {"root": 1, "tip": 4}}, {"chord": {"tip": 0.8}},
               {"shape": {"upper": [0.002, 0.01, 0.02, 0.01, 0.005, -0.001], "lower": [-0.001, -0.01, 0, 0, 0, 0.001]}}]
    m = DesignModel.from_file(write_design(tmp_path, mesh, changes, points=(6, 5, 2),
                                           extra={"constraints": [{"add_material": {"lower": -0.001}}]}))
    J = m.constraint_jacobian()
    assert J.shape == (len(m.constraint_names), m.n_vars) and len(m.constraint_names) > 100
    for k in range(m.n_vars):
        h = 1e-4 if m.units[k] != "length" else 1e-5
        np.testing.assert_allclose(J[:, k], central(m, k, h), rtol=1e-6, atol=1e-9, err_msg=m.names[k])
    assert np.all(m.constraint_lower == -0.001)
