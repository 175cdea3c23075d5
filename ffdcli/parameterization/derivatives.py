"""Analytic derivatives of the deformed lattice and surface with respect to the design variables.

The pipeline is P_0 -> P_1 = c_0(P_0) -> ... -> P' = c_{K-1}(P_{K-1}). The forward chain rule:
a variable of change ``c`` moves P_{c+1} by ``c.jacobian_own(P_c)``, and that motion is carried
through every later change ``d`` by its derivative with respect to its input lattice,
``d.jvp_P(P_d, dP)``. All directions are carried together (``jvp_P`` takes leading batch axes).

The surface follows the lattice linearly, ``X = X0 + B (P' - P0)`` with ``B`` the (N, n_ctrl)
basis matrix of the embedding whose columns are the control points in C order of ``(n, m, l)``
(``P.reshape(-1, 3)``), so ``dX/dv = B @ dP'/dv``.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import scipy.sparse as sp
from numba import njit, prange
from scipy.sparse.linalg import LinearOperator

from ffdcli.box.frame import LatticeFrame
from ffdcli.lattice.embedding import Embedding
from ffdcli.parameterization.changes import Change


def lattice_jacobian(P0: np.ndarray, frame: LatticeFrame, changes: Sequence[Change]) -> np.ndarray:
    """dP'/dv: (n*m*l*3, n_vars), rows in the order of ``P'.reshape(-1)`` (point-major, x y z),
    columns in the order of :func:`ffdcli.parameterization.changes.design_variables` (angles per degree)."""
    P = np.array(P0, dtype=float, copy=True)
    J = np.zeros((0,) + P.shape)
    for change in changes:
        own = change.jacobian_own(P, frame)                    # (k, n, m, l, 3) at P_c
        if J.shape[0]:
            J = change.jvp_P(P, frame, J)
        J = np.concatenate([J, own], axis=0)
        P = change.apply(P, frame)
    return J.reshape(J.shape[0], P.size).T.copy()     # P.size: zero variables give (n_ctrl*3, 0)


def surface_jacobian(B: sp.spmatrix | np.ndarray, lattice_jac: np.ndarray) -> np.ndarray:
    """dX/dv: (N*3, n_vars) for the N surface points, rows point-major (x0, y0, z0, x1, ...).

    B
        (N, n_ctrl) basis matrix (sparse CSR from ``Embedding.basis_matrix()``, or dense).
    lattice_jac
        (n_ctrl*3, n_vars) from :func:`lattice_jacobian`.
    """
    n_ctrl = B.shape[1]
    n_vars = lattice_jac.shape[1]
    if lattice_jac.shape[0] != 3 * n_ctrl:
        raise ValueError(f"lattice Jacobian has {lattice_jac.shape[0]} rows, expected 3 * {n_ctrl}")
    by_point = lattice_jac.reshape(n_ctrl, 3 * n_vars)        # row = control point, cols = (xyz, var)
    if sp.issparse(B) and B.format == "csr":
        out = csr_times_dense(B, by_point)
    else:
        out = np.asarray(B @ by_point)
    return out.reshape(B.shape[0] * 3, n_vars)


def csr_times_dense(B: sp.csr_matrix, D: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """``B @ D`` for a CSR matrix ``B`` (N, K) and a dense ``D`` (K, M), into ``out`` (N, M) float64.

    The same sums as ``B @ D`` to rounding (each output row sums its nonzeros four at a time, in CSR
    order), computed by a compiled loop over the rows of ``B`` in parallel threads; SciPy's product
    is single-threaded.
    ``out`` (C-contiguous, float64) is overwritten if given, else allocated.
    """
    D = np.ascontiguousarray(D, dtype=np.float64)
    if D.ndim != 2 or D.shape[0] != B.shape[1]:
        raise ValueError(f"D must have shape ({B.shape[1]}, M), got {D.shape}")
    shape = (B.shape[0], D.shape[1])
    if out is None:
        out = np.empty(shape)
    elif out.shape != shape or out.dtype != np.float64 or not out.flags.c_contiguous:
        raise ValueError(f"out must be a C-contiguous float64 array of shape {shape}")
    _csr_times_dense_nb(B.indptr, B.indices, B.data.astype(np.float64, copy=False), D, out)
    return out


# Four nonzeros per pass over the output row (one load and store of the row per four products, not
# per product: about twice as fast); "contract" lets the products fuse into multiply-adds (ulps).
@njit(cache=True, parallel=True, fastmath={"contract"})
def _csr_times_dense_nb(indptr, indices, data, D, out):
    n_rows, m = out.shape
    for i in prange(n_rows):
        row = out[i]
        for q in range(m):
            row[q] = 0.0
        k = indptr[i]
        end = indptr[i + 1]
        while k + 4 <= end:
            w0, w1, w2, w3 = data[k], data[k + 1], data[k + 2], data[k + 3]
            s0, s1, s2, s3 = D[indices[k]], D[indices[k + 1]], D[indices[k + 2]], D[indices[k + 3]]
            for q in range(m):
                row[q] += (w0 * s0[q] + w1 * s1[q]) + (w2 * s2[q] + w3 * s3[q])
            k += 4
        while k < end:
            w = data[k]
            src = D[indices[k]]
            for q in range(m):
                row[q] += w * src[q]
            k += 1


def surface_jvp(B, lattice_jac: np.ndarray, dv) -> np.ndarray:
    """(N, 3) surface motion for a change ``dv`` (n_vars,) of the design variables."""
    dP = (lattice_jac @ np.asarray(dv, dtype=float)).reshape(-1, 3)
    return np.asarray(B @ dP)


def vjp(B, g: np.ndarray, lattice_jac: np.ndarray) -> np.ndarray:
    """dJ/dv (n_vars,) = sum over points of g . dX/dv, for g = dJ/dX (N, 3); never forms dX/dv.

    ``B`` is the basis matrix (sparse or dense, N x n_ctrl) or the :class:`~ffdcli.lattice.embedding.Embedding`
    itself: then ``B.T @ g`` is its compiled tensor-product kernel (:meth:`Embedding.rmatvec`), which
    reads the per-axis basis values (about a third of the bytes of the CSR matrix) and is several
    times faster than SciPy's product; ``(B.T @ g).reshape(-1) @ lattice_jac`` follows (n_ctrl*3 x
    n_vars, small)."""
    g = np.asarray(g, dtype=float)
    n_points = B.n_points if isinstance(B, Embedding) else B.shape[0]
    if g.shape != (n_points, 3):
        raise ValueError(f"g must have shape ({n_points}, 3), got {g.shape}")
    gP = B.rmatvec(g) if isinstance(B, Embedding) else np.asarray(B.T @ g)   # (n_ctrl, 3)
    return gP.reshape(-1) @ lattice_jac


def surface_operator(B, lattice_jac: np.ndarray) -> LinearOperator:
    """dX/dv as a (N*3, n_vars) LinearOperator that never forms the dense product.

    ``op @ dv`` is the surface motion (flattened point-major) and ``op.T @ g`` (``g`` flattened
    (N*3,)) the vector-Jacobian product; the dense matrix of 1M points x 100 variables is 2.4 GB,
    the factors ``B`` and ``lattice_jac`` a few hundred MB at most.
    """
    n_points = B.shape[0]
    n_vars = lattice_jac.shape[1]
    return LinearOperator(
        (3 * n_points, n_vars), dtype=float,
        matvec=lambda dv: surface_jvp(B, lattice_jac, np.ravel(dv)).reshape(-1),
        rmatvec=lambda g: vjp(B, np.reshape(g, (n_points, 3)), lattice_jac),
    )
