"""The derivative chain: the stages composed, values in on every call, and the MPI reductions.

::

    values --LatticeStage--> lattices --SurfaceStage--> surface displacement b ----------+
                                  |                                                         |
                                  +------FrameStage (volume.carry)---> frames F ------------+--VolumeStage--> mesh
                                  +------FrameStage ("gradient")-----> F_map --+                         |
                                                     b ------------------------+--QualityStage--(design map, measure)

Each product of :class:`DesignChain` takes the design values it is asked about (nothing is set on
the chain and read back): ``surface_points(values)``, ``mesh_vjp(values, g)``, ... The forward
products compose the stages' ``jvp`` from the values down, the reverse products their ``vjp`` from
the output up. What is computed for some values (the lattices, dP'/dv, the frames' local
derivatives) is kept by the stage with the hash of those values and reused while they repeat.

The chain owns the reductions over MPI ranks (:class:`~ffdcli.chain.share.MeshShare`): the agreement
that every rank holds the same values, the warp shared among the ranks, the reverse products
summed, the finite check.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from ffdcli.chain.cache import Memo, digest
from ffdcli.chain.frames import FrameStage
from ffdcli.chain.lattices import LatticeStage
from ffdcli.chain.quality import QualityStage
from ffdcli.chain.share import MeshShare
from ffdcli.chain.surface import SurfaceStage
from ffdcli.chain.volume import VolumeStage
from ffdcli.errors import InputError, QualityError
from ffdcli.parameterization.components import layout
from ffdcli.quality.design_map import DESIGN_ZONE


class DesignChain:
    """The stages of one design's components over one mesh (module docstring).

    Parameters
    ----------
    components : sequence of ffdcli.parameterization.components.Component
        The prepared components (box, embedding, changes), file order.
    volume : VolumeStage
        The volume motion of the mesh (with its :class:`MeshShare`); kept by the caller between
        chains of the same mesh (its warp model is built once).
    error : callable (message, key) -> InputError, optional
        Names a refused change by the design file's key.
    path : path, optional
        The design file (the errors of a deformation name it).
    """

    def __init__(self, components, volume: VolumeStage, *, error: Callable | None = None, path=None):
        self.components = tuple(components)
        self.path = path
        lay = layout(list(self.components))
        self.layout = lay
        self.single = len(self.components) == 1
        self.surface_ids = self.components[0].prep.surface.ids if self.single else lay.surface_ids
        S = len(self.surface_ids)
        self.lattices = LatticeStage(self.components, error)
        self.surface = SurfaceStage(self.components, lay.rows, S)
        self.volume = volume
        self.carry = volume.settings.carry
        self.frames_gradient = FrameStage(self.components, lay.rows, S, "gradient")
        self.frames_rotation = FrameStage(self.components, lay.rows, S, "rotation")
        self._mesh = Memo()
        self.quality = QualityStage((), volume.points0, self.surface_ids,
                                    lambda: DESIGN_ZONE * self.volume.model().chord)

    @property
    def share(self) -> MeshShare:
        return self.volume.share

    @property
    def n_vars(self) -> int:
        return self.lattices.n_vars

    def frame_stage(self, carry: str | None = None) -> FrameStage:
        """The frames the warp carries (``carry`` default: the design's ``volume.carry``)."""
        return self.frames_gradient if (carry or self.carry) == "gradient" else self.frames_rotation

    def per_component(self, P) -> tuple[np.ndarray, ...]:
        """Lattices as a tuple, one per component (one array: a single-component design's)."""
        if isinstance(P, np.ndarray) and P.ndim == 4:
            if not self.single:
                raise ValueError("surface motion of one lattice is for a single-component design")
            return (P,)
        if len(P) != len(self.components):
            raise ValueError(f"expected {len(self.components)} lattices, got {len(P)}")
        return tuple(P)

    # -- forward ---------------------------------------------------------------------------------
    def surface_points(self, values) -> np.ndarray:
        """(S, 3) the deformed surface points (rows of ``surface_ids``)."""
        X0 = self.volume.points0[self.surface_ids]
        return X0 + self.surface.forward(self.lattices.forward(values))

    def frames(self, values, carry: str | None = None) -> np.ndarray:
        """(S, 3, 3) the frames the surface hands the warp."""
        return self.frame_stage(carry).forward(self.lattices.forward(values))

    def place(self, P, progress=None) -> tuple[np.ndarray, np.ndarray]:
        """``(b (S, 3), points (N, 3))`` of the lattices ``P``: the surface displacement and every mesh
        node (a local mesh: its rows) as ``ffd deform`` places them, before the gate.

        Raises :class:`~ffdcli.errors.InputError` for lattices that move no surface point (never a
        silent success) and :class:`~ffdcli.errors.QualityError` for non-finite coordinates."""
        Ps = self.per_component(P)
        b = self.surface.forward(Ps)
        if not np.any(b) and any(not np.array_equal(Q, c.P0) for Q, c in zip(Ps, self.components, strict=True)):
            raise InputError("the design moves the lattice but no surface point (is the surface outside the "
                             "lattice?); nothing was written", path=self.path)
        F = self.frame_stage().forward(Ps) if self.volume.moves else None
        points = self.volume.forward((b, F), progress=progress)
        if not self.share.all_finite(points):
            raise QualityError("the deformed mesh has non-finite coordinates; are the design values far too "
                               "large? nothing was written", path=self.path)
        return b, points

    def mesh_points(self, values, progress=None) -> np.ndarray:
        """(N, 3) every mesh node as ``ffd deform`` places it."""
        values = np.asarray(values, dtype=float)
        return self._mesh.get(digest(values), lambda: self.place(self.lattices.forward(values), progress)[1])

    def design_map(self, values):
        """``(X_map (N, 3), zone (N,) bool)``: the input nodes near the wall moved by the design's own map;
        None without a volume motion."""
        if not self.volume.moves:
            return None
        Ps = self.lattices.forward(values)
        return self.quality.design_map(self.surface.forward(Ps), self.frames_gradient.forward(Ps))

    # -- the quality of the moved mesh (mesh_quality) --------------------------------------------
    def quality_inputs(self, values, mesh_points: Callable | None = None):
        """``x = (X, b, F)`` of the quality stage at ``values``: the mesh as ``ffd deform`` places it
        (``mesh_points()``: as deformed already), the surface displacement and the map's frames
        (``b``, ``F`` None without a volume motion: no design map)."""
        values = np.asarray(values, dtype=float)
        X = np.asarray(mesh_points() if mesh_points is not None else self.mesh_points(values), dtype=float)
        if not self.volume.moves:
            return X, None, None
        Ps = self.lattices.forward(values)
        return X, self.surface.forward(Ps), self.frames_gradient.forward(Ps)

    def quality_of(self, measures, values, jacobian: bool = False, mesh_points: Callable | None = None):
        """``(y (C,), dy/dv (C, n_vars) or None)`` of ``measures`` (``mesh_quality`` items) at ``values``:
        the quality stage's value, its reverse product carried down the chain (through the volume
        motion, and through the design map near the wall)."""
        stage = self.quality.over(measures)
        x = self.quality_inputs(values, mesh_points)
        if not jacobian:
            return stage.forward(x), None
        y = np.array([v for v, _, _ in stage.value_and_gradients(x)])
        rows = []
        for k in range(len(stage.measures)):
            gX, g_b, g_F = stage.vjp(x, np.eye(len(stage.measures))[k])
            row = np.asarray(self.mesh_vjp(values, gX), dtype=float)
            if np.any(g_b) or np.any(g_F):
                row = row + self._pull(values, g_b, g_F, "gradient")
            rows.append(row)
        return y, np.array(rows).reshape(len(rows), self.n_vars)

    # -- forward products ------------------------------------------------------------------------
    def surface_jvp(self, values, dv) -> np.ndarray:
        """(S, 3) dX_s/dv @ dv."""
        Ps = self.lattices.forward(values)
        return self.surface.jvp(Ps, self.lattices.jvp(values, dv))

    def mesh_jvp(self, values, dv, progress=None) -> np.ndarray:
        """(N, 3) every node's motion for ``dv``, through the volume motion."""
        Ps = self.lattices.forward(values)
        dPs = self.lattices.jvp(values, dv)
        db = self.surface.jvp(Ps, dPs)
        x = (self.surface.forward(Ps), self.frame_stage().forward(Ps)) if self.volume.moves else None
        dF = self.frame_stage().jvp(Ps, dPs) if self.volume.moves else None
        return self.volume.jvp(x, (db, dF), progress=progress)

    # -- reverse products ------------------------------------------------------------------------
    def _pull(self, values, g_b, g_F=None, carry: str | None = None) -> np.ndarray:
        """(n_vars,) from gradients at the surface displacement ``g_b`` (S, 3) and frames ``g_F``."""
        Ps = self.lattices.forward(values)
        gP = self.surface.vjp(Ps, g_b)
        if g_F is not None:
            gP = tuple(a + c for a, c in zip(gP, self.frame_stage(carry).vjp(Ps, g_F), strict=True))
        return self.lattices.vjp(values, gP)

    def surface_vjp(self, values, g) -> np.ndarray:
        """(n_vars,) dJ/dv for ``g`` = dJ/dX at the surface points (S, 3)."""
        return self._pull(values, g)

    def mesh_vjp(self, values, g, progress=None) -> np.ndarray:
        """(n_vars,) dJ/dv for ``g`` = dJ/dX at every mesh node (N, 3), through the volume motion (under
        MPI each rank sums its share of the volume, the sums reduced)."""
        if self.volume.moves:
            Ps = self.lattices.forward(values)
            x = (self.surface.forward(Ps), self.frame_stage().forward(Ps))
        else:
            x = None
        g_b, g_F = self.volume.vjp(x, g, progress=progress)
        return self._pull(values, g_b, g_F if self.volume.moves else None)

    def design_map_vjp(self, values, G) -> np.ndarray:
        """(n_vars,) dJ/dv for ``G`` = dJ/dX_map (N, 3) (:meth:`design_map`)."""
        g_b, g_F = self.quality.design_map_vjp(G)
        return self._pull(values, g_b, g_F, "gradient")
