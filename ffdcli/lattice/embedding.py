"""Embedding points in a lattice (point inversion) and the sparse basis that moves them.

:func:`embed` finds, for every point ``X``, the parameters ``u`` in [0, 1]^pdim that minimise
``|V(u) - X|`` for the lattice map ``V`` (see :mod:`ffdcli.lattice.lattice`). The lattice is not a
parallelepiped (it follows a swept, tapered, twisted wing), so the map is inverted numerically:

1. each point starts from a first-order inverse of the lattice map at the centre of its cell in a
   uniform grid (:class:`StartTable`: a table read and a 3 x 3 product per point, in the Newton
   kernel's own pass); the table is made once per call from a grid of samples (a few per knot span
   and direction) in a k-d tree, with about one cell per sample whatever the number of points;
2. a projected Gauss-Newton iteration with backtracking line search runs per point inside a
   parallel compiled loop (numba ``prange``; no Python loop over points), compiled per lattice
   degrees (:func:`ffdcli.lattice.lattice.eval_point_fixed_nb`: the lattice map unrolled, in vector
   operations, equal bit for bit to the generic evaluation). Parameters are clipped
   to [0, 1] at every step and the variables held at a bound by the gradient are frozen, so the
   iteration converges to the nearest point of the lattice also for points outside it (which stop
   once their residual is normal to the lattice, :data:`STATIONARY`);
3. parameters within ``snap`` (1e-10) of 0 or 1 are set exactly to 0 or 1 when the point stays
   within tolerance, so points on a lattice face (a wing root) get exact face parameters;
4. points whose residual is above the tolerance are retried from their nearest samples (k-d tree),
   keeping the best result.

A point is *inside* when its residual ``|V(u) - X|`` is at most ``tol * lattice.size``. Points
outside are reported and never snapped onto the lattice: :meth:`Embedding.displace` gives them a
zero displacement, so they keep their position when the lattice moves.

The :class:`Embedding` stores, per direction, the first non-zero basis index and the ``p + 1``
basis values of each point: the tensor-product form of the sparse basis matrix ``B`` (points x
control points) with ``X = B @ P``; :meth:`Embedding.from_params` computes it in one compiled pass.
:meth:`Embedding.displace` (``B @ dP``) and :meth:`Embedding.rmatvec` (``B.T @ g``) are parallel
compiled loops over that form (about a third of the bytes of the CSR matrix), on control points
padded to 4-wide rows, with explicit vector fused multiply-adds (:mod:`ffdcli.lattice.simd`: ``B @ P``
contracts each point's support by :func:`ffdcli.lattice.simd.tensor_v`, unrolled for the lattice's
degrees; ``B.T @ g`` adds into the rows);
:meth:`Embedding.basis_matrix` builds the explicit CSR matrix. The ``*_reference`` functions are
NumPy versions the tests compare the kernels with.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np
from numba import njit, prange
from numba.cpython.unsafe.tuple import tuple_setitem
from scipy import sparse
from scipy.spatial import cKDTree

from ffdcli.errors import InputError
from ffdcli.lattice.lattice import (
    Lattice,
    derivatives,
    eval_point_fixed_nb,
    evaluate,
    fixed_widths,
    kernel_args,
    padded_rows,
)
from ffdcli.lattice.simd import axpy4, axpy8, axpy8x3, tensor_v
from ffdcli.lattice.spline import basis, basis_d1_tuple, find_span_nb
from ffdcli.progress import chunks, no_progress

#: Default inside tolerance, relative to the lattice size (bounding-box diagonal of the control points).
DEFAULT_TOL = 1e-10
#: Parameters closer than this to 0 or 1 are snapped onto the bound (when the residual allows it).
SNAP = 1e-10
#: A point outside the lattice has reached its nearest lattice point when the cosine between its
#: residual and the lattice's tangent directions is below this (first-order optimality).
STATIONARY = 1e-10
#: Points per Python-level chunk of :func:`embed` (paces progress).
CHUNK = 1 << 18


@dataclass
class Embedding:
    """Points embedded in a lattice: their parameters and the basis that maps control points to them.

    Attributes
    ----------
    shape : tuple of int
        Control points per direction of the lattice, e.g. ``(8, 6, 2)``.
    degree : tuple of int
        Degree per direction.
    knots : tuple of ndarray
        Knot vector per direction.
    params : ndarray, shape (N, pdim)
        Parameters in [0, 1]^pdim of the nearest lattice point to each embedded point.
    inside : ndarray of bool, shape (N,)
        ``residual <= tolerance``: the point is inside the lattice and moves with it.
    residual : ndarray, shape (N,)
        ``|V(params) - X|`` in mesh units (for a point outside: its distance to the lattice).
    tolerance : float
        The absolute inside tolerance (mesh units) used.
    first : tuple of ndarray of int32, shape (N,)
        Per direction: index of the first non-zero basis function at ``params``.
    values : tuple of ndarray, shape (N, p + 1)
        Per direction: the non-zero basis values at ``params``.
    """

    shape: tuple[int, ...]
    degree: tuple[int, ...]
    knots: tuple[np.ndarray, ...]
    params: np.ndarray
    inside: np.ndarray
    residual: np.ndarray
    tolerance: float
    first: tuple[np.ndarray, ...]
    values: tuple[np.ndarray, ...]

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_params(cls, lattice: Lattice, params, inside, residual, *, tolerance: float | None = None
                    ) -> Embedding:
        """Rebuild an embedding from what a cache stores: ``params``, ``inside`` and ``residual``.

        The per-direction basis indices and values are recomputed from ``params`` and the
        lattice's degrees and knots. ``tolerance`` defaults to ``DEFAULT_TOL * lattice.size``.
        """
        params = np.ascontiguousarray(params, dtype=np.float64)
        npts = params.shape[0] if params.ndim == 2 else -1
        if params.ndim != 2 or params.shape[1] != lattice.pdim:
            raise ValueError(f"params must have shape (N, {lattice.pdim}), got {params.shape}")
        inside = np.asarray(inside, dtype=bool)
        residual = np.asarray(residual, dtype=np.float64)
        if inside.shape != (npts,) or residual.shape != (npts,):
            raise ValueError(f"inside and residual must have shape ({npts},), got {inside.shape} "
                             f"and {residual.shape}")
        first = tuple(np.empty(npts, dtype=np.int32) for _ in range(lattice.pdim))
        values = tuple(np.empty((npts, p + 1)) for p in lattice.degree)
        k, deg = lattice.knots, lattice.degree
        if lattice.pdim == 3:
            args = (k[0], k[1], k[2], params, first[0], values[0], first[1], values[1], first[2], values[2])
        else:
            args = (k[0], k[1], _DUMMY_KNOTS, params, first[0], values[0], first[1], values[1], _DUMMY_FIRST,
                    _DUMMY_VALUES)
        widths = fixed_widths((*deg, 0) if lattice.pdim == 2 else deg)
        nchunk = min(npts, 16 * numba.get_num_threads())
        if npts and not _basis_axes_nb(*args, nchunk, *widths):
            raise ValueError("params must lie in [0, 1]")
        if tolerance is None:
            tolerance = DEFAULT_TOL * lattice.size
        return cls(shape=tuple(lattice.shape), degree=tuple(lattice.degree), knots=tuple(lattice.knots),
                   params=params, inside=inside, residual=residual, tolerance=float(tolerance),
                   first=first, values=values)

    # ------------------------------------------------------------------ sizes
    @property
    def n_points(self) -> int:
        return int(self.params.shape[0])

    @property
    def pdim(self) -> int:
        return len(self.shape)

    @property
    def n_ctrl(self) -> int:
        return int(np.prod(self.shape))

    def _control_array(self, control_points, name: str) -> tuple[np.ndarray, int]:
        """Control points (or their change) as a C-contiguous (n_ctrl, 4) array (zero-padded: a row is
        one 4-wide vector for the kernels), and gdim."""
        cp = np.asarray(control_points, dtype=np.float64)
        if cp.ndim == self.pdim + 1 and cp.shape[:-1] == tuple(self.shape):
            cp = cp.reshape(self.n_ctrl, cp.shape[-1])
        if cp.ndim != 2 or cp.shape[0] != self.n_ctrl or not 1 <= cp.shape[1] <= 3:
            raise ValueError(f"{name} must have shape {(*self.shape, 'gdim')} or ({self.n_ctrl}, gdim), "
                             f"got {np.shape(control_points)}")
        gdim = cp.shape[1]
        padded = np.zeros((cp.shape[0], 4))
        padded[:, :gdim] = cp
        return padded, gdim

    def _out_array(self, out, gdim: int) -> np.ndarray:
        if out is None:
            return np.empty((self.n_points, gdim))
        if (not isinstance(out, np.ndarray) or out.shape != (self.n_points, gdim) or out.dtype != np.float64
                or not out.flags.c_contiguous or not out.flags.writeable):
            raise ValueError(f"out must be a writeable C-contiguous float64 array of shape "
                             f"({self.n_points}, {gdim})")
        return out

    def _kernel_axes(self):
        """Per-axis (first, values) for the kernels, with a dummy third axis in 2D."""
        if self.pdim == 3:
            return (self.first[0], self.values[0], self.first[1], self.values[1], self.first[2],
                    self.values[2], True, np.int64(self.shape[1]), np.int64(self.shape[2]))
        return (self.first[0], self.values[0], self.first[1], self.values[1], _DUMMY_FIRST,
                _DUMMY_VALUES, False, np.int64(self.shape[1]), np.int64(1))

    # ------------------------------------------------------------------ products with B
    def evaluate(self, control_points, out: np.ndarray | None = None) -> np.ndarray:
        """``B @ P`` for every point (outside points get their nearest lattice point).

        Parameters
        ----------
        control_points : array_like, shape (*shape, gdim) or (n_ctrl, gdim)
        out : ndarray, shape (N, gdim), optional
            C-contiguous float64 array to write the result into (saves allocating N x gdim, and its
            page faults, at every call of a deformation loop).

        Returns
        -------
        points : ndarray, shape (N, gdim)
            ``out`` when given.
        """
        cp, gdim = self._control_array(control_points, "control_points")
        out = self._out_array(out, gdim)
        if self.n_points:
            _apply(self._kernel_axes(), cp, self.inside, False, out)
        return out

    def displace(self, delta_control_points, out: np.ndarray | None = None) -> np.ndarray:
        """``B @ dP`` with zero rows for outside points: the displacement of every point.

        The deformed points are ``X0 + displace(P' - P0)``; a zero change gives exact zeros.

        Parameters
        ----------
        delta_control_points : array_like, shape (*shape, gdim) or (n_ctrl, gdim)
        out : ndarray, shape (N, gdim), optional
            C-contiguous float64 array to write the result into.

        Returns
        -------
        displacement : ndarray, shape (N, gdim)
            ``out`` when given.
        """
        cp, gdim = self._control_array(delta_control_points, "delta_control_points")
        out = self._out_array(out, gdim)
        if self.n_points:
            _apply(self._kernel_axes(), cp, self.inside, True, out)
        return out

    def rmatvec(self, g) -> np.ndarray:
        """``B.T @ g``: pull a per-point vector back to the control points (adjoint of ``displace``).

        Parameters
        ----------
        g : array_like, shape (N, gdim)
            E.g. dJ/dX per point. Rows of outside points do not contribute.

        Returns
        -------
        ndarray, shape (n_ctrl, gdim)
            Control points in the C order of ``control_points.reshape(-1, gdim)``.
        """
        g = np.ascontiguousarray(g, dtype=np.float64)
        if g.ndim != 2 or g.shape[0] != self.n_points or not 1 <= g.shape[1] <= 3:
            raise ValueError(f"g must have shape ({self.n_points}, gdim), got {g.shape}")
        if not self.n_points:
            return np.zeros((self.n_ctrl, g.shape[1]))
        nchunk = min(self.n_points, 4 * numba.get_num_threads())
        out = np.empty((self.n_ctrl, g.shape[1]))
        _rmatvec(self._kernel_axes(), g, self.inside, nchunk, out)
        return out

    def basis_matrix(self) -> sparse.csr_matrix:
        """The sparse basis ``B`` (N x n_ctrl, CSR) with zero rows for outside points.

        Columns follow the C order of ``control_points.reshape(-1, gdim)``; column indices are
        sorted within each row.
        """
        nnz_row = int(np.prod([p + 1 for p in self.degree]))
        counts = self.inside.astype(np.int64) * nnz_row
        nnz = int(counts.sum())
        # 32-bit indices when they fit (what SciPy would convert them to anyway, at the cost of a copy)
        itype = np.int32 if max(nnz, self.n_ctrl) < np.iinfo(np.int32).max else np.int64
        indptr = np.zeros(self.n_points + 1, dtype=itype)
        indptr[1:] = np.cumsum(counts)
        cols = np.empty(nnz, dtype=itype)
        data = np.empty(nnz)
        if nnz:
            _basis_rows_nb(*self._kernel_axes(), self.inside, indptr, cols, data)
        return sparse.csr_matrix((data, cols, indptr), shape=(self.n_points, self.n_ctrl))

    # ------------------------------------------------------------------ report
    def outside_report(self, max_indices: int = 10) -> dict:
        """Points not inside the lattice: ``count``, ``indices`` (the first ``max_indices``),
        ``worst_distance`` (largest residual among them, mesh units; 0.0 if none), ``worst_index``
        (``None`` if none) and the ``tolerance`` used."""
        out = np.flatnonzero(~self.inside)
        if out.size:
            k = int(out[np.argmax(self.residual[out])])
            worst, worst_index = float(self.residual[k]), k
        else:
            worst, worst_index = 0.0, None
        return {"count": int(out.size), "indices": [int(i) for i in out[:max_indices]],
                "worst_distance": worst, "worst_index": worst_index, "tolerance": self.tolerance}


_DUMMY_FIRST = np.zeros(1, dtype=np.int32)
_DUMMY_VALUES = np.ones((1, 1))
_DUMMY_KNOTS = np.array([0.0, 1.0])


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def _basis_axes_chunk_nb(k0, k1, k2, params, f0, V0, f1, V1, f2, V2, lo, hi, w0, w1, w2):
    """:func:`_basis_axes_nb` for the points ``lo:hi``; returns the number of parameters not in [0, 1].

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
def _basis_axes_nb(k0, k1, k2, params, f0, V0, f1, V1, f2, V2, nchunk, w0, w1, w2):
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


# ----------------------------------------------------------------------------------------------
# B @ P and B.T @ g over the tensor-product form (compiled) and their NumPy references
# ----------------------------------------------------------------------------------------------

# Control points as 4-wide rows (x, y, z, 0): each multiply-add of the tensor product is one explicit
# vector fused multiply-add over the coordinates (ffdcli.lattice.simd.tensor_v; numba does not vectorise
# straight-line code), unrolled for the basis widths (tuples of the lattice's p + 1 per axis, so one
# compiled version per lattice degrees). Results move by ulps from a sum of separate products; a
# zero dP still gives 0.
@njit(cache=True, nogil=True, inline="always")
def _row_tuple(V, i, proto):
    """``V[i, :len(proto)]`` as a tuple (of the length of ``proto``, known when compiling)."""
    out = proto
    for a in range(len(proto)):
        out = tuple_setitem(out, a, V[i, a])
    return out


@njit(cache=True, nogil=True, _nrt=False)
def _apply_chunk_nb(f0, V0, f1, V1, f2, V2, has_w, n1, n2, R, inside, use_mask, out, lo, hi, w0, w1, w2):
    """Rows ``lo:hi`` of :func:`_apply_nb`; compiled without reference counting (no per-point
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
def _apply_nb(f0, V0, f1, V1, f2, V2, has_w, n1, n2, R, inside, use_mask, out, nchunk, w0, w1, w2):
    """``out = B @ P`` over the tensor-product form; ``R`` the control points as flat 4-wide rows
    (4 n_ctrl,), ``out`` (N, gdim); ``w0, w1, w2`` the basis widths
    (:func:`ffdcli.lattice.lattice.fixed_widths`, a third of width 1 in 2D); ``nchunk`` chunks of points."""
    npts = f0.shape[0]
    for ch in prange(nchunk):
        lo = ch * npts // nchunk
        hi = (ch + 1) * npts // nchunk
        _apply_chunk_nb(f0, V0, f1, V1, f2, V2, has_w, n1, n2, R, inside, use_mask, out, lo, hi, w0, w1, w2)


def _apply(axes, P, inside, use_mask, out):
    """``B @ P`` (``axes`` from ``Embedding._kernel_axes``, ``P`` (n_ctrl, 4))."""
    f0, V0, f1, V1, f2, V2, has_w = axes[:7]
    widths = tuple((0.0,) * V.shape[1] for V in (V0, V1, V2))
    nchunk = min(f0.shape[0], 4 * numba.get_num_threads())
    _apply_nb(*axes, P.reshape(-1), inside, use_mask, out, nchunk, *widths)


@njit(cache=True, parallel=True)
def _basis_rows_nb(f0, V0, f1, V1, f2, V2, has_w, n1, n2, inside, indptr, cols, data):
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
# vector fused multiply-add (ffdcli.lattice.simd: numba does not vectorise straight-line code): 4-wide per
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
    (:func:`ffdcli.lattice.simd.axpy8x3`): 4 vector updates per point instead of 16. Products grouped as
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


@njit(cache=True, nogil=True, inline="always")
def _sum_chunks(acc, stride, out):
    """``out[k, d] = acc[0, stride k + d] + acc[1, stride k + d] + ...`` in chunk order (serial: a
    few hundred sums per chunk; what ``acc.sum(axis=0)`` gives, without its temporaries)."""
    for k in range(out.shape[0]):
        for d in range(out.shape[1]):
            s = acc[0, stride * k + d]
            for ch in range(1, acc.shape[0]):
                s += acc[ch, stride * k + d]
            out[k, d] = s


def _rmatvec(axes, g, inside, nchunk, out):
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


def rmatvec_reference(emb: Embedding, g) -> np.ndarray:
    """NumPy/SciPy reference of :meth:`Embedding.rmatvec`: ``B.T @ g`` with ``B`` from
    :func:`basis_matrix_reference` (outside rows empty). Returns (n_ctrl, gdim)."""
    return np.asarray(basis_matrix_reference(emb).T @ np.asarray(g, dtype=np.float64))


def basis_matrix_reference(emb: Embedding) -> sparse.csr_matrix:
    """:meth:`Embedding.basis_matrix` built with NumPy broadcasting (int64 indices): the reference
    the compiled construction is tested against (same columns, same products, bit for bit)."""
    rows = np.flatnonzero(emb.inside)
    cols = np.zeros((rows.size, 1), dtype=np.int64)
    data = np.ones((rows.size, 1))
    for axis in range(emb.pdim):
        p1 = emb.degree[axis] + 1
        idx = emb.first[axis][rows, None].astype(np.int64) + np.arange(p1)[None, :]
        cols = (cols[:, :, None] * emb.shape[axis] + idx[:, None, :]).reshape(rows.size, -1)
        data = (data[:, :, None] * emb.values[axis][rows, None, :]).reshape(rows.size, -1)
    nnz_row = cols.shape[1]
    indptr = np.zeros(emb.n_points + 1, dtype=np.int64)
    indptr[1:] = np.cumsum(emb.inside.astype(np.int64) * nnz_row)
    return sparse.csr_matrix((data.ravel(), cols.ravel(), indptr), shape=(emb.n_points, emb.n_ctrl))


def dense_basis_reference(lattice: Lattice, params) -> np.ndarray:
    """NumPy reference of the basis matrix: dense (N, n_ctrl) from :func:`ffdcli.lattice.spline.basis`.

    For tests and small N only (memory N x n_ctrl).
    """
    params = np.asarray(params, dtype=np.float64)
    npts = params.shape[0]
    rows = np.arange(npts)[:, None]
    B = np.ones((npts, 1))
    for axis in range(lattice.pdim):
        first, vals = basis(lattice.knots[axis], lattice.degree[axis], params[:, axis])
        dense = np.zeros((npts, lattice.shape[axis]))
        dense[rows, first[:, None] + np.arange(vals.shape[1])[None, :]] = vals
        B = (B[:, :, None] * dense[:, None, :]).reshape(npts, -1)
    return B


# ----------------------------------------------------------------------------------------------
# Newton point inversion (compiled)
# ----------------------------------------------------------------------------------------------

@njit(cache=True, nogil=True, inline="always")
def _sqdist(R, n1, n2, k0, k1, k2, u, X, i, gdim, out, w0, w1, w2):
    """|V(u) - X[i]|^2; ``out`` (12,) receives V and its derivatives (see
    :func:`ffdcli.lattice.lattice.eval_point_fixed_nb`; ``w0, w1, w2``: the basis widths)."""
    res = eval_point_fixed_nb(R, n1, n2, k0, k1, k2, u[0], u[1], u[2], w0, w1, w2)
    for k in range(12):
        out[k] = res[k]
    s = 0.0
    for d in range(gdim):
        r = res[d] - X[i, d]
        s += r * r
    return s


@njit(cache=True, nogil=True, inline="always")
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


@njit(cache=True, nogil=True, inline="always")
def _newton_point(R, n1, n2, k0, k1, k2, pdim, gdim, X, i, u, tol2, stop2, snap, max_iter,
                  cur, trial, ut, step, grad, H, rhs, fixed, w0, w1, w2):
    """Projected Gauss-Newton for point ``X[i]``; ``u`` (3,) is the start and receives the result.

    Returns the squared residual at the result.
    """
    f = _sqdist(R, n1, n2, k0, k1, k2, u, X, i, gdim, cur, w0, w1, w2)
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
            ft = _sqdist(R, n1, n2, k0, k1, k2, ut, X, i, gdim, trial, w0, w1, w2)
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
                fs = _sqdist(R, n1, n2, k0, k1, k2, u, X, i, gdim, trial, w0, w1, w2)
                if fs <= tol2:
                    f = fs
                else:
                    u[e] = keep
    return f


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def _newton_chunk_nb(R, n1, n2, k0, k1, k2, X, params, tol2, stop2, snap, max_iter, residual, lo, hi,
                     use_table, t_lo, t_inv_h, t_dims, t_centers, t_params, t_jinv, w0, w1, w2, work, fixed):
    """Newton for the points ``lo:hi`` of ``X`` (see :func:`_newton_nb`); ``work`` (48,) and ``fixed``
    (3,) are the chunk's work arrays.

    A function of its own, called once per chunk from the parallel loop, not inlined into it: numba
    compiles it with the widths ``w0, w1, w2`` (tuples, :func:`ffdcli.lattice.lattice.fixed_widths`) as
    constants, and the parallel loop's array analysis never sees the per-point tuples. Compiled
    without numba's reference counting (``_nrt=False``: it allocates nothing): the arrays handed to
    the inlined per-point functions would otherwise be counted in and out at every point (about 30
    calls per point, atomic operations on counters shared by the threads). NumPy's error model: no
    zero-division checks (and their exception paths) around the basis recurrence's divisions (never
    by zero: a knot span's denominators are sums of non-empty knot intervals; the Gauss elimination
    checks its pivots first)."""
    gdim = X.shape[1]
    pdim = 3 if len(w2) > 1 else 2          # a constant: a 2D lattice has the third axis of degree 0
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
        f = _newton_point(R, n1, n2, k0, k1, k2, pdim, gdim, X, i, u, tol2, stop2, snap, max_iter,
                          cur, trial, ut, step, grad, H, rhs, fixed, w0, w1, w2)
        for e in range(pdim):
            params[i, e] = u[e]
        residual[i] = np.sqrt(f)


@njit(cache=True, parallel=True)
def _newton_nb(R, n1, n2, k0, k1, k2, X, params, tol, stop, snap, max_iter, residual, nchunk,
               use_table, t_lo, t_inv_h, t_dims, t_centers, t_params, t_jinv, w0, w1, w2):
    """Newton for every point of ``X``, from ``params`` or (``use_table``) from the start table
    ``t_*`` (:class:`StartTable`'s arrays), read in the same pass; writes ``params`` and ``residual``.
    ``nchunk`` chunks of points share the threads (:func:`_newton_chunk_nb`). ``w0, w1, w2``: the
    basis widths (:func:`ffdcli.lattice.lattice.fixed_widths`): a compiled version per lattice degrees,
    with the lattice evaluation unrolled (the results of the generic ``eval_point_nb``, bit for
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
        _newton_chunk_nb(R, n1, n2, k0, k1, k2, X, params, tol2, stop2, snap, max_iter, residual, lo, hi,
                         use_table, t_lo, t_inv_h, t_dims, t_centers, t_params, t_jinv, w0, w1, w2, work,
                         fixed)


# ----------------------------------------------------------------------------------------------
# embed()
# ----------------------------------------------------------------------------------------------

def sample_grid(lattice: Lattice, per_span: int = 4) -> np.ndarray:
    """Parameters of the start grid: ``per_span`` intervals in every non-empty knot span of every
    direction (ends included). Returns (S, pdim)."""
    axes = []
    for k in lattice.knots:
        breaks = np.unique(k)
        fine = (breaks[:-1, None] + (breaks[1:] - breaks[:-1])[:, None]
                * (np.arange(per_span) / per_span)[None, :]).ravel()
        axes.append(np.append(fine, 1.0))
    mesh = np.meshgrid(*axes, indexing="ij")
    return np.ascontiguousarray(np.stack([m.ravel() for m in mesh], axis=1))


@dataclass(frozen=True)
class StartTable:
    """Newton starts from a uniform grid of cells over the sampled lattice.

    Each cell holds the parameters ``u_c`` of the lattice point nearest its centre ``C`` and the
    pseudo-inverse ``J_c^+`` of the lattice map's Jacobian there; a point ``X`` of the cell starts at
    ``clip(u_c + J_c^+ (X - C), 0, 1)``: one table read and a 3 x 3 product per point instead of a
    k-d tree search (which took about a fifth of the embedding time), and a start whose error is of
    second order in the cell size, so Gauss-Newton needs about one iteration less than from the
    nearest sample. The cells are about as large as the sample spacing, per axis (a thin box gets
    few cells across its thickness); points outside the grid use its border cells. A finer table
    saves little (8x the cells: ~9 % of the Newton time) and costs ~3 us per cell in every call, so
    its size depends on the lattice only (and every MPI rank builds the same one).

    Attributes
    ----------
    lo : ndarray, shape (3,)
        Lower corner of the grid (mesh units; the unused axis of a 2D lattice is 0).
    inv_h : ndarray, shape (3,)
        Cells per mesh unit along each axis.
    dims : ndarray of int64, shape (3,)
        Cells along each axis (1 for an unused axis).
    centers : ndarray, shape (n_cells, gdim)
        Cell centres, C order of the cells.
    params : ndarray, shape (n_cells, pdim)
        Parameters of the lattice point nearest each centre.
    jinv : ndarray, shape (n_cells, pdim, gdim)
        Pseudo-inverse ``(J^T J)^-1 J^T`` of J = dV/du at ``params`` (zero where J is singular).
    """

    lo: np.ndarray
    inv_h: np.ndarray
    dims: np.ndarray
    centers: np.ndarray
    params: np.ndarray
    jinv: np.ndarray

    @classmethod
    def build(cls, lattice: Lattice, samples: np.ndarray, sample_points: np.ndarray, tree: cKDTree,
              tol_abs: float, cells_per_sample: float = 1.0, max_cells: int = 1 << 13,
              center_iter: int = 4) -> StartTable:
        """Grid over the bounding box of ``sample_points`` (S, gdim) with about ``cells_per_sample * S``
        cells (at most ``max_cells``); the centres are embedded from their nearest samples by at most
        ``center_iter`` Gauss-Newton steps."""
        gdim = sample_points.shape[1]
        lo = sample_points.min(axis=0)
        ext = sample_points.max(axis=0) - lo
        ext = np.maximum(ext, 1e-12 * max(float(ext.max()), 1e-300))
        ncell = min(max_cells, max(1, int(cells_per_sample * sample_points.shape[0])))
        h = (np.prod(ext) / ncell) ** (1.0 / gdim)
        dims = np.clip(np.ceil(ext / h), 1, 4096).astype(np.int64)
        axes = [lo[a] + (np.arange(dims[a]) + 0.5) * ext[a] / dims[a] for a in range(gdim)]
        centers = np.ascontiguousarray(np.stack([c.ravel() for c in np.meshgrid(*axes, indexing="ij")], axis=1))
        _, nearest = tree.query(centers, k=1)
        params = np.ascontiguousarray(samples[nearest])
        residual = np.empty(len(centers))
        # a start needs no 1e-13 accuracy: a few iterations (points outside the lattice, about half
        # the centres of a swept and twisted box, would otherwise take most of the build's time)
        _run_newton(kernel_args(lattice), centers, params, residual, tol_abs, tol_abs, SNAP, center_iter)
        jinv = np.zeros((len(centers), lattice.pdim, gdim))
        _pinv_nb(derivatives(lattice, params), jinv)
        lo3, inv3, dims3 = np.zeros(3), np.zeros(3), np.ones(3, dtype=np.int64)
        lo3[:gdim], inv3[:gdim], dims3[:gdim] = lo, dims / ext, dims
        return cls(lo=lo3, inv_h=inv3, dims=dims3, centers=centers, params=params,
                   jinv=np.ascontiguousarray(jinv))

    def start(self, points: np.ndarray) -> np.ndarray:
        """Start parameters (N, pdim) in [0, 1] for points (N, gdim)."""
        points = np.ascontiguousarray(points, dtype=np.float64)
        out = np.empty((points.shape[0], self.params.shape[1]))
        if points.shape[0]:
            _start_nb(points, self.lo, self.inv_h, self.dims, self.centers, self.params, self.jinv, out)
        return out


@njit(cache=True)
def _pinv_nb(J, out):
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


@njit(cache=True, nogil=True, inline="always")
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
def _start_nb(X, lo, inv_h, dims, centers, params, jinv, out):
    for i in prange(X.shape[0]):
        _start_point(X, i, lo, inv_h, dims, centers, params, jinv, out[i])


def start_reference(start: StartTable, points: np.ndarray) -> np.ndarray:
    """NumPy reference of :meth:`StartTable.start`."""
    points = np.asarray(points, dtype=np.float64)
    gdim = points.shape[1]
    cell = np.zeros(points.shape[0], dtype=np.int64)
    for a in range(3):
        j = np.zeros(points.shape[0], dtype=np.int64)
        if a < gdim:
            t = (points[:, a] - start.lo[a]) * start.inv_h[a]
            j = np.minimum(np.floor(np.maximum(t, 0.0)), start.dims[a] - 1).astype(np.int64)
        cell = cell * start.dims[a] + j
    u = start.params[cell] + np.einsum("ned,nd->ne", start.jinv[cell], points - start.centers[cell])
    return np.clip(u, 0.0, 1.0)


_NO_TABLE = (np.zeros(3), np.zeros(3), np.ones(3, dtype=np.int64), np.zeros((1, 1)), np.zeros((1, 1)),
             np.zeros((1, 1, 1)))


def _run_newton(args, points, params, residual, tol_abs, stop_abs, snap, max_iter, table=None):
    """Newton on ``points`` from ``params`` or, when ``table`` (a :class:`StartTable`) is given, from
    its starts (``params`` is then only written)."""
    t = _NO_TABLE if table is None else (table.lo, table.inv_h, table.dims, table.centers, table.params,
                                         table.jinv)
    # enough chunks per thread to balance the slower points outside the lattice; work arrays are
    # allocated per chunk, not per point
    nchunk = 16 * numba.get_num_threads()
    P, k0, k1, k2, p0, p1, p2 = args
    n1, n2 = np.int64(P.shape[1]), np.int64(P.shape[2])
    _newton_nb(padded_rows(P), n1, n2, k0, k1, k2, points, params, float(tol_abs), float(stop_abs), float(snap),
               int(max_iter), residual, nchunk, table is not None, *t, *fixed_widths((p0, p1, p2)))


def embed(lattice: Lattice, points, *, tol: float = DEFAULT_TOL, progress=None, samples_per_span: int = 4,
          retries: int = 4, max_iter: int = 50, snap: float = SNAP, comm=None) -> Embedding:
    """Embed points in a lattice: parameters of the nearest lattice point, residual, inside flag.

    Parameters
    ----------
    lattice : Lattice
    points : array_like, shape (N, gdim)
        Points in mesh units (``gdim`` = the lattice's).
    tol : float
        Inside tolerance relative to ``lattice.size``: a point is inside when its residual is at most
        ``tol * lattice.size``.
    progress : callable, optional
        A progress factory (``ffdcli.progress``); called once with ("embedding", N).
    samples_per_span : int
        Start-grid density: sample intervals per knot span and direction.
    retries : int
        Further starts (the next-nearest samples) for points whose first Newton ends outside.
    max_iter : int
        Gauss-Newton iterations per start.
    snap : float
        Parameters within ``snap`` of 0 or 1 become exactly 0 or 1 when the residual stays within
        the tolerance.
    comm : ffdcli.parallel.comm.SerialComm, optional
        Every rank passes all the points; each embeds its block (:meth:`~ffdcli.parallel.comm.SerialComm.share`)
        and the parameters are gathered, so every rank returns the whole embedding, equal bit for
        bit to the serial one (each point is inverted independently). An error on any rank is
        raised on every rank.

    Returns
    -------
    Embedding
    """
    if comm is not None and comm.size > 1:
        kw = dict(tol=tol, progress=progress, samples_per_span=samples_per_span, retries=retries,
                  max_iter=max_iter, snap=snap)
        pts = np.asarray(points, dtype=np.float64)
        lo, hi = comm.share(pts.shape[0] if pts.ndim == 2 else 0)
        part = comm.run(embed, lattice, pts[lo:hi] if pts.ndim == 2 else pts, **kw)
        # the parameters are gathered and every rank computes the basis values (bit for bit the
        # block's: the same compiled pass per point): a fourth of the bytes, faster than gathering them
        return Embedding.from_params(lattice, comm.allgather_rows(part.params), comm.allgather_rows(part.inside),
                                     comm.allgather_rows(part.residual), tolerance=part.tolerance)
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != lattice.gdim:
        raise ValueError(f"points must have shape (N, {lattice.gdim}), got {pts.shape}")
    if not np.all(np.isfinite(pts)):
        raise InputError("points to embed contain NaN or infinite coordinates")
    if not tol > 0:
        raise ValueError(f"tol must be positive, got {tol}")
    pts = np.ascontiguousarray(pts)
    npts = pts.shape[0]
    tol_abs = tol * lattice.size
    stop_abs = 1e-3 * tol_abs
    args = kernel_args(lattice)

    samples = sample_grid(lattice, samples_per_span)
    sample_points = evaluate(lattice, samples)
    tree = cKDTree(sample_points)
    start = StartTable.build(lattice, samples, sample_points, tree, tol_abs)
    params = np.empty((npts, lattice.pdim))
    residual = np.empty(npts)
    factory = progress or no_progress
    with factory("embedding", npts) as bar:
        for lo, hi in chunks(npts, CHUNK):
            _run_newton(args, pts[lo:hi], params[lo:hi], residual[lo:hi], tol_abs, stop_abs, snap, max_iter,
                        table=start)
            bar.update(hi - lo)

    # Retry the points left outside from their next-nearest samples, keeping the best result.
    fail = np.flatnonzero(residual > tol_abs)
    kmax = min(retries + 1, samples.shape[0])
    if fail.size and retries > 0:
        _, nearest = tree.query(pts[fail], k=kmax, workers=-1)
        for kth in range(kmax):          # the table's start was near, not always the nearest
            if not fail.size:
                break
            sub_pts = np.ascontiguousarray(pts[fail])
            sub_params = np.ascontiguousarray(samples[nearest[:, kth]])
            sub_res = np.empty(fail.size)
            _run_newton(args, sub_pts, sub_params, sub_res, tol_abs, stop_abs, snap, max_iter)
            better = sub_res < residual[fail]
            params[fail[better]] = sub_params[better]
            residual[fail[better]] = sub_res[better]
            still = residual[fail] > tol_abs
            fail = fail[still]
            nearest = nearest[still]

    inside = residual <= tol_abs
    return Embedding.from_params(lattice, params, inside, residual, tolerance=tol_abs)
