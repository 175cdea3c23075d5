"""The Python API for optimisation loops: load a design once, then evaluate it at any values.

>>> from ffdcli.api import DesignModel
>>> model = DesignModel.from_file("configs/rect_twist_linear.yaml")
>>> at = model.evaluate(model.values + 0.1)    # checked once (bounds; MPI: every rank the same)
>>> X = at.surface_points()                    # (S, 3), ordered as model.surface_ids
>>> dJdv = at.surface_vjp(dJdX)                # (n_vars,), never forms the Jacobian
>>> dJdv = at.mesh_vjp(dJdX_all_nodes)         # through the volume-mesh motion as well

The older form holds the values in the face: ``model.set_values(v)`` then ``model.surface_points()``,
``model.mesh_vjp(g)``, ... are ``model.evaluate(v)``'s products. Nothing is re-embedded: the box and
embedding are loaded (or built and cached) once.

The products are the derivative chain's (:mod:`ffdcli.chain`: values -> lattices -> surface; lattices
-> frames; surface and frames -> volume; volume -> quality), each exact:

* surface: ``dX/dv = B dP'/dv`` (:mod:`ffdcli.parameterization.derivatives`);
* volume (``volume.method: idw``): the warp is linear in the surface translations ``b`` and frame
  parts ``M = F - I`` (:func:`ffdcli.volume.warp.warp_vjp` is its transpose). With ``volume.carry:
  gradient`` (the default) the frame of a surface point is the FFD map's deformation gradient
  ``F = J(P') J(P0)^-1``, linear in the control points (``dF = J(dP') J(P0)^-1``). With ``carry:
  rotation`` it is the rotation ``R``, the polar factor of the surface-frame gradient F_s of F
  (:mod:`ffdcli.volume.frames`, with its derivative): ``dR = R Omega`` with ``Omega`` skew solving
  ``Omega U + U Omega = R^T dF - dF^T R`` (``U = R^T F``), i.e. in 3D
  ``(tr(U) I - U) omega = axial(R^T dF - dF^T R)``; in 2D the angle's derivative in closed form.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ffdcli.api.constraints import (
    ConstraintSet,
    constraint_jacobian_arrays,
    constraints_table,
    variables_table,
    write_constraint_jacobian,
)
from ffdcli.api.pointsets import ComponentPoints
from ffdcli.app.deform import deform_design
from ffdcli.app.deformation import Deformation, deform
from ffdcli.app.run import load_run
from ffdcli.app.write import write_outputs
from ffdcli.design import load_design
from ffdcli.errors import InputError
from ffdcli.io.outputs import plan_outputs
from ffdcli.mesh.numbers import as_numbers
from ffdcli.parallel.comm import SerialComm
from ffdcli.parameterization.changes import design_units
from ffdcli.parameterization.components import variable_bounds
from ffdcli.quality.gate import Remedies

#: How the API's user overrides the quality gate (the gate states the rule; :meth:`write` names its argument).
REMEDIES = Remedies(deform_anyway=", or pass force=True to deform it anyway",
                    write_anyway=" (force=True writes it anyway)", forced=" (force=True)")


@dataclass(frozen=True, eq=False)
class DesignPoint:
    """A design model at some values: every product of the chain there (:meth:`DesignModel.evaluate`).

    Nothing is stored on the model: the chain keeps what it computed for these values (with their
    hash) and reuses it while they repeat."""

    model: DesignModel
    values: np.ndarray

    @property
    def chain(self):
        return self.model.chain

    def _dv(self, dv, what: str) -> np.ndarray:
        return as_numbers(dv, (self.model.n_vars,), f"{what}: dv", hint="one value per design variable, in names order")

    # -- lattices and surface ---------------------------------------------------------------------
    def lattices(self) -> list[np.ndarray]:
        """Deformed control points of every component (file order)."""
        return list(self.chain.lattices.forward(self.values))

    def lattice_jacobian(self) -> np.ndarray:
        """dP'/dv (n_ctrl*3, n_vars); several components: block diagonal (``basis`` column order)."""
        return self.chain.lattices.jacobian(self.values)

    def surface_points(self) -> np.ndarray:
        """(S, 3) deformed surface points (the rows of ``surface_ids``)."""
        return self.chain.surface_points(self.values)

    def surface_jvp(self, dv) -> np.ndarray:
        """(S, 3) surface motion dX/dv @ dv for ``dv`` (n_vars,)."""
        return self.chain.surface_jvp(self.values, self._dv(dv, "surface_jvp"))

    def surface_vjp(self, g) -> np.ndarray:
        """(n_vars,) dJ/dv for g = dJ/dX at the surface points (S, 3)."""
        g = as_numbers(g, (len(self.chain.surface_ids), 3), "surface_vjp: g",
                       hint="one row per surface point, surface_ids order")
        return self.chain.surface_vjp(self.values, g)

    # -- every mesh node ---------------------------------------------------------------------------
    def mesh_points(self, progress=None) -> np.ndarray:
        """(N, 3) every mesh node as ``ffd deform`` places it."""
        return self.chain.mesh_points(self.values, progress).copy()

    def mesh_jvp(self, dv, progress=None) -> np.ndarray:
        """(N, 3) motion of every mesh node for ``dv`` (n_vars,), through the volume motion when it is IDW:
        the warp of ``(dX_s/dv dv, I + dF/dv dv)``, the surface nodes ``dX_s/dv dv`` exactly. The
        transpose of :meth:`mesh_vjp`."""
        return self.chain.mesh_jvp(self.values, self._dv(dv, "mesh_jvp"), progress)

    def mesh_vjp(self, g, progress=None) -> np.ndarray:
        """dJ/dv for g = dJ/dX at every mesh node (N, 3), through the volume motion when it is IDW:
        dJ/dv = (dX_s/dv)^T [g_s + (dX_v/db)^T g_v] + sum_s <(dX_v/dM_s)^T g_v, dF_s/dv>."""
        g = as_numbers(g, (self.model.run.prep.mesh.n_points, 3), "mesh_vjp: g", hint="one row per mesh node")
        return self.chain.mesh_vjp(self.values, g, progress)

    def design_map_points(self):
        """``(X_map (N, 3), zone (N,) bool)``: the input mesh's nodes near the wall moved by the design's
        own map (the FFD map linearised at the nearest surface node, the quality gate's reference), the
        others where they are in the input; None without a volume mesh that follows the surface."""
        return self.chain.design_map(self.values)

    def design_map_vjp(self, G) -> np.ndarray:
        """(n_vars,) dJ/dv for ``G = dJ/dX_map`` (N, 3): the reverse product of :meth:`design_map_points`."""
        return self.chain.design_map_vjp(self.values, G)

    # -- point sets --------------------------------------------------------------------------------
    def points(self, name: str) -> np.ndarray:
        """(k, 3) the points of set ``name`` moved by the design."""
        dPs = [P - c.P0 for P, c in zip(self.chain.lattices.forward(self.values), self.chain.components, strict=True)]
        return self.model.point_set(name).points(dPs)

    def points_jvp(self, name: str, dv) -> np.ndarray:
        """(k, 3) dX/dv @ dv for the points of set ``name`` and ``dv`` (n_vars,)."""
        ps = self.model.point_set(name)
        return ps.motion(self.chain.lattices.jvp(self.values, self._dv(dv, f"points_jvp({name!r})")))

    def points_vjp(self, name: str, g) -> np.ndarray:
        """(n_vars,) dJ/dv for ``g`` = dJ/dX (k, 3) at the points of set ``name``. Under MPI a
        collective: each rank passes its own points' ``g`` and every rank gets the sum over all ranks'
        points (the chain's reduction; forward products stay local)."""
        ps = self.model.point_set(name)
        return self.chain.share.sum(lambda: self.chain.lattices.vjp(self.values, ps.pull(g)))

    # -- the deformation as ffd deform makes it -----------------------------------------------------
    def deform(self, *, recover: bool = True, check: bool = True, progress=None) -> Deformation:
        """:func:`ffdcli.app.deformation.deform` at these values: every node, the quality gate's report
        (and, with ``recover``, its recovery attempts); nothing written."""
        P = self.chain.lattices.forward(self.values)
        return deform(self.model.run, P=P[0] if self.chain.single else list(P), recover=recover, check=check,
                      progress=progress)

    # -- constraints -------------------------------------------------------------------------------
    def constraint_values(self) -> np.ndarray:
        """(C,) the constraint items."""
        return self.model.constraint_set.values(self.chain, self.values, self.model.names)

    def constraint_jacobian(self) -> np.ndarray:
        """(C, n_vars) exact d(constraint item)/d(design variable)."""
        return self.model.constraint_set.jacobian(self.chain, self.values, self.model.names)


def _held(name: str):
    """A method of :class:`DesignModel` that is :class:`DesignPoint`'s ``name`` at the values held in the
    face (:meth:`DesignModel.set_values`): the older form of the API."""
    of_point = getattr(DesignPoint, name)

    @functools.wraps(of_point)
    def method(self, *args, **kwargs):
        return of_point(self._here, *args, **kwargs)

    method.__doc__ = f"{(of_point.__doc__ or '').strip()}\n\nAt the values held (:meth:`set_values`)."
    return method


class DesignModel:
    """A design prepared for repeated evaluation: values in, points and derivatives out.

    Attributes
    ----------
    run : ffdcli.app.run.DesignRun
        The design file with its box (loaded from the cache or built once) and its changes.
    chain : ffdcli.chain.DesignChain
        The derivative chain over the run's components and mesh.
    names : list of str
        (n_vars,) design-variable names, ``c<index>.<kind>[<j>]`` as in ``ffd grad``.
    values : ndarray, shape (n_vars,)
        The values the older methods (:meth:`surface_points`, ...) are evaluated at (:meth:`set_values`).
    bounds : ffdcli.parameterization.bounds.Bounds
        Natural (open) and user (``bounds:``, closed) bounds; :attr:`lower` and :attr:`upper`.
    """

    def __init__(self, run, comm=None):
        """``comm`` (:mod:`ffdcli.parallel.comm`; default the run's, else serial): under MPI every rank
        holds the same model (names, values, surface); point sets are per rank (each adds its own
        mesh partition's points) and their reverse products are summed over the ranks."""
        self.run = run
        self.comm = comm or getattr(run, "comm", None) or SerialComm()
        self.chain = run.chain
        self.names, self.values = run.variables()
        self.units = [u for c in run.components for u in design_units(list(c.changes))]
        self.bounds = variable_bounds(run.components, run.design)
        self.constraint_set = ConstraintSet(run)
        self._point_sets: dict[str, ComponentPoints] = {}

    @classmethod
    def from_file(cls, path, overrides=(), *, cache_dir=None, use_cache: bool = True,
                  progress=None, comm=None) -> DesignModel:
        """Load a design file (with ``--set`` style ``overrides``), its box from the cache or built.

        Parameters
        ----------
        path : str or Path
            The design file (YAML).
        overrides : sequence of str
            ``KEY=VALUE`` items as ``ffd deform --set``.
        cache_dir : str or Path, optional
            Where the box cache lives (default: beside the mesh).
        use_cache : bool
            False neither reads nor writes the cache.
        progress : callable, optional
            A progress factory (:mod:`ffdcli.progress`).
        comm : ffdcli.parallel.comm.SerialComm, optional
            MPI communicator: rank 0 reads the mesh and the cache and broadcasts them.
        """
        design = load_design(path, overrides=overrides)
        return cls(load_run(design, cache_dir=cache_dir, use_cache=use_cache, progress=progress, comm=comm),
                   comm=comm)

    # -- values ------------------------------------------------------------------------------
    @property
    def n_vars(self) -> int:
        """Number of design variables."""
        return len(self.names)

    @property
    def lower(self) -> np.ndarray:
        """(n_vars,) lower bounds (``-inf``: none); natural bounds are open (a factor must be > 0)."""
        return self.bounds.lower

    @property
    def upper(self) -> np.ndarray:
        """(n_vars,) upper bounds (``inf``: none)."""
        return self.bounds.upper

    def checked(self, values) -> np.ndarray:
        """``values`` (an array (n_vars,) in ``names`` order, or {name: value} over :attr:`values`) checked:
        :class:`~ffdcli.errors.InputError` naming the variable for NaN, inf, a value out of its bounds
        (:attr:`lower`, :attr:`upper`; chord and span factors > 0), an unknown name or a wrong length;
        under MPI every rank must give the same values (the chain's agreement)."""
        if isinstance(values, dict):
            unknown = [k for k in values if k not in self.names]
            if unknown:
                raise InputError(f"unknown design variable(s) {', '.join(unknown)}; the variables are "
                                 f"{', '.join(self.names)}")
            v = self.values.copy()
            for k, x in values.items():
                v[self.names.index(k)] = as_numbers(x, (), f"set_values: {k}")
            values = v
        return self.chain.share.same_values(values, self.bounds.check)

    def evaluate(self, values) -> DesignPoint:
        """The design at ``values`` (checked as :meth:`checked`): its products, nothing set on the model."""
        return DesignPoint(self, self.checked(values).copy())

    def at(self, values) -> DesignPoint:
        """The design at ``values`` the caller has checked already (:meth:`evaluate` without the check)."""
        return DesignPoint(self, np.asarray(values, dtype=float))

    def set_values(self, values) -> None:
        """Hold new values in the face (the older form; :meth:`evaluate` is the one without state). The
        model is unchanged when they are refused (:meth:`checked`)."""
        self.values = self.checked(values).copy()

    @property
    def _here(self) -> DesignPoint:
        return DesignPoint(self, self.values)

    # -- the products at the held values (the older form) -----------------------------------------
    lattices = _held("lattices")
    surface_points = _held("surface_points")
    lattice_jacobian = _held("lattice_jacobian")
    surface_jvp = _held("surface_jvp")
    surface_vjp = _held("surface_vjp")
    mesh_points = _held("mesh_points")
    mesh_jvp = _held("mesh_jvp")
    mesh_vjp = _held("mesh_vjp")
    design_map_points = _held("design_map_points")
    design_map_vjp = _held("design_map_vjp")
    points = _held("points")
    points_jvp = _held("points_jvp")
    points_vjp = _held("points_vjp")
    constraint_values = _held("constraint_values")
    constraint_jacobian = _held("constraint_jacobian")

    @property
    def surface_ids(self) -> np.ndarray:
        """(S,) mesh node ids of the surface points (every component's, sorted), in the row order of
        :meth:`surface_points`."""
        return self.chain.surface_ids

    @property
    def basis(self):
        """B (S, n_ctrl) CSR: surface displacement = B @ (P' - P0).reshape(-1, 3).

        Several components: block diagonal, the columns of the components' lattices one after the
        other (file order), the rows as ``surface_ids``."""
        return self.chain.surface.block_basis()

    def lattice(self):
        """Deformed control points (n, m, l, 3); several components: the list of every component's."""
        Ps = self.lattices()
        return Ps[0] if self.chain.single else Ps

    def jacobian_factors(self):
        """(B, D): dX/dv = B @ D reshaped, B (S, n_ctrl) sparse, D (n_ctrl*3, n_vars) dense.

        The product for point s, coordinate c, variable v is ``(B @ D.reshape(n_ctrl, 3*n_vars))
        [s, c*n_vars + v]``; :func:`ffdcli.parameterization.derivatives.surface_jacobian` forms it."""
        return self.basis, self.lattice_jacobian()

    def uses_volume(self) -> bool:
        """True when the volume mesh follows the surface (``volume.method: idw`` on a volume mesh)."""
        return self.chain.volume.moves

    def write(self, mesh=None, *, lattice=None, plot: bool = False, force: bool = False, progress=None,
              values=None) -> dict:
        """Write the deformed mesh of the held values (or ``values``) (and the lattice VTK, with ``plot``
        the picture) as ``ffd deform -o MESH --lattice LATTICE [--plot] [--force]`` does, by the same
        workflow (:func:`ffdcli.app.deform.deform_design`): every output checked before the work, the
        quality gate (nothing written unless ``force``), all outputs written together or none.
        ``mesh=None``: the design file's ``output:``. Returns {kind: path}."""
        at = self._here if values is None else self.evaluate(values)
        P = at.lattices()
        report = deform_design(self.run.design, output=mesh, lattice=lattice, plot=plot, force=force,
                               progress=progress, comm=self.comm, run=self.run, P=P[0] if self.chain.single else P,
                               remedies=REMEDIES)
        return report.written

    def write_mesh(self, result: Deformation, path) -> dict:
        """Write the mesh of a :class:`~ffdcli.app.deformation.Deformation` (:meth:`DesignPoint.deform`) to
        ``path`` in the format of its suffix, whole or not at all (the input is never overwritten).
        Returns {kind: path}."""
        plan = plan_outputs([("mesh", Path(path), False, "mesh")], inputs=(self.run.design.mesh,))
        return write_outputs(self.run, result, plan=plan)

    @property
    def design(self):
        """The loaded design file (:class:`ffdcli.design.Design`)."""
        return self.run.design

    @property
    def component_names(self) -> list[str]:
        """Each component's name, file order (``""``: the single-component form)."""
        return [c.name for c in self.run.components]

    @property
    def n_points(self) -> int:
        """N, the mesh's nodes (the rows of :meth:`mesh_points` and of ``mesh_vjp``'s ``g``)."""
        return self.run.prep.mesh.n_points

    # -- point sets --------------------------------------------------------------------------------
    def add_points(self, name: str, X, progress=None) -> dict:
        """Embed points ``X`` (k, 3) in the design's lattices under ``name`` (replacing a set of that name).

        Returns ``{"points": k, "outside": count, "outside_ids": [...], "outside_worst": distance}``:
        points outside every lattice are kept and never move."""
        cp = ComponentPoints.embed(str(name), self.run.components, X, progress=progress)
        self._point_sets[str(name)] = cp
        return {"points": cp.n_points, **cp.outside_report()}

    @property
    def point_sets(self) -> list[str]:
        """Names of the point sets added with :meth:`add_points`, in order."""
        return list(self._point_sets)

    def point_set(self, name: str) -> ComponentPoints:
        """The :class:`~ffdcli.api.pointsets.ComponentPoints` named ``name``."""
        try:
            return self._point_sets[name]
        except KeyError:
            have = ", ".join(self._point_sets) or "(none)"
            raise InputError(f"no point set named {name!r}; the point sets are: {have}") from None

    # -- constraints -------------------------------------------------------------------------------
    @property
    def constraints(self) -> list:
        """The constraint objects of the design file's ``constraints:`` (:mod:`ffdcli.constraints`),
        built once on the baseline surface and lattice; several components: every component's, in
        component order (see :attr:`constraint_groups`)."""
        return self.constraint_set.objects

    @property
    def constraint_groups(self) -> list[tuple[int, list]]:
        """``[(component index, its constraint objects)]``: each component's ``constraints:`` built on its
        own box and surface (the single-component form: one group, the file's ``constraints:``)."""
        return self.constraint_set.groups

    def set_constraints(self, specs, component: int = 0) -> None:
        """Replace the constraints of one component (default the first, by index) by a ``constraints:``
        list. Checked as a design file's ``constraints:`` is (the schema's words, the key path): an
        :class:`~ffdcli.errors.InputError` for a bad item or a component that does not exist."""
        self.constraint_set = self.constraint_set.replaced(specs, component)

    @property
    def constraint_names(self) -> list[str]:
        """(C,) ``k<index>.<kind>[<j>]`` of every constraint item (``<component>.k...`` with components)."""
        return self.constraint_set.names

    @property
    def constraint_lower(self) -> np.ndarray:
        """(C,) lower bounds of the constraint items (``-inf``: none)."""
        return self.constraint_set.bounds[0]

    @property
    def constraint_upper(self) -> np.ndarray:
        """(C,) upper bounds of the constraint items (``inf``: none)."""
        return self.constraint_set.bounds[1]

    # -- reports (what ffd vars / ffd constraints print: :mod:`ffdcli.api.constraints`) ----------------
    variables_table = variables_table
    constraints_table = constraints_table
    constraint_jacobian_arrays = constraint_jacobian_arrays
    write_constraint_jacobian = write_constraint_jacobian


def constraints_report(run, mesh_points: np.ndarray | None = None) -> list[dict]:
    """:meth:`DesignModel.constraints_table` of a :class:`ffdcli.app.run.DesignRun` (``ffd deform --json``).

    ``mesh_points``: (N, 3) the mesh as deformed already (``mesh_quality`` reads it instead of
    deforming the mesh once more)."""
    return DesignModel(run).constraints_table(mesh_points=mesh_points)
