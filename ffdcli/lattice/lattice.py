"""The B-spline lattice (trivariate volume, or bivariate patch in 2D) and its evaluation.

A :class:`Lattice` maps parameters ``(u, v, w)`` in [0, 1]^3 (``(u, v)`` in [0, 1]^2 for a 2D lattice)
to mesh coordinates::

    V(u, v, w) = sum_ijk N_i,p(u) N_j,q(v) N_k,r(w) P[i, j, k]

with clamped knot vectors, so the faces of the lattice are the B-spline surfaces of its face
control points and an undeformed lattice reproduces points exactly.

:func:`evaluate` and :func:`derivatives` run a parallel compiled loop (numba);
:func:`evaluate_reference` and :func:`derivatives_reference` are the plain NumPy tensor products
that the tests compare them with. The per-point kernel :func:`eval_point_nb` (any degrees, a work
array) has a twin for degrees known when compiling, :func:`eval_point_fixed_nb` (the same floats,
bit for bit; unrolled, the tensor product in 4-wide vector operations), which the Newton embedding
(``embedding.py``) calls a few times per point.

Internally a 2D lattice is treated as a 3D one with a third axis of one control point and degree
0 (basis value 1, derivative 0), so the compiled kernels are written once.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numba import njit, prange

from ffdcli.errors import InputError
from ffdcli.jit import tensor_d1
from ffdcli.lattice.spline import (
    basis_d1_row_nb,
    basis_d1_tuple,
    basis_derivs,
    check_knots,
    clamped_knots,
    degree_proto,
    find_span_count_nb,
    find_span_nb,
)
from ffdcli.mesh import diagonal
from ffdcli.settings import MAX_DEGREE, check_degree

#: Knot vector of the dummy third axis of a 2D lattice (one control point, degree 0). Read-only, as
#: every array :func:`kernel_args` hands the kernels: numba compiles one signature per array flag
#: combination, so a writable array here made 2D lattices compile the generic kernels again after
#: the warm-up (12 s for ``--degree 1,1`` of a 2D mesh).
DUMMY_KNOTS = np.array([0.0, 1.0])
DUMMY_KNOTS.setflags(write=False)


@dataclass(frozen=True)
class Lattice:
    """A clamped B-spline lattice.

    Attributes
    ----------
    control_points : ndarray, shape (*sizes, gdim)
        ``(n, m, l, gdim)`` for a volume (pdim = 3) or ``(n, l, gdim)`` for a 2D patch (pdim = 2);
        ``gdim >= pdim``. Stored as a read-only float64 copy.
    degree : tuple of int
        Degree per parametric direction, each in 1..5 and smaller than the number of points.
    knots : tuple of ndarray
        Clamped knot vectors on [0, 1], one per direction; ``None`` (default) = uniform
        (:func:`ffdcli.lattice.spline.clamped_knots`).

    Invalid sizes, degrees or knots raise :class:`ffdcli.errors.InputError`.
    """

    control_points: np.ndarray
    degree: tuple[int, ...]
    knots: tuple[np.ndarray, ...] | None = field(default=None)

    def __post_init__(self):
        cp = np.array(self.control_points, dtype=np.float64, order="C", copy=True)
        if cp.ndim not in (3, 4):
            raise InputError(f"lattice control points must have shape (n, l, dim) or (n, m, l, dim), "
                             f"got shape {cp.shape}")
        pdim = cp.ndim - 1
        sizes = cp.shape[:-1]
        gdim = cp.shape[-1]
        if not pdim <= gdim <= 3:
            allowed = "3" if pdim == 3 else "2 or 3"
            raise InputError(f"a {pdim}D lattice needs {allowed} coordinates per control point, got {gdim}")
        if not np.all(np.isfinite(cp)):
            raise InputError("lattice control points contain NaN or infinite coordinates")
        degree = np.atleast_1d(np.asarray(self.degree))
        if degree.size == 1:
            degree = np.repeat(degree, pdim)
        if degree.size != pdim or not np.all(degree == np.round(degree)):
            raise InputError(f"degree needs {pdim} integers (one per direction), got {self.degree!r}")
        degree = tuple(int(d) for d in degree)
        check_degree(sizes, degree, key=None)
        if self.knots is None:
            knots = tuple(clamped_knots(n, p) for n, p in zip(sizes, degree, strict=True))
        else:
            if len(self.knots) != pdim:
                raise InputError(f"a {pdim}D lattice needs {pdim} knot vectors, got {len(self.knots)}")
            try:
                knots = tuple(check_knots(k, p, n) for k, p, n in zip(self.knots, degree, sizes, strict=True))
            except ValueError as exc:
                raise InputError(f"invalid knot vector: {exc}") from None
        cp.setflags(write=False)
        for k in knots:
            k.setflags(write=False)
        object.__setattr__(self, "control_points", cp)
        object.__setattr__(self, "degree", degree)
        object.__setattr__(self, "knots", knots)

    @property
    def pdim(self) -> int:
        """Number of parametric directions (2 or 3)."""
        return self.control_points.ndim - 1

    @property
    def gdim(self) -> int:
        """Number of coordinates of a control point."""
        return self.control_points.shape[-1]

    @property
    def shape(self) -> tuple[int, ...]:
        """Control points per direction, e.g. ``(8, 6, 2)``."""
        return self.control_points.shape[:-1]

    @property
    def n_ctrl(self) -> int:
        """Total number of control points."""
        return int(np.prod(self.shape))

    @property
    def size(self) -> float:
        """Length scale of the lattice: the diagonal of the bounding box of its control points."""
        return size(self)

    def with_control_points(self, control_points) -> Lattice:
        """The same lattice (degrees, knots) with other control points of the same shape."""
        control_points = np.asarray(control_points, dtype=np.float64)
        if control_points.shape != self.control_points.shape:
            raise ValueError(f"control points of shape {self.control_points.shape} expected, "
                             f"got {control_points.shape}")
        return Lattice(control_points, self.degree, self.knots)


def size(lattice: Lattice) -> float:
    """Length scale of ``lattice``: the bounding-box diagonal of its control points (mesh units)."""
    return diagonal(lattice.control_points.reshape(-1, lattice.gdim))


# ----------------------------------------------------------------------------------------------
# Internal 3-axis form shared by the compiled kernels
# ----------------------------------------------------------------------------------------------

def kernel_args(lattice: Lattice):
    """``(P4, k0, k1, k2, p0, p1, p2)`` for the compiled kernels.

    ``P4`` is the control points as a C-contiguous (n0, n1, n2, 3) array: a 2D lattice gets a dummy
    third axis of one point (with knots [0, 1] and degree 0), and 2-coordinate control points a zero
    third coordinate, so the kernels are written once for three axes and three coordinates.
    """
    cp = lattice.control_points
    if lattice.pdim == 2:
        cp = cp.reshape(cp.shape[0], cp.shape[1], 1, cp.shape[2])
        k0, k1 = lattice.knots
        k2 = DUMMY_KNOTS
        p0, p1 = lattice.degree
        p2 = 0
    else:
        k0, k1, k2 = lattice.knots
        p0, p1, p2 = lattice.degree
    if cp.shape[-1] < 3:
        cp = np.concatenate([cp, np.zeros(cp.shape[:-1] + (3 - cp.shape[-1],))], axis=-1)
    P4 = np.ascontiguousarray(cp)
    if P4.flags.writeable:          # a new array (2-coordinate control points): read-only like the rest
        P4.setflags(write=False)
    return P4, k0, k1, k2, np.int64(p0), np.int64(p1), np.int64(p2)


@njit(cache=True, nogil=True, inline="always")
def eval_point_nb(P, k0, k1, k2, p0, p1, p2, u0, u1, u2, W):
    """V and its first derivatives at (u0, u1, u2), for the kernels (``P`` as from :func:`kernel_args`).

    Returns a tuple of 12 floats: ``V`` (3), ``dV/du0`` (3), ``dV/du1`` (3), ``dV/du2`` (3). ``W`` is
    a (8, MAX_DEGREE + 1) work array whose rows 0-5 receive the basis values and derivatives of the
    three axes (N0, D0, N1, D1, N2, D2) and rows 6-7 are scratch. The tensor product is contracted one
    axis at a time (w, then v, then u) into scalar accumulators. Inlined into the callers' loops (no
    array views, no reference counting per point: 2.5x faster than passing 1D work arrays).
    """
    s0 = find_span_nb(k0, p0, u0)
    s1 = find_span_nb(k1, p1, u1)
    s2 = find_span_nb(k2, p2, u2)
    basis_d1_row_nb(k0, p0, s0, u0, W, 0, 1, 6, 7)
    basis_d1_row_nb(k1, p1, s1, u1, W, 2, 3, 6, 7)
    basis_d1_row_nb(k2, p2, s2, u2, W, 4, 5, 6, 7)
    f0 = s0 - p0
    f1 = s1 - p1
    f2 = s2 - p2
    x0 = x1 = x2 = 0.0
    xu0 = xu1 = xu2 = 0.0
    xv0 = xv1 = xv2 = 0.0
    xw0 = xw1 = xw2 = 0.0
    for a in range(p0 + 1):
        r0 = r1 = r2 = 0.0
        rv0 = rv1 = rv2 = 0.0
        rw0 = rw1 = rw2 = 0.0
        for b in range(p1 + 1):
            q0 = q1 = q2 = 0.0
            qw0 = qw1 = qw2 = 0.0
            for c in range(p2 + 1):
                n = W[4, c]
                dn = W[5, c]
                c0 = P[f0 + a, f1 + b, f2 + c, 0]
                c1 = P[f0 + a, f1 + b, f2 + c, 1]
                c2 = P[f0 + a, f1 + b, f2 + c, 2]
                q0 += n * c0
                q1 += n * c1
                q2 += n * c2
                qw0 += dn * c0
                qw1 += dn * c1
                qw2 += dn * c2
            n = W[2, b]
            dn = W[3, b]
            r0 += n * q0
            r1 += n * q1
            r2 += n * q2
            rv0 += dn * q0
            rv1 += dn * q1
            rv2 += dn * q2
            rw0 += n * qw0
            rw1 += n * qw1
            rw2 += n * qw2
        n = W[0, a]
        dn = W[1, a]
        x0 += n * r0
        x1 += n * r1
        x2 += n * r2
        xu0 += dn * r0
        xu1 += dn * r1
        xu2 += dn * r2
        xv0 += n * rv0
        xv1 += n * rv1
        xv2 += n * rv2
        xw0 += n * rw0
        xw1 += n * rw1
        xw2 += n * rw2
    return x0, x1, x2, xu0, xu1, xu2, xv0, xv1, xv2, xw0, xw1, xw2


@njit(cache=True, nogil=True, inline="always")
def eval_point_fixed_nb(R, n1, n2, k0, k1, k2, u0, u1, u2, w0, w1, w2):
    """:func:`eval_point_nb` for degrees known when compiling: the same 12 floats, bit for bit.

    ``R`` is the control points as 4-wide rows (:func:`padded_rows`), ``n1, n2`` the number of
    control points along axes 1 and 2 (1 for the third axis of a 2D lattice). ``w0, w1, w2`` are
    :func:`fixed_widths` of the lattice, tuples whose lengths are the basis widths ``p + 1`` per
    axis; numba compiles a version of the caller per widths, in which the basis
    (:func:`ffdcli.lattice.spline.basis_d1_tuple`) stays in registers and the tensor product is unrolled
    straight-line vector code (:func:`ffdcli.jit.tensor_d1`: one 4-wide operation per multiply or
    add of the scalar kernel, the same operations in the same order). About 3x faster than
    :func:`eval_point_nb` (degrees 3, 3, 1).
    """
    p0 = len(w0) - 1
    p1 = len(w1) - 1
    p2 = len(w2) - 1
    s0 = find_span_count_nb(k0, p0, u0)
    s1 = find_span_count_nb(k1, p1, u1)
    s2 = find_span_count_nb(k2, p2, u2)
    N0, D0 = basis_d1_tuple(k0, s0, u0, w0)
    N1, D1 = basis_d1_tuple(k1, s1, u1, w1)
    N2, D2 = basis_d1_tuple(k2, s2, u2, w2)
    first = ((s0 - p0) * n1 + (s1 - p1)) * n2 + (s2 - p2)
    return tensor_d1(R, first, n1 * n2, n2, N0, D0, N1, D1, N2, D2)


def padded_rows(P4: np.ndarray) -> np.ndarray:
    """The control points of :func:`kernel_args` (n0, n1, n2, 3) as 4-wide rows ``(x, y, z, 0)`` in
    one flat array (4 n_ctrl,), for :func:`eval_point_fixed_nb`."""
    rows = np.zeros((P4.shape[0] * P4.shape[1] * P4.shape[2], 4))
    rows[:, :3] = P4.reshape(-1, 3)
    return rows.reshape(-1)


def fixed_widths(degrees):
    """``(w0, w1, w2)`` for :func:`eval_point_fixed_nb` from the degrees ``(p0, p1, p2)`` of
    :func:`kernel_args`: three tuples of ``p + 1`` zeros (three flat tuples, not a nested one: a
    numba parallel loop takes flat tuples only)."""
    return tuple(degree_proto(p) for p in degrees)


@njit(cache=True, parallel=True)
def _evaluate_nb(P, k0, k1, k2, p0, p1, p2, params, gdim, want_jac, out, jac):
    npts = params.shape[0]
    pdim = params.shape[1]
    nchunk = min(npts, 256)
    for c in prange(nchunk):
        W = np.zeros((8, MAX_DEGREE + 1))
        lo = c * npts // nchunk
        hi = (c + 1) * npts // nchunk
        for i in range(lo, hi):
            u2 = params[i, 2] if pdim == 3 else 0.0
            res = eval_point_nb(P, k0, k1, k2, p0, p1, p2, params[i, 0], params[i, 1], u2, W)
            for d in range(gdim):
                out[i, d] = res[d]
            if want_jac:
                for d in range(gdim):
                    for e in range(pdim):
                        jac[i, d, e] = res[3 + 3 * e + d]


def _check_params(lattice: Lattice, params) -> np.ndarray:
    params = np.ascontiguousarray(params, dtype=np.float64)
    if params.ndim != 2 or params.shape[1] != lattice.pdim:
        raise ValueError(f"params must have shape (N, {lattice.pdim}), got {params.shape}")
    if params.size and not (np.all(params >= 0.0) and np.all(params <= 1.0)):
        raise ValueError("params must lie in [0, 1]")
    return params


def evaluate(lattice: Lattice, params) -> np.ndarray:
    """Points of the lattice at the given parameters.

    Parameters
    ----------
    lattice : Lattice
    params : array_like, shape (N, pdim)
        Parameters in [0, 1]^pdim.

    Returns
    -------
    points : ndarray, shape (N, gdim)
    """
    params = _check_params(lattice, params)
    out = np.empty((params.shape[0], lattice.gdim))
    if params.shape[0]:
        _evaluate_nb(*kernel_args(lattice), params, lattice.gdim, False, out, np.empty((0, 0, 0)))
    return out


def derivatives(lattice: Lattice, params) -> np.ndarray:
    """First derivatives of the lattice map w.r.t. its parameters.

    Returns
    -------
    jac : ndarray, shape (N, gdim, pdim)
        ``jac[i, :, a] = dV/du_a`` at ``params[i]``.
    """
    params = _check_params(lattice, params)
    out = np.empty((params.shape[0], lattice.gdim))
    jac = np.empty((params.shape[0], lattice.gdim, lattice.pdim))
    if params.shape[0]:
        _evaluate_nb(*kernel_args(lattice), params, lattice.gdim, True, out, jac)
    return jac


def axis_tables(lattice: Lattice, params, nder: int):
    """Dense per-axis basis tables (N, n_axis) of the value and its derivatives (NumPy)."""
    tables = []
    npts = params.shape[0]
    rows = np.arange(npts)[:, None]
    for axis in range(lattice.pdim):
        p = lattice.degree[axis]
        first, ders = basis_derivs(lattice.knots[axis], p, params[:, axis], nder)
        dense = np.zeros((nder + 1, npts, lattice.shape[axis]))
        cols = first[:, None] + np.arange(p + 1)[None, :]
        for k in range(nder + 1):
            dense[k, rows, cols] = ders[k]
        tables.append(dense)
    return tables


def evaluate_reference(lattice: Lattice, params) -> np.ndarray:
    """NumPy reference of :func:`evaluate`: dense tensor product (for tests and small N)."""
    params = _check_params(lattice, params)
    t = axis_tables(lattice, params, 0)
    P = lattice.control_points
    if lattice.pdim == 2:
        return np.einsum("ni,nk,ikd->nd", t[0][0], t[1][0], P)
    return np.einsum("ni,nj,nk,ijkd->nd", t[0][0], t[1][0], t[2][0], P)


def derivatives_reference(lattice: Lattice, params) -> np.ndarray:
    """NumPy reference of :func:`derivatives` (dense tensor product)."""
    params = _check_params(lattice, params)
    t = axis_tables(lattice, params, 1)
    P = lattice.control_points
    if lattice.pdim == 2:
        du = np.einsum("ni,nk,ikd->nd", t[0][1], t[1][0], P)
        dv = np.einsum("ni,nk,ikd->nd", t[0][0], t[1][1], P)
        return np.stack([du, dv], axis=-1)
    du = np.einsum("ni,nj,nk,ijkd->nd", t[0][1], t[1][0], t[2][0], P)
    dv = np.einsum("ni,nj,nk,ijkd->nd", t[0][0], t[1][1], t[2][0], P)
    dw = np.einsum("ni,nj,nk,ijkd->nd", t[0][0], t[1][0], t[2][1], P)
    return np.stack([du, dv, dw], axis=-1)
