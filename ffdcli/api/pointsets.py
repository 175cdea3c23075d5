"""Point sets of a :class:`~ffdcli.api.DesignModel`: any points embedded in its lattice, moved by the
design, with their exact products (pyGeo's ``addPointSet``)."""

from __future__ import annotations

import numpy as np

from ffdcli.errors import InputError
from ffdcli.lattice.pointset import PointSet


class PointSetsMixin:
    """The point-set part of :class:`~ffdcli.api.DesignModel` (``_point_sets``: {name: PointSet})."""

    def add_points(self, name: str, X, progress=None) -> dict:
        """Embed points ``X`` (k, 3) in the design's lattice under ``name`` (replacing a set of that name).

        Returns ``{"points": k, "outside": count, "outside_ids": [...], "outside_worst": distance}``:
        points outside the lattice are kept and never move."""

        ps = PointSet.embed(str(name), self.run.box, X, progress=progress)
        self._point_sets[str(name)] = ps
        return {"points": ps.n_points, **ps.outside_report()}

    @property
    def point_sets(self) -> list[str]:
        """Names of the point sets added with :meth:`add_points`, in order."""
        return list(self._point_sets)

    def point_set(self, name: str):
        """The :class:`ffdcli.lattice.pointset.PointSet` named ``name``."""
        try:
            return self._point_sets[name]
        except KeyError:
            have = ", ".join(self._point_sets) or "(none)"
            raise InputError(f"no point set named {name!r}; the point sets are: {have}") from None

    def _dP(self) -> np.ndarray:
        return (self.lattice() - self.run.P0).reshape(-1, 3)

    def points(self, name: str) -> np.ndarray:
        """(k, 3) the points of set ``name`` moved by the current design."""
        return self.point_set(name).points(self._dP())

    def points_jvp(self, name: str, dv) -> np.ndarray:
        """(k, 3) dX/dv @ dv for the points of set ``name`` and ``dv`` (n_vars,)."""
        ps = self.point_set(name)
        return ps.jvp(self.lattice_jacobian(), self._check_dv(dv, f"points_jvp({name!r})"))

    def points_vjp(self, name: str, g) -> np.ndarray:
        """(n_vars,) dJ/dv for ``g`` = dJ/dX (k, 3) at the points of set ``name``.

        Under MPI (``comm``) a collective: each rank passes its own points' ``g`` and every rank gets
        the sum over all ranks' points (forward products, :meth:`points_jvp`, stay local)."""
        local = self.comm.run(self.point_set(name).vjp, self.lattice_jacobian(), g)
        return self.comm.allreduce_sum(np.asarray(local, dtype=np.float64))

