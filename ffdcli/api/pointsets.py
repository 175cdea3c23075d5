"""Point sets of a :class:`~ffdcli.api.DesignModel`: any points embedded in its lattice, moved by the
design, with their exact products (pyGeo's ``addPointSet``).

With several components each point follows the first component (file order) whose lattice holds it;
a point inside none never moves. A set is a value: the products take the lattices' changes (forward)
or give the lattices' gradients (reverse), and the chain (:mod:`ffdcli.chain`) carries them to and
from the design values.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ffdcli.lattice.pointset import PointSet
from ffdcli.mesh.numbers import as_numbers


@dataclass(frozen=True, eq=False)
class ComponentPoints:
    """A point set over the components of a design: per component its :class:`PointSet` (every point
    embedded in that component's lattice) and the mask of the points it moves (inside it, and in no
    earlier component)."""

    name: str
    parts: tuple            # ((PointSet, mask (k,) bool), ...) one per component, file order

    @classmethod
    def embed(cls, name: str, components, X, progress=None) -> ComponentPoints:
        """Embed ``X`` (k, 3) in every component's lattice (each point belongs to the first that holds it)."""
        parts, taken = [], None
        for comp in components:
            ps = PointSet.embed(str(name), comp.box, X, progress=progress)
            mask = ps.inside.copy() if taken is None else ps.inside & ~taken
            taken = mask if taken is None else taken | mask
            parts.append((ps, mask))
        return cls(str(name), tuple(parts))

    @property
    def n_points(self) -> int:
        return self.parts[0][0].n_points

    @property
    def points0(self) -> np.ndarray:
        return self.parts[0][0].points0

    @property
    def inside(self) -> np.ndarray:
        """(k,) bool: the point moves with some component's lattice."""
        return np.logical_or.reduce([mask for _, mask in self.parts])

    def outside_report(self) -> dict:
        out = np.flatnonzero(~self.inside)
        rep = {"outside": int(out.size), "outside_ids": out[:10].tolist()}
        if out.size:
            rep["outside_worst"] = float(np.min([ps.embedding.residual[out] for ps, _ in self.parts], axis=0).max())
        return rep

    def points(self, dPs) -> np.ndarray:
        """(k, 3) moved points for the lattice changes ``dPs`` (per component, any shape of (n_ctrl_c, 3))."""
        return self.points0 + self.motion(dPs)

    def motion(self, dPs) -> np.ndarray:
        """(k, 3) the points' motion for lattice changes ``dPs`` (linear: also the forward product)."""
        out = np.zeros((self.n_points, 3))
        for (ps, mask), dP in zip(self.parts, dPs, strict=True):
            out[mask] += np.asarray(ps.basis @ np.asarray(dP, dtype=float).reshape(-1, 3))[mask]
        return out

    def pull(self, g) -> tuple[np.ndarray, ...]:
        """Per component ``B_c^T g`` (n_ctrl_c, 3) for ``g`` (k, 3) = dJ/dX at the points (the transpose of
        :meth:`motion`; each component its own points' rows)."""
        g = as_numbers(g, (self.n_points, 3), f"point set {self.name!r}: g")
        out = []
        for ps, mask in self.parts:
            gm = g if len(self.parts) == 1 else np.where(mask[:, None], g, 0.0)
            # B.T @ g by the embedding's compiled kernel: ``basis`` is the embedding's basis matrix with
            # outside rows zero, which rmatvec skips
            out.append(ps.embedding.rmatvec(np.ascontiguousarray(gm)))
        return tuple(out)
