"""Issue 15: variable bounds, set_values refusals and point sets of the API (exact vs central differences)."""

from __future__ import annotations

import numpy as np
import pytest
from wingcase import write_design, write_surface_wing

from ffdcli.api import DesignModel
from ffdcli.errors import InputError
from ffdcli.parameterization.bounds import make_bounds

KINDS = [{"twist": {"root": 1, "tip": 6}}, {"span": 1.1}, {"sweep": 5}, {"dihedral": -3},
         {"chord": {"tip": 0.7}}, {"shape": {"upper": [0, 0.01, 0.02, 0.01, 0.005, 0],
                                             "lower": [0, -0.01, 0, 0, 0, 0]}}]


@pytest.fixture(scope="module")
def model(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("ps")
    mesh = write_surface_wing(tmp, le_sweep_deg=20, taper=0.5)
    return DesignModel.from_file(write_design(tmp, mesh, KINDS))


def test_natural_bounds(model):
    lo, hi = model.lower, model.upper
    k = model.names.index("c1.span")
    assert lo[k] == 0 and hi[k] == np.inf
    k = model.names.index("c4.chord.tip")
    assert lo[k] == 0
    k = model.names.index("c2.sweep")
    # the sweep angle after the span change: 20 deg on the surface scaled by 1.1 in span
    lam = np.degrees(np.arctan(np.tan(np.radians(20)) / 1.1))
    assert lo[k] == pytest.approx(-85 - lam, abs=0.05) and hi[k] == pytest.approx(85 - lam, abs=0.05)
    k = model.names.index("c0.twist.tip")
    assert lo[k] == -np.inf and hi[k] == np.inf
    assert model.units[model.names.index("c0.twist.tip")] == "deg"
    assert model.units[model.names.index("c1.span")] == "factor"
    assert model.units[model.names.index("c5.shape.upper[1]")] == "length"


@pytest.mark.parametrize("name, bad", [("c1.span", 0.0), ("c1.span", -1.0), ("c4.chord.tip", 0.0),
                                       ("c0.twist.tip", np.nan), ("c5.shape.lower[2]", np.inf),
                                       ("c2.sweep", 200.0)])
def test_set_values_refuses(model, name, bad):
    v0 = model.values.copy()
    v = v0.copy()
    v[model.names.index(name)] = bad
    with pytest.raises(InputError, match=name.replace("[", r"\[").replace("]", r"\]")):
        model.set_values(v)
    np.testing.assert_array_equal(model.values, v0)
    with pytest.raises(InputError, match="expected"):
        model.set_values(v0[:-1])
    with pytest.raises(InputError, match="dv must have shape"):
        model.surface_jvp(np.ones(model.n_vars + 1))
    with pytest.raises(InputError, match="g must have shape"):
        model.surface_vjp(np.ones((3, 3)))


def test_user_bounds_by_name_and_prefix():
    names = ["c0.twist[0]", "c0.twist[1]", "c1.span", "c2.shape.upper[0]", "c2.shape.lower[0]"]
    nat = np.array([[-np.inf, np.inf]] * 2 + [[0, np.inf]] + [[-np.inf, np.inf]] * 2)
    b = make_bounds(names, nat, {"c0.twist": [-10, 10], "c0.twist[1]": {"lower": -2}, "c1.span": [0.5, None],
                                 "c2.shape": [-0.1, 0.1], "c2.shape.lower": [None, 0]})
    np.testing.assert_array_equal(b.lower, [-10, -2, 0.5, -0.1, -np.inf])
    np.testing.assert_array_equal(b.upper, [10, np.inf, np.inf, 0.1, 0])
    with pytest.raises(InputError, match="c0.twist\\[0\\]"):
        b.check([11, 0, 1, 0, 0])
    b.check([10, 0, 1, 0, 0])            # user bounds are closed
    with pytest.raises(InputError) as e:
        make_bounds(names, nat, {"c9.twist": [0, 1]})
    assert e.value.key == "bounds.c9.twist"
    with pytest.raises(InputError, match="above"):
        make_bounds(names, nat, {"c1.span": [2, 1]})
    with pytest.raises(InputError, match="natural"):
        make_bounds(names, nat, {"c1.span": [-2, -1]})
    with pytest.raises(InputError, match="outside its bounds"):
        make_bounds(names, nat, {"c1.span": [2, 3]}, values=np.array([0, 0, 1.0, 0, 0]))


def _fd(model, f, k, h=1e-5):
    v0 = model.values.copy()
    vp, vm = v0.copy(), v0.copy()
    vp[k] += h
    vm[k] -= h
    model.set_values(vp)
    fp = f()
    model.set_values(vm)
    fm = f()
    model.set_values(v0)
    return (fp - fm) / (2 * h)


@pytest.mark.parametrize("span_sign, sections", [(1, "xy"), (-1, "xz"), (1, "zx")])
def test_point_set_moves_like_the_surface_and_its_derivatives(tmp_path, span_sign, sections):
    mesh = write_surface_wing(tmp_path, le_sweep_deg=15, taper=0.6, span_sign=span_sign, sections=sections)
    m = DesignModel.from_file(write_design(tmp_path, mesh, KINDS))
    X0 = m.run.prep.surface.points
    rng = np.random.default_rng(3)
    idx = rng.choice(len(X0), 40, replace=False)
    far = X0.max(axis=0) + 10.0                 # outside the lattice: reported, never moved
    rep = m.add_points("probe", np.vstack([X0[idx], far]))
    assert rep["points"] == 41 and rep["outside"] == 1 and rep["outside_ids"] == [40]
    assert m.point_sets == ["probe"]
    np.testing.assert_allclose(m.points("probe")[:40], m.surface_points()[idx], atol=1e-9)
    np.testing.assert_array_equal(m.points("probe")[40], far)
    g = rng.standard_normal((41, 3))
    grad = m.points_vjp("probe", g)
    dv = rng.standard_normal(m.n_vars)
    assert grad @ dv == pytest.approx(np.sum(g * m.points_jvp("probe", dv)), rel=1e-12)
    for k in range(m.n_vars):
        fd = _fd(m, lambda: float(np.sum(g * m.points("probe"))), k)
        assert grad[k] == pytest.approx(fd, rel=1e-6, abs=1e-6 * np.abs(grad).max()), m.names[k]
    with pytest.raises(InputError, match="no point set"):
        m.points("nope")
    with pytest.raises(InputError, match="shape"):
        m.add_points("bad", np.ones((3, 2)))
    with pytest.raises(InputError, match="NaN"):
        m.add_points("bad", np.full((3, 3), np.nan))
