"""Point sets: any points embedded in a design's lattice, moved with it, with exact derivatives.

A solver that owns its mesh partition, a structural model, the point pairs of a thickness
constraint: each is a :class:`PointSet` with its own embedding in the same lattice as the surface.
Points outside the lattice are reported (``inside``) and never move. The moved points are
``X0 + B (P' - P0)`` with ``B`` the (k, n_ctrl) basis of the set, so ``dX/dv = B dP'/dv`` with the
lattice Jacobian ``D = dP'/dv`` (n_ctrl*3, n_vars) of :func:`ffdcli.parameterization.derivatives.lattice_jacobian`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ffdcli.lattice.embedding import embed
from ffdcli.mesh.numbers import as_numbers


@dataclass(frozen=True, eq=False)
class PointSet:
    """Points embedded in a box's lattice.

    name
        What the caller calls the set.
    points0
        (k, 3) the points as given (mesh units).
    embedding
        :class:`ffdcli.lattice.embedding.Embedding` of the points in the box's core lattice.
    basis
        (k, n_ctrl) CSR: displacement = basis @ (P' - P0).reshape(-1, 3); zero rows outside.
    """

    name: str
    points0: np.ndarray
    embedding: object
    basis: sp.csr_matrix

    @classmethod
    def embed(cls, name: str, box, X, *, progress=None) -> PointSet:
        """Embed ``X`` (k, 3) in the lattice of ``box`` (:class:`ffdcli.box.box.Box`).

        Raises :class:`InputError` if ``X`` is not (k, 3) finite numbers; points outside the lattice
        are kept (``inside`` False) and never move."""
        X = as_numbers(X, (None, 3), f"point set {name!r}: points")      # finite (k, 3)
        emb = embed(box.lattice(), box.core_points(X), progress=progress)
        B = emb.basis_matrix().tocsr()
        if len(X) and (~emb.inside).any():
            B = sp.diags(emb.inside.astype(float)) @ B       # outside points never move
            B = B.tocsr()
        return cls(name=name, points0=X.copy(), embedding=emb, basis=B)

    @property
    def n_points(self) -> int:
        return int(self.points0.shape[0])

    @property
    def inside(self) -> np.ndarray:
        """(k,) bool: the point is inside the lattice and moves with it."""
        return self.embedding.inside

    def outside_report(self) -> dict:
        """``{"outside": count, "outside_ids": first indices, "outside_worst": distance}``."""
        out = np.flatnonzero(~self.inside)
        rep = {"outside": int(out.size), "outside_ids": out[:10].tolist()}
        if out.size:
            rep["outside_worst"] = float(self.embedding.residual[out].max())
        return rep

    def points(self, dP_flat: np.ndarray) -> np.ndarray:
        """(k, 3) moved points for the lattice change ``dP_flat = (P' - P0).reshape(-1, 3)``."""
        return self.points0 + np.asarray(self.basis @ dP_flat)

    def jacobian(self, D: np.ndarray) -> np.ndarray:
        """(k, 3, n_vars) dX/dv for the lattice Jacobian ``D`` (n_ctrl*3, n_vars)."""
        nv = D.shape[1]
        by_point = D.reshape(D.shape[0] // 3, 3 * nv)     # not -1: zero variables are a design too
        return np.asarray(self.basis @ by_point).reshape(self.n_points, 3, nv)

    def jvp(self, D: np.ndarray, dv) -> np.ndarray:
        """(k, 3) motion of the points for a change ``dv`` (n_vars,) of the design variables."""
        dv = as_numbers(dv, (D.shape[1],), f"point set {self.name!r}: dv", hint="one value per design variable")
        return np.asarray(self.basis @ (D @ dv).reshape(-1, 3))

    def vjp(self, D: np.ndarray, g) -> np.ndarray:
        """(n_vars,) sum over points of ``g . dX/dv`` for ``g`` (k, 3)."""
        g = as_numbers(g, (self.n_points, 3), f"point set {self.name!r}: g")
        # B.T @ g by the embedding's compiled kernel (a few times SciPy's CSR product; same sums to
        # rounding): ``basis`` is the embedding's basis matrix, outside rows zero, which rmatvec skips
        return self.embedding.rmatvec(g).reshape(-1) @ D
