"""The gate's wall-layer figures (ffdcli.quality.wall_layer): first-cell height after / before and the
off-wall angle change at the wall nodes, a warning by default, a refusal with volume.first_cell."""

import numpy as np
import pytest

from ffdcli.errors import QualityError
from ffdcli.quality.wall_layer import enforce_wall_layer, wall_layer_report
from ffdcli.testing.ogrid import airfoil_ogrid_mesh
from ffdcli.volume.wall_layer import off_wall_edges


@pytest.fixture(scope="module")
def rans():
    return airfoil_ogrid_mesh("0012", n_around=65, n_radial=45, first_cell=1e-6)


@pytest.mark.parametrize("stretch", [0.97, 0.995, 1.004, 1.02])
def test_first_cells_stretched_are_counted(rans, stretch):
    m = rans
    ids = m.marker_point_ids("airfoil")
    e = off_wall_edges(m.points, m.cells, m.marker_faces("airfoil"), ids)
    after = m.points.copy()
    rng = np.random.default_rng(int(stretch * 1000))
    moved = rng.choice(np.arange(1, len(ids) - 1), 7, replace=False)     # not the trailing edge (node 0)
    nodes = e.node[moved]
    after[nodes] = m.points[ids[moved]] + stretch * (m.points[nodes] - m.points[ids[moved]])
    r = wall_layer_report(m, "airfoil", after, m.points, tolerance=0.01)
    assert r is not None and r.n_wall == len(ids) - 1                   # the sharp trailing edge left out
    assert np.isclose(min(r.ratio_min, 1.0), min(stretch, 1.0)) and np.isclose(max(r.ratio_max, 1.0),
                                                                                max(stretch, 1.0))
    assert r.n_failed == (7 if abs(stretch - 1) > 0.01 else 0)
    if r.n_failed:
        assert "first cells" in enforce_wall_layer(r)[0]
        with pytest.raises(QualityError, match="first cells"):
            enforce_wall_layer(r, refuse=True)
        assert "written anyway" in enforce_wall_layer(r, refuse=True, force=True)[0]
    else:
        assert enforce_wall_layer(r, refuse=True) == []


def test_check_reports_heights_and_an_euler_mesh_nothing(rans):
    r = wall_layer_report(rans, "airfoil")
    assert r.ratio_min is None and 9e-7 < r.height_min <= r.height_max < 1.1e-6
    assert "first cell" in r.summary()
    assert wall_layer_report(airfoil_ogrid_mesh("0012", 33, 17, first_cell=5e-2), "airfoil") is None
