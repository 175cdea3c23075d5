"""Point sets of a :class:`~ffdcli.api.DesignModel`: any points embedded in its lattice, moved by the
design, with their exact products (pyGeo's ``addPointSet``).

With several components each point follows the first component (file order) whose lattice holds it;
a point inside none never moves."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ffdcli.errors import InputError
from ffdcli.lattice.pointset import PointSet
from ffdcli.mesh.numbers import as_numbers


@dataclass(frozen=True, eq=False)
class ComponentPoints:
    """A point set over the components of a design: per component its :class:`PointSet` (every point
    embedded in that component's lattice) and the mask of the points it moves (inside it, and in no
    earlier component)."""

    name: str
    parts: tuple            # ((PointSet, mask (k,) bool), ...) one per component, file order

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

    def points(self, dPs: list[np.ndarray]) -> np.ndarray:
        """(k, 3) moved points for the lattice changes ``dPs`` (per component (n_ctrl_c, 3))."""
        out = self.points0.copy()
        for (ps, mask), dP in zip(self.parts, dPs, strict=True):
            out[mask] += np.asarray(ps.basis @ dP)[mask]
        return out

    def jvp(self, Ds: list[np.ndarray], dv) -> np.ndarray:
        """(k, 3) motion of the points for ``dv`` (n_vars,); ``Ds`` the components' rows of dP/dv."""
        out = np.zeros((self.n_points, 3))
        for (ps, mask), D in zip(self.parts, Ds, strict=True):
            out[mask] += ps.jvp(D, dv)[mask]
        return out

    def vjp(self, Ds: list[np.ndarray], g) -> np.ndarray:
        """(n_vars,) sum over points of ``g . dX/dv`` for ``g`` (k, 3)."""
        total = None
        for (ps, mask), D in zip(self.parts, Ds, strict=True):
            # one component: g as given (PointSet.vjp checks it); several: each its own points' rows
            gm = g if len(self.parts) == 1 else np.where(mask[:, None], as_numbers(g, (self.n_points, 3),
                                                                                   f"point set {self.name!r}: g"), 0.0)
            part = ps.vjp(D, gm)
            total = part if total is None else total + part
        return total


class PointSetsMixin:
    """The point-set part of :class:`~ffdcli.api.DesignModel` (``_point_sets``: {name: ComponentPoints})."""

    def add_points(self, name: str, X, progress=None) -> dict:
        """Embed points ``X`` (k, 3) in the design's lattices under ``name`` (replacing a set of that name).

        Returns ``{"points": k, "outside": count, "outside_ids": [...], "outside_worst": distance}``:
        points outside every lattice are kept and never move."""

        parts, taken = [], None
        for comp in self.run.components:
            ps = PointSet.embed(str(name), comp.box, X, progress=progress)
            mask = ps.inside.copy() if taken is None else ps.inside & ~taken
            taken = mask if taken is None else taken | mask
            parts.append((ps, mask))
        cp = ComponentPoints(str(name), tuple(parts))
        self._point_sets[str(name)] = cp
        return {"points": cp.n_points, **cp.outside_report()}

    @property
    def point_sets(self) -> list[str]:
        """Names of the point sets added with :meth:`add_points`, in order."""
        return list(self._point_sets)

    def point_set(self, name: str) -> ComponentPoints:
        """The :class:`ComponentPoints` named ``name``."""
        try:
            return self._point_sets[name]
        except KeyError:
            have = ", ".join(self._point_sets) or "(none)"
            raise InputError(f"no point set named {name!r}; the point sets are: {have}") from None

    def _component_rows(self) -> list[np.ndarray]:
        """Each component's rows of dP/dv (n_ctrl_c * 3, n_vars)."""
        J = self.lattice_jacobian()
        ctrl = self.run.layout.ctrl_offsets
        return [J[3 * a:3 * b] for a, b in zip(ctrl[:-1], ctrl[1:], strict=True)]

    def points(self, name: str) -> np.ndarray:
        """(k, 3) the points of set ``name`` moved by the current design."""
        dPs = [(P - c.P0).reshape(-1, 3) for P, c in zip(self.lattices(), self.run.components, strict=True)]
        return self.point_set(name).points(dPs)

    def points_jvp(self, name: str, dv) -> np.ndarray:
        """(k, 3) dX/dv @ dv for the points of set ``name`` and ``dv`` (n_vars,)."""
        ps = self.point_set(name)
        return ps.jvp(self._component_rows(), self._check_dv(dv, f"points_jvp({name!r})"))

    def points_vjp(self, name: str, g) -> np.ndarray:
        """(n_vars,) dJ/dv for ``g`` = dJ/dX (k, 3) at the points of set ``name``.

        Under MPI (``comm``) a collective: each rank passes its own points' ``g`` and every rank gets
        the sum over all ranks' points (forward products, :meth:`points_jvp`, stay local)."""
        local = self.comm.run(self.point_set(name).vjp, self._component_rows(), g)
        return self.comm.allreduce_sum(np.asarray(local, dtype=np.float64))
