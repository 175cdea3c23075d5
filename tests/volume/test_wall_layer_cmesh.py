"""The rigid wall layer on a C-mesh (ffdcli.testing.cmesh: sharp trailing edge, conforming wake cut):
every first cell kept, no cell inverted, the cut's nodes (one node for both sides) moved as one smooth
line, and the cells beside the trailing edge and along the cut no worse than with the warp alone."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from ffdcli.app.deformation import deform
from ffdcli.app.run import load_run
from ffdcli.design import load_design
from ffdcli.io.formats import write_mesh
from ffdcli.quality.metrics import cell_quality
from ffdcli.testing.cmesh import c_grid, cmesh
from ffdcli.testing.naca import naca4

SIZE = (97, 25, 49, 1e-6)
DESIGNS = {"twist-20": [{"twist": {"angle": -20, "axis": 0.25}}],
           "twist+5": [{"twist": {"angle": 5, "axis": 0.25}}],
           "shape5%": [{"shape": {"random": 0.05, "seed": 7}}],
           "shape1%": [{"shape": {"random": 0.01, "seed": 11}}],
           "chord0.9": [{"chord": 0.9}],
           "flap15": [{"flap": {"hinge": 0.75, "angle": 15}}],
           "slat10": [{"slat": {"hinge": 0.15, "angle": 10}}]}


@pytest.fixture(scope="module")
def case(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("cmesh")
    xy = naca4("2412", 161)
    write_mesh(cmesh(xy, *SIZE), tmp / "c.su2")
    _, ids, _, _, _ = c_grid(xy, *SIZE, 100.0)
    n_wake = SIZE[1]
    return tmp, ids[:n_wake + 1, 0][::-1]          # the cut's nodes from the trailing edge downstream


def _run(tmp, name, layer):
    path = tmp / f"{name}_{layer}.yaml"
    path.write_text(yaml.safe_dump({"mesh": str(tmp / "c.su2"), "surface": "airfoil", "box": {"points": [10, 2]},
                                    "volume": {"wall_layer": layer}, "changes": DESIGNS[name]}))
    run = load_run(load_design(path), use_cache=False)
    return run, deform(run, recover=False)


@pytest.mark.parametrize("name", list(DESIGNS))
def test_the_layer_holds_on_a_c_mesh(case, name):
    tmp, cut = case
    run, res = _run(tmp, name, "rigid")
    _, alone = _run(tmp, name, "none")
    assert run.warp_model().layer is not None
    assert res.quality.ok and res.quality.n_inverted == 0
    wall = res.wall_layer
    assert abs(wall.ratio_min - 1) < 1e-4 and abs(wall.ratio_max - 1) < 1e-4 and wall.angle_change < 0.01
    mesh = run.chain.share.mesh
    # the cut stays a smooth line: its nodes keep their order downstream, and its turn from node to
    # node is no larger than the warp alone makes it (plus a degree)
    def turns(p):
        e = np.diff(p[cut, :2], axis=0)
        ang = np.arctan2(e[:, 1], e[:, 0])
        return np.degrees(np.abs(np.diff(ang)))
    assert np.all(np.diff(res.points[cut, 0]) > 0)
    assert turns(res.points).max() <= turns(alone.points).max() + 1.0
    # the cells touching the trailing edge and the cut: no worse than the warp alone's
    quads = mesh.cells[0].data
    near = np.isin(quads, cut).any(axis=1)
    q_layer = cell_quality(res.points, mesh.cells, 2)
    q_alone = cell_quality(alone.points, mesh.cells, 2)
    q_layer = np.concatenate(q_layer) if isinstance(q_layer, list) else q_layer
    q_alone = np.concatenate(q_alone) if isinstance(q_alone, list) else q_alone
    assert q_layer[near].min() >= q_alone[near].min() - 1e-3
