"""The design's own map near the wall: where the FFD map, linearised at the nearest surface node, puts
the input mesh's nodes (the one home of that rule; the quality gate and ``mesh_quality`` both use it).

A node within ``zone`` (a length: the gate's 0.15 mean chords) of the surface goes to::

    x_j + b_j + F_j (x - x_j)

``j`` its nearest surface node, ``b`` the surface displacement, ``F`` the FFD map's deformation gradient
there (inside the lattice the FFD map itself to second order in the distance; beyond its margin an
extension of it). The map is affine in ``(b, F)``, and both are linear in the control points, so its
reverse product is exact: :meth:`DesignMapZone.vjp` beside :meth:`DesignMapZone.apply`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

#: The zone near the wall, in mean chords, where the gate compares cells with the design's own map.
DESIGN_ZONE = 0.15


def linearised_map(X: np.ndarray, Xs: np.ndarray, b: np.ndarray, F: np.ndarray) -> np.ndarray:
    """(k, 3) ``Xs + b + F (X - Xs)``: points ``X`` (k, 3) moved by the map linearised at their surface
    nodes ``Xs`` (k, 3) (input positions), ``b`` (k, 3) and ``F`` (k, 3, 3) there."""
    return X + b + np.einsum("kij,kj->ki", F - np.eye(3), X - Xs)


@dataclass(frozen=True, eq=False)
class DesignMapZone:
    """The input nodes near the wall and what the map needs of them (built once on the input mesh).

    nodes
        (Z,) mesh node ids within the zone (surface nodes included), increasing.
    nearest
        (Z,) the row of each one's nearest surface node (rows of the run's surface, ``surface_ids``).
    offset
        (Z, 3) ``x - x_j`` on the input mesh.
    n_points
        Nodes of the whole mesh (``mask`` has this length).
    """

    nodes: np.ndarray
    nearest: np.ndarray
    offset: np.ndarray
    n_points: int

    @classmethod
    def build(cls, points: np.ndarray, surface_ids: np.ndarray, zone: float) -> DesignMapZone:
        """The zone of ``points`` (N, 3) within ``zone`` of the surface nodes ``surface_ids`` (S,)."""
        points = np.asarray(points, dtype=np.float64)
        Xs = points[surface_ids]
        d, j = cKDTree(Xs).query(points)
        nodes = np.flatnonzero(d <= zone)
        return cls(nodes=nodes, nearest=j[nodes].astype(np.int64), offset=points[nodes] - Xs[j[nodes]],
                   n_points=len(points))

    @property
    def mask(self) -> np.ndarray:
        """(N,) True at the zone's nodes."""
        m = np.zeros(self.n_points, dtype=bool)
        m[self.nodes] = True
        return m

    def moved(self, node_ids: np.ndarray, X0: np.ndarray, b: np.ndarray, F: np.ndarray) -> np.ndarray:
        """(k, 3): where the map puts input nodes ``node_ids`` (NaN rows for nodes outside the zone);
        ``X0`` (N, 3) the input points, ``b`` (S, 3), ``F`` (S, 3, 3)."""
        node_ids = np.asarray(node_ids, dtype=np.int64)
        at = np.searchsorted(self.nodes, node_ids)
        inside = (at < len(self.nodes)) & (self.nodes[np.minimum(at, len(self.nodes) - 1)] == node_ids) \
            if len(self.nodes) else np.zeros(len(node_ids), dtype=bool)
        out = np.full((len(node_ids), 3), np.nan)
        k = at[inside]
        j = self.nearest[k]
        X = X0[node_ids[inside]]
        out[inside] = linearised_map(X, X - self.offset[k], b[j], F[j])
        return out

    def apply(self, X0: np.ndarray, b: np.ndarray, F: np.ndarray) -> np.ndarray:
        """(N, 3): ``X0`` with the zone's nodes moved by the map (the others as in the input)."""
        out = np.array(X0, dtype=np.float64)
        X = out[self.nodes]
        out[self.nodes] = linearised_map(X, X - self.offset, b[self.nearest], F[self.nearest])
        return out

    def vjp(self, G: np.ndarray, n_surface: int) -> tuple[np.ndarray, np.ndarray]:
        """The reverse product of :meth:`apply`: ``(g_b (S, 3), g_F (S, 3, 3))`` for ``G`` (N, 3) ``=
        dJ/d(apply's result)`` (rows outside the zone do not depend on ``b`` or ``F``)."""
        Gz = np.asarray(G, dtype=np.float64)[self.nodes]
        g_b = np.zeros((n_surface, 3))
        np.add.at(g_b, self.nearest, Gz)
        g_F = np.zeros((n_surface, 3, 3))
        np.add.at(g_F, self.nearest, Gz[:, :, None] * self.offset[:, None, :])
        return g_b, g_F
