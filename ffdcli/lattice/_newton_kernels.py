"""The compiled Newton point inversion of :func:`ffdcli.lattice.embedding.embed` and its start table.

Two versions of the same code, chosen by the lattice's degrees (:func:`run_newton`):

- for the degrees of :data:`SPECIALISED` (the defaults and the usual choices), the lattice map is
  evaluated by :func:`ffdcli.lattice.lattice.eval_point_fixed_nb`: compiled for the degrees,
  unrolled, in 4-wide vector operations, about 3x faster per evaluation;
- for every other combination (degrees 1 to 5 per direction), by the generic
  :func:`ffdcli.lattice.lattice.eval_point_nb` (degrees at run time): one compiled kernel for all of
  them, so a new combination of degrees compiles nothing.

Both evaluations give the same floats, bit for bit (``tests/lattice/test_lattice.py``), so the
embedding does not depend on which ran (``tests/lattice/test_embedding.py``). The per-point
functions are inlined by LLVM (:func:`ffdcli.jit.inlined`), not by numba: the Newton kernel of one
degree combination compiles in about a third of the time of numba's own ``inline="always"``.
"""

from __future__ import annotations

import numba
import numpy as np
from numba import njit, prange, types
from numba.extending import overload

from ffdcli.jit import inlined, kernel
from ffdcli.lattice.lattice import eval_point_fixed_nb, eval_point_nb, fixed_widths, padded_rows
from ffdcli.settings import MAX_DEGREE

#: Lattice degrees ``(p0, p1, p2)`` of the kernels' three-axis form (a 2D lattice's third is 0) that
#: have kernels compiled for them: the default boxes (3D 6 x 8 x 2 and 2D 6 x 5 give (3, 3, 1) and
#: (3, 3)), the all-cubic box and the 2D box of two rows. Every other combination runs the generic
#: kernels, which give the same results bit for bit.
SPECIALISED = frozenset({(3, 3, 1), (3, 3, 3), (3, 3, 0), (3, 1, 0)})
#: A point outside the lattice has reached its nearest lattice point when the cosine between its
#: residual and the lattice's tangent directions is below this (first-order optimality).
STATIONARY = 1e-10


def specialised(degrees) -> bool:
    """Whether the three-axis degrees ``(p0, p1, p2)`` have kernels of their own (:data:`SPECIALISED`)."""
    return tuple(int(p) for p in degrees) in SPECIALISED


# ----------------------------------------------------------------------------------------------
# The lattice map at a point: unrolled for the degrees, or generic
# ----------------------------------------------------------------------------------------------

def _eval_lat(lat, u0, u1, u2):
    """V and its first derivatives at ``(u0, u1, u2)`` (12 floats, see
    :func:`ffdcli.lattice.lattice.eval_point_nb`) of the lattice ``lat``: either
    ``(R, n1, n2, k0, k1, k2, w0, w1, w2)`` (rows and widths of
    :func:`ffdcli.lattice.lattice.eval_point_fixed_nb`) or ``(P, k0, k1, k2, p0, p1, p2, W)`` (the
    arguments of :func:`ffdcli.lattice.lattice.eval_point_nb`). Compiled code only."""
    raise NotImplementedError("compiled code only")


def _is_fixed(lat) -> bool:
    return isinstance(lat, types.BaseTuple) and len(lat) == 9 and isinstance(lat[8], types.UniTuple)


@overload(_eval_lat, jit_options=dict(nogil=True, error_model="numpy", _nrt=False, forceinline=True))
def _eval_lat_impl(lat, u0, u1, u2):
    if _is_fixed(lat):
        def fixed(lat, u0, u1, u2):
            R, n1, n2, k0, k1, k2, w0, w1, w2 = lat
            return eval_point_fixed_nb(R, n1, n2, k0, k1, k2, u0, u1, u2, w0, w1, w2)
        return fixed

    def generic(lat, u0, u1, u2):
        P, k0, k1, k2, p0, p1, p2, W = lat
        return eval_point_nb(P, k0, k1, k2, p0, p1, p2, u0, u1, u2, W)
    return generic


def _lat_pdim(lat):
    """Parametric dimension (2 or 3) of ``lat`` (see :func:`_eval_lat`); a compile-time constant for
    the unrolled form. Compiled code only."""
    raise NotImplementedError("compiled code only")


@overload(_lat_pdim, jit_options=dict(nogil=True, _nrt=False, forceinline=True))
def _lat_pdim_impl(lat):
    if _is_fixed(lat):
        return lambda lat: 3 if len(lat[8]) > 1 else 2    # a 2D lattice: third axis of degree 0
    return lambda lat: 3 if lat[6] > 0 else 2


@inlined
def _sqdist(lat, u, X, i, gdim, out):
    """|V(u) - X[i]|^2; ``out`` (12,) receives V and its derivatives (:func:`_eval_lat`)."""
    res = _eval_lat(lat, u[0], u[1], u[2])
    for k in range(12):
        out[k] = res[k]
    s = 0.0
    for d in range(gdim):
        r = res[d] - X[i, d]
        s += r * r
    return s


@inlined
def _solve_small(H, rhs, n, x):
    """Solve the n x n (n <= 3) system H x = rhs by Gaussian elimination with partial pivoting.

    ``H`` and ``rhs`` are overwritten. Returns False when a pivot is negligible (singular H).
    """
    scale = 0.0
    for e in range(n):
        scale = max(scale, abs(H[e, e]))
    if scale == 0.0:
        return False
    for k in range(n):
        piv = k
        for r in range(k + 1, n):
            if abs(H[r, k]) > abs(H[piv, k]):
                piv = r
        if abs(H[piv, k]) <= 1e-13 * scale:
            return False
        if piv != k:
            for c in range(n):
                t = H[k, c]
                H[k, c] = H[piv, c]
                H[piv, c] = t
            t = rhs[k]
            rhs[k] = rhs[piv]
            rhs[piv] = t
        for r in range(k + 1, n):
            m = H[r, k] / H[k, k]
            for c in range(k, n):
                H[r, c] -= m * H[k, c]
            rhs[r] -= m * rhs[k]
    for k in range(n - 1, -1, -1):
        s = rhs[k]
        for c in range(k + 1, n):
            s -= H[k, c] * x[c]
        x[k] = s / H[k, k]
    return True


@inlined
def _newton_point(lat, pdim, gdim, X, i, u, tol2, stop2, snap, max_iter, cur, trial, ut, step, grad, H, rhs,
                  fixed):
    """Projected Gauss-Newton for point ``X[i]``; ``u`` (3,) is the start and receives the result; ``lat``
    the lattice as :func:`_eval_lat` takes it.

    Returns the squared residual at the result.
    """
    f = _sqdist(lat, u, X, i, gdim, cur)
    for _ in range(max_iter):
        if f <= stop2:
            break
        # gradient J^T r and Gauss-Newton matrix J^T J (J columns are cur[3 + 3e: 6 + 3e])
        for e in range(pdim):
            s = 0.0
            for d in range(gdim):
                s += cur[3 + 3 * e + d] * (cur[d] - X[i, d])
            grad[e] = s
            for e2 in range(pdim):
                s = 0.0
                for d in range(gdim):
                    s += cur[3 + 3 * e + d] * cur[3 + 3 * e2 + d]
                H[e, e2] = s
        # variables held at a bound by the gradient stay there (active set)
        nfree = 0
        for e in range(pdim):
            fixed[e] = (u[e] <= 0.0 and grad[e] > 0.0) or (u[e] >= 1.0 and grad[e] < 0.0)
            if not fixed[e]:
                nfree += 1
        if nfree == 0:
            break
        trace = 0.0
        for e in range(pdim):
            if fixed[e]:
                for e2 in range(pdim):
                    H[e, e2] = 0.0
                    H[e2, e] = 0.0
                H[e, e] = 1.0
                rhs[e] = 0.0
            else:
                rhs[e] = -grad[e]
                trace += H[e, e]
        if f > tol2:
            # a point outside at its nearest lattice point: the residual is normal to the lattice
            # (|J^T r| <= 1e-10 |J| |r|); stop here rather than in the line search's 40 halvings
            # (the distance is flat there: further steps change it below rounding)
            g2 = 0.0
            for e in range(pdim):
                if not fixed[e]:
                    g2 += grad[e] * grad[e]
            if g2 <= STATIONARY * STATIONARY * f * trace:
                break
        ok = _solve_small(H, rhs, pdim, step)
        if not ok:
            # singular Jacobian (degenerate lattice cell): scaled steepest descent
            for e in range(pdim):
                step[e] = 0.0 if fixed[e] else -grad[e] / max(trace, 1e-300)
        # backtracking along the projected path u(alpha) = clip(u + alpha * step)
        alpha = 1.0
        accepted = False
        max_halvings = 4 if f <= tol2 else 40
        for _ls in range(max_halvings):
            for e in range(pdim):
                v = u[e] + alpha * step[e]
                ut[e] = 0.0 if v < 0.0 else (1.0 if v > 1.0 else v)
            ft = _sqdist(lat, ut, X, i, gdim, trial)
            if ft < f:
                accepted = True
                break
            alpha *= 0.5
        if not accepted:
            break
        moved = 0.0
        for e in range(pdim):
            moved = max(moved, abs(ut[e] - u[e]))
            u[e] = ut[e]
        for k in range(12):
            cur[k] = trial[k]
        f = ft
        if moved <= 1e-15:
            break
    # exact face parameters for points on (or within 1e-10 of) a face of the lattice
    if f <= tol2:
        for e in range(pdim):
            target = -1.0
            if 0.0 < u[e] <= snap:
                target = 0.0
            elif 1.0 - snap <= u[e] < 1.0:
                target = 1.0
            if target >= 0.0:
                keep = u[e]
                u[e] = target
                fs = _sqdist(lat, u, X, i, gdim, trial)
                if fs <= tol2:
                    f = fs
                else:
                    u[e] = keep
    return f


@kernel
def _newton_chunk_nb(lat, X, params, tol2, stop2, snap, max_iter, residual, lo, hi,
                     use_table, t_lo, t_inv_h, t_dims, t_centers, t_params, t_jinv, work, fixed):
    """Newton for the points ``lo:hi`` of ``X`` (see :func:`_newton_fixed_nb`); ``lat`` the lattice
    (:func:`_eval_lat`); ``work`` (48,) and ``fixed`` (3,) are the chunk's work arrays.

    A function of its own, called once per chunk from the parallel loop, not inlined into it: numba
    compiles it with the lattice's form (and, unrolled, its widths) as constants, and the parallel
    loop's array analysis never sees the per-point tuples. Compiled without numba's reference
    counting (:func:`ffdcli.jit.kernel`: it allocates nothing): the arrays handed to the per-point
    functions would otherwise be counted in and out at every point (about 30 calls per point,
    atomic operations on counters shared by the threads). NumPy's error model: no zero-division
    checks (and their exception paths) around the basis recurrence's divisions (never by zero: a
    knot span's denominators are sums of non-empty knot intervals; the Gauss elimination checks its
    pivots first)."""
    gdim = X.shape[1]
    pdim = _lat_pdim(lat)
    cur = work[0:12]
    trial = work[12:24]
    u = work[24:27]
    ut = work[27:30]
    step = work[30:33]
    grad = work[33:36]
    rhs = work[36:39]
    H = work[39:48].reshape((3, 3))
    for i in range(lo, hi):
        if use_table:
            _start_point(X, i, t_lo, t_inv_h, t_dims, t_centers, t_params, t_jinv, u)
        else:
            for e in range(pdim):
                u[e] = params[i, e]
        f = _newton_point(lat, pdim, gdim, X, i, u, tol2, stop2, snap, max_iter, cur, trial, ut, step, grad, H,
                          rhs, fixed)
        for e in range(pdim):
            params[i, e] = u[e]
        residual[i] = np.sqrt(f)


@njit(cache=True, parallel=True)
def _newton_fixed_nb(R, n1, n2, k0, k1, k2, X, params, tol, stop, snap, max_iter, residual, nchunk,
                     use_table, t_lo, t_inv_h, t_dims, t_centers, t_params, t_jinv, w0, w1, w2):
    """Newton for every point of ``X``, from ``params`` or (``use_table``) from the start table
    ``t_*`` (:class:`ffdcli.lattice.embedding.StartTable`'s arrays), read in the same pass; writes
    ``params`` and ``residual``. ``nchunk`` chunks of points share the threads
    (:func:`_newton_chunk_nb`). ``R, n1, n2, w0, w1, w2``: the rows and basis widths of
    :func:`ffdcli.lattice.lattice.eval_point_fixed_nb`: a compiled version per lattice degrees, with
    the lattice evaluation unrolled (the results of the generic :func:`_newton_generic_nb`, bit for
    bit, in a third of the time)."""
    npts = X.shape[0]
    tol2 = tol * tol
    stop2 = stop * stop
    nchunk = min(npts, nchunk)
    for ch in prange(nchunk):
        lo = ch * npts // nchunk
        hi = (ch + 1) * npts // nchunk
        work = np.zeros(48)
        fixed = np.zeros(3, dtype=np.bool_)
        _newton_chunk_nb((R, n1, n2, k0, k1, k2, w0, w1, w2), X, params, tol2, stop2, snap, max_iter, residual,
                         lo, hi, use_table, t_lo, t_inv_h, t_dims, t_centers, t_params, t_jinv, work, fixed)


@njit(cache=True, parallel=True)
def _newton_generic_nb(P, k0, k1, k2, p0, p1, p2, X, params, tol, stop, snap, max_iter, residual, nchunk,
                       use_table, t_lo, t_inv_h, t_dims, t_centers, t_params, t_jinv):
    """:func:`_newton_fixed_nb` for any degrees (``p0, p1, p2`` at run time, ``P`` the control points
    of :func:`ffdcli.lattice.lattice.kernel_args`): one compiled kernel for every combination."""
    npts = X.shape[0]
    tol2 = tol * tol
    stop2 = stop * stop
    nchunk = min(npts, nchunk)
    for ch in prange(nchunk):
        lo = ch * npts // nchunk
        hi = (ch + 1) * npts // nchunk
        work = np.zeros(48)
        fixed = np.zeros(3, dtype=np.bool_)
        W = np.zeros((8, MAX_DEGREE + 1))
        _newton_chunk_nb((P, k0, k1, k2, p0, p1, p2, W), X, params, tol2, stop2, snap, max_iter, residual,
                         lo, hi, use_table, t_lo, t_inv_h, t_dims, t_centers, t_params, t_jinv, work, fixed)


#: The start table's arrays when there is none (Newton from the given parameters).
NO_TABLE = (np.zeros(3), np.zeros(3), np.ones(3, dtype=np.int64), np.zeros((1, 1)), np.zeros((1, 1)),
            np.zeros((1, 1, 1)))


def run_newton(args, points, params, residual, tol_abs, stop_abs, snap, max_iter, table=None):
    """Newton on ``points`` (N, gdim) from ``params`` (N, pdim) or, when ``table`` (the six arrays of a
    :class:`ffdcli.lattice.embedding.StartTable`) is given, from its starts (``params`` is then only
    written); ``residual`` (N,) receives ``|V(params) - X|``. ``args``: the lattice as
    :func:`ffdcli.lattice.lattice.kernel_args` gives it; the unrolled kernel when its degrees are
    :data:`SPECIALISED`, else the generic one."""
    t = NO_TABLE if table is None else table
    # enough chunks per thread to balance the slower points outside the lattice; work arrays are
    # allocated per chunk, not per point
    nchunk = 16 * numba.get_num_threads()
    P, k0, k1, k2, p0, p1, p2 = args
    common = (points, params, float(tol_abs), float(stop_abs), float(snap), int(max_iter), residual, nchunk,
              table is not None, *t)
    if specialised((p0, p1, p2)):
        n1, n2 = np.int64(P.shape[1]), np.int64(P.shape[2])
        _newton_fixed_nb(padded_rows(P), n1, n2, k0, k1, k2, *common, *fixed_widths((p0, p1, p2)))
    else:
        _newton_generic_nb(P, k0, k1, k2, np.int64(p0), np.int64(p1), np.int64(p2), *common)


# ----------------------------------------------------------------------------------------------
# The start table's kernels
# ----------------------------------------------------------------------------------------------

@njit(cache=True)
def pinv_nb(J, out):
    """``out[c] = (J^T J)^-1 J^T`` of each (gdim, pdim) ``J[c]`` (zero where J^T J is singular)."""
    gdim = J.shape[1]
    pdim = J.shape[2]
    H = np.zeros((3, 3))
    rhs = np.zeros(3)
    x = np.zeros(3)
    for c in range(J.shape[0]):
        for d in range(gdim):
            for e in range(pdim):
                for e2 in range(pdim):
                    s = 0.0
                    for k in range(gdim):
                        s += J[c, k, e] * J[c, k, e2]
                    H[e, e2] = s
                rhs[e] = J[c, d, e]
            if not _solve_small(H, rhs, pdim, x):
                for e in range(pdim):
                    for d2 in range(gdim):
                        out[c, e, d2] = 0.0
                break
            for e in range(pdim):
                out[c, e, d] = x[e]


@inlined
def _start_point(X, i, lo, inv_h, dims, centers, params, jinv, u):
    """The start of point ``X[i]`` into ``u``: ``clip(u_c + J_c^+ (X - C), 0, 1)`` of its cell."""
    gdim = X.shape[1]
    pdim = params.shape[1]
    cell = 0
    for a in range(3):
        j = 0
        if a < gdim:
            t = (X[i, a] - lo[a]) * inv_h[a]
            if t > 0.0:
                j = int(t) if t < dims[a] else dims[a] - 1
        cell = cell * dims[a] + j
    for e in range(pdim):
        v = params[cell, e]
        for d in range(gdim):
            v += jinv[cell, e, d] * (X[i, d] - centers[cell, d])
        u[e] = 0.0 if v < 0.0 else (1.0 if v > 1.0 else v)


@njit(cache=True, parallel=True)
def start_nb(X, lo, inv_h, dims, centers, params, jinv, out):
    for i in prange(X.shape[0]):
        _start_point(X, i, lo, inv_h, dims, centers, params, jinv, out[i])
