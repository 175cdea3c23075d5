"""B.T @ g (Embedding.rmatvec) by the vectorised kernels against the NumPy/SciPy reference, and the
vector fused multiply-adds (ffdcli.jit) they are built on."""

from __future__ import annotations

import numba
import numpy as np
import pytest
from lattice_cases import curved_patch, wing_lattice
from numba import njit
from numba.core.errors import TypingError

from ffdcli.jit import axpy4, axpy8, axpy8x3
from ffdcli.lattice._embedding_kernels import _rmatvec_442_nb, _rmatvec_442c_nb, _rmatvec_nb
from ffdcli.lattice.embedding import (
    Embedding,
    basis_matrix_reference,
    dense_basis_reference,
    rmatvec_reference,
)
from ffdcli.lattice.lattice import evaluate_reference
from ffdcli.lattice.pointset import PointSet
from ffdcli.parameterization.derivatives import lattice_jacobian, vjp

CASES = {
    "3d-442": lambda: wing_lattice((8, 6, 2), (3, 3, 1)),          # the default box: the 8-wide kernel
    "3d-cubic-16x12x4": lambda: wing_lattice((16, 12, 4), 3),
    "3d-mixed-6x5x3": lambda: wing_lattice((6, 5, 3), (2, 1, 2)),
    "3d-linear-w-not-contiguous": lambda: wing_lattice((8, 6, 4), (3, 3, 1)),
    "2d-gdim2": lambda: curved_patch((6, 5), (3, 2), gdim=2),
    "2d-gdim3": lambda: curved_patch((7, 4), (2, 3), gdim=3),
}


def _embedding(lat, n, seed, outside=()):
    """An Embedding of n random parameters (faces included) without the Newton solve."""
    rng = np.random.default_rng(seed)
    u = rng.uniform(0.0, 1.0, (n, lat.pdim))
    u[: n // 8, 0] = rng.choice([0.0, 1.0], n // 8)
    u[n // 8: n // 4, -1] = rng.choice([0.0, 1.0], n // 4 - n // 8)
    inside = np.ones(n, dtype=bool)
    inside[list(outside)] = False
    return Embedding.from_params(lat, u, inside, np.where(inside, 0.0, 1.0))


def _bound(emb, g):
    """Per entry: sum of |B_ik g_i| over the points, the scale of the rounding errors of B.T @ g."""
    return np.asarray(abs(basis_matrix_reference(emb)).T @ np.abs(g))


@pytest.mark.parametrize("case", sorted(CASES))
@pytest.mark.parametrize("gdim", [1, 2, 3])
def test_rmatvec_matches_the_reference(case, gdim):
    lat = CASES[case]()
    emb = _embedding(lat, 5000, seed=gdim)
    g = np.random.default_rng(11).normal(size=(emb.n_points, gdim))
    got, ref = emb.rmatvec(g), rmatvec_reference(emb, g)
    assert got.shape == (lat.n_ctrl, gdim) and got.flags.c_contiguous
    # same products, summed in another order (per chunk, then over the chunks): ~1e-16 of the sum
    # of |terms|; 1e-13 leaves room for any order, a wrong product or index is O(1) off
    assert np.all(np.abs(got - ref) <= 1e-13 * _bound(emb, g))


@pytest.mark.parametrize("shape", [(8, 6, 2), (8, 6, 4)])
def test_the_442_kernels_are_the_general_one_to_rounding(shape):
    """The cubic-cubic-linear kernels (8-wide; 24-wide when the third axis has 2 control points) and
    the general 4-wide one give the same sums to ulps (their products are grouped differently), for
    any split into chunks; the result is the chunks' sum in chunk order."""
    lat = wing_lattice(shape, (3, 3, 1))
    emb = _embedding(lat, 20_000, seed=3, outside=[0, 17, 19_999])
    g = np.random.default_rng(4).normal(size=(emb.n_points, 3))
    axes = emb._kernel_axes()
    kernels = [(_rmatvec_nb, 4), (_rmatvec_442_nb, 4)] + ([(_rmatvec_442c_nb, 3)] if shape[2] == 2 else [])
    for nchunk in (1, 3, 8, 4 * numba.get_num_threads()):
        results = []
        for kernel, stride in kernels:
            acc, out = np.zeros((nchunk, stride * lat.n_ctrl)), np.empty((lat.n_ctrl, 3))
            kernel(*axes, g, emb.inside, acc, out)
            if stride == 4:
                assert not acc[:, 3::4].any()                      # the padding lane stays 0
            np.testing.assert_array_equal(out, acc.sum(axis=0).reshape(-1, stride)[:, :3])
            results.append(out)
        for r in results[1:]:
            assert np.all(np.abs(r - results[0]) <= 1e-14 * _bound(emb, g))
    # rmatvec: the last (fastest fitting) kernel with 4 chunks per thread
    np.testing.assert_array_equal(emb.rmatvec(g), results[-1])


@pytest.mark.parametrize("case", ["3d-442", "3d-cubic-16x12x4", "2d-gdim2"])
def test_outside_rows_do_not_contribute(case):
    """Rows of outside points are skipped, not multiplied by zero: not even a NaN or inf of g there
    reaches the control points."""
    lat = CASES[case]()
    out = [0, 1, 2, 500, 1999]
    emb = _embedding(lat, 2000, seed=5, outside=out)
    g = np.random.default_rng(6).normal(size=(emb.n_points, lat.gdim))
    ref = rmatvec_reference(emb, g)
    g[out] = [np.nan] + [np.inf] * (lat.gdim - 1)
    got = emb.rmatvec(g)
    assert np.all(np.isfinite(got))
    assert np.all(np.abs(got - ref) <= 1e-13 * _bound(emb, np.nan_to_num(g, nan=0.0, posinf=0.0)))
    # every point outside: exact zeros
    none = Embedding.from_params(lat, emb.params, np.zeros(emb.n_points, dtype=bool), emb.residual)
    assert not none.rmatvec(g).any()


@pytest.mark.parametrize("case", ["3d-442", "2d-gdim3"])
def test_empty_embedding(case):
    lat = CASES[case]()
    emb = Embedding.from_params(lat, np.zeros((0, lat.pdim)), np.zeros(0, dtype=bool), np.zeros(0))
    for gdim in (1, 3):
        got = emb.rmatvec(np.zeros((0, gdim)))
        assert got.shape == (lat.n_ctrl, gdim) and not got.any()


def test_vjp_through_the_kernel_is_the_reference():
    """vjp(embedding, g, D) = (B.T g).reshape(-1) @ D of the reference B, for the default box."""
    from benchmarks.bench_derivatives import design_changes
    from ffdcli.parameterization.changes import LatticeFrame

    lat = wing_lattice((8, 6, 2), (3, 3, 1))
    emb = _embedding(lat, 3000, seed=9, outside=[10])
    frame = LatticeFrame.from_lattice(lat.shape, (1.0, 0.0, 0.0), (0.0, 0.0, 1.0), (0.0, 1.0, 0.0))
    D = lattice_jacobian(lat.control_points, frame, design_changes(6, 8, 2))
    g = np.random.default_rng(10).normal(size=(emb.n_points, 3))
    ref = rmatvec_reference(emb, g).reshape(-1) @ D
    got = vjp(emb, g, D)
    scale = _bound(emb, g).reshape(-1) @ np.abs(D)
    assert np.all(np.abs(got - ref) <= 1e-13 * scale)


def test_point_set_vjp_is_its_basis_transpose():
    """PointSet.vjp goes through the embedding's kernel: the same as its CSR basis' transpose."""
    lat = wing_lattice((8, 6, 2), (3, 3, 1))
    emb = _embedding(lat, 500, seed=12, outside=[3, 4])
    ps = PointSet(name="p", points0=np.zeros((500, 3)), embedding=emb, basis=emb.basis_matrix())
    D = np.random.default_rng(13).normal(size=(3 * lat.n_ctrl, 7))
    g = np.random.default_rng(14).normal(size=(500, 3))
    ref = np.asarray(ps.basis.T @ g).reshape(-1) @ D
    np.testing.assert_allclose(ps.vjp(D, g), ref, rtol=0, atol=1e-13 * (_bound(emb, g).reshape(-1) @ np.abs(D)).max())


# ---------------------------------------------------------------------------------------------- simd

@njit(cache=False)
def _call4(out, k, w, x):
    axpy4(out, k, w, x[0], x[1], x[2], x[3])


@njit(cache=False)
def _call8(out, k, w, x):
    axpy8(out, k, w, x[0], x[1], x[2], x[3], x[4], x[5], x[6], x[7])


@pytest.mark.parametrize("width, call", [(4, _call4), (8, _call8)])
def test_axpy_updates_its_lanes_only(width, call):
    rng = np.random.default_rng(1)
    out = rng.normal(size=20)
    x = rng.normal(size=width)
    before = out.copy()
    call(out, 5, 0.75, x)
    np.testing.assert_allclose(out[5:5 + width], before[5:5 + width] + 0.75 * x, rtol=1e-15, atol=1e-15)
    np.testing.assert_array_equal(np.delete(out, np.arange(5, 5 + width)),
                                  np.delete(before, np.arange(5, 5 + width)))


@pytest.mark.parametrize("width, call", [(4, _call4), (8, _call8)])
def test_axpy_rounds_once(width, call):
    """fma(w, x, a) with w = x = 1 + 2^-30 and a = -(1 + 2^-29): the exact result 2^-60 survives a
    single rounding; a multiply then an add would round w x to 1 + 2^-29 and give 0."""
    e = 2.0 ** -30
    out = np.full(width, -(1.0 + 2 * e))
    call(out, 0, 1.0 + e, np.full(width, 1.0 + e))
    np.testing.assert_array_equal(out, np.full(width, 2.0 ** -60))


@njit(cache=False)
def _call8x3(out, k, w, u, g):
    axpy8x3(out, k, w, u[0], u[1], u[2], u[3], u[4], u[5], u[6], u[7], g[0], g[1], g[2])


def test_axpy8x3_adds_the_scaled_outer_product():
    rng = np.random.default_rng(2)
    out, u, g = rng.normal(size=30), rng.normal(size=8), rng.normal(size=3)
    before = out.copy()
    _call8x3(out, 3, -1.5, u, g)
    np.testing.assert_allclose(out[3:27], before[3:27] - 1.5 * np.outer(u, g).ravel(), rtol=1e-15, atol=1e-15)
    np.testing.assert_array_equal(out[:3], before[:3])
    np.testing.assert_array_equal(out[27:], before[27:])
    # u g rounded, then one fused multiply-add: w = 1 + 2^-30 times (1 + 2^-30) * 1, plus -(1 + 2^-29)
    e = 2.0 ** -30
    out = np.full(24, -(1.0 + 2 * e))
    _call8x3(out, 0, 1.0 + e, np.full(8, 1.0 + e), np.ones(3))
    np.testing.assert_array_equal(out, np.full(24, 2.0 ** -60))


def test_axpy_refuses_what_it_cannot_address():
    @njit(cache=False)
    def two_d(out):
        axpy4(out, 0, 1.0, 1.0, 2.0, 3.0, 4.0)

    with pytest.raises(TypingError):
        two_d(np.zeros((2, 4)))
    with pytest.raises(TypingError):
        two_d(np.zeros(8, dtype=np.float32))
    with pytest.raises(TypingError):
        two_d(np.zeros(16)[::2])


APPLY_CASES = dict(CASES, **{
    "3d-linear": lambda: wing_lattice((3, 2, 2), 1),
    "3d-deg5-4-2": lambda: wing_lattice((7, 6, 4), (5, 4, 2)),
    "2d-linear-gdim2": lambda: curved_patch((4, 3), (1, 1), gdim=2),
})


@pytest.mark.parametrize("case", sorted(APPLY_CASES))
def test_apply_kernel_is_the_dense_reference(case):
    # B @ P by the vector-FMA kernel (compiled per basis widths) against the dense NumPy basis: the
    # same sum of products in another order and rounding, so to ulps of the coordinates; outside
    # rows are zero in displace and the nearest lattice point in evaluate
    lat = APPLY_CASES[case]()
    outside = (1, 5, 77)
    emb = _embedding(lat, 500, 11, outside)
    rng = np.random.default_rng(5)
    P = lat.control_points + 0.1 * rng.normal(size=lat.control_points.shape)
    ref = dense_basis_reference(lat, emb.params) @ P.reshape(-1, lat.gdim)
    scale = np.abs(P).max()
    np.testing.assert_allclose(emb.evaluate(P), ref, rtol=0, atol=1e-14 * scale)
    disp = emb.displace(P)
    np.testing.assert_allclose(disp[emb.inside], ref[emb.inside], rtol=0, atol=1e-14 * scale)
    assert not disp[list(outside)].any()
    # evaluate at the lattice's own control points is the lattice map
    np.testing.assert_allclose(emb.evaluate(lat.control_points), evaluate_reference(lat, emb.params), rtol=0,
                               atol=1e-14 * np.abs(lat.control_points).max())
