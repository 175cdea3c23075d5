"""Every mesh node of a :class:`~ffdcli.api.DesignModel`: where ``ffd deform`` puts it, its exact
forward and reverse products through the volume motion, and the write of the deformed mesh.

The warp is linear in the surface translations ``b`` and frame parts ``M = F - I``
(:func:`ffdcli.volume.warp.warp_vjp` is its transpose); the frames' derivative is
:func:`ffdcli.volume.surface_motion.frame_jacobian`.
"""

from __future__ import annotations

import numpy as np

from ffdcli.app.deform import deform_design
from ffdcli.app.deformation import deform, design_zone, volume_method
from ffdcli.app.prepare import is_surface_mesh
from ffdcli.mesh.numbers import as_numbers
from ffdcli.quality.gate import Remedies
from ffdcli.volume.surface_motion import frame_jacobian
from ffdcli.volume.warp import warp, warp_vjp

#: How the API's user overrides the quality gate (the gate states the rule; :meth:`write` names its argument).
_REMEDIES = Remedies(deform_anyway=", or pass force=True to deform it anyway",
                     write_anyway=" (force=True writes it anyway)", forced=" (force=True)")


class VolumeMixin:
    """The whole-mesh part of :class:`~ffdcli.api.DesignModel`."""

    def _warp_model(self, progress=None):
        return self.run.warp_model(progress)

    def uses_volume(self) -> bool:
        """True when the volume mesh follows the surface (``volume.method: idw`` on a volume mesh)."""

        mesh = self.run.prep.mesh
        return volume_method(self.run) == "idw" and mesh.n_cells > 0 and not is_surface_mesh(mesh)

    def mesh_points(self, progress=None) -> np.ndarray:
        """(N, 3) every mesh node as ``ffd deform`` places it."""

        return deform(self.run, P=self.lattice(), progress=progress, check=False).points

    def write(self, mesh=None, *, lattice=None, plot: bool = False, force: bool = False, progress=None) -> dict:
        """Write the deformed mesh of the current values (and the lattice VTK, with ``plot`` the
        picture) as ``ffd deform -o MESH --lattice LATTICE [--plot] [--force]`` does, by the same
        workflow (:func:`ffdcli.app.deform.deform_design`): every output checked before the work, the
        quality gate (nothing written unless ``force``), all outputs written together or none.
        ``mesh=None``: the design file's ``output:``. Returns {kind: path}."""
        report = deform_design(self.run.design, output=mesh, lattice=lattice, plot=plot, force=force,
                               progress=progress, comm=self.comm, run=self.run, P=self.lattice(),
                               remedies=_REMEDIES)
        return report.written

    def _frame_jacobian(self):
        """d(frame)/dv (n_vars, S, 3, 3) at the surface points (zero for points outside the lattice):
        the derivative of :meth:`ffdcli.app.run.DesignRun.surface_frames` (``volume.carry``)."""
        if "dR" not in self._cache:
            run = self.run
            self._cache["dR"] = frame_jacobian(run.components, self.lattices(), run.layout, self.n_vars,
                                               len(self.surface_ids), run.warp_settings.carry, run.single)
        return self._cache["dR"]

    def _frames(self):
        """(S, 3, 3) the frames the warp is given at the current values: where its wall layer
        (:mod:`ffdcli.volume.layer_motion`, nonlinear in them) is linearised."""
        if "frames" not in self._cache:
            self._cache["frames"] = self.run.surface_frames(self.lattice())
        return self._cache["frames"]

    def _design_zone(self):
        """The nodes near the wall of :mod:`ffdcli.quality.design_map` (built once)."""
        if "zone" not in self._static:
            self._static["zone"] = design_zone(self.run)
        return self._static["zone"]

    def design_map_points(self):
        """``(X_map (N, 3), zone (N,) bool)``: the input mesh's nodes near the wall moved by the design's
        own map (the FFD map linearised at the nearest surface node, the quality gate's reference), the
        others where they are in the input; None without a volume mesh that follows the surface."""
        if not self.uses_volume():
            return None
        if "map" not in self._cache:
            zone, run, P = self._design_zone(), self.run, self.lattice()
            X_map = zone.apply(run.prep.mesh.points, run.surface_displacement(P), run.surface_frames(P, "gradient"))
            self._cache["map"] = (X_map, zone.mask)
        return self._cache["map"]

    def design_map_vjp(self, G) -> np.ndarray:
        """(n_vars,) dJ/dv for ``G = dJ/dX_map`` (N, 3): the reverse product of :meth:`design_map_points`
        (the map is affine in the surface displacement and the frames F, both linear in the lattice)."""
        run = self.run
        g_b, g_F = self._design_zone().vjp(G, len(self.surface_ids))
        if run.warp_settings.carry == "gradient":          # the warp's frames are F already
            dF = self._frame_jacobian()
        else:
            if "dF" not in self._cache:
                self._cache["dF"] = frame_jacobian(run.components, self.lattices(), run.layout, self.n_vars,
                                                   len(self.surface_ids), "gradient", run.single)
            dF = self._cache["dF"]
        return self.surface_vjp(g_b) + np.einsum("sij,vsij->v", g_F, dF)

    def mesh_jvp(self, dv, progress=None) -> np.ndarray:
        """(N, 3) motion of every mesh node for ``dv`` (n_vars,), through the volume motion when it is IDW.

        The warp is a fixed linear map of the surface translations and frame parts ``M = F - I``
        (:func:`ffdcli.volume.warp.warp`; its wall layer linearised at the current frames), so the product is the warp of ``(dX_s/dv dv, I + dF/dv dv)``; the
        surface nodes get ``dX_s/dv dv`` exactly. The transpose of :meth:`mesh_vjp`."""
        dv = self._check_dv(dv, "mesh_jvp")
        ids = self.surface_ids
        dXs = self.surface_jvp(dv)
        out = np.zeros((self.run.prep.mesh.n_points, 3))
        if self.uses_volume():

            dR = np.tensordot(dv, self._frame_jacobian(), axes=1)
            out = warp(self._warp_model(progress), dXs, np.eye(3) + dR, progress=progress, at=self._frames())
        out[ids] = dXs
        return out

    def mesh_vjp(self, g, progress=None) -> np.ndarray:
        """dJ/dv for g = dJ/dX at every mesh node (N, 3), through the volume motion when it is IDW.

        dJ/dv = (dX_s/dv)^T [g_s + (dX_v/db)^T g_v] + sum_s <(dX_v/dM_s)^T g_v, dR_s/dv>."""
        mesh = self.run.prep.mesh
        g = as_numbers(g, (mesh.n_points, 3), "mesh_vjp: g", hint="one row per mesh node")
        ids = self.surface_ids
        if not self.uses_volume():
            return self.surface_vjp(g[ids])

        gs = g.copy()
        gs[ids] = 0.0          # surface nodes are placed by the FFD exactly; the warp's own value there is overwritten
        comm = self.comm if self.comm.size > 1 else None      # each rank sums its share of the volume
        g_b, g_M = warp_vjp(self._warp_model(progress), gs, progress=progress, comm=comm, at=self._frames())
        g_b = g_b + g[ids] - gs[ids]
        out = self.surface_vjp(g_b)
        dR = self._frame_jacobian()
        out += np.einsum("sij,vsij->v", g_M, dR)
        return out


