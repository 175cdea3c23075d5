"""``volume``: the volume (2D: area) enclosed by the surface, as a ratio to the baseline.

Volume enclosed by the surface triangles (quads split in two), by the divergence theorem
``V = 1/6 sum (a - o) . ((b - o) x (c - o))`` with ``o`` on the root plane: the open root of a
half wing lies in that plane, where ``(x - o) . n = 0``, so the symmetry plane closes the wing
exactly and contributes nothing. A closed surface gives its volume for any ``o``. In 2D: the area
enclosed by the airfoil. Ratio to the baseline.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from ffdcli.constraints.base import CONSTRAINTS, Constraint, item_schema, surface_segments, surface_triangles


@njit(cache=True)
def _volume_nb(X, tri, o, want_grad, G):
    """Compiled :func:`_enclosed`: the volume; the gradient is accumulated into ``G`` (zeroed) if asked."""
    vol = 0.0
    for t in range(tri.shape[0]):
        i0, i1, i2 = tri[t, 0], tri[t, 1], tri[t, 2]
        ax, ay, az = X[i0, 0] - o[0], X[i0, 1] - o[1], X[i0, 2] - o[2]
        bx, by, bz = X[i1, 0] - o[0], X[i1, 1] - o[1], X[i1, 2] - o[2]
        cx, cy, cz = X[i2, 0] - o[0], X[i2, 1] - o[1], X[i2, 2] - o[2]
        bcx, bcy, bcz = by * cz - bz * cy, bz * cx - bx * cz, bx * cy - by * cx
        vol += ax * bcx + ay * bcy + az * bcz
        if want_grad:
            G[i0, 0] += bcx
            G[i0, 1] += bcy
            G[i0, 2] += bcz
            G[i1, 0] += cy * az - cz * ay
            G[i1, 1] += cz * ax - cx * az
            G[i1, 2] += cx * ay - cy * ax
            G[i2, 0] += ay * bz - az * by
            G[i2, 1] += az * bx - ax * bz
            G[i2, 2] += ax * by - ay * bx
    return vol / 6.0


def enclosed_volume(X: np.ndarray, tri: np.ndarray, o: np.ndarray, grad: bool = False):
    """Volume ``1/6 sum (a - o) . ((b - o) x (c - o))`` of triangles ``tri`` (T, 3) of points ``X`` (S, 3)
    and, if ``grad``, its gradient (S, 3) with respect to the points (compiled; see :func:`_enclosed`)."""
    X = np.ascontiguousarray(X, dtype=np.float64)
    G = np.zeros_like(X) if grad else np.zeros((0, 3))
    vol = _volume_nb(X, np.ascontiguousarray(tri, dtype=np.int64), np.asarray(o, dtype=np.float64), grad, G)
    if grad:
        G /= 6.0
    return vol, (G if grad else None)


def _enclosed(X: np.ndarray, cells: np.ndarray, o: np.ndarray, dim: int, grad: bool):
    """NumPy reference of :func:`enclosed_volume`: volume of triangles (T, 3) relative to ``o``, and its
    gradient (S, 3) with respect to the points if ``grad``."""
    if dim == 3:
        a, b, c = (X[cells[:, q]] - o for q in range(3))
        bc = np.cross(b, c)
        vol = float(np.einsum("ij,ij->", a, bc)) / 6.0
        if not grad:
            return vol, None
        G = np.zeros_like(X)
        for q, v in ((0, bc), (1, np.cross(c, a)), (2, np.cross(a, b))):
            for d in range(3):
                G[:, d] += np.bincount(cells[:, q], weights=v[:, d], minlength=len(X))
        return vol, G / 6.0
    raise AssertionError("2D areas use _area")  # pragma: no cover


def _area(X: np.ndarray, seg: np.ndarray, o: np.ndarray, ax: tuple[int, int], grad: bool):
    """Signed area 1/2 sum (a - o) x (b - o) of segments (E, 2) in the plane of mesh axes ``ax``."""
    i, j = ax
    a, b = X[seg[:, 0]] - o, X[seg[:, 1]] - o
    area = 0.5 * float(np.sum(a[:, i] * b[:, j] - a[:, j] * b[:, i]))
    if not grad:
        return area, None
    G = np.zeros_like(X)
    n = len(X)
    G[:, i] += 0.5 * (np.bincount(seg[:, 0], b[:, j], n) - np.bincount(seg[:, 1], a[:, j], n))
    G[:, j] += 0.5 * (np.bincount(seg[:, 1], a[:, i], n) - np.bincount(seg[:, 0], b[:, i], n))
    return area, G


@dataclass(frozen=True, eq=False)
class Volume(Constraint):
    """Enclosed volume (2D: area) of the surface as a ratio to the baseline (see the module docstring).

    cells
        (T, 3) triangles (3D) or (E, 2) segments (2D) of the surface, local point indices.
    origin
        (3,) a point on the root plane.
    base
        The baseline volume (signed: the face orientation's sign cancels in the ratio).
    """

    cells: np.ndarray = None
    origin: np.ndarray = None
    base: float = 1.0
    dim: int = 3
    plane: tuple[int, int] = (0, 1)

    kind = "volume"

    @classmethod
    def schema(cls) -> dict:
        return item_schema("volume enclosed by the surface (a half wing closed by its symmetry plane; 2D: the "
                           "area), as a ratio to the baseline")

    @classmethod
    def from_spec(cls, spec: dict, ctx) -> Volume:
        """Built on the baseline surface (its volume or area is the base)."""
        box, X = ctx.box, ctx.surface.points
        if box.dim == 3:
            cells = surface_triangles(ctx.surface.faces)
            plane = (0, 1)
        else:
            cells = surface_segments(ctx.surface.faces)
            plane = (box.axes.chord, box.axes.thickness)
        if not len(cells):
            raise ctx.fail("the surface has no faces to enclose a volume")
        origin = np.asarray(box.te_points[0], dtype=float).copy()     # on the root plane (3D)
        made = dict(index=ctx.index, lower=ctx.lower, upper=ctx.upper, cells=cells, origin=origin, dim=box.dim,
                    plane=plane)
        v0 = cls(base=1.0, **made).measure(X)[0]
        size = float(np.ptp(box.control_points.reshape(-1, 3), axis=0).max()) or 1.0
        if not abs(v0) > 1e-12 * size ** box.dim:
            raise ctx.fail("the surface encloses no volume (an open surface whose opening is not the root plane?)")
        return cls(base=v0, **made)

    @property
    def size(self) -> int:
        return 1

    @property
    def scalar(self) -> bool:
        return True

    def measure(self, X, grad=False):
        """(volume or area, gradient (S, 3) or None) of surface points ``X`` (S, 3)."""
        if self.dim == 3:
            return enclosed_volume(X, self.cells, self.origin, grad)
        return _area(X, self.cells, self.origin, self.plane, grad)

    def value(self, inp):
        return np.array([self.measure(inp.X)[0] / self.base])

    def jacobian(self, inp):
        return self.value_and_jacobian(inp)[1]

    def value_and_jacobian(self, inp):
        vol, G = self.measure(inp.X, grad=True)
        gP = inp.rmatvec(G).reshape(-1)
        return np.array([vol / self.base]), (gP @ inp.D)[None, :] / self.base


CONSTRAINTS.register(Volume)
