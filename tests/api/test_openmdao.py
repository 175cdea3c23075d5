"""Issue 15: the OpenMDAO component (check_partials, matrix-free products) and the examples/ optimisations."""

from __future__ import annotations

import importlib.util
import sys

import numpy as np
import pytest
from conftest import REPO
from wingcase import write_design, write_surface_wing, write_volume_wing

om = pytest.importorskip("openmdao.api", reason="openmdao is not installed (pip install 'ffdcli[openmdao]')")

from ffdcli.api import DesignModel  # noqa: E402
from ffdcli.openmdao import FFDComponent, input_name  # noqa: E402

CHANGES = [{"twist": {"root": 1, "tip": 4}}, {"span": 1.05}, {"sweep": 3}, {"chord": {"tip": 0.8}},
           {"shape": {"upper": [0, 0.004, 0.006, 0.004, 0.002, 0], "lower": [0, -0.003, -0.004, 0, 0, 0]}}]
CONSTRAINTS = [{"thickness": {"chord": [0.3, 0.6], "span": [0.2, 0.8], "lower": 1.0}},
               {"volume": {"lower": 1.0}}, {"le_te": {}}]


def test_input_names():
    assert input_name("c0.twist.tip") == "c0_twist"
    assert input_name("c3.shape.upper[2]") == "c3_shape"
    assert input_name("c1.span") == "c1_span"
    assert input_name("c7.sweep.offsets[3]") == "c7_sweep"
    assert input_name("wing.c0.twist[1]") == "wing_c0_twist"


def test_component_inputs_outputs_and_check_partials(tmp_path):
    mesh = write_surface_wing(tmp_path, sections="xz", taper=0.6, le_sweep_deg=15)
    design = write_design(tmp_path, mesh, CHANGES, points=(6, 4, 2), extra={"constraints": CONSTRAINTS})
    probe = np.array([[0.3, 1.0, 0.02], [0.6, 2.0, -0.01], [50.0, 50.0, 50.0]])
    prob = om.Problem(reports=False)
    comp = prob.model.add_subsystem("ffd", FFDComponent(design=str(design), points={"probe": probe}),
                                    promotes=["*"])
    prob.setup(force_alloc_complex=False)
    assert comp.input_names == ["c0_twist", "c1_span", "c2_sweep", "c3_chord", "c4_shape"]
    assert comp.input_variables("c0_twist") == ["c0.twist.root", "c0.twist.tip"]
    lo, hi = comp.design_var_bounds("c1_span")
    assert 0 < lo[0] < 1e-5 and hi[0] == 1e30
    prob.run_model()
    model = DesignModel.from_file(design)
    model.set_constraints(CONSTRAINTS)
    np.testing.assert_allclose(prob["surface"], model.surface_points(), atol=1e-14)
    vol = model.constraint_values()[model.constraint_names.index("k1.volume")]
    np.testing.assert_allclose(prob["k1_volume"], [vol], rtol=1e-14)
    np.testing.assert_array_equal(prob["probe"][2], probe[2])         # outside the lattice: never moved
    prob["c1_span"] = 1.1
    prob.run_model()
    model.set_values({**dict(zip(model.names, model.values)), "c1.span": 1.1})
    np.testing.assert_allclose(prob["surface"], model.surface_points(), atol=1e-14)
    data = prob.check_partials(method="fd", form="central", step=1e-6, out_stream=None)
    assert len(data["ffd"]) == 5 * 5                 # (surface, probe, thickness, volume, le_te) x 5 inputs
    for (of, wrt), d in data["ffd"].items():
        ref = np.abs(d["J_fd"]).max()
        for key in ("J_fwd", "J_rev"):
            np.testing.assert_allclose(d[key], d["J_fd"], atol=1e-6 * max(ref, 1.0), err_msg=f"{of} wrt {wrt} {key}")
        np.testing.assert_allclose(d["J_fwd"], d["J_rev"], atol=1e-12 * max(ref, 1.0), err_msg=f"{of} {wrt}")


def test_mesh_output_jvp_is_the_transpose_of_the_vjp(tmp_path):
    mesh = write_volume_wing(tmp_path)
    design = write_design(tmp_path, mesh, CHANGES, points=(6, 4, 2))
    model = DesignModel.from_file(design)
    assert model.uses_volume()
    rng = np.random.default_rng(1)
    dv = rng.standard_normal(model.n_vars)
    g = rng.standard_normal((model.run.prep.mesh.n_points, 3))
    lhs = float(np.sum(g * model.mesh_jvp(dv)))
    rhs = float(model.mesh_vjp(g) @ dv)
    assert lhs == pytest.approx(rhs, rel=1e-10)
    # and against central differences of the mesh in one direction
    v0 = model.values.copy()
    h = 1e-6
    model.set_values(v0 + h * dv)
    Xp = model.mesh_points()
    model.set_values(v0 - h * dv)
    Xm = model.mesh_points()
    model.set_values(v0)
    fd = (Xp - Xm) / (2 * h)
    np.testing.assert_allclose(model.mesh_jvp(dv), fd, atol=1e-6 * np.abs(fd).max())


def _example(name):
    spec = importlib.util.spec_from_file_location(name, REPO / "examples" / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules[name] = mod
    spec.loader.exec_module(mod)
    return mod


def test_example_inverse_design(tmp_path):
    out = _example("inverse_design").run(tmp_path)
    assert out["iterations"] < 60 and out["success"]
    np.testing.assert_allclose(out["values"], out["target"], atol=1e-6)
    assert out["volume"] >= 1 - 1e-9 and out["thickness"].min() >= 1 - 1e-9


def test_example_min_area_fixed_volume(tmp_path):
    out = _example("min_area_fixed_volume").run(tmp_path)
    exp = out["expected"]
    assert out["success"]
    assert out["span"] == pytest.approx(exp["span"], abs=1e-6)
    np.testing.assert_allclose(out["chord"], exp["chord"], atol=1e-6)
    assert out["area"] == pytest.approx(exp["area"], abs=1e-6)
    assert out["volume"] == pytest.approx(1.0, abs=1e-8)           # active
