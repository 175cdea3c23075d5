"""volume -> quality: the ``mesh_quality`` constraints' measure of the moved mesh.

``x = (X, b, F)``: the mesh points (N, 3), the surface displacement (S, 3) and the FFD map's
deformation gradients at the surface (S, 3, 3) (``b``, ``F`` None: no design map, a mesh the volume
motion does not move; every cell is judged against its input); ``y`` (C,) the KS minimum of each ``mesh_quality``
item (:meth:`ffdcli.constraints.mesh_quality.MeshQuality.measure`), each cell's quality over its
reference, which near the wall is what the design's own map makes of the cell
(:class:`ffdcli.quality.design_map.DesignMapZone`: the input nodes within
:data:`~ffdcli.quality.design_map.DESIGN_ZONE` mean chords moved by ``x_j + b_j + F_j (x - x_j)``,
affine in ``(b, F)``). ``jvp`` and ``vjp`` are the measure's gradients with respect to ``X`` and to the
map's points, carried to ``(b, F)`` by the map's own products.

This stage is the one home of that rule: the ``mesh_quality`` constraint
(:mod:`ffdcli.constraints.mesh_quality`) gives its measure and reads its value and derivative here,
through :meth:`ffdcli.chain.DesignChain.quality`. A chain keeps one stage without measures (the
design map) and makes one per set of measures with :meth:`QualityStage.over`, which shares the
zone (built once per mesh).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from ffdcli.chain.cache import Memo, Once, digest
from ffdcli.chain.stage import Stage
from ffdcli.quality.design_map import DesignMapZone


class QualityStage(Stage):
    """volume -> quality (module docstring).

    Parameters
    ----------
    measures : sequence of ffdcli.constraints.mesh_quality.MeshQuality
        The items measured (may be empty: then only the design map is used).
    points0 : (N, 3) array
        The input mesh's points.
    surface_ids : (S,) int array
        The run's surface nodes.
    zone_length : callable () -> float
        The reach of the design map (:data:`~ffdcli.quality.design_map.DESIGN_ZONE` mean chords),
        asked once.
    """

    def __init__(self, measures, points0: np.ndarray, surface_ids: np.ndarray, zone_length: Callable[[], float]):
        self.measures = tuple(measures)
        self.points0 = points0
        self.surface_ids = np.asarray(surface_ids)
        self._zone_length = zone_length
        self._zone = Once()
        self._grads = Memo()

    def over(self, measures) -> QualityStage:
        """A stage of the same mesh measuring ``measures`` (the zone shared: it is built once)."""
        stage = QualityStage(measures, self.points0, self.surface_ids, self._zone_length)
        stage._zone = self._zone
        return stage

    def zone(self) -> DesignMapZone:
        """The input nodes near the wall (built once)."""
        return self._zone.get(lambda: DesignMapZone.build(self.points0, self.surface_ids, self._zone_length()))

    # -- the design's own map --------------------------------------------------------------------
    def design_map(self, b: np.ndarray, F: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(X_map (N, 3), zone (N,) bool)``: the input nodes near the wall moved by the map, the others
        where they are in the input."""
        zone = self.zone()
        return zone.apply(self.points0, b, F), zone.mask

    def design_map_jvp(self, db: np.ndarray, dF: np.ndarray) -> np.ndarray:
        """(N, 3) the map's motion for ``(db, dF)`` (zero outside the zone)."""
        zone = self.zone()
        out = np.zeros((zone.n_points, 3))
        j = zone.nearest
        out[zone.nodes] = db[j] + np.einsum("kij,kj->ki", dF[j], zone.offset)
        return out

    def design_map_vjp(self, G: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(g_b (S, 3), g_F (S, 3, 3))`` for ``G`` = dJ/dX_map (N, 3)."""
        return self.zone().vjp(G, len(self.surface_ids))

    # -- the stage -------------------------------------------------------------------------------
    def _map(self, b, F):
        """``(X_map, zone)`` of ``(b, F)``, or ``(None, None)`` without a map (``F`` None)."""
        return (None, None) if F is None else self.design_map(b, F)

    def forward(self, x) -> np.ndarray:
        X, b, F = x
        X_map, mask = self._map(b, F)
        return np.array([m.measure(X, X_map=X_map, zone=mask)[0] for m in self.measures])

    def value_and_gradients(self, x) -> list[tuple[float, np.ndarray, np.ndarray | None]]:
        """Per item ``(value, dvalue/dX (N, 3), dvalue/dX_map (N, 3) or None)`` at ``x`` (kept while
        ``x`` repeats)."""
        X, b, F = x

        def compute():
            X_map, mask = self._map(b, F)
            return [m.measure(X, grad=True, X_map=X_map, zone=mask) for m in self.measures]
        return self._grads.get(digest(X, b, F), compute)

    def gradients(self, x) -> list[tuple[np.ndarray, np.ndarray | None]]:
        """Per item ``(dvalue/dX (N, 3), dvalue/dX_map (N, 3) or None)`` at ``x``."""
        return [(G, G_map) for _, G, G_map in self.value_and_gradients(x)]

    def jvp(self, x, dx) -> np.ndarray:
        dX, db, dF = dx
        dmap = None
        out = []
        for G, G_map in self.gradients(x):
            v = float(np.sum(G * dX))
            if G_map is not None and np.any(G_map):
                dmap = self.design_map_jvp(db, dF) if dmap is None else dmap
                v += float(np.sum(G_map * dmap))
            out.append(v)
        return np.array(out)

    def vjp(self, x, gy) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(gX (N, 3), g_b (S, 3), g_F (S, 3, 3))``; ``g_b``, ``g_F`` are zeros (not computed) where no
        cell is judged against the design map."""
        X, b, F = x
        gX = np.zeros_like(np.asarray(X, dtype=float))
        G_all = np.zeros_like(gX)
        any_map = False
        for g, (G, G_map) in zip(np.asarray(gy, dtype=float), self.gradients(x), strict=True):
            gX += g * G
            if G_map is not None and np.any(G_map):
                G_all += g * G_map
                any_map = True
        if not any_map:
            S = len(self.surface_ids)
            return gX, np.zeros((S, 3)), np.zeros((S, 3, 3))
        g_b, g_F = self.design_map_vjp(G_all)
        return gX, g_b, g_F
