"""A deflected flap's hinge with the rigid wall layer (ffdcli.volume.wall_layer): the layer, no thicker
than the wall's spacing, does not fold below the hinge, where a structured mesh's stacks of thin cells
reach 0.1 chord and more; every first cell kept, no cell inverted, with the layer itself (no recovery)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from ffdcli.app.deformation import deform
from ffdcli.app.run import load_run
from ffdcli.design import load_design
from ffdcli.io.formats import write_mesh
from ffdcli.testing.ogrid import airfoil_ogrid_mesh
from ffdcli.volume.wall_layer import STACK_SPACINGS, off_wall_edges
from ffdcli.volume.warp import prepare_mesh_warp

RAE2822 = Path("/work/shared/data/su2/deformation__rae2822__mesh_RAE2822_turb_ffd.su2")

MESHES = {"o0012_97": lambda: airfoil_ogrid_mesh("0012", 97, 61, first_cell=1e-6),
          "o4415_81": lambda: airfoil_ogrid_mesh("4415", 81, 61, first_cell=1e-5)}


def _deform(tmp_path, mesh_path, surface, hinge, angle):
    path = tmp_path / f"flap_{hinge}_{angle}.yaml"
    path.write_text(yaml.safe_dump({"mesh": str(mesh_path), "surface": surface, "box": {"points": [10, 2]},
                                    "changes": [{"flap": {"hinge": hinge, "angle": angle}}]}))
    run = load_run(load_design(path), use_cache=False)
    res = deform(run, recover=False)
    return run, res


def _holds(run, res):
    assert res.quality.n_inverted == 0 and res.quality.ok
    wall = res.wall_layer
    assert abs(wall.ratio_min - 1) < 1e-4 and abs(wall.ratio_max - 1) < 1e-4 and wall.angle_change < 0.01
    layer = run.warp_model().layer
    assert layer is not None and len(layer.rows)


@pytest.mark.parametrize("name", list(MESHES))
@pytest.mark.parametrize("hinge, angle", [(0.7, 20), (0.75, 20), (0.75, -20), (0.72, 15)])
def test_a_flap_keeps_the_layer_unfolded_below_its_hinge(tmp_path, name, hinge, angle):
    write_mesh(MESHES[name](), tmp_path / f"{name}.su2")
    _holds(*_deform(tmp_path, tmp_path / f"{name}.su2", "airfoil", hinge, angle))


@pytest.mark.skipif(not RAE2822.is_file(), reason="the shared data's RAE2822 RANS mesh is not present")
@pytest.mark.parametrize("angle", [10, 20])
def test_the_rae2822_flap_holds_the_layer(tmp_path, angle):
    """SU2's RAE2822 RANS mesh: its quads stay thinner than wide 0.09 to 0.12 chord below the hinge
    (6 wall spacings); a layer that thick folded 0.2 chord below a 10 degree flap's hinge."""
    _holds(*_deform(tmp_path, RAE2822, "AIRFOIL", 0.75, angle))


def test_the_layer_is_no_thicker_than_the_wall_spacing():
    m = airfoil_ogrid_mesh("0012", 97, 61, first_cell=1e-6)
    model, _ = prepare_mesh_warp(m, "airfoil")
    layer = model.layer
    spacing = off_wall_edges(m.points, m.cells, m.marker_faces("airfoil"), model.surface_ids).spacing.max()
    # the nodes of the layer proper (weight 1) lie within the largest spacing of the wall
    d = np.min(np.linalg.norm(layer.position[layer.weight == 1][:, None] - layer.wall_position[None], axis=2), axis=1)
    assert d.max() <= STACK_SPACINGS * spacing * 1.0001
