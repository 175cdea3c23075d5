"""Point inversion and the sparse basis (ffdcli.lattice.embedding) on curved, non-affine lattices."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from lattice_cases import curved_patch, wing_grid, wing_lattice

from ffdcli.errors import InputError
from ffdcli.lattice.embedding import (
    DEFAULT_TOL,
    Embedding,
    basis_matrix_reference,
    dense_basis_reference,
    embed,
    sample_grid,
)
from ffdcli.lattice.lattice import Lattice, evaluate
from ffdcli.lattice.spline import basis, basis_compiled

CASES = {
    "3d-wing": lambda: wing_lattice((8, 6, 2), (3, 3, 1)),
    "3d-wing-16x12x4": lambda: wing_lattice((16, 12, 4), 3),
    "2d-gdim2": lambda: curved_patch((6, 5), (3, 2), gdim=2),
}


def random_params(rng, pdim, n):
    u = rng.uniform(0.0, 1.0, (n, pdim))
    u[: n // 8, 0] = rng.choice([0.0, 1.0], n // 8)        # some points on faces (a wing root)
    u[n // 8: n // 4, -1] = rng.choice([0.0, 1.0], n // 8)
    return u


@pytest.fixture(scope="module", params=sorted(CASES))
def embedded(request):
    lat = CASES[request.param]()
    rng = np.random.default_rng(7)
    u = random_params(rng, lat.pdim, 3000)
    X = evaluate(lat, u)
    return lat, u, X, embed(lat, X)


def test_points_of_the_lattice_are_recovered(embedded):
    lat, u, X, emb = embedded
    assert emb.inside.all()
    assert emb.tolerance == pytest.approx(DEFAULT_TOL * lat.size, rel=1e-15)
    assert np.max(emb.residual) <= 1e-10 * lat.size
    # the residual is what it says: |V(params) - X|
    np.testing.assert_allclose(emb.residual, np.linalg.norm(evaluate(lat, emb.params) - X, axis=1),
                               rtol=0, atol=1e-15 * lat.size)
    # params: residual <= 1e-10 size and the lattice Jacobian's smallest singular value is at least
    # ~0.02 size here, so params are within 5e-9 of the generating ones (a wrong branch is off by > 1e-2)
    np.testing.assert_allclose(emb.params, u, rtol=0, atol=5e-9)
    # face parameters are exact (snapped) for points on a face
    on_face = (u == 0.0) | (u == 1.0)
    np.testing.assert_array_equal(emb.params[on_face], u[on_face])


def test_embedding_evaluate_reproduces_points(embedded):
    lat, u, X, emb = embedded
    P0 = lat.control_points
    np.testing.assert_allclose(emb.evaluate(P0), X, rtol=0, atol=1e-10 * lat.size)
    np.testing.assert_allclose(emb.evaluate(P0.reshape(-1, lat.gdim)), emb.evaluate(P0), rtol=0, atol=0)
    # zero change, exact zero displacement
    assert not np.any(emb.displace(np.zeros_like(P0)))


def test_basis_matrix_products(embedded):
    lat, u, X, emb = embedded
    B = emb.basis_matrix()
    assert B.shape == (emb.n_points, lat.n_ctrl)
    nnz_row = int(np.prod([p + 1 for p in lat.degree]))
    assert B.nnz == emb.n_points * nnz_row
    P = lat.control_points.reshape(-1, lat.gdim)
    # B @ P and the compiled kernel sum the same products in another order: ~ulps of the coordinates
    np.testing.assert_allclose(B @ P, emb.evaluate(P), rtol=0, atol=1e-13 * lat.size)
    np.testing.assert_allclose(B @ P, evaluate(lat, emb.params), rtol=0, atol=1e-13 * lat.size)
    np.testing.assert_allclose(B.sum(axis=1).A1, 1.0, rtol=0, atol=1e-14)
    dense = dense_basis_reference(lat, emb.params[:200])
    np.testing.assert_allclose(B[:200].toarray(), dense, rtol=0, atol=1e-14)
    rng = np.random.default_rng(8)
    dP = rng.normal(size=P.shape)
    np.testing.assert_allclose(emb.displace(dP), B @ dP, rtol=0, atol=1e-13)


def test_basis_matrix_is_the_numpy_construction_bit_for_bit(embedded):
    """The compiled CSR construction equals the NumPy reference exactly (same products in the same
    order), also with outside points (empty rows) in between."""
    lat, u, X, emb = embedded
    inside = np.ones(emb.n_points, dtype=bool)
    inside[[0, 5, 6, 1000, emb.n_points - 1]] = False
    for e in (emb, Embedding.from_params(lat, emb.params, inside, emb.residual)):
        B, ref = e.basis_matrix(), basis_matrix_reference(e)
        assert B.shape == ref.shape and B.has_sorted_indices
        np.testing.assert_array_equal(B.indptr, ref.indptr)
        np.testing.assert_array_equal(B.indices, ref.indices)
        np.testing.assert_array_equal(B.data, ref.data)


@settings(max_examples=10, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), gdim_cols=st.integers(1, 3))
def test_rmatvec_is_the_transpose(embedded, seed, gdim_cols):
    lat, u, X, emb = embedded
    rng = np.random.default_rng(seed)
    g = rng.normal(size=(emb.n_points, gdim_cols))
    B = emb.basis_matrix()
    # sums of ~3000 products of order 1 accumulated in another order: 1e-12 relative to the largest
    np.testing.assert_allclose(emb.rmatvec(g), B.T @ g, rtol=0, atol=1e-12 * np.abs(g).sum())
    x = rng.normal(size=(lat.n_ctrl, gdim_cols))
    lhs = np.sum(emb.displace(x) * g)
    np.testing.assert_allclose(lhs, np.sum(x * emb.rmatvec(g)), rtol=1e-11)


@settings(max_examples=8, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_affine_invariance(embedded, seed):
    """Moving every control point by A P + b moves every embedded point by A X + b."""
    lat, u, X, emb = embedded
    rng = np.random.default_rng(seed)
    A = np.eye(lat.gdim) + 0.3 * rng.normal(size=(lat.gdim, lat.gdim))
    b = rng.normal(size=lat.gdim)
    P = lat.control_points.reshape(-1, lat.gdim)
    scale = lat.size * np.abs(A).max() + np.abs(b).max()
    np.testing.assert_allclose(emb.evaluate(P @ A.T + b), X @ A.T + b, rtol=0, atol=1e-10 * scale)
    np.testing.assert_allclose(emb.displace(P @ (A - np.eye(lat.gdim)).T + b), X @ A.T + b - X,
                               rtol=0, atol=1e-10 * scale)


def test_from_params_round_trip(embedded):
    lat, u, X, emb = embedded
    back = Embedding.from_params(lat, emb.params, emb.inside, emb.residual)
    assert back.tolerance == emb.tolerance
    assert back.shape == emb.shape and back.degree == emb.degree
    for a in range(lat.pdim):
        np.testing.assert_array_equal(back.first[a], emb.first[a])
        np.testing.assert_array_equal(back.values[a], emb.values[a])
    P = lat.control_points
    np.testing.assert_array_equal(back.evaluate(P), emb.evaluate(P))
    # the one-pass kernel of all axes gives the 1D compiled basis of each axis, bit for bit, and
    # agrees with the NumPy Cox-de Boor
    for a in range(lat.pdim):
        f, v = basis_compiled(lat.knots[a], lat.degree[a], emb.params[:, a])
        np.testing.assert_array_equal(back.first[a], f)
        np.testing.assert_array_equal(back.values[a], v)
        f, v = basis(lat.knots[a], lat.degree[a], emb.params[:, a])
        np.testing.assert_array_equal(back.first[a], f)
        np.testing.assert_allclose(back.values[a], v, rtol=0, atol=1e-14)
    bad = emb.params.copy()
    bad[-1, -1] = np.nan
    with pytest.raises(ValueError, match="must lie in"):
        Embedding.from_params(lat, bad, emb.inside, emb.residual)
    with pytest.raises(ValueError, match="params must have shape"):
        Embedding.from_params(lat, emb.params[:, :1], emb.inside, emb.residual)
    with pytest.raises(ValueError, match="inside and residual"):
        Embedding.from_params(lat, emb.params, emb.inside[1:], emb.residual)
    with pytest.raises(ValueError, match="must lie in"):
        Embedding.from_params(lat, emb.params + 2.0, emb.inside, emb.residual)


# ---------------------------------------------------------------------------------------------- outside

def test_points_outside_are_reported_not_snapped():
    lat = wing_lattice()
    rng = np.random.default_rng(9)
    u = rng.uniform(0, 1, (400, 3))
    X = evaluate(lat, u)
    out_idx = np.arange(0, 400, 10)
    # push every 10th point out of the top face along z (the thickness direction points up)
    u_top = u[out_idx].copy()
    u_top[:, 2] = 1.0
    X[out_idx] = evaluate(lat, u_top) + np.array([0.0, 0.0, 0.2])
    # and a few far away
    X[5] = [100.0, 0.0, 0.0]
    X[7] = [-50.0, 30.0, -20.0]
    out_idx = np.sort(np.concatenate([out_idx, [5, 7]]))
    emb = embed(lat, X)
    np.testing.assert_array_equal(np.flatnonzero(~emb.inside), out_idx)
    assert np.all(emb.residual[out_idx] > emb.tolerance)
    assert np.all(emb.residual[emb.inside] <= emb.tolerance)
    assert np.all((emb.params >= 0) & (emb.params <= 1))
    # residual is the distance to the nearest lattice point: at most the 0.2 offset for the pushed
    # points, and at least the distance of the far points to the control-point bounding box
    pushed = np.setdiff1d(out_idx, [5, 7])
    assert np.all(emb.residual[pushed] <= 0.2 + 1e-12)
    assert np.all(emb.residual[pushed] > 0.05)
    assert emb.residual[5] > 100.0 - lat.control_points[..., 0].max()
    # outside points do not move with the lattice
    dP = rng.normal(size=lat.control_points.shape)
    d = emb.displace(dP)
    assert not np.any(d[out_idx])
    assert np.all(np.abs(d[emb.inside]).sum(axis=1) > 0)
    B = emb.basis_matrix()
    assert B[out_idx].nnz == 0
    np.testing.assert_allclose(emb.rmatvec(np.ones((400, 3))), B.T @ np.ones((400, 3)), rtol=0, atol=1e-12)
    rep = emb.outside_report(max_indices=5)
    assert rep["count"] == out_idx.size and rep["indices"] == list(out_idx[:5])
    assert rep["worst_index"] == 5 and rep["worst_distance"] == emb.residual[5]
    assert rep["tolerance"] == emb.tolerance


def test_outside_distance_in_a_box_is_exact():
    """Trilinear unit box: the nearest point of (1.5, 0.5, 0.5) is (1, 0.5, 0.5) at distance 0.5."""
    g = np.stack(np.meshgrid([0.0, 1.0], [0.0, 1.0], [0.0, 1.0], indexing="ij"), axis=-1)
    lat = Lattice(g, 1)
    emb = embed(lat, [[1.5, 0.5, 0.5], [0.25, -0.5, 0.75], [0.3, 0.4, 0.5]])
    np.testing.assert_array_equal(emb.inside, [False, False, True])
    np.testing.assert_allclose(emb.residual[:2], [0.5, 0.5], rtol=0, atol=1e-12)
    np.testing.assert_allclose(emb.params, [[1.0, 0.5, 0.5], [0.25, 0.0, 0.75], [0.3, 0.4, 0.5]],
                               rtol=0, atol=1e-12)
    rep = Embedding.outside_report(embed(lat, [[0.5, 0.5, 0.5]]))
    assert rep == {"count": 0, "indices": [], "worst_distance": 0.0, "worst_index": None,
                   "tolerance": emb.tolerance}


def test_sample_grid_covers_every_span():
    lat = wing_lattice((8, 6, 2), (3, 3, 1))
    s = sample_grid(lat, 4)
    # 5 spans x 4 + 1 = 21 along u, 3 spans x 4 + 1 = 13 along v, 1 span x 4 + 1 = 5 along w
    assert s.shape == (21 * 13 * 5, 3)
    assert s.min() == 0.0 and s.max() == 1.0


def test_progress_is_called():
    lat = wing_lattice()
    calls = []

    class Bar:
        def __enter__(self):
            return self

        def __exit__(self, *exc):
            return False

        def update(self, n):
            calls.append(n)

    def factory(label, total):
        calls.append((label, total))
        return Bar()

    embed(lat, evaluate(lat, np.full((10, 3), 0.5)), progress=factory)
    assert calls[0] == ("embedding", 10) and sum(calls[1:]) == 10


# ---------------------------------------------------------------------------------------------- bad input

def test_embed_rejects_bad_input():
    lat = wing_lattice()
    with pytest.raises(InputError, match="NaN"):
        embed(lat, [[0.0, 0.0, np.nan]])
    with pytest.raises(InputError, match="NaN"):
        embed(lat, [[0.0, np.inf, 0.0]])
    with pytest.raises(ValueError, match=r"points must have shape \(N, 3\)"):
        embed(lat, np.zeros((4, 2)))
    with pytest.raises(ValueError, match=r"points must have shape \(N, 3\)"):
        embed(lat, np.zeros(3))
    with pytest.raises(ValueError, match="tol must be positive"):
        embed(lat, np.zeros((1, 3)), tol=0.0)
    emb = embed(lat, np.zeros((0, 3)))
    assert emb.n_points == 0 and emb.evaluate(lat.control_points).shape == (0, 3)
    emb = embed(lat, evaluate(lat, np.full((3, 3), 0.5)))
    with pytest.raises(ValueError, match="control_points must have shape"):
        emb.evaluate(np.zeros((8, 6, 3, 3)))
    with pytest.raises(ValueError, match="delta_control_points must have shape"):
        emb.displace(np.zeros((95, 3)))
    with pytest.raises(ValueError, match="g must have shape"):
        emb.rmatvec(np.zeros((4, 3)))
    with pytest.raises(InputError, match="needs more than 3 control points"):
        Lattice(wing_grid((3, 6, 2)), (3, 3, 1))


def test_2d_embedding_with_three_coordinates():
    lat = curved_patch((5, 4), (4, 1), gdim=3)
    rng = np.random.default_rng(11)
    u = rng.uniform(0, 1, (300, 2))
    X = evaluate(lat, u)
    emb = embed(lat, X)
    assert emb.inside.all() and emb.residual.max() <= 1e-10 * lat.size
    np.testing.assert_allclose(emb.params, u, rtol=0, atol=5e-9)
    # a point off the surface (along its normal) is outside at its normal distance
    du = evaluate(lat, u[:1] + [[1e-6, 0]]) - evaluate(lat, u[:1] - [[1e-6, 0]])
    dv = evaluate(lat, u[:1] + [[0, 1e-6]]) - evaluate(lat, u[:1] - [[0, 1e-6]])
    nrm = np.cross(du[0], dv[0])
    nrm /= np.linalg.norm(nrm)
    emb2 = embed(lat, X[:1] + 1e-3 * nrm)
    assert not emb2.inside[0]
    assert emb2.residual[0] == pytest.approx(1e-3, rel=1e-3)
    assert not np.any(emb2.displace(np.ones(lat.control_points.shape)))


def test_out_argument_is_filled_and_checked(embedded):
    lat, u, X, emb = embedded
    P = lat.control_points
    buf = np.full((emb.n_points, lat.gdim), np.nan)
    assert emb.evaluate(P, out=buf) is buf
    np.testing.assert_array_equal(buf, emb.evaluate(P))
    assert emb.displace(np.ones_like(P), out=buf) is buf
    np.testing.assert_array_equal(buf, emb.displace(np.ones_like(P)))
    for bad in (np.empty((emb.n_points, lat.gdim), dtype=np.float32), np.empty((emb.n_points + 1, lat.gdim)),
                np.empty((lat.gdim, emb.n_points)).T):
        with pytest.raises(ValueError, match="out must be"):
            emb.evaluate(P, out=bad)


@pytest.mark.parametrize("case", sorted(CASES))
def test_start_table_kernel_matches_numpy_and_starts_near(case):
    """The compiled start lookup equals its NumPy reference (points inside, on and far outside the
    grid), and its starts are close: half the points start within 2e-2 of their parameters (about a
    third of a cell: the table has about one cell per start sample, its build being a fixed cost of
    every embed call), and Gauss-Newton from these starts converges in a few steps."""
    from scipy.spatial import cKDTree

    from ffdcli.lattice._newton_kernels import run_newton
    from ffdcli.lattice.embedding import SNAP, StartTable, start_reference
    from ffdcli.lattice.lattice import kernel_args

    lat = CASES[case]()
    rng = np.random.default_rng(3)
    samples = sample_grid(lat, 4)
    S = evaluate(lat, samples)
    table = StartTable.build(lat, samples, S, cKDTree(S), 1e-10 * lat.size)
    u = rng.uniform(0.0, 1.0, (2000, lat.pdim))
    X = evaluate(lat, u)
    far = S.min(axis=0) + rng.uniform(-1.0, 2.0, (300, S.shape[1])) * np.ptp(S, axis=0)
    pts = np.concatenate([X, far, S[:50]])
    got = table.start(pts)
    np.testing.assert_allclose(got, start_reference(table, pts), rtol=0, atol=1e-14)
    assert got.shape == (len(pts), lat.pdim) and np.all((got >= 0) & (got <= 1))
    err = np.abs(got[: len(X)] - u).max(axis=1)
    assert np.median(err) < 2e-2
    params, residual = got[: len(X)].copy(), np.empty(len(X))
    run_newton(kernel_args(lat), X, params, residual, 1e-10 * lat.size, 1e-13 * lat.size, SNAP, 5)
    assert np.mean(residual <= 1e-10 * lat.size) > 0.99
