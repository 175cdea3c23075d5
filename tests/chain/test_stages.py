"""Each stage of the derivative chain on its own: its ``jvp`` against central differences of
its ``forward``, and its ``vjp`` the exact transpose of its ``jvp`` (``<J dx, w> = <dx, J^T w>``), in
several random directions, 3D and 2D, one component and several, both frame carries."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import REPO
from test_components import THREE, write_components, write_parts
from wingcase import write_design, write_volume_wing

from ffdcli.app.run import load_run
from ffdcli.chain import (
    FrameStage,
    LatticeStage,
    MeshShare,
    QualityStage,
    Stage,
    SurfaceStage,
    VolumeStage,
    derivative_basis,
)
from ffdcli.constraints.base import ConstraintContext
from ffdcli.constraints.mesh_quality import MeshQuality
from ffdcli.design import load_design
from ffdcli.lattice.lattice import derivatives
from ffdcli.parameterization.components import layout
from ffdcli.settings import WarpSettings


# -- structured inputs: arrays or tuples of arrays ---------------------------------------------------
def _map(f, *xs):
    if isinstance(xs[0], tuple):
        return tuple(_map(f, *ys) for ys in zip(*xs, strict=True))
    return f(*xs)


def _dot(a, b) -> float:
    if isinstance(a, tuple):
        return sum(_dot(x, y) for x, y in zip(a, b, strict=True))
    return float(np.sum(np.asarray(a) * np.asarray(b)))


def _norm(a) -> float:
    return _dot(a, a) ** 0.5


def _random_like(x, rng, scale=1.0):
    return _map(lambda a: scale * rng.standard_normal(np.shape(a)), x)


def check_stage(stage: Stage, x, dx, *, h: float, rel: float, seeds=(0, 1, 2)):
    """jvp against central differences; vjp against jvp in random directions ``w``."""
    yp = stage.forward(_map(lambda a, d: a + h * d, x, dx))
    ym = stage.forward(_map(lambda a, d: a - h * d, x, dx))
    fd = _map(lambda p, m: (np.asarray(p) - np.asarray(m)) / (2 * h), yp, ym)
    jv = stage.jvp(x, dx)
    err = _norm(_map(lambda a, b: np.asarray(a) - np.asarray(b), jv, fd))
    assert err <= rel * max(_norm(fd), 1e-300), (type(stage).__name__, err, _norm(fd))
    assert _norm(jv) > 0, "a direction that moves nothing proves nothing"
    for seed in seeds:
        rng = np.random.default_rng(100 + seed)
        w = _random_like(jv, rng)
        d2 = _random_like(dx, rng)
        lhs = _dot(stage.jvp(x, d2), w)
        rhs = _dot(d2, stage.vjp(x, w))
        assert lhs == pytest.approx(rhs, rel=1e-10, abs=1e-12 * _norm(w) * _norm(d2)), type(stage).__name__


# -- designs -----------------------------------------------------------------------------------------
CHANGES = [{"twist": {"root": 1, "tip": 8}}, {"span": 1.05}, {"sweep": 4}, {"chord": {"tip": 0.8}},
           {"shape": {"upper": [0, .01, .015, .01, .005, 0], "lower": [0, -.005, -.01, -.005, 0, 0]}}]


@pytest.fixture(scope="module")
def wing3d(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("wing3d")
    mesh = write_volume_wing(tmp, le_sweep_deg=15)
    return load_run(load_design(write_design(tmp, mesh, CHANGES, volume={"method": "idw"})), use_cache=False)


@pytest.fixture(scope="module")
def airfoil2d():
    return load_run(load_design(REPO / "configs" / "naca0012_s1223.yaml"), use_cache=False)


@pytest.fixture(scope="module")
def three(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("three")
    mesh = write_parts(tmp, "span-y")
    return load_run(load_design(write_components(tmp, mesh, THREE)), use_cache=False)


def _values(run):
    return run.variables()[1]


def _stages(run):
    comps = run.components
    lay = layout(comps)
    S = len(run.surface_ids)
    return comps, lay, S


def _lattices(run):
    return LatticeStage(run.components).forward(_values(run))


# -- values -> lattices ------------------------------------------------------------------------------
@pytest.mark.parametrize("case", ["wing3d", "airfoil2d", "three"])
def test_lattice_stage(case, request):
    run = request.getfixturevalue(case)
    stage = LatticeStage(run.components)
    v = _values(run)
    rng = np.random.default_rng(len(v))
    for _ in range(2):
        dv = rng.standard_normal(len(v))
        check_stage(stage, v, dv, h=1e-6, rel=1e-6)


def test_lattice_stage_recomputes_only_for_other_values(wing3d):
    stage = LatticeStage(wing3d.components)
    v = _values(wing3d)
    a = stage.forward(v)
    assert stage.forward(v.copy()) is a                       # the same values (another array): kept
    w = v.copy()
    w[0] += 1.0
    b = stage.forward(w)
    assert b is not a and not np.array_equal(a[0], b[0])     # other values: recomputed, no clearing by hand
    assert np.array_equal(stage.forward(v)[0], a[0])


# -- lattices -> surface ----------------------------------------------------------------------------
@pytest.mark.parametrize("case", ["wing3d", "airfoil2d", "three"])
def test_surface_stage(case, request):
    run = request.getfixturevalue(case)
    comps, lay, S = _stages(run)
    stage = SurfaceStage(comps, lay.rows, S)
    Ps = _lattices(run)
    rng = np.random.default_rng(7)
    dPs = tuple(_plane(c, rng.standard_normal(P.shape) * 0.01) for c, P in zip(comps, Ps, strict=True))
    check_stage(stage, Ps, dPs, h=1e-3, rel=1e-9)
    assert np.array_equal(stage.forward(Ps), run.surface_displacement(list(Ps)))    # what ffd deform moves


def _plane(comp, dP):
    """A change of a 2D lattice moves its points in the airfoil's plane (the core spline's)."""
    if comp.box.dim == 3:
        return dP
    out = np.zeros_like(dP)
    out[..., comp.box.plane_axes] = dP[..., comp.box.plane_axes]
    return out


# -- lattices -> frames -----------------------------------------------------------------------------
def test_derivative_basis_is_the_lattice_derivative(wing3d, airfoil2d):
    for run in (wing3d, airfoil2d):
        comp = run.components[0]
        rng = np.random.default_rng(3)
        P = comp.P0 + _plane(comp, 0.05 * rng.standard_normal(comp.P0.shape))
        params = comp.prep.embedding.params[comp.prep.embedding.inside][:200]
        dB = derivative_basis(comp.box.lattice(comp.P0), params)
        core = comp.box.core_control_points(P).reshape(-1, comp.box.dim if comp.box.dim == 3 else 2)
        J = np.stack([B @ core for B in dB], axis=-1)
        assert np.allclose(J, derivatives(comp.box.lattice(P), params), rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("carry", ["gradient", "rotation"])
@pytest.mark.parametrize("case", ["wing3d", "airfoil2d", "three"])
def test_frame_stage(case, carry, request):
    run = request.getfixturevalue(case)
    comps, lay, S = _stages(run)
    stage = FrameStage(comps, lay.rows, S, carry)
    Ps = _lattices(run)
    rng = np.random.default_rng(11)
    for _ in range(2):
        dPs = tuple(_plane(c, rng.standard_normal(P.shape) * 0.01) for c, P in zip(comps, Ps, strict=True))
        check_stage(stage, Ps, dPs, h=1e-5, rel=1e-6)
    assert np.array_equal(stage.forward(Ps), run.surface_frames(list(Ps), carry))


# -- surface and frames -> volume --------------------------------------------------------------------
@pytest.mark.parametrize("case", ["wing3d", "airfoil2d"])
def test_volume_stage(case, request):
    run = request.getfixturevalue(case)
    mesh = run.prep.mesh
    names = [n for c in run.components for n in c.prep.surface.names]
    settings = WarpSettings.from_dict(run.design.volume or {})
    stage = VolumeStage(MeshShare(mesh), run.surface_ids, names, settings, moves=True)
    S = len(run.surface_ids)
    rng = np.random.default_rng(5)
    b = 0.01 * rng.standard_normal((S, 3))
    F = np.eye(3) + 0.02 * rng.standard_normal((S, 3, 3))
    if mesh.dim == 2:           # a 2D mesh moves in its plane
        span = run.box.axes.span
        b[:, span] = 0.0
        F[:, span, :] = F[:, :, span] = 0.0
        F[:, span, span] = 1.0
    db = rng.standard_normal((S, 3)) * 0.01
    dF = rng.standard_normal((S, 3, 3)) * 0.01
    if mesh.dim == 2:
        db[:, span] = 0.0
        dF[:, span, :] = dF[:, :, span] = 0.0
    check_stage(stage, (b, F), (db, dF), h=1e-3, rel=1e-8)
    X = stage.forward((b, F))
    assert np.array_equal(X[run.surface_ids], mesh.points[run.surface_ids] + b)   # the surface exactly


# -- volume -> quality --------------------------------------------------------------------------------
@pytest.mark.parametrize("case", ["wing3d", "airfoil2d"])
def test_quality_stage(case, request):
    run = request.getfixturevalue(case)
    mesh = run.prep.mesh
    items = [MeshQuality.from_spec(spec, ConstraintContext(index=k, key=f"constraints[{k}].mesh_quality", lower=0.3,
                                                           upper=np.inf, box=run.box, surface=run.prep.surface,
                                                           mesh=mesh))
             for k, spec in enumerate([{}, {"gap": 0.05, "good": 0.8}])]
    chord = 0.5 * float(np.ptp(mesh.points[run.surface_ids], axis=0).max())
    stage = QualityStage(items, mesh.points, run.surface_ids, lambda: 0.3 * chord)
    comps, lay, S = _stages(run)
    Ps = _lattices(run)
    b = SurfaceStage(comps, lay.rows, S).forward(Ps)
    F = FrameStage(comps, lay.rows, S, "gradient").forward(Ps)
    names = [n for c in run.components for n in c.prep.surface.names]
    settings = WarpSettings.from_dict(run.design.volume or {})
    X = VolumeStage(MeshShare(mesh), run.surface_ids, names, settings, moves=True).forward(
        (b, FrameStage(comps, lay.rows, S, settings.carry).forward(Ps)))      # the design's own mesh
    rng = np.random.default_rng(9)
    # a generic point: where the design leaves a cell near the wall as it was, its map quality equals its
    # input quality and the reference min(base, map) has a kink (the derivative is one-sided there)
    b = b + 1e-4 * rng.standard_normal(b.shape)
    F = F + 1e-4 * rng.standard_normal(F.shape)
    dX = rng.standard_normal(X.shape) * 1e-3
    db = rng.standard_normal(b.shape) * 1e-3
    dF = rng.standard_normal(F.shape) * 1e-3
    if mesh.dim == 2:
        span = run.box.axes.span
        for a in (dX, db, b):
            a[:, span] = 0.0
        for a in (dF, F):
            a[:, span, :] = a[:, :, span] = 0.0
        F[:, span, span] = 1.0
    assert stage.zone().nodes.size
    check_stage(stage, (X, b, F), (dX, db, dF), h=1e-6, rel=1e-5)
    # the design map's part is exercised: some cell near the wall is judged against the map
    assert any(G_map is not None and np.any(G_map) for _, G_map in stage.gradients((X, b, F)))
