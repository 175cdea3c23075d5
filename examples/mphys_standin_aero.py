"""A stand-in for ADflow (or DAFoam) in MPhys: the solver's surface mesh, and two analytic "aerodynamic"
functions of the surface coordinates where the flow solve would be. Plain NumPy, OpenMDAO and MPhys (no
ffd, no pyGeo), so that one run script runs with either geometry in either environment.

The surface comes from an ``.npz`` with ``points`` (N, 3) and ``triangles`` (T, 3) (ids into points);
under MPI each rank holds a contiguous block of the points (a distributed ``x_aero0``), as a flow solver
holds its partition's. With X the surface points (x chord, y span, z up), N their count, L the reference
length and x_c the reference chord station, the functions are

    cl = 2 pi aoa + c_l / (N L^2) * sum_i -z_i (x_i - x_c)          (nose-up twist raises it)
    cd = c_d0 + k / (N L^2) * sum_i z_i^2 + cl^2 / (pi A)

smooth and nonlinear in X, with exact derivatives (matrix-free, summed over the ranks).
"""

from __future__ import annotations

import numpy as np
import openmdao.api as om
from mphys import Builder, MPhysVariables

X_MESH = MPhysVariables.Aerodynamics.Surface.Mesh.COORDINATES          # x_aero0_mesh
X_AERO = MPhysVariables.Aerodynamics.Surface.COORDINATES              # x_aero
X_AERO0 = MPhysVariables.Aerodynamics.Surface.COORDINATES_INITIAL     # x_aero0
C_L, K_THICK, C_D0, ASPECT = 4.0, 0.5, 0.008, 8.0


def share(n: int, rank: int, size: int) -> tuple[int, int]:
    """This rank's contiguous block of n rows."""
    q, r = divmod(n, size)
    lo = rank * q + min(rank, r)
    return lo, lo + q + (1 if rank < r else 0)


class StandinMesh(om.IndepVarComp):
    """The solver's surface coordinates (this rank's block), with ADflow's two helper methods."""

    def initialize(self):
        self.options.declare("points", desc="(N, 3) every surface point")
        self.options.declare("triangles", desc="(T, 3) the surface's triangles")
        self.options.declare("block", desc="(lo, hi) this rank's rows")

    def setup(self):
        lo, hi = self.options["block"]
        self.add_output(X_MESH, val=self.options["points"][lo:hi].ravel(), distributed=True,
                        tags=["mphys_coordinates"])

    def mphys_get_surface_mesh(self):
        lo, hi = self.options["block"]
        return self.options["points"][lo:hi].copy()

    def mphys_get_triangulated_surface(self):
        """pyGeo's 'point-vector' format: [p0, p1 - p0, p2 - p0] of every triangle."""
        P, T = self.options["points"], self.options["triangles"]
        return [P[T[:, 0]], P[T[:, 1]] - P[T[:, 0]], P[T[:, 2]] - P[T[:, 0]]]


class StandinAero(om.ExplicitComponent):
    """cl and cd of the surface coordinates ``x_aero`` and the angle of attack (see the module docstring)."""

    def initialize(self):
        self.options.declare("n_points", types=int, desc="N: every rank's points")
        self.options.declare("length", types=float, desc="L: reference length")
        self.options.declare("x_ref", types=float, desc="x_c: reference chord station")
        self.options.declare("initial", default=False, desc="also read x_aero0 (MPhys' parallel scenario wiring)")
        self.options.declare("comm", default=None, recordable=False,
                             desc="the ranks the surface is split over (default: the component's)")

    def setup(self):
        self.add_input(X_AERO, shape_by_conn=True, distributed=True, tags=["mphys_coupling"])
        if self.options["initial"]:
            self.add_input(X_AERO0, shape_by_conn=True, distributed=True, tags=["mphys_coordinates"])
        self.add_input("aoa", val=0.0, units="rad", tags=["mphys_input"])
        self.add_output("cl", tags=["mphys_result"])
        self.add_output("cd", tags=["mphys_result"])

    def _scale(self):
        o = self.options
        return 1.0 / (o["n_points"] * o["length"] ** 2)

    def _total(self, local):
        comm = self.options["comm"] or self.comm
        return comm.allreduce(local) if comm.size > 1 else local

    def _sums(self, X):
        s = self._scale()
        return self._total(np.array([np.sum(-X[:, 2] * (X[:, 0] - self.options["x_ref"])), np.sum(X[:, 2] ** 2)]) * s)

    def compute(self, inputs, outputs):
        a, b = self._sums(inputs[X_AERO].reshape(-1, 3))
        cl = 2 * np.pi * inputs["aoa"][0] + C_L * a
        outputs["cl"] = cl
        outputs["cd"] = C_D0 + K_THICK * b + cl ** 2 / (np.pi * ASPECT)

    def compute_jacvec_product(self, inputs, d_inputs, d_outputs, mode):
        X = inputs[X_AERO].reshape(-1, 3)
        s = self._scale()
        a, _ = self._sums(X)
        cl = 2 * np.pi * inputs["aoa"][0] + C_L * a
        dcl = np.zeros_like(X)                           # d cl / dX (this rank's rows)
        dcl[:, 0] = -C_L * s * X[:, 2]
        dcl[:, 2] = -C_L * s * (X[:, 0] - self.options["x_ref"])
        dcd = 2 * cl / (np.pi * ASPECT) * dcl
        dcd[:, 2] += 2 * K_THICK * s * X[:, 2]
        dcl_da, dcd_da = 2 * np.pi, 2 * cl / (np.pi * ASPECT) * 2 * np.pi
        if mode == "fwd":
            if X_AERO in d_inputs:
                dX = d_inputs[X_AERO].reshape(-1, 3)
                local = np.array([np.sum(dcl * dX), np.sum(dcd * dX)])
                tot = self._total(local)
                if "cl" in d_outputs:
                    d_outputs["cl"] += tot[0]
                if "cd" in d_outputs:
                    d_outputs["cd"] += tot[1]
            if "aoa" in d_inputs:
                if "cl" in d_outputs:
                    d_outputs["cl"] += dcl_da * d_inputs["aoa"]
                if "cd" in d_outputs:
                    d_outputs["cd"] += dcd_da * d_inputs["aoa"]
        else:
            gl = d_outputs["cl"][0] if "cl" in d_outputs else 0.0
            gd = d_outputs["cd"][0] if "cd" in d_outputs else 0.0
            if X_AERO in d_inputs:
                d_inputs[X_AERO] += (gl * dcl + gd * dcd).reshape(-1)
            if "aoa" in d_inputs:
                d_inputs["aoa"] += gl * dcl_da + gd * dcd_da


class StandinAeroBuilder(Builder):
    """The builder a run script takes in place of ``ADflowBuilder``."""

    def __init__(self, surface_file, length: float = 1.0, x_ref: float = 0.25, initial: bool = False):
        super().__init__()
        data = np.load(surface_file)
        self.points = np.asarray(data["points"], dtype=float)
        self.triangles = np.asarray(data["triangles"], dtype=np.int64)
        self.length, self.x_ref, self.initial = float(length), float(x_ref), bool(initial)
        self.block = (0, len(self.points))

    def initialize(self, comm):
        self.block = share(len(self.points), comm.rank, comm.size)

    def get_mesh_coordinate_subsystem(self, scenario_name=None):
        return StandinMesh(points=self.points, triangles=self.triangles, block=self.block)

    def get_coupling_group_subsystem(self, scenario_name=None):
        return StandinAero(n_points=len(self.points), length=self.length, x_ref=self.x_ref, initial=self.initial)

    def get_number_of_nodes(self):
        return self.block[1] - self.block[0]

    def get_ndof(self):
        return 3
