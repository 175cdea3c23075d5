"""surface and frames -> volume: every mesh node as the warp moves it (:mod:`ffdcli.volume.warp`).

``x = (b, F)``: the surface displacement (S, 3) and frames (S, 3, 3) (rows as the run's surface);
``y`` the mesh points (N, 3): ``X0 + warp(b, F)`` with the surface nodes exactly ``X0 + b`` (bit for
bit where the FFD puts them). The warp is a fixed linear map of ``(b, M = F - I)`` (a rigid wall
layer, :mod:`ffdcli.volume.layer_motion`, is not: its products are linearised at ``x = (b, F)``,
``at=``), so ``jvp`` is ``warp(db, I + dF)`` and ``vjp`` its exact transpose
:func:`ffdcli.volume.warp.warp_vjp`. Without a
volume motion (``volume.method: none``, a surface mesh) only the surface nodes move.

A thin wrapper: the motion itself is :mod:`ffdcli.volume`'s, built once on the input mesh.
"""

from __future__ import annotations

import numpy as np

from ffdcli.chain.cache import Once
from ffdcli.chain.share import MeshShare
from ffdcli.chain.stage import Stage
from ffdcli.settings import WarpSettings
from ffdcli.volume.cache import ReferenceCache
from ffdcli.volume.wall_layer import layer_arrays
from ffdcli.volume.warp import WarpModel, prepare_mesh_warp, warp, warp_vjp


class VolumeStage(Stage):
    """surface and frames -> volume (module docstring).

    Parameters
    ----------
    share : MeshShare
        The mesh (this rank's share of it) and the reductions.
    surface_ids : (S,) int array
        The run's surface nodes (rows of the mesh).
    names : sequence of str
        The surface markers (every component's).
    settings : ffdcli.settings.WarpSettings
        The design's ``volume:`` settings.
    moves : bool
        False: no volume motion (``volume.method: none`` or a mesh without volume cells).
    warp_cache : ffdcli.volume.cache.ReferenceCache, optional
        Where the warp's reference weights are kept between runs.
    """

    def __init__(self, share: MeshShare, surface_ids: np.ndarray, names, settings: WarpSettings, moves: bool,
                 warp_cache: ReferenceCache | None = None):
        self.share = share
        self.surface_ids = np.asarray(surface_ids)
        self.names = list(names)
        self.settings = settings
        self.moves = bool(moves)
        self.warp_cache = warp_cache
        self._model = Once()
        self._cached = False              # the model's reference weights are in the cache file

    @property
    def points0(self) -> np.ndarray:
        return self.share.mesh.points

    def model(self, progress=None) -> WarpModel:
        """The IDW model of the mesh, built once (a design loop does not rebuild its tree)."""
        return self._model.get(lambda: self._build(progress))

    def _build(self, progress) -> WarpModel:
        kept = {}

        def saved_layer(target_ids):            # the cache file read once: the weights and the wall layer
            kept["weights"], layer = self.warp_cache.load_all(target_ids)
            return layer

        model, _ = prepare_mesh_warp(self.share.mesh, self.names, self.settings, progress=progress,
                                     size=self.share.diagonal(), targets=self.share.targets(),
                                     nodes=self.share.nodes(),
                                     saved_layer=None if self.warp_cache is None else saved_layer)
        if not np.array_equal(model.surface_ids, self.surface_ids):
            raise RuntimeError("the warp's surface nodes differ from the box's")
        if "weights" in kept:
            weights = kept["weights"]
        else:
            weights = None if self.warp_cache is None else self.warp_cache.load(model.target_ids)
        if weights is not None:
            model.set_reference_weights(weights)
            self._cached = True
        return model

    def forward(self, x, progress=None) -> np.ndarray:
        b, F = x
        ids = self.surface_ids
        points = self.points0.copy()
        if self.moves:
            model = self.model(progress)
            points += self.share.warp(model, b, F, progress)     # MPI: each rank its rows or its block
            if self.warp_cache is not None and not self._cached:
                # the reference weights were computed by this warp: keep them for the next run (NaN
                # where a wall layer moves the target wholly: never warped, never walked)
                layer = None if model.layer is None else layer_arrays(model.layer)
                self._cached = self.warp_cache.save(model.target_ids, model.reference_weights(every=False), layer)
        else:
            points[ids] += b
        # The surface goes exactly where the FFD put it (bit for bit X0 + B @ dP).
        points[ids] = self.points0[ids] + b
        return points

    def jvp(self, x, dx, progress=None) -> np.ndarray:
        db, dF = dx
        db = np.asarray(db, dtype=float)
        if self.moves:       # a wall layer is not linear in the frames: linearised at x (at=)
            out = warp(self.model(progress), db, np.eye(3) + dF, progress=progress, at=(x[0], x[1]))
        else:
            out = np.zeros((len(self.points0), 3))
        out[self.surface_ids] = db
        return out

    def vjp(self, x, gy, progress=None) -> tuple[np.ndarray, np.ndarray]:
        g = np.asarray(gy, dtype=float)
        ids = self.surface_ids
        if not self.moves:
            return g[ids].copy(), np.zeros((len(ids), 3, 3))
        gs = g.copy()
        gs[ids] = 0.0          # surface nodes are placed by the FFD exactly; the warp's own value there is overwritten
        g_b, g_M = warp_vjp(self.model(progress), gs, progress=progress, comm=self.share.reduction_comm(),
                            at=(x[0], x[1]))
        return g_b + g[ids], g_M
