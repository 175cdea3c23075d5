"""Embedding points in a lattice (point inversion) and the sparse basis that moves them.

:func:`embed` finds, for every point ``X``, the parameters ``u`` in [0, 1]^pdim that minimise
``|V(u) - X|`` for the lattice map ``V`` (see :mod:`ffdcli.lattice.lattice`). The lattice is not a
parallelepiped (it follows a swept, tapered, twisted wing), so the map is inverted numerically:

1. each point starts from a first-order inverse of the lattice map at the centre of its cell in a
   uniform grid (:class:`StartTable`: a table read and a 3 x 3 product per point, in the Newton
   kernel's own pass); the table is made once per call from a grid of samples (a few per knot span
   and direction) in a k-d tree, with about one cell per sample whatever the number of points;
2. a projected Gauss-Newton iteration with backtracking line search runs per point inside a
   parallel compiled loop (numba ``prange``; no Python loop over points; :mod:`ffdcli.lattice._newton_kernels`),
   compiled for the usual lattice degrees (:func:`ffdcli.lattice.lattice.eval_point_fixed_nb`: the
   lattice map unrolled, in vector operations) and generic for the others (equal bit for bit).
   Parameters are clipped
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
padded to 4-wide rows, with explicit vector fused multiply-adds (:mod:`ffdcli.jit`: ``B @ P``
contracts each point's support by :func:`ffdcli.jit.tensor_v`, unrolled for the lattice's
degrees; ``B.T @ g`` adds into the rows);
:meth:`Embedding.basis_matrix` builds the explicit CSR matrix. The ``*_reference`` functions are
NumPy versions the tests compare the kernels with.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np
from scipy import sparse
from scipy.spatial import cKDTree

from ffdcli.errors import InputError
from ffdcli.lattice._embedding_kernels import apply, basis_axes, basis_rows_nb, rmatvec
from ffdcli.lattice._newton_kernels import STATIONARY, pinv_nb, run_newton, start_nb  # noqa: F401  (STATIONARY:

#   the Newton kernel's stopping rule for points outside, part of this module's documented behaviour)
from ffdcli.lattice.lattice import DUMMY_KNOTS, Lattice, derivatives, evaluate, kernel_args
from ffdcli.lattice.spline import basis
from ffdcli.progress import chunks, no_progress

#: Default inside tolerance, relative to the lattice size (bounding-box diagonal of the control points).
DEFAULT_TOL = 1e-10
#: Parameters closer than this to 0 or 1 are snapped onto the bound (when the residual allows it).
SNAP = 1e-10
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
        knots = (*lattice.knots, DUMMY_KNOTS)[:3]
        first3 = (*first, _DUMMY_FIRST)[:3]
        values3 = (*values, _DUMMY_VALUES)[:3]
        degrees = (*lattice.degree, 0)[:3]
        if npts and not basis_axes(knots, params, first3, values3, degrees):
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
            apply(self._kernel_axes(), cp, self.inside, False, out)
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
            apply(self._kernel_axes(), cp, self.inside, True, out)
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
        rmatvec(self._kernel_axes(), g, self.inside, nchunk, out)
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
            basis_rows_nb(*self._kernel_axes(), self.inside, indptr, cols, data)
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
        run_newton(kernel_args(lattice), centers, params, residual, tol_abs, tol_abs, SNAP, center_iter)
        jinv = np.zeros((len(centers), lattice.pdim, gdim))
        pinv_nb(derivatives(lattice, params), jinv)
        lo3, inv3, dims3 = np.zeros(3), np.zeros(3), np.ones(3, dtype=np.int64)
        lo3[:gdim], inv3[:gdim], dims3[:gdim] = lo, dims / ext, dims
        return cls(lo=lo3, inv_h=inv3, dims=dims3, centers=centers, params=params,
                   jinv=np.ascontiguousarray(jinv))

    def start(self, points: np.ndarray) -> np.ndarray:
        """Start parameters (N, pdim) in [0, 1] for points (N, gdim)."""
        points = np.ascontiguousarray(points, dtype=np.float64)
        out = np.empty((points.shape[0], self.params.shape[1]))
        if points.shape[0]:
            start_nb(points, self.lo, self.inv_h, self.dims, self.centers, self.params, self.jinv, out)
        return out


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
    table = (start.lo, start.inv_h, start.dims, start.centers, start.params, start.jinv)
    params = np.empty((npts, lattice.pdim))
    residual = np.empty(npts)
    factory = progress or no_progress
    with factory("embedding", npts) as bar:
        for lo, hi in chunks(npts, CHUNK):
            run_newton(args, pts[lo:hi], params[lo:hi], residual[lo:hi], tol_abs, stop_abs, snap, max_iter,
                       table=table)
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
            run_newton(args, sub_pts, sub_params, sub_res, tol_abs, stop_abs, snap, max_iter)
            better = sub_res < residual[fail]
            params[fail[better]] = sub_params[better]
            residual[fail[better]] = sub_res[better]
            still = residual[fail] > tol_abs
            fail = fail[still]
            nearest = nearest[still]

    inside = residual <= tol_abs
    return Embedding.from_params(lattice, params, inside, residual, tolerance=tol_abs)
