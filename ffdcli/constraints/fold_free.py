"""``fold_free``: the FFD volume does not fold.

``min over u of det J'(u) / det J0(u)``: the Jacobian determinant of the lattice map after the
changes over that of the baseline, i.e. ``det F`` of the deformation of the box, > 0 when the
FFD volume (and so the mesh inside it) does not fold. Sampled (not a guaranteed bound) on a
parameter grid of ``samples`` points per knot span and direction plus every knot, so it includes
every corner, edge and face of the box; between samples ``det F`` is a smooth rational function
whose dips of less than a sample spacing are not seen. Exact for affine changes (span, sweep,
dihedral, uniform chord: ``det F`` constant). The derivative is that of the smallest sample; where
several samples tie for the smallest (regions that no shape variable reaches keep one ratio), it
is that of one of them (a one-sided derivative, as for any minimum).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ffdcli.constraints.base import CONSTRAINTS, Constraint, item_schema
from ffdcli.lattice.embedding import sample_grid
from ffdcli.lattice.lattice import axis_tables, derivatives

#: Samples per knot span and direction of ``fold_free`` by default.
FOLD_SAMPLES = 4


@dataclass(frozen=True, eq=False)
class FoldFree(Constraint):
    """``min det F`` over a parameter grid of the box (see the module docstring).

    box
        :class:`ffdcli.box.box.Box` (its core lattice and how control points map to it).
    params
        (N, pdim) sample parameters.
    det0
        (N,) baseline det J at the samples (never 0).
    """

    box: object = None
    params: np.ndarray = None
    det0: np.ndarray = None

    kind = "fold_free"

    @classmethod
    def schema(cls) -> dict:
        return item_schema("smallest Jacobian determinant of the lattice map over the box, as a ratio to "
                           "the baseline (> 0: the box does not fold)",
                           {"samples": {"type": "integer", "minimum": 1, "maximum": 64,
                                        "description": "samples per knot span and direction (default 4)"}})

    @classmethod
    def from_spec(cls, spec: dict, ctx) -> FoldFree:
        """The sample grid (``samples`` per knot span, default :data:`FOLD_SAMPLES`) and the baseline
        determinants."""
        samples = int(spec.get("samples", FOLD_SAMPLES))
        if not 1 <= samples <= 64:
            raise ctx.fail(f"samples per knot span must be 1 to 64, got {samples}", f"{ctx.key}.samples")
        lat = ctx.box.lattice()
        params = sample_grid(lat, samples)
        det0 = np.linalg.det(derivatives(lat, params))
        if not np.all(np.abs(det0) > 0) or not (np.all(det0 > 0) or np.all(det0 < 0)):
            raise ctx.fail("the baseline lattice is already folded (its Jacobian determinant changes sign)")
        return cls(index=ctx.index, lower=ctx.lower, upper=ctx.upper, box=ctx.box, params=params, det0=det0)

    @property
    def size(self) -> int:
        return 1

    @property
    def scalar(self) -> bool:
        return True

    def ratios(self, P) -> np.ndarray:
        """(N,) det J'(u) / det J0(u) at the samples for control points ``P`` (n, m, l, 3)."""
        J = derivatives(self.box.lattice(P), self.params)
        return np.linalg.det(J) / self.det0

    def value(self, inp):
        return np.array([self.ratios(inp.P).min()])

    def jacobian(self, inp):
        box = self.box
        r = self.ratios(inp.P)
        q = int(np.argmin(r))
        u = self.params[q:q + 1]
        J = derivatives(box.lattice(inp.P), u)[0]                        # (gdim, pdim)
        nv = inp.D.shape[1]
        D = inp.D.reshape(*inp.P.shape, nv)                               # (n, m, l, 3, nv)
        t = axis_tables(box.lattice(), u, 1)                             # per axis (2, 1, n_axis)
        if box.dim == 3:
            a, b, c = (t[k][:, 0] for k in range(3))
            dJ = np.stack([np.einsum("i,j,k,ijkdv->vd", a[1], b[0], c[0], D),
                           np.einsum("i,j,k,ijkdv->vd", a[0], b[1], c[0], D),
                           np.einsum("i,j,k,ijkdv->vd", a[0], b[0], c[1], D)], axis=-1)
        else:
            Dc = D[:, 0][:, :, box.plane_axes, :]                        # (n, l, 2, nv)
            a, c = t[0][:, 0], t[1][:, 0]
            dJ = np.stack([np.einsum("i,k,ikdv->vd", a[1], c[0], Dc),
                           np.einsum("i,k,ikdv->vd", a[0], c[1], Dc)], axis=-1)
        # d det J = det J tr(J^-1 dJ); as a ratio to det J0: r tr(J^-1 dJ)
        out = r[q] * np.einsum("ab,vba->v", np.linalg.inv(J), dJ)
        return out[None, :]


CONSTRAINTS.register(FoldFree)
