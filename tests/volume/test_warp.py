"""The volume mesh follows the surface: IDW with rotations, tree approximation, transpose."""

from __future__ import annotations

from pathlib import Path

import jsonschema
import numpy as np
import pytest

from ffdcli.errors import InputError
from ffdcli.geometry.surface import vertex_areas
from ffdcli.mesh import CellBlock, Mesh
from ffdcli.volume.warp import (
    WarpSettings,
    idw_reference,
    marker_roles,
    prepare_mesh_warp,
    prepare_warp,
    rotations_from_deformation_gradient,
    warp,
    warp_vjp,
)

# Hex faces, VTK node order, outward for a positively oriented hex.
HEX_FACES = np.array([[0, 3, 2, 1], [4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]])


def box_wing_mesh(x=None, y=None, z=None, wing=((-0.5, 0.5), (0.0, 1.0), (-0.1, 0.1))) -> Mesh:
    """A structured hex grid (x, y, z lines) with a box-shaped "wing" hole from the y = 0 plane.

    Markers: ``wing`` (the hole's faces), ``symmetry`` (y = y[0], outside the hole), ``farfield``
    (the other five sides of the grid).
    """
    x = np.linspace(-2, 2, 17) if x is None else np.asarray(x)
    y = np.linspace(0, 2, 9) if y is None else np.asarray(y)
    z = (np.array([-2, -1.5, -1, -0.5, -0.25, -0.1, 0.1, 0.25, 0.5, 1, 1.5, 2.0]) if z is None
         else np.asarray(z))
    nx, ny, nz = len(x), len(y), len(z)
    X, Y, Z = np.meshgrid(x, y, z, indexing="ij")
    pts = np.column_stack([X.ravel(), Y.ravel(), Z.ravel()])
    idx = np.arange(nx * ny * nz).reshape(nx, ny, nz)
    i, j, k = np.meshgrid(np.arange(nx - 1), np.arange(ny - 1), np.arange(nz - 1), indexing="ij")
    i, j, k = i.ravel(), j.ravel(), k.ravel()
    hexes = np.column_stack([idx[i, j, k], idx[i + 1, j, k], idx[i + 1, j + 1, k], idx[i, j + 1, k],
                             idx[i, j, k + 1], idx[i + 1, j, k + 1], idx[i + 1, j + 1, k + 1],
                             idx[i, j + 1, k + 1]])
    c = pts[hexes].mean(axis=1)
    (x0, x1), (y0, y1), (z0, z1) = wing
    hole = (c[:, 0] > x0) & (c[:, 0] < x1) & (c[:, 1] > y0) & (c[:, 1] < y1) & (c[:, 2] > z0) & (c[:, 2] < z1)
    hexes = hexes[~hole]
    faces = hexes[:, HEX_FACES].reshape(-1, 4)
    key = np.sort(faces, axis=1)
    _, inv, cnt = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    bfaces = faces[cnt[inv.ravel()] == 1]
    fc = pts[bfaces].mean(axis=1)
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    on_box = np.any(np.isclose(fc, lo) | np.isclose(fc, hi), axis=1)
    sym = np.isclose(fc[:, 1], lo[1])
    markers = {"wing": [CellBlock("quad", bfaces[~on_box])],
               "symmetry": [CellBlock("quad", bfaces[sym])],
               "farfield": [CellBlock("quad", bfaces[on_box & ~sym])]}
    return Mesh(points=pts, dim=3, cells=[CellBlock("hexahedron", hexes)], markers=markers)


def sphere_cloud(ns=1500, nt=3000, seed=0):
    """Surface nodes on the unit sphere with random areas, targets in a cube around it."""
    rng = np.random.default_rng(seed)
    s = rng.normal(size=(ns, 3))
    s /= np.linalg.norm(s, axis=1)[:, None]
    t = rng.uniform(-3, 3, size=(nt, 3))
    t = t[np.linalg.norm(t, axis=1) > 1.02]
    pts = np.vstack([s, t])
    areas = np.zeros(len(pts))
    areas[:ns] = rng.uniform(0.5, 1.5, ns)
    return pts, np.arange(ns), areas, rng


def rot_z(angle):
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])


@pytest.fixture(scope="module")
def mesh():
    return box_wing_mesh()


# ---------------------------------------------------------------------------------------------
# marker roles and settings


def test_default_roles_symmetry_slides_farfield_fixed(mesh):
    roles = marker_roles(mesh.points, mesh.markers, "wing", 3)
    assert roles.roles == {"wing": "surface", "symmetry": "sliding", "farfield": "fixed"}
    (plane,) = roles.sliding
    assert np.array_equal(np.abs(plane.normal), [0, 1, 0])     # snapped to the mesh axis exactly
    # symmetry nodes on the wing are surface nodes, on the farfield fixed: neither slides
    assert not np.intersect1d(plane.ids, roles.surface_ids).size
    assert not np.intersect1d(plane.ids, roles.fixed_ids).size
    assert np.all(mesh.points[plane.ids, 1] == 0.0)


def test_user_roles_override_and_errors(mesh):
    s = WarpSettings(fixed=("symmetry",))
    assert marker_roles(mesh.points, mesh.markers, "wing", 3, s).roles["symmetry"] == "fixed"
    with pytest.raises(InputError, match="farfield.*not planar"):
        marker_roles(mesh.points, mesh.markers, "wing", 3, WarpSettings(sliding=("farfield",)))
    with pytest.raises(InputError, match="no marker named 'tail'") as e:
        marker_roles(mesh.points, mesh.markers, "wing", 3, WarpSettings(fixed=["tail"]))
    assert e.value.key == "volume.fixed"
    with pytest.raises(InputError, match="deforming surface"):
        marker_roles(mesh.points, mesh.markers, "wing", 3, WarpSettings(fixed=["wing"]))


def test_settings_from_dict_key_paths():
    s = WarpSettings.from_dict({"a": 2, "b": 6, "fixed": "farfield", "tolerance": 0}, "d.yaml")
    assert (s.a, s.b, s.fixed, s.tolerance) == (2.0, 6.0, ("farfield",), 0.0)
    assert WarpSettings.from_dict(None) == WarpSettings()
    for bad, key in [({"a": -1}, "volume.a"), ({"b": 1}, "volume.b"), ({"alpha": "x"}, "volume.alpha"),
                     ({"method": "rbf"}, "volume.method"), ({"ldef": 0}, "volume.ldef"),
                     ({"chunk": 0.5}, "volume.chunk"), ({"colour": 1}, "volume.colour"),
                     ({"a": True}, "volume.a"), ({"fixed": [1]}, "volume.fixed"),
                     ({"fixed": ["x"], "sliding": ["x"]}, "volume")]:
        with pytest.raises(InputError) as e:
            WarpSettings.from_dict(bad, "d.yaml")
        assert e.value.key == key and e.value.path == "d.yaml", (bad, e.value)
        assert str(e.value).startswith(f"d.yaml: {key}: ")
    schema = WarpSettings.schema()
    jsonschema.validate({"method": "none", "a": 3, "fixed": ["farfield"]}, schema)
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate({"alpha": 0}, schema)


def test_vertex_areas_share_faces_equally():
    pts = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0.0]])
    tri = vertex_areas(pts, [CellBlock("triangle", [[0, 1, 2], [0, 2, 3]])])
    quad = vertex_areas(pts, [CellBlock("quad", [[0, 1, 2, 3]])])
    line = vertex_areas(pts, [CellBlock("line", [[0, 1], [1, 2]])])
    # 1e-15: sums of thirds/quarters of 0.5 and 1, rounding only
    np.testing.assert_allclose(tri, [1 / 3, 1 / 6, 1 / 3, 1 / 6], rtol=1e-15)
    np.testing.assert_allclose(quad, [0.25] * 4, rtol=1e-15)
    np.testing.assert_allclose(line, [0.5, 1, 0.5, 0], rtol=1e-15)


# ---------------------------------------------------------------------------------------------
# the warp itself


@pytest.mark.parametrize("rotate,reach", [(False, 0.25), (True, 0.25), (True, None), (True, 0.05)])
def test_kernels_match_numpy_reference(rotate, reach):
    pts, sid, areas, rng = sphere_cloud()
    st = WarpSettings(tolerance=1e-3, rotation_reach=reach)
    m = prepare_warp(pts, sid, settings=st, areas=areas)
    b = 0.05 * rng.normal(size=(len(sid), 3))
    R = np.stack([rot_z(a) for a in rng.uniform(-0.2, 0.2, len(sid))]) if rotate else None
    ref = idw_reference(m.surface_pos, areas[sid], b, R, pts[len(sid):] - m.origin, st, m.ldef,
                        m.rotation_length)
    exact = warp(m, b, R, exact=True)
    tree = warp(m, b, R)
    # the exact kernel is the same sum in another order: rounding only (|d| ~ 0.1)
    np.testing.assert_allclose(exact[len(sid):], ref, rtol=0, atol=1e-14)
    # the tree's documented guarantee: error <= tolerance x the largest surface displacement
    bmax = np.linalg.norm(b, axis=1).max()
    err = np.linalg.norm(tree - exact, axis=1).max()
    assert err <= st.tolerance * bmax, err / bmax
    assert err > 0        # it really approximated (a tree that never aggregates would pass above)
    # and tolerance 0 is the exact sum up to summation order
    m0 = prepare_warp(pts, sid, settings=WarpSettings(tolerance=0, rotation_reach=reach), areas=areas)
    np.testing.assert_allclose(warp(m0, b, R), exact, rtol=0, atol=1e-13)


def test_boundary_conditions(mesh):
    model, roles = prepare_mesh_warp(mesh, "wing")
    rng = np.random.default_rng(1)
    b = 0.02 * rng.normal(size=(model.n_surface, 3))
    b[mesh.points[model.surface_ids, 1] == 0, 1] = 0       # wing root stays on the symmetry plane
    d = warp(model, b)
    assert np.array_equal(d[roles.surface_ids], b)          # bit for bit
    assert np.all(d[roles.fixed_ids] == 0.0)
    (plane,) = roles.sliding
    assert np.all(d[plane.ids, 1] == 0.0)                  # on their plane exactly
    assert np.abs(d[plane.ids][:, [0, 2]]).max() > 1e-4    # and they do slide
    free = np.setdiff1d(np.arange(mesh.n_points), np.concatenate([roles.surface_ids, roles.fixed_ids,
                                                                   plane.ids]))
    assert np.abs(d[free]).max() > 1e-4


def test_method_none_moves_only_the_surface(mesh):
    model, roles = prepare_mesh_warp(mesh, "wing", WarpSettings(method="none"))
    b = np.full((model.n_surface, 3), 0.01)
    d = warp(model, b)
    assert np.array_equal(d[roles.surface_ids], b)
    assert np.count_nonzero(np.any(d != 0, axis=1)) == model.n_surface


def test_rigid_motion_without_fixed_sources_is_reproduced_exactly(mesh):
    """With only the surface as source, the normalised weights reproduce any rigid motion (without
    the rotation fade: with it, the rotation part is only carried near the surface)."""
    roles = marker_roles(mesh.points, mesh.markers, "wing", 3)
    model = prepare_warp(mesh.points, roles.surface_ids, faces=roles.faces,
                         settings=WarpSettings(rotation_reach=None))
    x = mesh.points
    t = np.array([0.03, -0.01, 0.02])
    d = warp(model, np.tile(t, (model.n_surface, 1)))
    # a group's aggregate of a constant motion is exact: rounding only (|d| ~ 0.04)
    np.testing.assert_allclose(d, np.broadcast_to(t, d.shape), rtol=0, atol=1e-15)
    p = np.array([0.5, 0.0, 0.0])                            # about the trailing edge, z axis
    R = rot_z(np.radians(10))
    b = (x[model.surface_ids] - p) @ (R - np.eye(3)).T
    d = warp(model, b, np.tile(R, (model.n_surface, 1, 1)))
    # beta_i = -M p and M are the same for every source, so aggregation is exact again
    np.testing.assert_allclose(d, (x - p) @ (R - np.eye(3)).T, rtol=0, atol=1e-14)


def test_fixed_farfield_near_surface_moves_almost_rigidly():
    """With the farfield fixed, nodes next to the wing follow its rigid motion, far ones do not.

    A first layer of nodes 0.02 chord off the wing (a boundary-layer-like spacing).
    """
    mesh = box_wing_mesh(x=[-2, -1.5, -1, -0.75, -0.52, -0.5, -0.25, 0, 0.25, 0.5, 0.52, 0.75, 1, 1.5, 2],
                         y=[0, 0.25, 0.5, 0.75, 1, 1.02, 1.25, 1.5, 2],
                         z=[-2, -1.5, -1, -0.5, -0.25, -0.12, -0.1, 0.1, 0.12, 0.25, 0.5, 1, 1.5, 2])
    model, roles = prepare_mesh_warp(mesh, "wing")
    x = mesh.points
    ws = x[roles.surface_ids]
    dist = np.min(np.linalg.norm(x[:, None, :] - ws[None, :, :], axis=2), axis=1)
    moving = np.ones(len(x), dtype=bool)
    moving[roles.surface_ids] = moving[roles.fixed_ids] = False
    near = moving & (dist <= 0.021)
    far = moving & (np.abs(x).max(axis=1) >= 1.5)
    assert near.sum() > 50 and far.sum() > 100
    t = np.array([0.0, 0.0, 0.05])
    d = warp(model, np.tile(t, (model.n_surface, 1)))
    # measured (alpha 1): at least 0.999 t near, at most 0.33 t at 1.5 chords (the farfield is at 2)
    assert np.all(d[near, 2] >= 0.999 * t[2]) and np.all(d[near, 2] <= t[2] * (1 + 1e-12))
    assert np.abs(d[far]).max() <= 0.4 * t[2]
    # the wing rotates 0.1 rad about its trailing edge: the first layer rotates with it
    p = np.array([0.5, 0.0, 0.0])
    R = np.array([[np.cos(0.1), 0, np.sin(0.1)], [0, 1, 0], [-np.sin(0.1), 0, np.cos(0.1)]])
    b = (ws - p) @ (R - np.eye(3)).T
    rigid = (x[near] - p) @ (R - np.eye(3)).T
    d = warp(model, b, np.tile(R, (model.n_surface, 1, 1)))
    rel = np.linalg.norm(d[near] - rigid, axis=1) / np.linalg.norm(rigid, axis=1)
    # measured 1.7e-3 at worst with the (faded) rotation term, 2.2e-4 without the fade, 0.2
    # without rotations (translations only)
    assert rel.max() < 3e-3
    d0 = warp(model, b)
    rel0 = np.linalg.norm(d0[near] - rigid, axis=1) / np.linalg.norm(rigid, axis=1)
    assert rel0.max() > 0.1


@pytest.mark.parametrize("n_far", [400, 4000])
def test_tree_with_a_fixed_farfield_keeps_the_error_bound(n_far):
    """The fixed sources' subtree (walked after the surface, weight only) against the direct sum:
    a far-field sphere of few and of many nodes around the sphere cloud."""
    pts, sid, areas, rng = sphere_cloud()
    far = rng.normal(size=(n_far, 3))
    far = 8.0 * far / np.linalg.norm(far, axis=1)[:, None]
    pts = np.vstack([pts, far])
    areas = np.concatenate([areas, np.full(n_far, 4 * np.pi * 64 / n_far)])
    fid = np.arange(len(pts) - n_far, len(pts))
    st = WarpSettings(tolerance=1e-3)
    m = prepare_warp(pts, sid, fid, settings=st, areas=areas)
    assert 0 < m.fixed_node < len(m.node_lo)
    b = 0.05 * rng.normal(size=(len(sid), 3))
    R = np.stack([rot_z(a) for a in rng.uniform(-0.2, 0.2, len(sid))])
    exact = warp(m, b, R, exact=True)
    tree = warp(m, b, R)
    np.testing.assert_array_equal(tree[fid], 0.0)
    bmax = np.linalg.norm(b, axis=1).max()
    err = np.linalg.norm(tree - exact, axis=1).max()
    assert 0 < err <= st.tolerance * bmax, err / bmax


@pytest.mark.parametrize("exact", [False, True])
def test_vjp_is_the_transpose(mesh, exact):
    model, roles = prepare_mesh_warp(mesh, "wing")
    rng = np.random.default_rng(2)
    ns = model.n_surface
    v = rng.normal(size=(ns, 3))
    V = rng.normal(size=(ns, 3, 3))
    g = rng.normal(size=(mesh.n_points, 3))
    gb, gM = warp_vjp(model, g, exact=exact)
    # the warp is one fixed linear map (b, M) -> d: its tree decisions depend on the mesh only
    lhs = np.sum(g * warp(model, v, np.eye(3) + V, exact=exact))
    rhs = np.sum(gb * v) + np.sum(gM * V)
    # both sides are the same bilinear form summed in a different order: rounding, ~1e-16 relative
    assert abs(lhs - rhs) <= 1e-12 * (abs(lhs) + np.abs(g).sum() * np.abs(v).max()), (lhs, rhs)
    lhs_b = np.sum(g * warp(model, v, exact=exact))
    assert abs(lhs_b - np.sum(gb * v)) <= 1e-12 * np.abs(g).sum() * np.abs(v).max()


def test_vjp_is_the_derivative_away_from_thresholds(mesh):
    """Finite differences of warp (the tree decisions do not depend on the motion) agree with the vjp."""
    model, _ = prepare_mesh_warp(mesh, "wing")
    rng = np.random.default_rng(3)
    ns = model.n_surface
    b0 = 0.02 * rng.normal(size=(ns, 3))
    g = rng.normal(size=(mesh.n_points, 3))
    v = rng.normal(size=(ns, 3))
    gb, _ = warp_vjp(model, g)
    h = 1e-3
    fd = (np.sum(g * warp(model, b0 + h * v)) - np.sum(g * warp(model, b0 - h * v))) / (2 * h)
    # warp is linear in b with the decisions fixed: central differences are exact up to rounding
    np.testing.assert_allclose(fd, np.sum(gb * v), rtol=1e-10)


# ---------------------------------------------------------------------------------------------
# rotations


def test_rotations_from_deformation_gradient():
    rng = np.random.default_rng(4)
    n = 50
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1)[:, None]
    w, x, y, z = q.T
    R = np.stack([np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
                  np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
                  np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1)], 1)
    A = rng.normal(size=(n, 3, 3)) * 0.2
    U = np.eye(3) + A @ A.transpose(0, 2, 1)                 # symmetric positive definite stretch
    out = rotations_from_deformation_gradient(R @ U)
    # SVD of well-conditioned 3x3 matrices: rounding only
    np.testing.assert_allclose(out, R, atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(out), 1, atol=1e-12)
    # 2D: rotation about z by theta, with an in-plane stretch
    th = rng.uniform(-1, 1, n)
    F = np.stack([rot_z(t) @ np.diag([1.2, 0.9, 1.0]) for t in th])
    out2 = rotations_from_deformation_gradient(F, axis=2)
    np.testing.assert_allclose(out2, np.stack([rot_z(t) for t in th]), atol=1e-12)


def annulus_mesh(nr=12, nt=64, r0=0.5, r1=10.0) -> Mesh:
    """A 2D O-mesh of quads in the x-y plane (z = 0): ``airfoil`` inside, ``farfield`` outside."""
    r = r0 * (r1 / r0) ** (np.arange(nr) / (nr - 1))
    t = 2 * np.pi * np.arange(nt) / nt
    R, T = np.meshgrid(r, t, indexing="ij")
    pts = np.column_stack([(R * np.cos(T)).ravel(), (R * np.sin(T)).ravel(), np.zeros(R.size)])
    idx = np.arange(nr * nt).reshape(nr, nt)
    i, j = (a.ravel() for a in np.meshgrid(np.arange(nr - 1), np.arange(nt), indexing="ij"))
    jn = (j + 1) % nt
    quads = np.column_stack([idx[i, j], idx[i + 1, j], idx[i + 1, jn], idx[i, jn]])
    lines = lambda k: np.column_stack([idx[k], np.roll(idx[k], -1)])  # noqa: E731
    return Mesh(points=pts, dim=2, cells=[CellBlock("quad", quads)],
                markers={"airfoil": [CellBlock("line", lines(0))],
                         "farfield": [CellBlock("line", lines(-1))]})


def test_2d_mesh_rotation_stays_in_plane():
    mesh = annulus_mesh()
    model, roles = prepare_mesh_warp(mesh, "airfoil")
    assert roles.roles == {"airfoil": "surface", "farfield": "fixed"}   # a circle is not a straight line
    x = mesh.points
    th = np.radians(5)
    Rz = rot_z(th)
    xs = x[model.surface_ids]
    F = np.tile(Rz, (model.n_surface, 1, 1))
    R = rotations_from_deformation_gradient(F, axis=2)
    d = warp(model, xs @ (Rz - np.eye(3)).T, R)
    assert np.all(d[:, 2] == 0.0)                         # the plane is kept exactly
    r = np.linalg.norm(x[:, :2], axis=1)
    first = np.isclose(r, r[model.surface_ids].max() * (10 / 0.5) ** (1 / 11))
    rigid = x[first] @ (Rz - np.eye(3)).T
    # the first ring (0.66 radius, 0.16 off the disc) rotates with it: measured 0.012 of the rigid
    # motion with the faded frame rotations (rotation_reach 0.3: rho = 0.3 x pi / 2; less at 0.5), 8.3e-4
    # without the fade, 0.30 without rotations
    err = np.linalg.norm(d[first] - rigid, axis=1).max() / np.linalg.norm(rigid, axis=1).min()
    assert err <= 0.02
    nofade, _ = prepare_mesh_warp(mesh, "airfoil", WarpSettings(rotation_reach=None))
    d1 = warp(nofade, xs @ (Rz - np.eye(3)).T, R)
    assert np.all(d1[:, 2] == 0.0)
    assert np.linalg.norm(d1[first] - rigid, axis=1).max() <= 2e-3 * np.linalg.norm(rigid, axis=1).min()
    d0 = warp(model, xs @ (Rz - np.eye(3)).T)
    assert np.linalg.norm(d0[first] - rigid, axis=1).max() >= 0.1 * np.linalg.norm(rigid, axis=1).min()


@pytest.mark.slow
def test_rotation_fade_bounds_the_overshoot(tmp_path):
    """A tip that twists: no volume node moves further than the surface motion near it explains.

    The bundled CRM-like wing (tip chord 0.3 inside the domain) twisted 10 degrees at the tip.
    Without the fade the rotation term carries the nodes a tip chord behind and above the tip
    round as a rigid body, 3.0 x further than any surface node moves; with it, carrying the FFD
    gradient (the default carry: the twist's spanwise rate is a shear the gradient keeps), 1.11 x
    at rotation_reach 0.3 and 1.18 x at the default 0.5 (1.09 x carrying the rotation at 0.3).
    """
    import yaml

    from ffdcli.app.run import load_run
    from ffdcli.design import load_design

    root = Path(__file__).resolve().parents[2]
    design = tmp_path / "d.yaml"
    design.write_text(yaml.safe_dump({"mesh": str(root / "samples" / "crm_wing.su2"), "surface": "wing",
                                      "box": {"points": [6, 8, 2], "sections": "xz"},
                                      "changes": [{"twist": {"tip": 10}}]}))
    run = load_run(load_design(design), cache_dir=tmp_path)
    P = run.lattice_after()
    b, R = run.surface_displacement(P), run.surface_frames(P)
    bmax = np.linalg.norm(b, axis=1).max()
    out = {}
    default = WarpSettings().rotation_reach
    for reach in (None, 0.3, default):
        model, _ = prepare_mesh_warp(run.prep.mesh, "wing", WarpSettings(rotation_reach=reach))
        out[reach] = np.linalg.norm(warp(model, b, R), axis=1).max() / bmax
    assert out[None] > 1.5, out
    assert out[0.3] <= 1.15, out
    assert default == 0.5 and out[default] <= 1.2, out


def test_one_schema_for_volume():
    """The design file's volume: block is WarpSettings' schema, gate keys included, and agrees with
    WarpSettings on every default (one home)."""
    from ffdcli.design.schema import design_schema
    from ffdcli.quality.rules import DEFAULT_THRESHOLD
    from ffdcli.settings import GATE_KEYS

    vol = design_schema()["properties"]["volume"]
    assert vol == WarpSettings.schema()
    props = vol["properties"]
    st = WarpSettings()
    for name, doc in WarpSettings.field_docs().items():
        assert props[name]["description"] == doc
        if "default" in props[name]:
            assert props[name]["default"] == getattr(st, name), name
    assert set(props) == set(WarpSettings.field_docs()) | set(GATE_KEYS)
    assert props["threshold"]["default"] == DEFAULT_THRESHOLD
    # every key of the schema is accepted by from_dict, and a gate key is not the warp's
    assert WarpSettings.from_dict({"threshold": 0.1, "rotation_reach": None, "chunk": 1000}).chunk == 1000
    with pytest.raises(InputError, match="rotation_reach"):
        WarpSettings.from_dict({"rotation_reach": -1})


@pytest.mark.parametrize("rotate", [False, True])
def test_a_node_moves_the_same_whichever_nodes_are_warped_with_it(rotate):
    """The block walk only shares the walk: each node's decisions and sums are its own, so a warp of a
    subset of the nodes (an MPI rank's part, ``targets=``) or of a row range that cuts blocks gives each
    node the whole run's value, bit for bit; and the subset's transpose is the transpose."""
    pts, sid, areas, rng = sphere_cloud(ns=2000, nt=6000, seed=3)
    b = 0.02 * rng.normal(size=(len(sid), 3))
    R = np.stack([rot_z(a) for a in 0.1 * rng.normal(size=len(sid))]) if rotate else None
    whole_model = prepare_warp(pts, sid, areas=areas)
    whole = warp(whole_model, b, R)
    sub = rng.choice(np.arange(len(sid), len(pts)), size=700, replace=False)
    part_model = prepare_warp(pts, sid, areas=areas, targets=sub)
    part = warp(part_model, b, R)
    np.testing.assert_array_equal(part[sub], whole[sub])
    rows = [warp(whole_model, b, R, rows=r) for r in ((0, 37), (37, 1000), (1000, whole_model.n_targets))]
    np.testing.assert_array_equal(np.concatenate(rows), whole[whole_model.target_ids])
    g = np.zeros_like(part)
    g[sub] = rng.normal(size=(len(sub), 3))
    gb, gM = warp_vjp(part_model, g)
    V = 1e-3 * rng.normal(size=(len(sid), 3, 3))
    lhs = float((g * warp(part_model, b, np.eye(3) + V)).sum())
    assert lhs == pytest.approx(float((gb * b).sum() + (gM * V).sum()), rel=1e-12, abs=1e-14)
