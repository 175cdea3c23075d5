"""``add_material``: the shape may only add material (ADODG Case 1): every upper-surface node stays on
or above its baseline position and every lower-surface node on or below, along the thickness axis.

One item per wing surface node that faces up or down: ``side_i t . (X_i - X0_i)`` in mesh units, with
``t`` the box's thickness direction, ``X0_i`` the node's baseline position, ``X_i = X0_i + B_i (P' - P0)``
where the design puts it, and ``side_i`` +1 on the upper surface, -1 on the lower (the sign of the
outward vertex normal's thickness component; the normals are turned outward by the sign of
``sum_i a_i n_i . (X_i - c)``, the divergence theorem's enclosed volume, so the mesh's face
orientation does not matter). ``>= 0`` (the default lower bound) means the node moved outward or not
at all. A node whose normal is perpendicular to the thickness axis (within :data:`SIDE_TOL`: the
leading-edge point of a symmetric section, a blunt trailing edge's base, a flat tip cap) is on neither
side and has no item.

Linear in the control points: the value is ``A (P' - P0)`` with ``A = diag(side) B_sel (x) t``
constant, so its Jacobian ``A dP'/dv`` is exact, and constant for the changes linear in their values
(``shape``). Why every node and not N chord stations: at a station the surface point is where the
moved surface crosses the station's line, which is not linear in the lattice; a node is, and it is
the mesh the flow solver sees. For moves along the thickness axis (``shape`` on an untwisted,
unswept section, ADODG Case 1) the nodes keep their chord position and the two readings are the same
at every node's station; for changes that move nodes along the chord too (twist, chord) the node
reading holds each surface point, not each station.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ffdcli.constraints.base import CONSTRAINTS, Constraint, item_schema
from ffdcli.geometry.surface import vertex_areas, vertex_normals

#: A node whose unit normal has a thickness component of at most this is on neither side.
SIDE_TOL = 1e-6


@dataclass(frozen=True, eq=False)
class AddMaterial(Constraint):
    """``side * t . (X - X0)`` at the surface nodes that face up or down (module docstring).

    ids
        (C,) the nodes of the items (local ids of the surface, in order).
    side
        (C,) +1 on the upper surface, -1 on the lower.
    X0
        (C, 3) their baseline positions.
    direction
        (3,) the unit thickness direction ``t``.
    """

    ids: np.ndarray = None
    side: np.ndarray = None
    X0: np.ndarray = None
    direction: np.ndarray = None

    kind = "add_material"
    default_bounds = (0.0, None)

    @classmethod
    def schema(cls) -> dict:
        return item_schema("the shape only adds material: at every surface node facing up or down, the move "
                           "along the thickness axis outward from the baseline (upper: up, lower: down), in "
                           "mesh units; lower defaults to 0")

    @classmethod
    def from_spec(cls, spec: dict, ctx) -> AddMaterial:
        """The nodes with a side, on the baseline surface."""
        X = np.asarray(ctx.surface.points, dtype=np.float64)
        faces = ctx.surface.faces
        t = np.asarray(ctx.box.frame.thickness_dir, dtype=np.float64)
        n = vertex_normals(X, faces)
        if np.sum(vertex_areas(X, faces) * np.einsum("ij,ij->i", n, X - X.mean(axis=0))) < 0:
            n = -n                                          # the faces point inward: turn the normals out
        nt = n @ t
        ids = np.flatnonzero(np.abs(nt) > SIDE_TOL)
        if not ids.size:
            raise ctx.fail("the surface has no node facing up or down along the thickness axis")
        return cls(index=ctx.index, lower=ctx.lower, upper=ctx.upper, ids=ids, side=np.sign(nt[ids]),
                   X0=X[ids].copy(), direction=t)

    @property
    def size(self) -> int:
        return len(self.ids)

    def value(self, inp):
        return self.side * ((inp.X[self.ids] - self.X0) @ self.direction)

    def jacobian(self, inp):
        nv = inp.D.shape[1]
        Dt = np.einsum("d,cdv->cv", self.direction, inp.D.reshape(-1, 3, nv))    # (n_ctrl, n_vars)
        return self.side[:, None] * np.asarray(inp.B[self.ids] @ Dt)


CONSTRAINTS.register(AddMaterial)
