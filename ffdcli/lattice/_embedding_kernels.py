"""The compiled kernels of :class:`ffdcli.lattice.embedding.Embedding`: its basis, ``B @ P`` and ``B.T @ g``.

The NumPy references they are tested against are in :mod:`ffdcli.lattice.embedding`
(``basis_matrix_reference``, ``rmatvec_reference``, ``dense_basis_reference``) and
:func:`ffdcli.lattice.spline.basis`.

The basis pass and ``B @ P`` have two versions, chosen by the lattice's degrees
(:func:`ffdcli.lattice._newton_kernels.specialised`): unrolled for the degrees of
:data:`~ffdcli.lattice._newton_kernels.SPECIALISED` (the basis in registers, the tensor product
in explicit 4-wide fused multiply-adds, :func:`ffdcli.jit.tensor_v`), and generic (widths at run
time, one compiled kernel for every other combination) with the same operations in the same order,
so the same floats bit for bit (the generic ``B @ P`` rounds with the scalar :func:`ffdcli.jit.fma`,
lane for lane the vector one). ``B.T @ g`` reads its widths at run time (with two unrolled kernels
for the default box) and ``basis_matrix`` is generic.
"""

from __future__ import annotations

import numba
import numpy as np
from numba import njit, prange

from ffdcli.jit import axpy4, axpy8, axpy8x3, fma, inlined, kernel, tensor_v, tuple_setitem
from ffdcli.lattice._newton_kernels import specialised
from ffdcli.lattice.lattice import fixed_widths
from ffdcli.lattice.spline import basis_d1_tuple, basis_row_nb, find_span_nb
from ffdcli.settings import MAX_DEGREE

# ----------------------------------------------------------------------------------------------
# The basis of every point: first index and values per axis
# ----------------------------------------------------------------------------------------------

@kernel
def _basis_axes_chunk_nb(k0, k1, k2, params, f0, V0, f1, V1, f2, V2, lo, hi, w0, w1, w2):
    """:func:`_basis_axes_fixed_nb` for the points ``lo:hi``; returns the number of parameters not in [0, 1].

    Compiled per basis widths (``w0, w1, w2``: :func:`ffdcli.lattice.lattice.fixed_widths`) with the basis
    of :func:`ffdcli.lattice.spline.basis_d1_tuple` in registers; without reference counting and zero-division
    checks per point, as :func:`_newton_chunk_nb`."""
    pdim = params.shape[1]
    p0 = len(w0) - 1
    p1 = len(w1) - 1
    p2 = len(w2) - 1
    bad = 0
    for i in range(lo, hi):
        t = params[i, 0]
        if not (0.0 <= t <= 1.0):
            bad += 1
            t = 0.0
        span = find_span_nb(k0, p0, t)
        N, _ = basis_d1_tuple(k0, span, t, w0)
        f0[i] = span - p0
        for a in range(p0 + 1):
            V0[i, a] = N[a]
        t = params[i, 1]
        if not (0.0 <= t <= 1.0):
            bad += 1
            t = 0.0
        span = find_span_nb(k1, p1, t)
        N, _ = basis_d1_tuple(k1, span, t, w1)
        f1[i] = span - p1
        for a in range(p1 + 1):
            V1[i, a] = N[a]
        if pdim == 3:
            t = params[i, 2]
            if not (0.0 <= t <= 1.0):
                bad += 1
                t = 0.0
            span = find_span_nb(k2, p2, t)
            N, _ = basis_d1_tuple(k2, span, t, w2)
            f2[i] = span - p2
            for a in range(p2 + 1):
                V2[i, a] = N[a]
    return bad


@njit(cache=True, parallel=True)
def _basis_axes_fixed_nb(k0, k1, k2, params, f0, V0, f1, V1, f2, V2, nchunk, w0, w1, w2):
    """Per-axis first index and basis values of every point, in one pass over ``params`` (N, pdim)
    in ``nchunk`` chunks (:func:`_basis_axes_chunk_nb`); the third axis is skipped when ``params``
    has two columns. The values are :func:`ffdcli.lattice.spline.basis_compiled`'s, bit for bit (the
    operations of :func:`ffdcli.lattice.spline.basis_row_nb`, unrolled for the widths ``w0, w1, w2``).
    Returns False if a parameter is not in [0, 1] (NaN included)."""
    npts = params.shape[0]
    bad = 0
    for ch in prange(nchunk):
        lo = ch * npts // nchunk
        hi = (ch + 1) * npts // nchunk
        bad += _basis_axes_chunk_nb(k0, k1, k2, params, f0, V0, f1, V1, f2, V2, lo, hi, w0, w1, w2)
    return bad == 0


@inlined
def _axis_generic(knots, p, params, i, axis, first, values, W):
    """Axis ``axis`` of point ``i`` by :func:`ffdcli.lattice.spline.basis_row_nb` (degree ``p`` at run
    time); returns 1 if the parameter is not in [0, 1] (then taken as 0), else 0."""
    t = params[i, axis]
    bad = 0
    if not (0.0 <= t <= 1.0):
        bad = 1
        t = 0.0
    span = find_span_nb(knots, p, t)
    basis_row_nb(knots, p, span, t, W, 0, 1, 2)
    first[i] = span - p
    for a in range(p + 1):
        values[i, a] = W[0, a]
    return bad


@kernel
def _basis_axes_generic_chunk_nb(k0, k1, k2, params, f0, V0, f1, V1, f2, V2, lo, hi, p0, p1, p2, W):
    """:func:`_basis_axes_chunk_nb` with the degrees at run time (``W`` a (3, MAX_DEGREE + 1) work
    array): the same operations (:func:`ffdcli.lattice.spline.basis_row_nb` is
    :func:`ffdcli.lattice.spline.basis_d1_tuple`'s values, bit for bit)."""
    pdim = params.shape[1]
    bad = 0
    for i in range(lo, hi):
        bad += _axis_generic(k0, p0, params, i, 0, f0, V0, W)
        bad += _axis_generic(k1, p1, params, i, 1, f1, V1, W)
        if pdim == 3:
            bad += _axis_generic(k2, p2, params, i, 2, f2, V2, W)
    return bad


@njit(cache=True, parallel=True)
def _basis_axes_generic_nb(k0, k1, k2, params, f0, V0, f1, V1, f2, V2, nchunk, p0, p1, p2):
    """:func:`_basis_axes_fixed_nb` for any degrees: one compiled kernel for every combination."""
    npts = params.shape[0]
    bad = 0
    for ch in prange(nchunk):
        lo = ch * npts // nchunk
        hi = (ch + 1) * npts // nchunk
        W = np.zeros((3, MAX_DEGREE + 1))
        bad += _basis_axes_generic_chunk_nb(k0, k1, k2, params, f0, V0, f1, V1, f2, V2, lo, hi, p0, p1, p2, W)
    return bad == 0


def basis_axes(knots, params, first, values, degrees) -> bool:
    """Fill ``first`` (per axis (N,) int32) and ``values`` (per axis (N, p + 1)) from ``params`` (N, pdim):
    ``knots``, ``first``, ``values`` and ``degrees`` have three entries (a 2D lattice's third is the
    dummy axis of degree 0: knots [0, 1], arrays it never writes). Returns False if a parameter is
    not in [0, 1] (NaN included). Unrolled kernel for :data:`SPECIALISED` degrees, else generic."""
    npts = params.shape[0]
    nchunk = min(npts, 16 * numba.get_num_threads())
    args = (knots[0], knots[1], knots[2], params, first[0], values[0], first[1], values[1], first[2], values[2],
            nchunk)
    if specialised(degrees):
        return _basis_axes_fixed_nb(*args, *fixed_widths(degrees))
    return _basis_axes_generic_nb(*args, *(np.int64(p) for p in degrees))


# ----------------------------------------------------------------------------------------------
# B @ P over the tensor-product form
# ----------------------------------------------------------------------------------------------

# Control points as 4-wide rows (x, y, z, 0): each multiply-add of the tensor product is one explicit
# vector fused multiply-add over the coordinates (ffdcli.jit.tensor_v; numba does not vectorise
# straight-line code), unrolled for the basis widths (tuples of the lattice's p + 1 per axis, so one
# compiled version per lattice degrees). Results move by ulps from a sum of separate products; a
# zero dP still gives 0.
@inlined
def _row_tuple(V, i, proto):
    """``V[i, :len(proto)]`` as a tuple (of the length of ``proto``, known when compiling)."""
    out = proto
    for a in range(len(proto)):
        out = tuple_setitem(out, a, V[i, a])
    return out


@kernel
def _apply_chunk_nb(f0, V0, f1, V1, f2, V2, has_w, n1, n2, R, inside, use_mask, out, lo, hi, w0, w1, w2):
    """Rows ``lo:hi`` of :func:`_apply_fixed_nb`; compiled without reference counting (no per-point
    reference-count updates of the arrays handed to the inlined functions)."""
    gdim = out.shape[1]
    for i in range(lo, hi):
        if use_mask and not inside[i]:
            for d in range(gdim):
                out[i, d] = 0.0
            continue
        i2 = i if has_w else 0                       # 2D: the dummy axis, one value 1 at index 0
        N0 = _row_tuple(V0, i, w0)
        N1 = _row_tuple(V1, i, w1)
        N2 = _row_tuple(V2, i2, w2)
        k = (f0[i] * n1 + f1[i]) * n2 + f2[i2]
        x = tensor_v(R, k, n1 * n2, n2, N0, N1, N2)
        for d in range(gdim):
            out[i, d] = x[d]


@njit(cache=True, parallel=True)
def _apply_fixed_nb(f0, V0, f1, V1, f2, V2, has_w, n1, n2, R, inside, use_mask, out, nchunk, w0, w1, w2):
    """``out = B @ P`` over the tensor-product form; ``R`` the control points as flat 4-wide rows
    (4 n_ctrl,), ``out`` (N, gdim); ``w0, w1, w2`` the basis widths
    (:func:`ffdcli.lattice.lattice.fixed_widths`, a third of width 1 in 2D); ``nchunk`` chunks of points."""
    npts = f0.shape[0]
    for ch in prange(nchunk):
        lo = ch * npts // nchunk
        hi = (ch + 1) * npts // nchunk
        _apply_chunk_nb(f0, V0, f1, V1, f2, V2, has_w, n1, n2, R, inside, use_mask, out, lo, hi, w0, w1, w2)


@kernel
def _apply_generic_chunk_nb(f0, V0, f1, V1, f2, V2, has_w, n1, n2, R, inside, use_mask, out, lo, hi):
    """:func:`_apply_chunk_nb` with the basis widths at run time (the shapes of ``V0, V1, V2``): per
    coordinate, the fused multiply-adds of :func:`ffdcli.jit.tensor_v` in the same order (axis 2, then
    1, then 0, each sum from zero), by the scalar :func:`ffdcli.jit.fma`: the same floats, bit for bit."""
    gdim = out.shape[1]
    a1 = V0.shape[1]
    b1 = V1.shape[1]
    c1 = V2.shape[1]
    s0 = n1 * n2
    for i in range(lo, hi):
        if use_mask and not inside[i]:
            for d in range(gdim):
                out[i, d] = 0.0
            continue
        i2 = i if has_w else 0                       # 2D: the dummy axis, one value 1 at index 0
        k = (f0[i] * n1 + f1[i]) * n2 + f2[i2]
        x0 = x1 = x2 = 0.0
        for a in range(a1):
            r0 = r1 = r2 = 0.0
            ka = k + a * s0
            for b in range(b1):
                q0 = q1 = q2 = 0.0
                kb = ka + b * n2
                for c in range(c1):
                    w = V2[i2, c]
                    row = 4 * (kb + c)
                    q0 = fma(w, R[row], q0)
                    q1 = fma(w, R[row + 1], q1)
                    q2 = fma(w, R[row + 2], q2)
                w = V1[i, b]
                r0 = fma(w, q0, r0)
                r1 = fma(w, q1, r1)
                r2 = fma(w, q2, r2)
            w = V0[i, a]
            x0 = fma(w, r0, x0)
            x1 = fma(w, r1, x1)
            x2 = fma(w, r2, x2)
        out[i, 0] = x0
        if gdim > 1:
            out[i, 1] = x1
        if gdim > 2:
            out[i, 2] = x2


@njit(cache=True, parallel=True)
def _apply_generic_nb(f0, V0, f1, V1, f2, V2, has_w, n1, n2, R, inside, use_mask, out, nchunk):
    """:func:`_apply_fixed_nb` for any basis widths: one compiled kernel for every combination."""
    npts = f0.shape[0]
    for ch in prange(nchunk):
        lo = ch * npts // nchunk
        hi = (ch + 1) * npts // nchunk
        _apply_generic_chunk_nb(f0, V0, f1, V1, f2, V2, has_w, n1, n2, R, inside, use_mask, out, lo, hi)


def apply(axes, P, inside, use_mask, out):
    """``out = B @ P`` (``axes`` from ``Embedding._kernel_axes``, ``P`` (n_ctrl, 4) C-contiguous, ``out``
    (N, gdim)); rows of outside points zero when ``use_mask``. Unrolled for :data:`SPECIALISED`
    degrees, else generic."""
    f0, V0, f1, V1, f2, V2, has_w = axes[:7]
    nchunk = min(f0.shape[0], 4 * numba.get_num_threads())
    if specialised(tuple(V.shape[1] - 1 for V in (V0, V1, V2))):
        widths = tuple((0.0,) * V.shape[1] for V in (V0, V1, V2))
        _apply_fixed_nb(*axes, P.reshape(-1), inside, use_mask, out, nchunk, *widths)
    else:
        _apply_generic_nb(*axes, P.reshape(-1), inside, use_mask, out, nchunk)


# ----------------------------------------------------------------------------------------------
# The CSR rows of B, and B.T @ g
# ----------------------------------------------------------------------------------------------

@njit(cache=True, parallel=True)
def basis_rows_nb(f0, V0, f1, V1, f2, V2, has_w, n1, n2, inside, indptr, cols, data):
    """The CSR rows of B: for each inside point, its (p+1)(q+1)(r+1) columns in increasing order
    and the products V0[a] * V1[b] * V2[c] of its basis values (in that order of multiplication)."""
    npts = f0.shape[0]
    a1 = V0.shape[1]
    b1 = V1.shape[1]
    c1 = V2.shape[1] if has_w else 1
    for i in prange(npts):
        if not inside[i]:
            continue
        k = indptr[i]
        i2 = f2[i] if has_w else 0
        for a in range(a1):
            for b in range(b1):
                base = ((f0[i] + a) * n1 + (f1[i] + b)) * n2 + i2
                wab = V0[i, a] * V1[i, b]
                for c in range(c1):
                    cols[k] = base + c
                    data[k] = wab * V2[i, c] if has_w else wab
                    k += 1


# B.T @ g scatters each point's products into the rows of its (p+1)(q+1)(r+1) control points. The
# accumulator is flat, 4 doubles per control point (x, y, z, 0), and every update is one explicit
# vector fused multiply-add (ffdcli.jit: numba does not vectorise straight-line code): 4-wide per
# control point in the general kernel, 8-wide over the two control points of a linear third axis in
# the cubic-cubic-linear kernel, and 24-wide (3 doubles per control point) over the 8 adjacent
# control points of a slice when that third axis has only its 2 control points (the default box).
@njit(cache=True, parallel=True)
def _rmatvec_nb(f0, V0, f1, V1, f2, V2, has_w, n1, n2, g, inside, acc, out):
    """``out = B.T @ g``, (n_ctrl, gdim): ``acc[chunk] += B[chunk rows].T @ g`` per chunk of points
    (one accumulator per chunk: no two threads add into one array), then the chunks summed in order
    (:func:`_sum_chunks`); ``acc`` (nchunk, n_ctrl * 4), zero on entry, every 4th entry stays 0.
    Any basis widths, 2D (``has_w`` False) or 3D; rows of outside points are skipped.

    Per control point the update is ``fma(V0[a] V1[b] V2[c], g, acc)``: the same value, bit for bit,
    as the scalar ``acc[k, q] += w * g[q]`` with contraction."""
    npts = f0.shape[0]
    gdim = g.shape[1]
    nchunk = acc.shape[0]
    a1 = V0.shape[1]
    b1 = V1.shape[1]
    c1 = V2.shape[1] if has_w else 1
    for ch in prange(nchunk):
        lo = ch * npts // nchunk
        hi = (ch + 1) * npts // nchunk
        part = acc[ch]
        for i in range(lo, hi):
            if not inside[i]:
                continue
            g0 = g[i, 0]
            g1 = g[i, 1] if gdim > 1 else 0.0
            g2 = g[i, 2] if gdim > 2 else 0.0
            i0 = f0[i]
            i1 = f1[i]
            i2 = f2[i] if has_w else 0
            for a in range(a1):
                wa = V0[i, a]
                for b in range(b1):
                    wab = wa * V1[i, b]
                    base = ((i0 + a) * n1 + (i1 + b)) * n2 + i2
                    for c in range(c1):
                        w = wab * V2[i, c] if has_w else wab
                        axpy4(part, 4 * (base + c), w, g0, g1, g2, 0.0)
    _sum_chunks(acc, 4, out)


@njit(cache=True, parallel=True)
def _rmatvec_442_nb(f0, V0, f1, V1, f2, V2, has_w, n1, n2, g, inside, acc, out):
    """:func:`_rmatvec_nb` for the default box (cubic, cubic, linear: widths 4, 4, 2; 3D only) with
    the widths known when compiling: the two control points ``c = 0, 1`` of a column are adjacent
    (C order), so each of the 16 ``(a, b)`` columns is one 8-wide update
    ``acc[4 base : 4 base + 8] += V0[a] V1[b] * (V2[0] g, 0, V2[1] g, 0)``. The products are grouped
    as ``(V0 V1) (V2 g)`` instead of ``((V0 V1) V2) g``: results differ from the general kernel's by
    ulps."""
    npts = f0.shape[0]
    gdim = g.shape[1]
    nchunk = acc.shape[0]
    for ch in prange(nchunk):
        lo = ch * npts // nchunk
        hi = (ch + 1) * npts // nchunk
        part = acc[ch]
        for i in range(lo, hi):
            if not inside[i]:
                continue
            g0 = g[i, 0]
            g1 = g[i, 1] if gdim > 1 else 0.0
            g2 = g[i, 2] if gdim > 2 else 0.0
            v0 = V2[i, 0]
            v1 = V2[i, 1]
            t0, t1, t2 = v0 * g0, v0 * g1, v0 * g2
            s0, s1, s2 = v1 * g0, v1 * g1, v1 * g2
            i0 = f0[i]
            i1 = f1[i]
            i2 = f2[i]
            for a in range(4):
                wa = V0[i, a]
                for b in range(4):
                    base = ((i0 + a) * n1 + (i1 + b)) * n2 + i2
                    axpy8(part, 4 * base, wa * V1[i, b], t0, t1, t2, 0.0, s0, s1, s2, 0.0)
    _sum_chunks(acc, 4, out)


@njit(cache=True, parallel=True)
def _rmatvec_442c_nb(f0, V0, f1, V1, f2, V2, has_w, n1, n2, g, inside, acc, out):
    """:func:`_rmatvec_442_nb` when the third axis has its two control points only (``n2 == 2``, the
    default 8 x 6 x 2 box): then the 4 x 2 control points ``(b, c)`` of a slice ``a`` are 8 adjacent
    rows, and with 3 doubles per control point (no padding lane: ``acc`` (nchunk, n_ctrl * 3)) each
    slice is one 24-wide update ``acc[3 base_a : 3 base_a + 24] += V0[a] * ((V1[b] V2[c]) g)``
    (:func:`ffdcli.jit.axpy8x3`): 4 vector updates per point instead of 16. Products grouped as
    ``V0 ((V1 V2) g)``: ulps from the other kernels."""
    npts = f0.shape[0]
    gdim = g.shape[1]
    nchunk = acc.shape[0]
    for ch in prange(nchunk):
        lo = ch * npts // nchunk
        hi = (ch + 1) * npts // nchunk
        part = acc[ch]
        for i in range(lo, hi):
            if not inside[i]:
                continue
            g0 = g[i, 0]
            g1 = g[i, 1] if gdim > 1 else 0.0
            g2 = g[i, 2] if gdim > 2 else 0.0
            v0 = V2[i, 0]
            v1 = V2[i, 1]
            u0 = V1[i, 0]
            u1 = V1[i, 1]
            u2 = V1[i, 2]
            u3 = V1[i, 3]
            base = (f0[i] * n1 + f1[i]) * 2                 # f2 == 0: one span along the third axis
            for a in range(4):
                axpy8x3(part, 3 * (base + 2 * a * n1), V0[i, a], u0 * v0, u0 * v1, u1 * v0, u1 * v1,
                        u2 * v0, u2 * v1, u3 * v0, u3 * v1, g0, g1, g2)
    _sum_chunks(acc, 3, out)


@inlined
def _sum_chunks(acc, stride, out):
    """``out[k, d] = acc[0, stride k + d] + acc[1, stride k + d] + ...`` in chunk order (serial: a
    few hundred sums per chunk; what ``acc.sum(axis=0)`` gives, without its temporaries)."""
    for k in range(out.shape[0]):
        for d in range(out.shape[1]):
            s = acc[0, stride * k + d]
            for ch in range(1, acc.shape[0]):
                s += acc[ch, stride * k + d]
            out[k, d] = s


def rmatvec(axes, g, inside, nchunk, out):
    """``out = B.T @ g`` (n_ctrl, gdim) over ``nchunk`` chunks of points by the kernel that fits the
    basis widths (``axes`` from ``Embedding._kernel_axes``)."""
    f0, V0, f1, V1, f2, V2, has_w, n1, n2 = axes
    n_ctrl = out.shape[0]
    if has_w and V0.shape[1] == 4 and V1.shape[1] == 4 and V2.shape[1] == 2:
        if n2 == 2:
            _rmatvec_442c_nb(*axes, g, inside, np.zeros((nchunk, 3 * n_ctrl)), out)
        else:
            _rmatvec_442_nb(*axes, g, inside, np.zeros((nchunk, 4 * n_ctrl)), out)
    else:
        _rmatvec_nb(*axes, g, inside, np.zeros((nchunk, 4 * n_ctrl)), out)
