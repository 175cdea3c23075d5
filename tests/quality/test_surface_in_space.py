"""Issue 43, item 2: cells are judged by what they are. 2-D cells that do not lie in one plane are a
surface in space (a wing's skin, a closed box's faces), not an airfoil mesh: the gate and ``ffd check``
report no volume cells (never "inverted", never exit 3) and ``mesh_quality`` refuses the mesh as the
docs say; 2-D cells in one plane, whatever the plane, are still judged as flat cells.

Surfaces are generated: closed boxes of random size and orientation (quads, or triangles), a closed
tube, wavy sheets of random amplitude; flat meshes in random tilted planes with a cell turned over.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import run_ffd

from ffdcli.constraints.base import ConstraintContext
from ffdcli.constraints.mesh_quality import MeshQuality
from ffdcli.errors import InputError
from ffdcli.io.formats import write_mesh
from ffdcli.mesh import CellBlock, Mesh
from ffdcli.quality.gate import check_quality
from ffdcli.quality.metrics import in_one_plane


def _rotation(rng) -> np.ndarray:
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    return q


def _grid(nx, ny):
    """(nx*ny, 2) points of a unit grid and its (.., 4) quads, counter-clockwise."""
    x, y = np.meshgrid(np.linspace(0, 1, nx), np.linspace(0, 1, ny), indexing="ij")
    idx = np.arange(nx * ny).reshape(nx, ny)
    quads = np.stack([idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]], axis=-1).reshape(-1, 4)
    return np.column_stack([x.ravel(), y.ravel()]), quads


def _box(rng, triangles: bool) -> Mesh:
    """The six faces of a box of random size, rotated and moved, each face a small grid."""
    size = rng.uniform(0.2, 5.0, size=3)
    pts, cells = [], []
    uv, quads = _grid(4, 4)
    for axis in range(3):
        for side in (0.0, 1.0):
            a, b = [k for k in range(3) if k != axis]
            p = np.zeros((len(uv), 3))
            p[:, a], p[:, b], p[:, axis] = uv[:, 0], uv[:, 1], side
            cells.append(quads[:, ::-1] + sum(len(x) for x in pts) if side == 0.0 else
                         quads + sum(len(x) for x in pts))
            pts.append(p)
    P = (np.concatenate(pts) * size) @ _rotation(rng).T + rng.normal(size=3)
    Q = np.concatenate(cells)
    if triangles:
        T = np.concatenate([Q[:, [0, 1, 2]], Q[:, [0, 2, 3]]])
        return Mesh(points=P, dim=2, cells=[CellBlock("triangle", T)])
    return Mesh(points=P, dim=2, cells=[CellBlock("quad", Q)])


def _tube(rng) -> Mesh:
    n, k = 24, 6
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    r = rng.uniform(0.1, 2.0)
    z = np.linspace(0, rng.uniform(0.5, 4.0), k)
    P = np.array([[r * np.cos(a), r * np.sin(a), h] for h in z for a in t])
    quads = [[j * n + i, j * n + (i + 1) % n, (j + 1) * n + (i + 1) % n, (j + 1) * n + i]
             for j in range(k - 1) for i in range(n)]
    return Mesh(points=P @ _rotation(rng).T, dim=2, cells=[CellBlock("quad", np.array(quads))])


def _wavy(rng, amplitude: float) -> Mesh:
    uv, quads = _grid(12, 9)
    z = amplitude * np.sin(3 * uv[:, 0]) * np.cos(2 * uv[:, 1] + rng.uniform(0, 3))
    return Mesh(points=np.column_stack([uv, z]) @ _rotation(rng).T, dim=2, cells=[CellBlock("quad", quads)])


def _tilted_flat(rng) -> tuple[Mesh, int]:
    """A flat grid in a random plane with one interior node pushed across a neighbour: inverted cells."""
    uv, quads = _grid(7, 6)
    uv = uv + rng.uniform(-0.02, 0.02, size=uv.shape)
    node = 3 * 6 + 2
    uv[node] = uv[node] + np.array([0.3, 0.0])
    P = np.column_stack([uv * rng.uniform(0.5, 3), np.zeros(len(uv))]) @ _rotation(rng).T
    return Mesh(points=P, dim=2, cells=[CellBlock("quad", quads)]), node


def _surfaces(seed: int):
    rng = np.random.default_rng(seed)
    return [_box(rng, False), _box(rng, True), _tube(rng), _wavy(rng, rng.uniform(1e-3, 0.3))]


@pytest.mark.parametrize("seed", range(4))
def test_a_surface_in_space_has_no_volume_cells_to_judge(seed):
    for mesh in _surfaces(seed):
        cells = mesh.cells[0]
        assert not in_one_plane(mesh.points, mesh.cells, np.array([0.0, 0.0, 1.0]))
        report = check_quality(mesh)
        assert report.count == 0 and report.n_inverted == 0 and report.ok
        assert report.surface_cells == len(cells)
        # a design that moves it: still nothing to judge, nothing refused
        moved = mesh.points + np.random.default_rng(seed).normal(scale=0.01, size=mesh.points.shape)
        after = check_quality(mesh, moved, points_before=mesh.points)
        assert after.count == 0 and after.ok and after.n_failed == 0


@pytest.mark.parametrize("seed", range(4))
def test_flat_cells_in_any_plane_are_still_judged(seed):
    mesh, _ = _tilted_flat(np.random.default_rng(seed))
    report = check_quality(mesh)
    assert report.count == len(mesh.cells[0]) and report.surface_cells == 0
    assert report.n_inverted > 0 and not report.ok


@pytest.mark.parametrize("seed", range(3))
def test_mesh_quality_refuses_a_surface_in_space(seed):
    def ctx(mesh):
        return ConstraintContext(index=0, key="constraints[0].mesh_quality", lower=0.3, upper=np.inf, box=None,
                                 surface=None, mesh=mesh)

    for mesh in _surfaces(seed):
        with pytest.raises(InputError, match="volume mesh") as e:
            MeshQuality.from_spec({}, ctx(mesh))
        assert e.value.key == "constraints[0].mesh_quality"
    flat, _ = _tilted_flat(np.random.default_rng(seed))
    flat = Mesh(points=flat.points, dim=2, cells=[CellBlock("quad", flat.cells[0].data[:10])])
    assert MeshQuality.from_spec({}, ctx(flat)).rho > 0


def test_ffd_check_of_a_unit_cube_says_no_volume_cells(tmp_path):
    cube = _box(np.random.default_rng(0), False)
    unit = Mesh(points=cube.points, dim=2, cells=cube.cells)
    path = tmp_path / "cube.vtk"
    write_mesh(unit, path)
    proc = run_ffd("check", path, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert "no volume cells" in proc.stdout and "inverted" not in proc.stdout
