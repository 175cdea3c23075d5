"""The kernels compiled for the usual lattice degrees (ffdcli.lattice._newton_kernels.SPECIALISED) and
the generic ones every other combination runs give the same floats, bit for bit: the Newton
embedding (parameters, residuals), the basis pass of Embedding.from_params and B @ P."""

from __future__ import annotations

import numpy as np
import pytest
from lattice_cases import curved_patch, wing_lattice

from ffdcli.lattice import _newton_kernels
from ffdcli.lattice._newton_kernels import specialised
from ffdcli.lattice.embedding import embed
from ffdcli.lattice.lattice import evaluate, kernel_args
from ffdcli.settings import DEFAULT_POINTS, default_degree

# (lattice, its three-axis degrees): the defaults, run both ways (an uncommon combination forced
# through the unrolled kernels would cost the suite one more compile; the unrolled evaluation is
# checked against the generic one for such widths in test_lattice.py)
CASES = {
    "3d-default-331": (lambda: wing_lattice((8, 6, 2), (3, 3, 1)), (3, 3, 1)),
    "2d-default-33": (lambda: curved_patch((6, 5), (3, 3), gdim=2), (3, 3, 0)),
}


def _run(lat, X, dP):
    emb = embed(lat, X)
    return emb, emb.displace(dP), emb.evaluate(lat.control_points)


@pytest.mark.parametrize("case", sorted(CASES))
def test_unrolled_and_generic_kernels_agree_bit_for_bit(case, monkeypatch):
    make, degrees = CASES[case]
    lat = make()
    assert tuple(int(p) for p in kernel_args(lat)[4:]) == degrees
    rng = np.random.default_rng(7)
    u = rng.uniform(0.0, 1.0, (3000, lat.pdim))
    u[:200, 0] = rng.choice([0.0, 1.0], 200)                            # faces
    X = evaluate(lat, u) + 1e-4 * lat.size * rng.normal(size=(3000, lat.gdim))
    X[-100:] += 0.2 * lat.size                                          # outside
    dP = rng.normal(size=lat.control_points.shape)
    assert specialised(degrees)
    a, da, ea = _run(lat, X, dP)
    monkeypatch.setattr(_newton_kernels, "SPECIALISED", frozenset())
    assert not specialised(degrees)
    b, db, eb = _run(lat, X, dP)
    assert 0 < a.inside.sum() < len(X)
    for name in ("params", "residual", "inside"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    for fa, fb, va, vb in zip(a.first, b.first, a.values, b.values, strict=True):
        assert np.array_equal(fa, fb) and np.array_equal(va, vb)
    assert np.array_equal(da, db) and np.array_equal(ea, eb)


def test_the_specialised_degrees_are_the_defaults():
    """The default boxes (3D 6 x 8 x 2, 2D 6 x 5: degree min(3, points - 1)) run the unrolled kernels."""
    for dim, points in DEFAULT_POINTS.items():
        degrees = tuple(default_degree(n) for n in points) + ((0,) if dim == 2 else ())
        assert specialised(degrees), degrees


@pytest.mark.parametrize("make", [lambda: wing_lattice((8, 6, 2), (3, 3, 1)),
                                  lambda: curved_patch((6, 5), (1, 1), gdim=2),
                                  lambda: curved_patch((6, 5), (2, 4), gdim=3)])
def test_the_kernels_get_read_only_arrays_whatever_the_lattice(make):
    """numba compiles one signature per array flag combination: a writable array among the kernels'
    arguments (the 2D dummy knots, 2-coordinate control points padded to 3) compiled the generic
    kernels a second time after the warm-up. Every array handed over is read-only."""
    args = kernel_args(make())
    arrays = [a for a in args if isinstance(a, np.ndarray)]
    assert len(arrays) == 4
    assert not any(a.flags.writeable for a in arrays)
