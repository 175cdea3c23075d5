"""lattices -> surface: the wing surface's displacement ``B (P' - P0)``, every component's rows.

``x`` a tuple of every component's control points (n, m, l, 3); ``y`` the displacement (S, 3) of the
run's surface points (rows as ``surface_ids``: every component's nodes, sorted). The map is affine, so
``jvp`` is ``B dP`` (the embedding's compiled ``displace``) and ``vjp`` is ``B^T g`` (its compiled
``rmatvec``), per component. Points outside a lattice do not move.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ffdcli.chain.cache import Once
from ffdcli.chain.stage import Stage
from ffdcli.volume.surface_motion import component_displacement


class SurfaceStage(Stage):
    """lattices -> surface displacement (module docstring).

    Parameters
    ----------
    components : sequence of Component
    rows : sequence of (S_c,) int arrays
        Each component's surface points' rows in the run's surface.
    n_surface : int
        S, the run's surface points.
    """

    def __init__(self, components, rows, n_surface: int):
        self.components = tuple(components)
        self.rows = tuple(rows)
        self.n_surface = int(n_surface)
        self._basis = [Once() for _ in self.components]
        self._block = Once()

    @property
    def single(self) -> bool:
        return len(self.components) == 1

    def basis(self, c: int):
        """Component ``c``'s B (S_c, n_ctrl_c) CSR."""
        return self._basis[c].get(lambda: self.components[c].prep.embedding.basis_matrix().tocsr())

    def block_basis(self):
        """B (S, n_ctrl) CSR of the run: block diagonal, the columns of the components' lattices one after
        the other (file order), the rows as the run's surface."""
        return self._block.get(self._block_basis)

    def _block_basis(self):
        if self.single:
            return self.basis(0)
        r, c, d, off = [], [], [], 0
        for k, rows in enumerate(self.rows):
            b = self.basis(k).tocoo()
            r.append(rows[b.row])
            c.append(b.col + off)
            d.append(b.data)
            off += self.basis(k).shape[1]
        return sp.csr_matrix((np.concatenate(d), (np.concatenate(r), np.concatenate(c))), shape=(self.n_surface, off))

    def forward(self, x) -> np.ndarray:
        if self.single:
            return component_displacement(self.components[0], x[0])
        out = np.zeros((self.n_surface, 3))
        for comp, rows, P in zip(self.components, self.rows, x, strict=True):
            out[rows] = component_displacement(comp, P)
        return out

    def jvp(self, x, dx) -> np.ndarray:
        moved = [comp.prep.embedding.displace(np.asarray(dP, dtype=float).reshape(-1, 3))
                 for comp, dP in zip(self.components, dx, strict=True)]
        if self.single:
            return moved[0]
        out = np.zeros((self.n_surface, 3))
        for rows, m in zip(self.rows, moved, strict=True):
            out[rows] = m
        return out

    def vjp(self, x, gy) -> tuple[np.ndarray, ...]:
        g = np.asarray(gy, dtype=float)
        if self.single:
            gs = [g]
        else:
            gs = [np.ascontiguousarray(g[rows]) for rows in self.rows]
        return tuple(comp.prep.embedding.rmatvec(gc).reshape(comp.P0.shape)
                     for comp, gc in zip(self.components, gs, strict=True))
