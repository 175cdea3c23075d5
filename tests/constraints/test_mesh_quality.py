"""The ``mesh_quality`` constraint (a smooth minimum of the volume cells' quality after the design over
before) with its exact derivative through the volume motion, read from the chain's quality stage."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import REPO, run_ffd
from wingcase import write_design, write_surface_wing, write_volume_wing

from ffdcli.api import DesignModel
from ffdcli.app.pipeline import deform
from ffdcli.constraints import KS_GAP, MESH_QUALITY_LOWER, MeshQuality, build_constraints, ks_min
from ffdcli.constraints.mesh_quality import corner_values, corner_vjp
from ffdcli.mesh import CellBlock, Mesh
from ffdcli.quality.metrics import cell_orientation, cell_quality, corner_table, raw_quality

RECT = REPO / "samples" / "rect_wing.su2"
AIRFOIL = REPO / "samples" / "naca0012_2d.su2"
MQ = [{"mesh_quality": {"lower": 0.3}}]
#: The plain ratio (no cap on the reference): every cell that gets worse counts, so the design map's
#: branch of the reference (cells near the wall) is active and its derivative is checked too.
MQ_PLAIN = [{"mesh_quality": {"lower": 0.3, "good": 1.0}}]

# one reference cell of every type (VTK order, positive), and 2D cells in the z = 0 plane
CELLS = {
    "tetra": ([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], 3),
    "hexahedron": ([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]], 3),
    "wedge": ([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [0, 1, 1]], 3),
    "pyramid": ([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0.5, 0.5, 1]], 3),
    "triangle": ([[0, 0, 0], [1, 0, 0], [0, 1, 0]], 2),
    "quad": ([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], 2),
}


def _jittered(ctype, n=40, scale=0.15, seed=0):
    """``n`` copies of a reference cell, each its own nodes, moved at random (still valid)."""
    ref, dim = CELLS[ctype]
    ref = np.asarray(ref, float)
    rng = np.random.default_rng(seed)
    k = len(ref)
    pts = np.concatenate([ref + i * 3.0 * np.array([1, 0, 0]) for i in range(n)])
    jit = rng.uniform(-scale, scale, pts.shape)
    if dim == 2:
        jit[:, 2] = 0.0
    data = np.arange(n * k).reshape(n, k)
    return pts + jit, data, dim


def _mesh_constraint(mesh, gap=None, good=1.0):
    """The constraint on ``mesh`` (``good: 1`` unless said: the plain ratio to the input's quality)."""
    spec = {"good": good} if gap is None else {"gap": gap, "good": good}
    if good is None:
        del spec["good"]
    return build_constraints([{"mesh_quality": spec}], None, None, [], mesh=mesh)[0]


@pytest.mark.parametrize("ctype", list(CELLS))
def test_corner_kernels_match_their_numpy_references_and_the_gate(ctype):
    pts, data, dim = _jittered(ctype)
    plane = np.array([0.0, 0.0, 1.0]) if dim == 2 else np.zeros(3)
    a = corner_values(pts, data, ctype, plane)
    b = corner_values(pts, data, ctype, plane, use_numba=False)
    np.testing.assert_allclose(a, b, rtol=1e-13, atol=1e-15)
    # the gate's scaled Jacobian is the smallest corner
    np.testing.assert_allclose(a.min(axis=1), raw_quality(pts, data, ctype, plane if dim == 2 else None), rtol=1e-13)
    coef = np.random.default_rng(1).standard_normal(a.shape)
    Ga, Gb = np.zeros_like(pts), np.zeros_like(pts)
    corner_vjp(pts, data, ctype, plane, coef, Ga)
    corner_vjp(pts, data, ctype, plane, coef, Gb, use_numba=False)
    np.testing.assert_allclose(Ga, Gb, rtol=1e-12, atol=1e-13)
    # the reverse product against central differences of sum(coef * values) along a random motion
    d = np.random.default_rng(2).standard_normal(pts.shape)
    if dim == 2:
        d[:, 2] = 0.0
    h = 1e-6
    fd = (np.sum(coef * corner_values(pts + h * d, data, ctype, plane))
          - np.sum(coef * corner_values(pts - h * d, data, ctype, plane))) / (2 * h)
    assert np.sum(Ga * d) == pytest.approx(fd, rel=1e-7)
    assert corner_table(ctype)[0].shape[1] == dim + 1


@pytest.mark.parametrize("ctype", list(CELLS))
def test_value_is_a_smooth_lower_bound_of_the_worst_ratio(ctype):
    pts, data, dim = _jittered(ctype)
    mesh = Mesh(points=pts, cells=[CellBlock(ctype, data)], dim=dim)
    c = _mesh_constraint(mesh)
    assert isinstance(c, MeshQuality) and c.names == ["k0.mesh_quality"]
    assert c.lower == MESH_QUALITY_LOWER and c.upper == np.inf
    v0 = c.measure(pts)[0]
    assert 1.0 - KS_GAP <= v0 <= 1.0                    # the baseline: every ratio >= 1, the worst = 1
    moved = pts + np.random.default_rng(3).uniform(-0.1, 0.1, pts.shape) * ([1, 1, 1] if dim == 3 else [1, 1, 0])
    q0 = cell_quality(pts, mesh.cells, dim)
    q1 = cell_quality(moved, mesh.cells, dim, orientation=cell_orientation(pts, mesh.cells, dim))
    worst = float(np.min(q1 / q0))
    v = c.measure(moved)[0]
    assert worst - KS_GAP <= v <= worst + 1e-12
    # a sharper KS: closer
    assert abs(_mesh_constraint(mesh, gap=0.005).measure(moved)[0] - worst) <= 0.005 + 1e-12
    # the gradient of the whole value against central differences
    val, G, _ = c.measure(moved, grad=True)
    d = np.random.default_rng(4).standard_normal(pts.shape) * ([1, 1, 1] if dim == 3 else [1, 1, 0])
    h = 1e-7
    fd = (c.measure(moved + h * d)[0] - c.measure(moved - h * d)[0]) / (2 * h)
    assert np.sum(G * d) == pytest.approx(fd, rel=1e-6)
    _, Gr, _ = c.measure(moved, grad=True, use_numba=False)
    np.testing.assert_allclose(G, Gr, rtol=1e-11, atol=1e-12 * np.abs(G).max())


def test_ks_min():
    r = np.array([0.5, 0.7, 2.0, 0.5])
    v, w = ks_min(r, 50.0)
    assert v == pytest.approx(0.5 - np.log(2 + np.exp(-10) + np.exp(-75)) / 50.0)
    assert w.sum() == pytest.approx(1.0) and w[0] == w[3] and w[2] < 1e-30
    assert ks_min(np.array([-3.0, 1.0]), 10.0)[0] <= -3.0            # negative ratios (inverted cells) too


def _fd_constraint(model, names=None, rel=1e-6, step=1e-4):
    """The mesh_quality item's derivative against central differences of its value (steps of ``step``
    per unit of the variable: the truncation error is O(step^2), below ``rel`` for these designs)."""
    k = model.constraint_names.index("k0.mesh_quality")
    J = model.constraint_jacobian()[k]
    v0 = model.values.copy()
    for i, name in enumerate(model.names):
        if names and name not in names:
            continue
        h = step * max(1.0, abs(v0[i]))
        vp, vm = v0.copy(), v0.copy()
        vp[i] += h
        vm[i] -= h
        model.set_values(vp)
        fp = model.constraint_values()[k]
        model.set_values(vm)
        fm = model.constraint_values()[k]
        model.set_values(v0)
        fd = (fp - fm) / (2 * h)
        assert J[i] == pytest.approx(fd, rel=rel, abs=rel * max(np.abs(J).max(), 1e-3)), name
    return J


@pytest.mark.parametrize("changes", [
    [{"twist": {"root": 1, "tip": 12}}, {"dihedral": 4}, {"sweep": 6}],
    [{"chord": {"tip": 0.7}}, {"span": 1.1},
     {"shape": {"upper": [0, 0.01, 0.02, 0.01, 0.005, 0], "lower": [0, -0.01, 0, 0, 0, 0]}}],
])
def test_derivative_through_the_volume_motion_hex_wing(tmp_path, changes):
    mesh = write_volume_wing(tmp_path, taper=0.6, le_sweep_deg=15)
    model = DesignModel.from_file(write_design(tmp_path, mesh, changes, volume={"method": "idw"},
                                               extra={"constraints": MQ_PLAIN}))
    assert model.uses_volume()
    J = _fd_constraint(model)
    assert np.abs(J).max() > 0
    assert model.constraint_values()[0] < 1.0 - KS_GAP         # the design made some cell worse
    c = model.constraints[0]
    X_map, zone = model.design_map_points()
    assert sum(a.sum() for _, a, _ in c.references(X_map, zone)) > 0     # the map's branch is in the derivative


def test_derivative_through_the_volume_motion_tets_and_quads(tmp_path):
    """The bundled rectangular wing (105k tetrahedra) and the 2D NACA 0012 O-grid (quads)."""
    for mesh, surface, changes in ((RECT, "wing", [{"twist": {"tip": 20}}, {"dihedral": 5}]),
                                   (AIRFOIL, "airfoil", [{"twist": {"angle": 4}},
                                                         {"shape": {"upper": [0, 0.01, 0.02, 0.0],
                                                                    "lower": [0, -0.01, 0, 0]}}])):
        design = tmp_path / f"{mesh.stem}.yaml"
        pts = [6, 8, 2] if surface == "wing" else [4, 3]
        design.write_text(json.dumps({"mesh": str(mesh), "surface": surface, "box": {"points": pts},
                                      "changes": changes, "constraints": MQ}))
        model = DesignModel.from_file(design, cache_dir=tmp_path)
        # the O-grid's wall cells are ~1e-4 chords thick: a 1e-4 shape step (mesh units) is not small
        # for them (central differences then differ by 1e-5, shrinking as step^2: 1e-7 at 1e-5)
        _fd_constraint(model, step=1e-4 if surface == "wing" else 1e-5)


@pytest.mark.parametrize("case", ["hex_wing", "airfoil_2d"])
def test_the_constraint_is_the_quality_stage_of_the_chain(tmp_path, case):
    """One home for the rule: each item's value and Jacobian are the chain's quality stage's, bit for bit
    the composition of the model's public products (the measure on the moved mesh against the design
    map, ``mesh_vjp`` of its mesh gradient plus ``design_map_vjp`` of its map gradient); several items
    at once give the rows of each alone."""
    if case == "hex_wing":
        mesh = write_volume_wing(tmp_path, taper=0.6, le_sweep_deg=15)
        design = write_design(tmp_path, mesh, [{"chord": {"tip": 0.7}}, {"twist": {"root": 1, "tip": 8}}],
                              volume={"method": "idw"}, extra={"constraints": MQ_PLAIN + MQ})
    else:
        design = tmp_path / "airfoil.yaml"
        design.write_text(json.dumps({"mesh": str(AIRFOIL), "surface": "airfoil", "box": {"points": [4, 3]},
                                      "changes": [{"twist": {"angle": 6}},
                                                  {"shape": {"upper": [0, 0.01, 0.02, 0.0],
                                                             "lower": [0, -0.01, 0, 0]}}],
                                      "constraints": MQ_PLAIN + MQ}))
    model = DesignModel.from_file(design, cache_dir=tmp_path)
    values, J = model.constraint_values(), model.constraint_jacobian()
    X = model.mesh_points()
    X_map, zone = model.design_map_points()
    mapped = 0
    for k, item in enumerate(model.constraints):
        value, G, G_map = item.measure(X, grad=True, X_map=X_map, zone=zone)
        expected = model.mesh_vjp(G)
        if np.any(G_map):
            expected = expected + model.design_map_vjp(G_map)
            mapped += 1
        assert values[k] == value
        assert np.array_equal(J[k], expected), np.abs(J[k] - expected).max()
    assert mapped, "the design map's part of the derivative is exercised"
    both, jac = model.chain.quality_of(model.constraints, model.values, jacobian=True)
    np.testing.assert_array_equal(both, values)
    np.testing.assert_allclose(jac, J, rtol=1e-14, atol=1e-14 * np.abs(J).max())


@pytest.mark.parametrize("change, path", [
    ({"twist": {"tip": 0}}, {15.0: "ok", 50.0: "warned", 60.0: "refused"}),
    ({"dihedral": 0}, {20.0: "ok", 34.0: "warned", 38.0: "refused"}),
])
def test_the_constraint_sees_a_refusal_coming(tmp_path, change, path):
    """A growing tip twist (dihedral) on the bundled rectangular wing, volume defaults, recovery off:
    the constraint falls below its bound (0.3) at a value the gate still accepts, and is below 0 (a
    cell inverted) where the gate refuses. (Measured on this mesh with the volume's default fade,
    ``rotation_reach`` 0.5: the gate refuses from 54 deg of tip twist, 35 deg of dihedral;
    mesh_quality crosses 0.3 near 47.5 and 33.8 deg. With 0.3: refused from 48 and 36 deg, crossing
    near 44 and 34 deg.)"""
    design = tmp_path / "rect.yaml"
    design.write_text(json.dumps({"mesh": str(RECT), "surface": "wing", "box": {"points": [6, 8, 2]},
                                  "changes": [change], "constraints": MQ}))
    model = DesignModel.from_file(design, cache_dir=tmp_path)
    for value, expect in path.items():
        model.set_values([value])
        gate = deform(model.run, P=model.lattice(), recover=False).quality
        mq = float(model.constraint_values()[0])
        if expect == "ok":
            assert gate.ok and mq > 0.3, (value, mq)
        elif expect == "warned":                     # warned before the gate fails ...
            assert gate.ok and mq < 0.3, (value, mq)
        else:                                        # ... which it does here, with inverted cells
            assert not gate.ok and gate.n_new_inverted > 0 and mq < 0.0, (value, mq)


def test_a_step_up_the_gradient_raises_the_worst_cell(tmp_path):
    """At a design that squeezes cells, a small step along the gradient (raising mesh_quality) raises
    the worst cell's ratio q_after / q_before and its quality; a step the other way lowers them."""
    mesh = write_volume_wing(tmp_path, taper=0.6, le_sweep_deg=15)
    model = DesignModel.from_file(write_design(tmp_path, mesh, [{"twist": {"root": 0, "tip": 25}}, {"dihedral": 8},
                                                                {"chord": {"tip": 0.6}}],
                                               volume={"method": "idw"}, extra={"constraints": MQ}))
    c = model.constraints[0]
    run, mesh0 = model.run, model.run.prep.mesh
    orient = cell_orientation(mesh0.points, mesh0.cells, mesh0.dim)
    q0 = cell_quality(mesh0.points, mesh0.cells, mesh0.dim, orientation=orient)

    def worst():
        X = model.mesh_points()
        q = cell_quality(X, mesh0.cells, mesh0.dim, orientation=orient)
        return float(np.min(q / q0)), float(q.min()), float(model.constraint_values()[0])

    v0 = model.values.copy()
    r0, qmin0, m0 = worst()
    g = model.constraint_jacobian()[0]
    step = 0.02 * g / np.linalg.norm(g) * np.maximum(1.0, np.abs(v0))
    model.set_values(v0 + step)
    up = worst()
    model.set_values(v0 - step)
    down = worst()
    assert up[2] > m0 > down[2]
    assert up[0] > r0 > down[0] and up[1] > qmin0 > down[1]
    assert isinstance(c, MeshQuality) and run is model.run


def test_ffd_constraints_table_and_jacobian(tmp_path):
    mesh = write_volume_wing(tmp_path)
    design = write_design(tmp_path, mesh, [{"twist": {"tip": 10}}, {"sweep": 5}], volume={"method": "idw"},
                          extra={"constraints": [{"volume": {"lower": 1.0}}, {"mesh_quality": {}}]})
    proc = run_ffd("constraints", design, "--json", "--jacobian", tmp_path / "J.npz", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    rows = {r["name"]: r for r in json.loads(proc.stdout)["constraints"]}
    assert rows["k1.mesh_quality"]["lower"] == 0.3 and rows["k1.mesh_quality"]["upper"] is None
    model = DesignModel.from_file(design)
    assert rows["k1.mesh_quality"]["value"] == pytest.approx(model.constraint_values()[1], rel=1e-12)
    with np.load(tmp_path / "J.npz") as z:
        assert list(z["names"]) == ["k0.volume", "k1.mesh_quality"]
        np.testing.assert_allclose(z["jacobian"][1], model.constraint_jacobian()[1], rtol=1e-10)
    text = run_ffd("constraints", design, cwd=tmp_path).stdout
    assert "k1.mesh_quality" in text
    # ffd deform --json reports it on the mesh it deformed (the same mesh here: no recovery needed)
    proc = run_ffd("deform", design, "--json", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    got = {r["name"]: r for r in json.loads(proc.stdout)["constraints"]}
    assert got["k1.mesh_quality"]["value"] == pytest.approx(rows["k1.mesh_quality"]["value"], rel=1e-12)


def test_bad_input_names_the_key(tmp_path):
    surface = write_surface_wing(tmp_path)
    design = write_design(tmp_path, surface, [{"twist": {"tip": 5}}], extra={"constraints": MQ})
    proc = run_ffd("constraints", design, cwd=tmp_path)
    assert proc.returncode == 2 and "constraints[0].mesh_quality" in proc.stderr and "volume mesh" in proc.stderr
    mesh = write_volume_wing(tmp_path)
    design = write_design(tmp_path, mesh, [{"twist": {"tip": 5}}], name="gap.yaml",
                          extra={"constraints": [{"mesh_quality": {"gap": 0}}]})
    proc = run_ffd("constraints", design, cwd=tmp_path)
    assert proc.returncode == 2 and "gap" in proc.stderr, proc.stderr


def test_openmdao_component_outputs_mesh_quality(tmp_path):
    om = pytest.importorskip("openmdao.api", reason="openmdao is not installed (pip install 'ffdcli[openmdao]')")
    from ffdcli.openmdao import FFDComponent

    mesh = write_volume_wing(tmp_path)
    design = write_design(tmp_path, mesh, [{"twist": {"tip": 10}}, {"dihedral": 3}], volume={"method": "idw"},
                          extra={"constraints": MQ})
    prob = om.Problem(reports=False)
    prob.model.add_subsystem("ffd", FFDComponent(design=str(design)), promotes=["*"])
    prob.setup()
    prob.run_model()
    model = DesignModel.from_file(design)
    np.testing.assert_allclose(prob["k0_mesh_quality"], model.constraint_values(), rtol=1e-12)
    data = prob.check_partials(method="fd", form="central", step=1e-5, out_stream=None)
    for (of, wrt), d in data["ffd"].items():
        if of == "k0_mesh_quality":
            for key in ("J_fwd", "J_rev"):
                np.testing.assert_allclose(d[key], d["J_fd"], rtol=1e-5, atol=1e-7, err_msg=f"{wrt} {key}")


@pytest.mark.parametrize("changes", [
    [{"chord": {"tip": 0.5}}],
    [{"span": 1.15}, {"sweep": 10}, {"twist": {"tip": -10}}, {"chord": {"tip": 0.5}}],
])
def test_what_the_design_itself_does_at_the_wall_is_not_counted(tmp_path, changes):
    """Halving the tip chord squeezes the cells on the tip's faces whatever the volume does: the gate
    accepts it (shaped by the design's own map), and mesh_quality, which compares the cells near the
    wall with that map, reads above its default bound; compared with the input mesh alone (``good: 1``,
    no map) the same mesh reads below it."""
    design = tmp_path / "chord.yaml"
    design.write_text(json.dumps({"mesh": str(RECT), "surface": "wing", "box": {"points": [6, 8, 2]},
                                  "changes": changes, "constraints": [{"mesh_quality": {}}, *MQ_PLAIN]}))
    model = DesignModel.from_file(design, cache_dir=tmp_path)
    assert deform(model.run, P=model.lattice()).quality.ok
    value, plain = model.constraint_values()
    c = model.constraints[1]
    alone = c.measure(model.mesh_points())[0]            # no map: every cell against its input quality
    assert value > MESH_QUALITY_LOWER > alone, (value, plain, alone)
    assert plain >= alone - 1e-12
