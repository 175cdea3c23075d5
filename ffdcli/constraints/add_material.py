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
side and has no item, with one exception: on a 2-D section, such a node between an upper and a lower
neighbour (the leading-edge point, a sharp trailing edge's point) is where the upper and the lower
surface meet, the upper surface's point at its chord station and the lower's, so it is on both: two
items, ``+t . (X - X0)`` and ``-t . (X - X0)``, which hold its move along the thickness axis at zero.
(Without them a design can meet the rule at every other node and move the leading-edge point off the
chord line: by 9.9e-6 chord at the 32-variable Case 1 optimum. ``le_te``'s equal and opposite edge
columns do not hold it: the point is inside the box, where the neighbouring columns move it too.)

Linear in the control points: the value is ``A (P' - P0)`` with ``A = diag(side) B_sel (x) t``
constant, so its Jacobian ``A dP'/dv`` is exact, and constant for the changes linear in their values
(``shape``). Why every node and not N chord stations: at a station the surface point is where the
moved surface crosses the station's line, which is not linear in the lattice; a node is, and it is
the mesh the flow solver sees. For moves along the thickness axis (``shape`` on an untwisted,
unswept section, ADODG Case 1) the nodes keep their chord position and the two readings are the same
at every node's station; for changes that move nodes along the chord too (twist, chord) the node
reading holds each surface point, not each station.

``between: k`` (2-D sections) states the rule at ``k`` more points between every two neighbouring
nodes, on the cubic through the two nodes tangent to the section there (a straight line at a corner
such as a sharp trailing edge), each point embedded in the lattice as a node is (a
:class:`~ffdcli.lattice.pointset.PointSet`) and held as a node is, on the side of its own normal.
Why: the rule holds at the points it is stated at and nowhere else. Between two active nodes the
lattice's surface and the baseline are different curves, so an optimum that meets the rule at the
optimisation mesh's nodes dips inside the baseline between them (ADODG Case 1 on the twice finer mesh:
by 1.4e-6 chord with 8 variables, about 1e-5 with 16 and 32). A dip between stations ``h`` apart
shrinks as ``h**2``: ``k`` points per segment divide it by about ``(k + 1)**2``. Still linear in the
control points: exact, constant Jacobian.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ffdcli.constraints.base import CONSTRAINTS, Constraint, item_schema, surface_segments
from ffdcli.geometry.surface import face_vectors, vertex_areas, vertex_normals
from ffdcli.lattice.pointset import PointSet
from ffdcli.mesh.model import CellBlock

#: A node whose unit normal has a thickness component of at most this is on neither side.
SIDE_TOL = 1e-6
#: A node where the two segments' normals differ from the node's normal by more than this angle is a
#: corner (a sharp trailing edge): the curves between points end there along their own segment.
CORNER_DEG = 30.0
#: The most points ``between`` may add per segment.
MAX_BETWEEN = 32


def points_between(X: np.ndarray, segments: np.ndarray, normals: np.ndarray, k: int
                   ) -> tuple[np.ndarray, np.ndarray]:
    """``k`` points between the two nodes of every segment of a 2-D section (in the x-y plane), on the
    cubic Hermite curve through the nodes with the section's tangents there.

    Parameters
    ----------
    X : ndarray, shape (S, 3)
        The section's nodes (z ignored: the section is in the x-y plane).
    segments : ndarray, shape (E, 2)
        Node ids of the segments.
    normals : ndarray, shape (S, 3)
        Unit outward vertex normals.
    k : int
        Points per segment, at the curve parameters ``j / (k + 1)``, ``j = 1..k``.

    Returns
    -------
    Q : ndarray, shape (E * k, 3)
        The points, segment by segment.
    n : ndarray, shape (E * k, 3)
        The curve's unit normal at each, turned to the side of its two nodes' normals.

    The tangent at a node is the vertex normal turned by 90 degrees (``(-n_y, n_x)``), pointing along
    the segment; at a corner (an incident segment's normal more than :data:`CORNER_DEG` from the
    node's) the segment's own direction, so the curve is the straight segment at that end.
    """
    a, b = segments[:, 0], segments[:, 1]
    d = X[b] - X[a]                                                   # (E, 3)
    L = np.linalg.norm(d, axis=1)
    u = d / np.where(L > 0, L, 1.0)[:, None]
    nseg = face_vectors(X, [CellBlock("line", segments)]) / np.where(L > 0, L, 1.0)[:, None]
    cos_corner = np.cos(np.radians(CORNER_DEG))
    tan = np.stack([-normals[:, 1], normals[:, 0], np.zeros(len(X))], axis=1)

    def end_tangent(node):
        t = tan[node]
        t = t * np.where(np.einsum("ij,ij->i", t, u) < 0, -1.0, 1.0)[:, None]
        corner = np.abs(np.einsum("ij,ij->i", nseg, normals[node])) < cos_corner
        return np.where(corner[:, None], u, t)

    Ta, Tb = end_tangent(a), end_tangent(b)
    s = (np.arange(1, k + 1) / (k + 1))[None, :, None]               # (1, k, 1)
    h00, h10, h01, h11 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s, -2 * s**3 + 3 * s**2, s**3 - s**2
    g00, g10, g01, g11 = 6 * s**2 - 6 * s, 3 * s**2 - 4 * s + 1, -6 * s**2 + 6 * s, 3 * s**2 - 2 * s
    Xa, Xb, La = X[a][:, None], X[b][:, None], L[:, None, None]
    Q = h00 * Xa + h10 * La * Ta[:, None] + h01 * Xb + h11 * La * Tb[:, None]
    dQ = g00 * Xa + g10 * La * Ta[:, None] + g01 * Xb + g11 * La * Tb[:, None]
    n = np.stack([dQ[..., 1], -dQ[..., 0], np.zeros(dQ.shape[:2])], axis=-1)
    n /= np.maximum(np.linalg.norm(n, axis=-1, keepdims=True), 1e-300)
    out = (normals[a] + normals[b])[:, None]
    n *= np.where(np.einsum("eki,eki->ek", n, np.broadcast_to(out, n.shape)) < 0, -1.0, 1.0)[..., None]
    Q[..., 2] = (Xa[..., 2] + (Xb[..., 2] - Xa[..., 2]) * s[..., 0])
    return Q.reshape(-1, 3), n.reshape(-1, 3)


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
    extra
        :class:`~ffdcli.lattice.pointset.PointSet` of the points ``between`` the nodes (their items
        follow the nodes'), or None.
    extra_side
        (M,) their sides.
    """

    ids: np.ndarray = None
    side: np.ndarray = None
    X0: np.ndarray = None
    direction: np.ndarray = None
    extra: PointSet | None = None
    extra_side: np.ndarray | None = None

    kind = "add_material"
    default_bounds = (0.0, None)

    @classmethod
    def schema(cls) -> dict:
        between = {"type": "integer", "minimum": 0, "maximum": MAX_BETWEEN,
                   "description": "2-D sections: also this many points between every two neighbouring nodes "
                                  "(on the cubic through them), held as the nodes are; 0 (default): the nodes "
                                  "only. The rule holds where it is stated: state it between the nodes for a "
                                  "design that will be evaluated on a finer mesh"}
        return item_schema("the shape only adds material: at every surface node facing up or down, the move "
                           "along the thickness axis outward from the baseline (upper: up, lower: down), in "
                           "mesh units; lower defaults to 0", {"between": between})

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
        side = np.where(np.abs(nt) > SIDE_TOL, np.sign(nt), 0.0)
        sided = np.flatnonzero(side)
        if not sided.size:
            raise ctx.fail("the surface has no node facing up or down along the thickness axis")
        meet = section_edges(surface_segments(faces), side) if ctx.box.dim == 2 else np.zeros(0, np.int64)
        ids = np.concatenate([sided, meet, meet])
        sides = np.concatenate([side[sided], np.ones(len(meet)), -np.ones(len(meet))])
        extra, extra_side = _between(spec, ctx, X, faces, n, t)
        return cls(index=ctx.index, lower=ctx.lower, upper=ctx.upper, ids=ids, side=sides,
                   X0=X[ids].copy(), direction=t, extra=extra, extra_side=extra_side)

    @property
    def size(self) -> int:
        return len(self.ids) + (0 if self.extra is None else self.extra.n_points)

    def value(self, inp):
        v = self.side * ((inp.X[self.ids] - self.X0) @ self.direction)
        if self.extra is None:
            return v
        moved = self.extra.points(inp.dP) - self.extra.points0
        return np.concatenate([v, self.extra_side * (moved @ self.direction)])

    def jacobian(self, inp):
        nv = inp.D.shape[1]
        Dt = np.einsum("d,cdv->cv", self.direction, inp.D.reshape(-1, 3, nv))    # (n_ctrl, n_vars)
        J = self.side[:, None] * np.asarray(inp.B[self.ids] @ Dt)
        if self.extra is None:
            return J
        return np.vstack([J, self.extra_side[:, None] * np.asarray(self.extra.basis @ Dt)])


def section_edges(segments: np.ndarray, side: np.ndarray) -> np.ndarray:
    """The nodes of a 2-D section on neither side whose segment neighbours include an upper and a lower
    node: where the upper and lower surfaces meet (the leading edge, a sharp trailing edge).

    segments : (E, 2) node ids; side : (S,) +1, -1 or 0. Returns the node ids, sorted.
    """
    if not len(segments):
        return np.zeros(0, dtype=np.int64)
    a, b = segments[:, 0], segments[:, 1]
    up = np.zeros(len(side), dtype=bool)
    lo = np.zeros(len(side), dtype=bool)
    for node, other in ((a, b), (b, a)):
        np.logical_or.at(up, node, side[other] > 0)
        np.logical_or.at(lo, node, side[other] < 0)
    return np.flatnonzero((side == 0) & up & lo)


def _between(spec, ctx, X, faces, normals, t) -> tuple[PointSet | None, np.ndarray | None]:
    """The :class:`PointSet` of ``between`` points that face up or down and their sides (None, None
    for ``between`` 0 or absent)."""
    k = int((spec or {}).get("between") or 0)
    if k <= 0:
        return None, None
    if k > MAX_BETWEEN:
        raise ctx.fail(f"between: {k} is more than {MAX_BETWEEN} points per segment; a few (3 to 8) already "
                       "divide the dip between nodes by 16 to 81", f"{ctx.key}.between")
    segments = surface_segments(faces)
    if ctx.box.dim != 2 or not len(segments) or any(b.type not in ("line", "vertex") for b in faces):
        raise ctx.fail("between is for 2-D sections (a surface of line segments); on a 3-D surface the rule "
                       "is stated at the nodes: leave between out", f"{ctx.key}.between")
    Q, nq = points_between(X, segments, normals, k)
    nt = nq @ t
    keep = np.abs(nt) > SIDE_TOL
    extra = PointSet.embed(f"k{ctx.index}.add_material.between", ctx.box, Q[keep], progress=ctx.progress)
    return extra, np.sign(nt[keep])


CONSTRAINTS.register(AddMaterial)
