"""``le_te``: the leading and trailing edges do not shear (linear, in mesh units).

For the first (leading-edge) and last (trailing-edge) chordwise control
points of each section, the sum of the shape moves of the upper (k = l-1) and lower (k = 0)
point; ``= 0`` (the default bounds) means they move by equal and opposite amounts, so the
shape variables cannot shear the section. One item per (section, edge) that some shape variable
moves, root to tip, leading edge before trailing edge.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ffdcli.constraints.base import CONSTRAINTS, Constraint, item_schema
from ffdcli.parameterization.changes import Shape


@dataclass(frozen=True, eq=False)
class LeTe(Constraint):
    """Linear: ``A @ values`` (c,), the summed upper + lower shape moves at each section's edges.

    A
        (c, n_vars) constant.
    rows
        (c, 2) (section j, edge 0 = leading / 1 = trailing) of each item.
    """

    A: np.ndarray = None
    rows: np.ndarray = None

    kind = "le_te"
    default_bounds = (0.0, 0.0)

    @classmethod
    def schema(cls) -> dict:
        return item_schema("upper + lower shape move of the first and last chordwise control points of each "
                           "section (mesh units); lower and upper default to 0")

    @classmethod
    def from_spec(cls, spec: dict, ctx) -> LeTe:
        """The rows of the edges that some shape variable moves."""
        P0 = ctx.box.control_points
        frame = ctx.box.frame
        n, m, l, _ = P0.shape
        sizes = [c.size for c in ctx.changes]
        nv = sum(sizes)
        A = np.zeros((2, m, nv))              # (edge, section, variable)
        at = 0
        for change, size in zip(ctx.changes, sizes, strict=True):
            if isinstance(change, Shape):
                amounts = change.jacobian_own(P0, frame) @ frame.thickness_dir        # (size, n, m, l)
                for e, i in enumerate((0, n - 1)):
                    A[e, :, at:at + size] = (amounts[:, i, :, l - 1] + amounts[:, i, :, 0]).T
            at += size
        A = A.transpose(1, 0, 2).reshape(2 * m, nv)           # section-major, LE before TE
        rows = np.stack(np.meshgrid(np.arange(m), np.arange(2), indexing="ij"), -1).reshape(-1, 2)
        keep = np.abs(A).max(axis=1) > 0
        return cls(index=ctx.index, lower=ctx.lower, upper=ctx.upper, A=A[keep], rows=rows[keep])

    @property
    def size(self) -> int:
        return self.A.shape[0]

    def value(self, inp):
        return self.A @ inp.values

    def jacobian(self, inp):
        return self.A.copy()


CONSTRAINTS.register(LeTe)
