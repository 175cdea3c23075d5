"""Derivatives (issue 7): dX/dv and dJ/dv against central finite differences of `ffd deform`."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import REPO, assert_clean_failure, run_ffd
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from wingcase import write_design, write_surface_wing, write_volume_wing

from ffdcli.api import DesignModel

# Central differences of a smooth map with step h have error O(h^2 f''') ~ 1e-10 relative for the
# steps below, and rounding ~ eps / h ~ 1e-11: a 1e-6 relative tolerance has a wide margin.
REL = 1e-6


def fd_check(model, g, functional, names=None):
    grad = functional["grad"](g)
    v0 = model.values.copy()
    for k, name in enumerate(model.names):
        if names and name not in names:
            continue
        h = 1e-4 * max(1.0, abs(v0[k]))
        vp, vm = v0.copy(), v0.copy()
        vp[k] += h
        vm[k] -= h
        model.set_values(vp)
        Jp = functional["value"](g)
        model.set_values(vm)
        Jm = functional["value"](g)
        model.set_values(v0)
        fd = (Jp - Jm) / (2 * h)
        assert grad[k] == pytest.approx(fd, rel=REL, abs=REL * np.abs(grad).max()), name


def surface_functional(model):
    return {"grad": model.surface_vjp, "value": lambda g: float(np.sum(g * model.surface_points()))}


def mesh_functional(model):
    return {"grad": model.mesh_vjp, "value": lambda g: float(np.sum(g * model.mesh_points()))}


ALL_KINDS = [{"twist": {"root": 2, "tip": 45}}, {"span": 1.1}, {"sweep": 5}, {"dihedral": -3},
             {"chord": {"tip": 0.7}}, {"shape": {"upper": [0, 0.01, 0.02, 0.01, 0.005, 0],
                                                 "lower": [0, -0.01, 0, 0, 0, 0]}},
             {"twist": [0, 1, 2, 3, 4, 5, 6, 7]}, {"sweep": {"offsets": [0, .01, .02, .03, .04, .05, .06, .07]}}]


def test_surface_derivatives_every_kind_pipeline(tmp_path):
    mesh = write_surface_wing(tmp_path, le_sweep_deg=20, taper=0.5)
    model = DesignModel.from_file(write_design(tmp_path, mesh, ALL_KINDS))
    assert "c0.twist.tip" in model.names and "c1.span" in model.names and "c6.twist[7]" in model.names
    g = np.random.default_rng(0).standard_normal((len(model.surface_ids), 3))
    fd_check(model, g, surface_functional(model))


def test_twist_at_zero(tmp_path):
    mesh = write_surface_wing(tmp_path)
    model = DesignModel.from_file(write_design(tmp_path, mesh, [{"twist": {"tip": 0}}, {"dihedral": 0}]))
    g = np.random.default_rng(1).standard_normal((len(model.surface_ids), 3))
    fd_check(model, g, surface_functional(model))


@settings(max_examples=6, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(tw=st.floats(-30, 30), sp=st.floats(0.8, 1.3), sw=st.floats(-15, 15), ch=st.floats(0.5, 1.5),
       order=st.permutations([0, 1, 2, 3]))
def test_random_designs(tmp_path, tw, sp, sw, ch, order):
    mesh = tmp_path / "wing.su2"
    if not mesh.exists():
        write_surface_wing(tmp_path, le_sweep_deg=10, taper=0.6)
    items = [{"twist": {"tip": tw}}, {"span": sp}, {"sweep": sw}, {"chord": {"tip": ch}}]
    model = DesignModel.from_file(write_design(tmp_path, mesh, [items[i] for i in order]))
    g = np.random.default_rng(2).standard_normal((len(model.surface_ids), 3))
    fd_check(model, g, surface_functional(model))


@pytest.mark.slow
def test_volume_path_matches_finite_differences(tmp_path):
    """dJ/dv of a functional of every node, through the IDW volume motion with rotations."""
    mesh = write_volume_wing(tmp_path, le_sweep_deg=15)
    # tolerance 0: the exact IDW sum, so that the finite differences see a smooth map (the tree's
    # decisions can switch between the +h and -h evaluations and add 1e-4 relative noise)
    model = DesignModel.from_file(write_design(tmp_path, mesh, [{"twist": {"tip": 10}}, {"span": 1.05},
                                                                 {"shape": {"upper": [0, .01, .01, .01, 0, 0]}}],
                                               volume={"method": "idw", "tolerance": 0}))
    assert model.uses_volume()
    g = np.random.default_rng(3).standard_normal((model.run.prep.mesh.n_points, 3))
    fd_check(model, g, mesh_functional(model), names={"c0.twist.tip", "c1.span", "c2.shape.upper[2]"})


def test_2d_derivatives_through_volume(tmp_path):
    model = DesignModel.from_file(REPO / "configs" / "naca0012_s1223.yaml",
                                  ["changes.0.shape.upper=[0, 0.01, 0.02, 0.01, 0.0, 0]", "volume.tolerance=0"])
    g = np.random.default_rng(4).standard_normal((model.run.prep.mesh.n_points, 3))
    g[:, 2] = 0
    fd_check(model, g, mesh_functional(model), names={"c0.shape.upper[1]", "c0.shape.upper[3]"})


def write_sens_csv(path, ids, pts, g):
    lines = ['"PointID","x","y","z","Sensitivity_x","Sensitivity_y","Sensitivity_z"']
    lines += [",".join([str(int(i))] + [repr(float(v)) for v in (*p, *s)]) for i, p, s in zip(ids, pts, g)]
    path.write_text("\n".join(lines) + "\n")


def test_cli_grad_csv_and_unordered(tmp_path):
    mesh = write_surface_wing(tmp_path)
    design = write_design(tmp_path, mesh, [{"twist": {"tip": 5}}, {"span": 1.1}])
    model = DesignModel.from_file(design)
    X = model.surface_points()
    g = np.random.default_rng(5).standard_normal(X.shape)
    expect = model.surface_vjp(g)
    write_sens_csv(tmp_path / "surface_sens.csv", model.surface_ids, X, g)
    proc = run_ffd("grad", str(design), "--sens", str(tmp_path / "surface_sens.csv"), "-o",
                   str(tmp_path / "grad.json"), "--json")
    assert proc.returncode == 0, proc.stderr
    got = json.loads((tmp_path / "grad.json").read_text())
    assert list(got) == model.names
    np.testing.assert_allclose([got[k] for k in model.names], expect, rtol=1e-12)
    # unordered rows, shuffled, space separated: matched by nearest coordinates
    o = np.random.default_rng(6).permutation(len(X))
    rows = np.c_[X[o], g[o]]
    np.savetxt(tmp_path / "unordered.dat", rows, fmt="%.17g")
    proc = run_ffd("grad", str(design), "--sens", str(tmp_path / "unordered.dat"), "--json")
    assert proc.returncode == 0, proc.stderr
    s = json.loads(proc.stdout)
    np.testing.assert_allclose([s["gradient"][k] for k in model.names], expect, rtol=1e-12)
    assert s["matched_by"] == "coordinates" and s["worst_match_distance"] == 0.0


def test_cli_grad_missing_points_is_an_error(tmp_path):
    mesh = write_surface_wing(tmp_path)
    design = write_design(tmp_path, mesh, [{"span": 1.1}])
    rows = np.array([[100.0, 100.0, 100.0, 1.0, 0.0, 0.0]])
    np.savetxt(tmp_path / "far.dat", rows)
    proc = run_ffd("grad", str(design), "--sens", str(tmp_path / "far.dat"))
    assert_clean_failure(proc, 2, "far.dat", "rows stand farther than", "--tolerance")


def test_jacobian_file(tmp_path):
    mesh = write_surface_wing(tmp_path)
    design = write_design(tmp_path, mesh, [{"twist": {"tip": 5}}, {"span": 1.1}])
    proc = run_ffd("jacobian", str(design), "-o", str(tmp_path / "jac.npz"), "--dense")
    assert proc.returncode == 0, proc.stderr
    import scipy.sparse as sp

    z = np.load(tmp_path / "jac.npz")
    B = sp.csr_matrix((z["B_data"], z["B_indices"], z["B_indptr"]), shape=tuple(z["B_shape"]))
    D = z["D"]
    J = (B @ D.reshape(B.shape[1], -1)).reshape(B.shape[0] * 3, -1)
    np.testing.assert_allclose(J, z["J"], rtol=0, atol=1e-14)
    model = DesignModel.from_file(design)
    dv = np.array([0.3, -0.02])
    np.testing.assert_allclose((J @ dv).reshape(-1, 3), model.surface_jvp(dv), atol=1e-14)


def bundled_design(tmp_path, mesh, sections, changes, volume=None):
    import yaml

    data = {"mesh": str(REPO / "samples" / mesh), "surface": "wing",
            "box": {"points": [6, 8, 2], "sections": sections}, "changes": changes}
    if volume:
        data["volume"] = volume
    p = tmp_path / "bundled.yaml"
    p.write_text(yaml.safe_dump(data))
    return p


@pytest.mark.slow
def test_bundled_crm_every_kind_surface(tmp_path):
    model = DesignModel.from_file(bundled_design(tmp_path, "crm_wing.su2", "xz", ALL_KINDS), cache_dir=tmp_path)
    g = np.random.default_rng(7).standard_normal((len(model.surface_ids), 3))
    fd_check(model, g, surface_functional(model))


@pytest.mark.slow
def test_bundled_rect_wing_through_the_volume(tmp_path):
    model = DesignModel.from_file(
        bundled_design(tmp_path, "rect_wing.su2", "xy", [{"twist": {"tip": 15}}, {"dihedral": 5}],
                       volume={"method": "idw", "tolerance": 0}), cache_dir=tmp_path)
    g = np.random.default_rng(8).standard_normal((model.run.prep.mesh.n_points, 3))
    fd_check(model, g, mesh_functional(model))


# Exact derivatives at the DEFAULT volume settings (the tree approximation included): the warp is a
# fixed linear map of the surface motion (its near/far decisions are made once, on the undeformed
# mesh), so central differences of mesh_points() match mesh_vjp to 1e-6 relative. Three design
# points on two wings: a generated swept wing (tip on the side boundary) and the bundled rectangular
# wing whose tip is inside the domain.
DESIGN_POINTS = [
    [{"twist": {"tip": 6}}, {"sweep": 4}, {"chord": {"tip": 0.8}}],
    [{"twist": {"root": -2, "tip": -9}}, {"span": 1.12}, {"dihedral": 4}],
    [{"shape": {"upper": [0, .012, .015, .01, 0, 0]}}, {"sweep": -7}, {"chord": {"root": 1.1, "tip": 1.3}}],
]


@pytest.mark.slow
@pytest.mark.parametrize("point", range(3))
def test_volume_derivatives_at_default_tolerance_generated_wing(tmp_path, point):
    mesh = write_volume_wing(tmp_path, le_sweep_deg=15, taper=0.6)
    model = DesignModel.from_file(write_design(tmp_path, mesh, DESIGN_POINTS[point]))
    assert model.uses_volume() and "tolerance" not in (model.run.design.volume or {})
    g = np.random.default_rng(10 + point).standard_normal((model.run.prep.mesh.n_points, 3))
    fd_check(model, g, mesh_functional(model))


@pytest.mark.slow
@pytest.mark.parametrize("point", range(3))
def test_volume_derivatives_at_default_tolerance_tip_inside(tmp_path, point):
    model = DesignModel.from_file(bundled_design(tmp_path, "rect_wing.su2", "xy", DESIGN_POINTS[point]),
                                  cache_dir=tmp_path)
    assert model.uses_volume()
    g = np.random.default_rng(20 + point).standard_normal((model.run.prep.mesh.n_points, 3))
    names = [n for n in model.names if "shape" not in n or n.endswith("[2]")]
    fd_check(model, g, mesh_functional(model), names=set(names))


def test_gradient_from_file_is_the_cli_grad_and_needs_every_surface_node(tmp_path):
    """The library call behind ffd grad: the same values, and the same refusal of a partial file."""
    from ffdcli.api import gradient_from_file
    from ffdcli.errors import InputError

    mesh = write_surface_wing(tmp_path)
    design = write_design(tmp_path, mesh, [{"twist": {"tip": 5}}, {"sweep": 3.0}])
    model = DesignModel.from_file(design)
    X = model.surface_points()
    g = np.random.default_rng(7).standard_normal(X.shape)
    write_sens_csv(tmp_path / "all.csv", model.surface_ids, X, g)
    grad = gradient_from_file(model, tmp_path / "all.csv")
    np.testing.assert_allclose(list(grad.values.values()), model.surface_vjp(g), rtol=1e-12)
    assert list(grad.values) == model.names and grad.surface_nodes == len(X) and not grad.through_volume
    write_sens_csv(tmp_path / "part.csv", model.surface_ids[1:], X[1:], g[1:])
    with pytest.raises(InputError, match="has no row for 1 of the"):
        gradient_from_file(model, tmp_path / "part.csv")
