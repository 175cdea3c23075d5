"""The rigid wall layer's shortcuts give the very bits of the long way (ffdcli.volume.warp,
ffdcli.volume.wall_layer, ffdcli.volume.wall_stacks): the targets that follow their wall wholly are not
warped, the reference weights are walked for the targets asked for only, one k-nearest search stands for
the bounded one, and a serial stack stops once above the cap its caller applies."""

import numpy as np
import pytest
import yaml
from scipy.spatial import cKDTree

from ffdcli.app.deformation import deform
from ffdcli.app.run import load_run
from ffdcli.design import load_design
from ffdcli.io.formats import write_mesh
from ffdcli.testing.ogrid import airfoil_ogrid_mesh
from ffdcli.volume import warp as warp_module
from ffdcli.volume.cache import load_cache
from ffdcli.volume.layer_motion import warped_rows
from ffdcli.volume.wall_layer import nodes_within, off_wall_edges, wall_normals
from ffdcli.volume.wall_stacks import stack_heights
from ffdcli.volume.warp import WarpSettings, prepare_mesh_warp, warp, warp_vjp


def _ogrid(code, first, tolerance):
    m = airfoil_ogrid_mesh(code, n_around=49, n_radial=33, first_cell=first)
    return m, "airfoil", WarpSettings(tolerance=tolerance)


def _wing():
    pytest.importorskip("gmsh")
    from ffdcli.testing.gmsh_wings import CASES, smaller, wing_volume_mesh

    return wing_volume_mesh(smaller(CASES["rect_z_rans32"], 4.0)), "wing", WarpSettings()


MESHES = {"0012 1e-6, tolerance 0": lambda: _ogrid("0012", 1e-6, 0.0),
          "2412 1e-5": lambda: _ogrid("2412", 1e-5, WarpSettings().tolerance),
          "32-layer wing": _wing}


@pytest.fixture(scope="module", params=list(MESHES))
def case(request):
    mesh, surface, settings = MESHES[request.param]()
    model, _ = prepare_mesh_warp(mesh, surface, settings)
    assert model.layer is not None
    return mesh, surface, settings, model


def _design(model, rng, scale):
    """Random surface translations (Ns, 3) and frames (Ns, 3, 3), smooth along the wall."""
    p = model.surface_pos
    size = np.ptp(p, axis=0).max()
    A = rng.normal(size=(3, 3)) * scale
    b = np.sin(p @ rng.normal(size=(3, 3)) / size) * scale * size + p @ A.T
    F = np.eye(3) + A + rng.normal(size=(len(p), 3, 3)) * scale * 0.1
    if np.ptp(p[:, 2]) == 0:                      # 2D: the plane stays the plane
        b[:, 2] = 0.0
        F[:, 2, :], F[:, :, 2] = 0.0, 0.0
        F[:, 2, 2] = 1.0
    return b, F


def test_the_rows_that_follow_their_wall_wholly_are_not_warped_and_nothing_changes(case, monkeypatch):
    mesh, surface, settings, model = case
    free = warped_rows(model.layer, 0, model.n_targets)
    assert free is not None and len(free) < model.n_targets            # the shortcut is taken
    whole = np.setdiff1d(np.arange(model.n_targets), free)
    assert np.all(np.isin(whole, model.layer.rows[model.layer.weight == 1.0]))
    rng = np.random.default_rng(len(free))
    designs = [_design(model, rng, s) for s in (1e-3, 2e-2, 5e-2)]
    short = [warp(model, b, F) for b, F in designs]
    short += [warp(model, b, F, at=designs[0]) for b, F in designs[1:]]    # the forward derivative too
    lo, hi = model.n_targets // 3, 2 * model.n_targets // 3
    short += [warp(model, *designs[1], rows=(lo, hi))]                     # one MPI rank's share
    monkeypatch.setattr(warp_module, "warped_rows", lambda layer, lo, hi: None)
    fresh, _ = prepare_mesh_warp(mesh, surface, settings)                  # its reference weights walked for all
    long = [warp(fresh, b, F) for b, F in designs]
    long += [warp(fresh, b, F, at=designs[0]) for b, F in designs[1:]]
    long += [warp(fresh, *designs[1], rows=(lo, hi))]
    for a, c in zip(short, long, strict=True):
        assert np.array_equal(a, c)


def test_reference_weights_walked_for_some_targets_are_those_walked_for_all(case):
    mesh, surface, settings, model = case
    rng = np.random.default_rng(7)
    fresh, _ = prepare_mesh_warp(mesh, surface, settings)
    n = fresh.n_targets
    every = fresh.tolerances(0, n).copy()
    part, _ = prepare_mesh_warp(mesh, surface, settings)
    for _ in range(3):                              # ranges and rows in any order, some asked twice
        lo = int(rng.integers(0, n))
        hi = int(rng.integers(lo, n + 1))
        rows = np.sort(rng.choice(hi - lo, size=(hi - lo) // 2, replace=False)) if hi > lo else None
        assert np.array_equal(part.tolerances(lo, hi, rows), every[lo:hi] if rows is None else every[lo + rows])
        assert np.array_equal(part.tolerances(lo, hi), every[lo:hi])
    assert np.array_equal(part.reference_weights(), fresh.reference_weights())


def test_a_stack_stopped_at_its_cap_gives_the_same_capped_height(case):
    mesh, surface, _, model = case
    pts, faces, ids = mesh.points, mesh.marker_faces(surface), model.surface_ids
    nrm = wall_normals(pts, faces, ids)
    edges = off_wall_edges(pts, mesh.cells, faces, ids, nrm)
    full = stack_heights(pts, mesh.cells, ids, nrm, edges.spacing, edges.node)
    rng = np.random.default_rng(3)
    stopped = np.zeros(len(ids), bool)
    for cap in (edges.spacing, full * rng.uniform(0.2, 1.5, len(ids)), 3.0 * edges.spacing):
        short = stack_heights(pts, mesh.cells, ids, nrm, edges.spacing, edges.node, cap=cap)
        assert np.array_equal(np.minimum(short, cap), np.minimum(full, cap))
        assert np.all(short <= full)
        stopped |= short < full
    assert stopped.any()                            # the walk did stop short


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_one_nearest_search_finds_the_nodes_the_bounded_search_finds(seed):
    rng = np.random.default_rng(seed)
    wall = rng.normal(size=(200, 3))
    x = np.concatenate([rng.normal(size=(3000, 3)) * 2, wall[:50] + 1e-300, wall[50:60]])
    tree = cKDTree(wall)
    d, _ = tree.query(x, k=4)
    # reaches exactly at some nodes' nearest distances (the rounding's edge), and in between
    for reach in [*rng.choice(d[:, 0][d[:, 0] > 0], 5), *rng.uniform(0.01, 2.0, 3), float(d[:, 0].max())]:
        want = np.flatnonzero(np.isfinite(tree.query(x, distance_upper_bound=reach)[0]))
        assert np.array_equal(nodes_within(tree, x, d[:, 0], reach), want)


def test_the_cache_keeps_the_weights_walked_and_a_second_run_walks_none(tmp_path, monkeypatch):
    m = airfoil_ogrid_mesh("2412", n_around=49, n_radial=33, first_cell=1e-6)
    write_mesh(m, tmp_path / "rans.su2")
    (tmp_path / "d.yaml").write_text(yaml.safe_dump({
        "mesh": str(tmp_path / "rans.su2"), "surface": "airfoil", "box": {"points": [8, 2]},
        "changes": [{"twist": {"angle": 6, "axis": 0.25}}, {"shape": {"random": 0.02, "seed": 5}}]}))
    design = load_design(tmp_path / "d.yaml")
    first = load_run(design)
    res = deform(first)
    model = first.warp_model()
    weights, _ = load_cache(first.warp_cache.path, first.warp_cache.key, model.target_ids)
    free = warped_rows(model.layer, 0, model.n_targets)
    not_walked = np.ones(model.n_targets, bool)
    not_walked[free] = False
    assert not_walked.any() and np.array_equal(np.isnan(weights), not_walked)
    with monkeypatch.context() as mp:             # the second run walks no reference weight
        mp.setattr(warp_module, "weight_reference_kernel", _no_walk)
        second = load_run(design)
        np.testing.assert_array_equal(deform(second).points, res.points)
    # a product of the second run walks the others when it needs them: the bits of a run that walked all
    rng = np.random.default_rng(1)
    b, F = _design(model, rng, 1e-2)
    g = rng.normal(size=(model.n_points, 3))
    fresh, _ = prepare_mesh_warp(m, "airfoil")
    fresh.reference_weights()
    for got, want in zip(warp_vjp(second.warp_model(), g, at=(b, F)), warp_vjp(fresh, g, at=(b, F)), strict=True):
        np.testing.assert_array_equal(got, want)


def _no_walk(*a, **k):
    raise AssertionError("a reference weight was walked")
