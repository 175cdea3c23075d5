"""Analytic derivatives against central finite differences of ``apply_changes``.

Steps: h = 1e-5 * max(1, |v|) per variable (degrees for angles). Central differences have a
truncation error ~ h^2 * |f'''| (about 1e-10 relative for these smooth trig/affine maps with O(1)
to O(100) curvature in these units) and a rounding error ~ eps * |f| / h (about 1e-11 for O(1)
coordinates); 1e-6 relative (the issue's bar) therefore cannot be met by a wrong formula (those
are off by O(1)) yet is never at risk from the differencing itself.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from test_changes import airfoil_lattice, wing_lattice

from ffdcli.parameterization.changes import (
    Chord,
    Dihedral,
    SectionLaw,
    Shape,
    Span,
    Sweep,
    Twist,
    apply_changes,
    design_variables,
    set_design_variables,
)
from ffdcli.parameterization.derivatives import lattice_jacobian, surface_jacobian, surface_jvp, surface_operator, vjp

REL = 1e-6


def fd_jacobian(P, frame, changes):
    _, v = design_variables(changes)
    cols = []
    for q in range(v.size):
        h = 1e-5 * max(1.0, abs(v[q]))
        e = np.zeros_like(v)
        e[q] = h
        plus = apply_changes(P, frame, set_design_variables(changes, v + e))
        minus = apply_changes(P, frame, set_design_variables(changes, v - e))
        cols.append(((plus - minus) / (2 * h)).reshape(-1))
    return np.stack(cols, axis=1)


def assert_matches_fd(P, frame, changes):
    J = lattice_jacobian(P, frame, changes)
    F = fd_jacobian(P, frame, changes)
    assert J.shape == F.shape == (P.size, design_variables(changes)[1].size)
    scale = np.abs(F).max(axis=0)
    err = np.abs(J - F).max(axis=0)
    names = design_variables(changes)[0]
    # per variable: relative to that column's largest entry (floor 1e-3: a column of zeros, e.g. a
    # root twist that moves nothing because the lattice is flat there, must be zero to 1e-9)
    bad = [(names[q], err[q], scale[q]) for q in range(len(names)) if err[q] > REL * max(scale[q], 1e-3)]
    assert not bad, bad
    return J


def skewed_lattice(**kw):
    """A wing lattice with sweep, dihedral and a little noise, so that no derivative is trivially 0."""
    P, frame = wing_lattice(sweep_deg=20.0, dihedral_deg=3.0, **kw)
    rng = np.random.default_rng(3)
    return P + rng.normal(scale=0.01, size=P.shape), frame


@pytest.mark.parametrize("theta", [0.0, 45.0])
def test_twist_list_and_laws_at_0_and_45_degrees(theta):
    P, frame = skewed_lattice()
    assert_matches_fd(P, frame, [Twist(np.full(8, theta))])
    assert_matches_fd(P, frame, [Twist(SectionLaw.root_tip(8, tip=theta))])
    assert_matches_fd(P, frame, [Twist(SectionLaw.root_tip(8, tip=theta, root=-theta / 3))])


@pytest.mark.parametrize("change", [
    Span(1.1), Span(0.8),
    Sweep(10.0), Sweep(-25.0), Sweep(offsets=np.linspace(0, 0.2, 8)),
    Dihedral(5.0), Dihedral(-5.0), Dihedral(offsets=np.linspace(0, -0.1, 8)),
    Chord(np.linspace(1, 0.5, 8)), Chord(SectionLaw.root_tip(8, tip=0.6, default_root=1.0)),
    Chord(SectionLaw.root_tip(8, tip=0.6, root=1.2)),
    Shape(np.linspace(0, 0.01, 6), -np.linspace(0, 0.01, 6), sections=[0, 3, 7]),
    Shape(np.full((6, 8), 0.01), None),
], ids=lambda c: f"{c.kind}")
def test_every_kind_alone(change):
    P, frame = skewed_lattice()
    assert_matches_fd(P, frame, [change])


def test_a_pipeline_of_every_kind_in_paper_order():
    P, frame = skewed_lattice()
    changes = [Twist(np.linspace(0, 45, 8)), Span(1.1), Sweep(8.0), Dihedral(-3.0),
               Chord(SectionLaw.root_tip(8, tip=0.6, default_root=1.0)),
               Shape(np.linspace(0, 0.01, 6), None), Sweep(offsets=np.linspace(0, 0.05, 8)),
               Twist(SectionLaw.root_tip(8, tip=15.0)), Dihedral(4.0)]
    J = assert_matches_fd(P, frame, changes)
    # the later sweep/dihedral depend on the earlier twist through the leading-edge line
    names = design_variables(changes)[0]
    assert np.abs(J[:, names.index("c0.twist[7]")]).max() > 0


def test_2d_twist_chord_shape():
    P, frame = airfoil_lattice()
    assert_matches_fd(P, frame, [Twist(SectionLaw.scalar(5.0)), Chord(SectionLaw.scalar(0.8)),
                                 Shape(np.linspace(0, 0.01, 6), -np.linspace(0, 0.01, 6)),
                                 Twist(SectionLaw.scalar(-3.0))])


_KINDS = ["twist", "twist_tip", "span", "sweep", "dihedral", "chord", "shape", "sweep_off"]


def _make(kind, x, m=8, n=6):
    return {
        "twist": lambda: Twist(np.linspace(0, 1, m) * 60 * x),
        "twist_tip": lambda: Twist(SectionLaw.root_tip(m, tip=60 * x)),
        "span": lambda: Span(1 + 0.3 * x),
        "sweep": lambda: Sweep(30 * x),
        "dihedral": lambda: Dihedral(10 * x),
        "chord": lambda: Chord(SectionLaw.root_tip(m, tip=1 + 0.4 * x, default_root=1.0)),
        "shape": lambda: Shape(0.02 * x * np.sin(np.arange(n)), None),
        "sweep_off": lambda: Sweep(offsets=0.1 * x * np.arange(m)),
    }[kind]()


@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(st.tuples(st.sampled_from(_KINDS), st.floats(-1, 1)), min_size=1, max_size=4))
def test_random_designs(items):
    P, frame = skewed_lattice()
    assert_matches_fd(P, frame, [_make(k, x) for k, x in items])


def test_surface_jacobian_and_vjp_are_b_times_the_lattice_jacobian():
    P, frame = skewed_lattice()
    changes = [Twist(np.linspace(0, 45, 8)), Span(1.1), Sweep(8.0)]
    J = lattice_jacobian(P, frame, changes)
    n_ctrl = P.size // 3
    B = sp.random(500, n_ctrl, density=0.1, format="csr", random_state=1)
    dX = surface_jacobian(B, J)
    assert dX.shape == (500 * 3, J.shape[1])
    # surface points X(v) = B @ P'(v): check dX against finite differences of that
    F = fd_jacobian(P, frame, changes)
    Bd = B.toarray()
    dX_fd = np.stack([(Bd @ F[:, q].reshape(-1, 3)).reshape(-1) for q in range(F.shape[1])], axis=1)
    np.testing.assert_allclose(dX, dX_fd, rtol=0, atol=REL * np.abs(dX_fd).max())
    # the same through a dense B, the jvp and the vjp
    np.testing.assert_allclose(surface_jacobian(Bd, J), dX, rtol=1e-13, atol=1e-13)
    dv = np.random.default_rng(0).normal(size=J.shape[1])
    np.testing.assert_allclose(surface_jvp(B, J, dv).reshape(-1), dX @ dv, rtol=1e-12, atol=1e-12)
    g = np.random.default_rng(1).normal(size=(500, 3))
    np.testing.assert_allclose(vjp(B, g, J), g.reshape(-1) @ dX, rtol=1e-12, atol=1e-10)
    with pytest.raises(ValueError):
        vjp(B, g[:10], J)
    op = surface_operator(B, J)
    assert op.shape == dX.shape
    np.testing.assert_allclose(op @ dv, dX @ dv, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(op.T @ g.reshape(-1), g.reshape(-1) @ dX, rtol=1e-12, atol=1e-10)


@pytest.mark.parametrize("density", [0.0, 0.05, 0.3])
def test_csr_times_dense_matches_scipy(density):
    """The compiled row-parallel product equals SciPy's ``B @ D`` (the NumPy/SciPy reference)."""
    from ffdcli.parameterization.derivatives import csr_times_dense

    rng = np.random.default_rng(3)
    B = sp.random(257, 40, density=density, format="csr", random_state=4)
    B.data = rng.normal(size=B.nnz)
    keep = np.ones(257)
    keep[5] = 0.0                              # an empty row among filled ones
    B = sp.csr_matrix(sp.diags(keep) @ B)
    B.eliminate_zeros()
    D = rng.normal(size=(40, 33))
    ref = np.asarray(B @ D)
    # both sum each row's (<= 40) products in float64, grouped differently (four at a time, fused
    # multiply-adds): rounding differs by a few ulps of the row's magnitude, ~1e-15 relative
    np.testing.assert_allclose(csr_times_dense(B, D), ref, rtol=0, atol=1e-13 * max(1.0, np.abs(ref).max()))
    out = np.full((257, 33), np.nan)           # out is overwritten, not accumulated into
    assert csr_times_dense(B, D, out=out) is out
    np.testing.assert_allclose(out, ref, rtol=0, atol=1e-13 * max(1.0, np.abs(ref).max()))
    with pytest.raises(ValueError):
        csr_times_dense(B, D[:5])
    with pytest.raises(ValueError):
        csr_times_dense(B, D, out=np.empty((257, 32)))


def test_surface_jacobian_csr_and_dense_b_agree_on_an_embedding():
    """The kernel path (CSR B of a real embedding) gives the same dX/dv as the dense-B product."""
    from ffdcli.lattice.embedding import embed
    from ffdcli.lattice.lattice import Lattice, evaluate

    P, frame = skewed_lattice()
    lattice = Lattice(P, (3, 3, 1))
    X = evaluate(lattice, np.random.default_rng(5).uniform(0, 1, (300, 3)))
    B = embed(lattice, X).basis_matrix()
    J = lattice_jacobian(P, frame, [Twist(np.linspace(0, 20, P.shape[1])), Span(1.1)])
    dense = surface_jacobian(B.toarray(), J)
    np.testing.assert_allclose(surface_jacobian(B, J), dense, rtol=0, atol=1e-13 * np.abs(dense).max())


@pytest.mark.parametrize("case", ["3d", "2d"])
def test_vjp_through_the_embedding_equals_the_csr_route(case):
    """vjp(embedding, g, D) (compiled B.T @ g over the per-axis basis, then D^T) equals the product
    through the CSR basis matrix to 1e-12, with points outside the lattice contributing nothing."""
    import lattice_cases

    from ffdcli.lattice.embedding import embed
    from ffdcli.lattice.lattice import evaluate

    rng = np.random.default_rng(5)
    lat = (lattice_cases.wing_lattice((8, 6, 2), (3, 3, 1)) if case == "3d"
           else lattice_cases.curved_patch((6, 5), (3, 2), gdim=2))
    X = evaluate(lat, rng.uniform(0.0, 1.0, (3000, lat.pdim)))
    X[:50] += 0.5 * lat.size                                  # outside: no contribution
    emb = embed(lat, X)
    assert 0 < (~emb.inside).sum() < len(X)
    D = rng.normal(size=(3 * emb.n_ctrl, 17))
    g = rng.normal(size=(len(X), 3))
    ref = vjp(emb.basis_matrix(), g, D)
    np.testing.assert_allclose(vjp(emb, g, D), ref, rtol=0, atol=1e-12 * np.abs(ref).max())
    g[~emb.inside] = 1e6
    np.testing.assert_allclose(vjp(emb, g, D), vjp(emb.basis_matrix(), g, D), rtol=0,
                               atol=1e-12 * np.abs(ref).max())
    with pytest.raises(ValueError, match="g must have shape"):
        vjp(emb, g[:10], D)
