"""The near-wall layer of a RANS mesh moves rigidly with its wall (ffdcli.volume.wall_layer,
ffdcli.volume.layer_motion): found from the mesh, first-cell height and off-wall angle kept, the sharp
trailing edge no worse than the warp alone, derivatives exact against central differences."""

from dataclasses import replace

import numpy as np
import pytest

from ffdcli.mesh import CellBlock
from ffdcli.quality.metrics import cell_quality
from ffdcli.testing.ogrid import airfoil_ogrid_mesh
from ffdcli.volume.layer_motion import (
    deformed_normals,
    deformed_normals_jvp,
    deformed_normals_vjp,
    wall_frames,
    wall_frames_jvp,
    wall_frames_vjp,
)
from ffdcli.volume.wall_layer import WallLayer, detect_wall_layer, layer_normals, off_wall_edges, sharp_nodes
from ffdcli.volume.warp import WarpSettings, prepare_mesh_warp, warp, warp_vjp


@pytest.fixture(scope="module", params=[("0012", 1e-6), ("2412", 1e-5)])
def rans(request):
    code, first = request.param
    m = airfoil_ogrid_mesh(code, n_around=65, n_radial=45, first_cell=first)
    model, _ = prepare_mesh_warp(m, "airfoil", WarpSettings(tolerance=0))
    return m, model


def _map(sp, amp, squeeze, twist_deg=0.0):
    """A smooth map of the plane (a bump, a thickness-wise squeeze, a twist about the quarter chord):
    the surface translations b (Ns, 3) and its gradient F (Ns, 3, 3) at the surface points ``sp``."""
    x, y = sp[:, 0], sp[:, 1]
    th = np.radians(twist_deg)
    c, s = np.cos(th), np.sin(th)
    R = np.array([[c, s, 0], [-s, c, 0], [0, 0, 1.0]])
    y1 = y + amp * np.sin(np.pi * x) + (squeeze - 1) * y
    p = np.column_stack([x - 0.25, y1, np.zeros_like(x)]) @ R.T + [0.25, 0, 0]
    G = np.broadcast_to(np.eye(3), (len(sp), 3, 3)).copy()
    G[:, 1, 0] = amp * np.pi * np.cos(np.pi * x)
    G[:, 1, 1] = squeeze
    return p - sp, R @ G


def _heights(m, model, d):
    faces = m.marker_faces("airfoil")
    e0 = off_wall_edges(m.points, m.cells, faces, model.surface_ids)
    e1 = off_wall_edges(m.points + d, m.cells, faces, model.surface_ids, edge_nodes=e0.node)
    return e1.height / e0.height, np.abs(e1.angle - e0.angle)


def test_a_rans_mesh_has_a_layer_an_euler_mesh_none():
    for first in (1e-6, 1e-5, 1e-4):
        m = airfoil_ogrid_mesh("0012", n_around=65, n_radial=45, first_cell=first)
        model, _ = prepare_mesh_warp(m, "airfoil")
        assert model.layer is not None and len(model.layer.rows)
        assert np.all(model.layer.weight[model.layer.weight > 0] <= 1)
    coarse = airfoil_ogrid_mesh("0012", n_around=33, n_radial=17, first_cell=5e-2)
    model, _ = prepare_mesh_warp(coarse, "airfoil")
    assert model.layer is None
    ids = model.surface_ids
    assert detect_wall_layer(coarse.points, coarse.cells, coarse.marker_faces("airfoil"), ids,
                             model.target_ids) is None
    off, _ = prepare_mesh_warp(airfoil_ogrid_mesh("0012", 65, 45, first_cell=1e-6), "airfoil",
                               WarpSettings(wall_layer="none"))
    assert off.layer is None


@pytest.mark.parametrize("twist", [-20.0, -7.0, 5.0, 20.0])
def test_a_twist_keeps_every_first_cell(rans, twist):
    m, model = rans
    b, F = _map(m.points[model.surface_ids], 0.0, 1.0, twist)
    ratio, dangle = _heights(m, model, warp(model, b, F))
    assert np.abs(ratio - 1).max() < 1e-6
    assert dangle.max() < 1e-3


@pytest.mark.parametrize("amp,squeeze", [(0.05, 1.0), (-0.05, 1.0), (0.02, 1.4), (-0.03, 0.7)])
def test_a_shape_move_keeps_every_first_cell(rans, amp, squeeze):
    """The warp alone stretches the first cells with the map's thickness-wise stretch; the layer keeps
    them at every wall node but the sharp trailing edge's own (no normal: its off-wall edge is the
    wake's), and no cell is worse than with the warp alone."""
    m, model = rans
    b, F = _map(m.points[model.surface_ids], amp, squeeze)
    ratio, dangle = _heights(m, model, warp(model, b, F))
    plain = replace(model, layer=None)
    ratio0, _ = _heights(m, model, warp(plain, b, F))
    judged = np.ones(model.n_surface, bool)
    judged[sharp_nodes(m.points, m.marker_faces("airfoil"), model.surface_ids)] = False
    assert judged.sum() == model.n_surface - 1
    assert np.abs(ratio[judged] - 1).max() < 1e-4
    assert dangle[judged].max() < 0.5
    assert np.abs(ratio0[judged] - 1).max() > 0.02          # what the warp alone does
    q = cell_quality(m.points + warp(model, b, F), m.cells, m.dim)
    q0 = cell_quality(m.points + warp(plain, b, F), m.cells, m.dim)
    assert q.min() >= q0.min() - 1e-3


def test_no_design_moves_nothing(rans):
    m, model = rans
    ns = model.n_surface
    d = warp(model, np.zeros((ns, 3)), np.broadcast_to(np.eye(3), (ns, 3, 3)).copy())
    assert np.all(d == 0)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_layer_derivatives_match_central_differences(rans, seed):
    m, model = rans
    rng = np.random.default_rng(seed)
    ns = model.n_surface
    b, F = _map(m.points[model.surface_ids], rng.uniform(-0.05, 0.05), rng.uniform(0.7, 1.3),
                rng.uniform(-20, 20))
    db = rng.normal(size=(ns, 3))
    db[:, 2] = 0
    dF = rng.normal(size=(ns, 3, 3))
    dF[:, 2, :] = dF[:, :, 2] = 0
    h = 1e-6
    fd = (warp(model, b + h * db, F + h * dF) - warp(model, b - h * db, F - h * dF)) / (2 * h)
    jv = warp(model, db, np.eye(3) + dF, at=(b, F))
    assert np.abs(fd - jv).max() < 1e-6 * np.abs(fd).max()
    g = rng.normal(size=(m.n_points, 3))
    g_b, g_M = warp_vjp(model, g, at=(b, F))
    assert np.isclose(np.sum(g * jv), np.sum(g_b * db) + np.sum(g_M * dF), rtol=1e-10)
    with pytest.raises(ValueError, match="at="):
        warp_vjp(model, g)


def test_wall_frame_products():
    """G maps the normal to the deformed wall's normal, keeps F along the wall, is F where there is no
    normal (a sharp edge) and I where F is and the normal stays; R is the least rotation taking n to
    n'; their forward and transposed products are exact."""
    rng = np.random.default_rng(3)
    n = 50
    nrm = rng.normal(size=(n, 3))
    nrm /= np.linalg.norm(nrm, axis=1)[:, None]
    nrm[:5] = 0.0
    n2 = nrm + 0.4 * rng.normal(size=(n, 3))
    n2 /= np.linalg.norm(n2, axis=1)[:, None]
    n2[5] = nrm[5]
    n2[49] = -nrm[49]                           # a wall turned over: no least rotation, R is G (finite)
    F = np.eye(3) + 0.3 * rng.normal(size=(n, 3, 3))
    F[5] = np.eye(3)
    G, R = wall_frames(F, nrm, n2, turns=True)
    assert np.array_equal(G[:5], F[:5]) and np.array_equal(G[5], np.eye(3)) and np.array_equal(R[5], np.eye(3))
    assert np.all(np.isfinite(R)) and np.array_equal(R[49], G[49])
    assert np.allclose(np.einsum("nij,nj->ni", G, nrm)[6:], n2[6:])
    assert np.allclose(np.einsum("nij,nj->ni", R, nrm)[6:], n2[6:])
    assert np.allclose(np.einsum("nij,nkj->nik", R[6:49], R[6:49]), np.eye(3))
    assert np.allclose(np.linalg.det(R[6:49]), 1)
    axis = np.cross(nrm, n2)                    # the least rotation keeps the axis n x n'
    assert np.allclose(np.einsum("nij,nj->ni", R, axis)[6:49], axis[6:49])
    t = np.cross(nrm, rng.normal(size=(n, 3)))
    assert np.allclose(np.einsum("nij,nj->ni", G, t), np.einsum("nij,nj->ni", F, t))
    dF = rng.normal(size=(n, 3, 3))
    dn = rng.normal(size=(n, 3))
    h = 1e-6
    for k in (0, 1):
        fd = (wall_frames(F + h * dF, nrm, n2 + h * dn, turns=True)[k]
              - wall_frames(F - h * dF, nrm, n2 - h * dn, turns=True)[k]) / (2 * h)
        jv = wall_frames_jvp(nrm, n2, dF, dn, turns=True)[k]
        assert np.abs(fd - jv)[6:].max() < 1e-7
    jG, jR = wall_frames_jvp(nrm, n2, dF, dn, turns=True)
    gG, gR = rng.normal(size=(2, n, 3, 3))
    gF, gn = wall_frames_vjp(nrm, n2, gG, gR)
    assert np.isclose(np.sum(gG * jG) + np.sum(gR * jR), np.sum(gF * dF) + np.sum(gn * dn))


@pytest.mark.parametrize("carry", ["gradient", "rotation"])
def test_design_model_products_through_the_layer_match_central_differences(tmp_path, carry):
    """DesignModel.mesh_jvp / mesh_vjp include the layer (linearised at the current frames): both match
    central differences of the mesh ``ffd deform`` writes, away from the baseline."""
    import yaml

    from ffdcli.api import DesignModel
    from ffdcli.io.formats import write_mesh

    m = airfoil_ogrid_mesh("2412", n_around=65, n_radial=45, first_cell=1e-6)
    write_mesh(m, tmp_path / "rans.su2")
    design = {"mesh": str(tmp_path / "rans.su2"), "surface": "airfoil", "box": {"points": [6, 2]},
              "volume": {"carry": carry},
              "changes": [{"twist": {"angle": 7, "axis": 0.25}}, {"shape": {"random": 0.02, "seed": 3}}]}
    (tmp_path / "d.yaml").write_text(yaml.safe_dump(design))
    model = DesignModel.from_file(tmp_path / "d.yaml", use_cache=False)
    assert model.run.warp_model().layer is not None
    rng = np.random.default_rng(5)
    v0 = model.values.copy()
    dv = rng.normal(size=model.n_vars) * (np.abs(v0) + 0.01)
    g = rng.normal(size=(m.n_points, 3))
    jv = model.mesh_jvp(dv)
    assert np.isclose(np.sum(g * jv), model.mesh_vjp(g) @ dv, rtol=1e-9)
    h = 1e-4
    model.set_values(v0 + h * dv)
    plus = model.mesh_points()
    model.set_values(v0 - h * dv)
    minus = model.mesh_points()
    fd = (plus - minus) / (2 * h)
    assert np.abs(fd - jv).max() <= 1e-6 * np.abs(fd).max()


def _sheet(rng, nx=7, nz=6):
    """A wavy triangulated sheet over x in [0, 1], z in [0, 1] (its root z = 0 on a plane) as a WallLayer
    with no layer nodes: its wall, faces and planes only."""
    x, z = np.meshgrid(np.linspace(0, 1, nx), np.linspace(0, 1, nz), indexing="ij")
    y = 0.1 * np.sin(3 * x + rng.uniform()) * (1 + z)
    pos = np.column_stack([x.ravel(), y.ravel(), z.ravel()])
    i = np.arange(nx * nz).reshape(nx, nz)
    a, b, c, d = i[:-1, :-1].ravel(), i[1:, :-1].ravel(), i[1:, 1:].ravel(), i[:-1, 1:].ravel()
    tri = np.concatenate([np.column_stack([a, b, c]), np.column_stack([a, c, d])])
    planes = np.zeros((len(pos), 3))
    planes[pos[:, 2] == 0] = [0.0, 0.0, 1.0]
    faces = (CellBlock("triangle", tri[: len(tri) // 2]), CellBlock("quad", np.column_stack([a, b, c, d])[::3]),
             CellBlock("triangle", tri[len(tri) // 2:]))
    unit = layer_normals(pos, faces, planes)
    return WallLayer(np.zeros(0, np.int64), None, np.zeros((0, 3)), pos, np.zeros(0), unit, 0.0, planes, None, faces)


def test_a_sliding_wall_node_keeps_its_first_cell_in_its_plane():
    """A root node on a symmetry plane: its normal is the mirrored wall's (the one-sided normal projected
    into the plane, unit), before and after the wall moves out of square with the plane; the deformed
    normals' forward and transposed products are exact."""
    rng = np.random.default_rng(4)
    layer = _sheet(rng)
    root = layer.planes[:, 2] != 0
    assert np.abs(layer.normals[root, 2]).max() == 0 and np.allclose(np.linalg.norm(layer.normals, axis=1), 1)
    pos = layer.wall_position
    b = np.column_stack([0.2 * pos[:, 2] * pos[:, 0], 0.05 * np.cos(2 * pos[:, 0]) * (1 + pos[:, 2]) ** 2,
                         0.1 * pos[:, 2] ** 2])            # a shear and a bend that tilt the root's wall
    one_sided = layer_normals(pos + b, layer.faces)
    assert np.abs(one_sided[root, 2]).max() > 0.05
    n2 = deformed_normals(layer, b)
    mirrored = one_sided[root] * [1.0, 1.0, 0.0]
    assert np.allclose(n2[root], mirrored / np.linalg.norm(mirrored, axis=1)[:, None])
    assert np.allclose(n2[~root], one_sided[~root])
    db = rng.normal(size=b.shape)
    h = 1e-6
    fd = (deformed_normals(layer, b + h * db) - deformed_normals(layer, b - h * db)) / (2 * h)
    jv = deformed_normals_jvp(layer, b, db)
    assert np.abs(fd - jv).max() < 1e-7 * np.abs(jv).max()
    g = rng.normal(size=b.shape)
    assert np.isclose(np.sum(g * jv), np.sum(deformed_normals_vjp(layer, b, g) * db), rtol=1e-12)
