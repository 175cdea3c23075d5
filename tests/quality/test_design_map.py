"""The design's own map near the wall (:mod:`ffdcli.quality.design_map`): one rule for the gate and
``mesh_quality``, and its exact reverse product."""

from __future__ import annotations

import numpy as np
import pytest
from wingcase import write_design, write_volume_wing

from ffdcli.api import DesignModel
from ffdcli.app.deformation import DESIGN_ZONE, design_map, design_zone
from ffdcli.quality.design_map import DesignMapZone, linearised_map


def test_apply_moved_and_vjp_on_random_data():
    rng = np.random.default_rng(0)
    X0 = rng.uniform(-1, 1, (300, 3))
    ids = np.arange(0, 300, 7)
    zone = DesignMapZone.build(X0, ids, 0.25)
    assert set(ids) <= set(zone.nodes) and len(zone.nodes) < len(X0)
    b = rng.standard_normal((len(ids), 3))
    F = np.eye(3) + 0.1 * rng.standard_normal((len(ids), 3, 3))
    out = zone.apply(X0, b, F)
    outside = ~zone.mask
    np.testing.assert_array_equal(out[outside], X0[outside])              # the others as in the input
    np.testing.assert_allclose(out[ids], X0[ids] + b, atol=1e-15)         # a surface node moves by b
    some = np.array([1, 2, ids[3], 299])
    got = zone.moved(some, X0, b, F)
    for k, n in enumerate(some):
        if zone.mask[n]:
            np.testing.assert_array_equal(got[k], out[n])
        else:
            assert np.isnan(got[k]).all()
    # the map is affine in (b, F): its reverse product is exact
    G = rng.standard_normal(X0.shape)
    db, dF = rng.standard_normal(b.shape), rng.standard_normal(F.shape)
    g_b, g_F = zone.vjp(G, len(ids))
    lin = zone.apply(X0, b + db, F + dF) - out
    assert np.sum(G * lin) == pytest.approx(np.sum(g_b * db) + np.sum(g_F * dF), rel=1e-12)
    k = zone.nearest[5]
    np.testing.assert_allclose(linearised_map(X0[zone.nodes[5]][None], X0[ids[k]][None], b[k][None], F[k][None])[0],
                               out[zone.nodes[5]], atol=1e-15)


def test_the_gate_and_mesh_quality_use_the_same_map(tmp_path):
    mesh = write_volume_wing(tmp_path, taper=0.6, le_sweep_deg=15)
    model = DesignModel.from_file(write_design(tmp_path, mesh, [{"chord": {"tip": 0.6}}, {"twist": {"tip": 8}}],
                                               volume={"method": "idw"}))
    run, P = model.run, model.lattice()
    X_map, inside = model.design_map_points()
    zone = design_zone(run)
    assert inside.sum() == len(zone.nodes) > len(model.surface_ids)
    gate = design_map(run, P)(np.arange(run.prep.mesh.n_points))
    np.testing.assert_allclose(gate[inside], X_map[inside], rtol=0, atol=1e-14)
    assert np.isnan(gate[~inside]).all()
    assert DESIGN_ZONE == 0.15


def test_design_map_vjp_against_central_differences(tmp_path):
    mesh = write_volume_wing(tmp_path, taper=0.6, le_sweep_deg=15)
    model = DesignModel.from_file(write_design(
        tmp_path, mesh, [{"twist": {"root": 1, "tip": 10}}, {"chord": {"tip": 0.7}}, {"dihedral": 4}],
        volume={"method": "idw", "carry": "rotation"}))          # the map's frames are F even then
    G = np.random.default_rng(3).standard_normal((model.run.prep.mesh.n_points, 3))
    g = model.design_map_vjp(G)
    v0 = model.values.copy()
    for i in range(len(v0)):
        h = 1e-5 * max(1.0, abs(v0[i]))
        vals = []
        for s in (1, -1):
            v = v0.copy()
            v[i] += s * h
            model.set_values(v)
            vals.append(np.sum(G * model.design_map_points()[0]))
        model.set_values(v0)
        assert g[i] == pytest.approx((vals[0] - vals[1]) / (2 * h), rel=1e-6), model.names[i]
