"""The Python API for optimisation loops: load a design once, then set values and get products.

>>> from ffdcli.api import DesignModel
>>> model = DesignModel.from_file("configs/rect_twist_linear.yaml")
>>> model.names[:2], model.values[:2]
>>> model.set_values(model.values + 0.1)
>>> X = model.surface_points()                 # (S, 3), ordered as model.surface_ids
>>> dJdv = model.surface_vjp(dJdX)             # (n_vars,), never forms the Jacobian
>>> dJdv = model.mesh_vjp(dJdX_all_nodes)      # through the volume-mesh motion as well

Nothing is re-embedded: the box and embedding are loaded (or built and cached) once.

Derivatives are exact (no finite differences):

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

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from ffdcli.app.pipeline import (
    deform,
    frame_gradient_inputs,
    full3,
    is_surface_mesh,
    load_run,
    volume_method,
    write_outputs,
)
from ffdcli.constraints.geometric import (
    ConstraintInputs,
    build_constraints,
    constraint_bounds,
    constraint_names,
    evaluate,
    satisfied,
)
from ffdcli.design import load_design
from ffdcli.errors import InputError
from ffdcli.io.atomic import atomic_write
from ffdcli.io.formats.sensitivity import Sensitivity, read_sensitivity
from ffdcli.io.outputs import plan_deform
from ffdcli.lattice.lattice import derivatives
from ffdcli.lattice.pointset import PointSet
from ffdcli.parallel.comm import SerialComm
from ffdcli.parameterization.bounds import make_bounds
from ffdcli.parameterization.changes import design_bounds, design_units
from ffdcli.parameterization.derivatives import surface_jvp, vjp
from ffdcli.quality.gate import enforce
from ffdcli.volume.frames import (  # noqa: F401  (re-exported: the API's names of PR 7)
    planar_rotation_derivative,
    polar_rotation_derivative,
    rotations_from_deformation_gradient,
    surface_frame_gradient,
    surface_frame_gradient_jvp,
)
from ffdcli.volume.warp import warp, warp_vjp


class DesignModel:
    """A design prepared for repeated evaluation: values in, points and derivatives out.

    Attributes
    ----------
    run : ffdcli.app.pipeline.DesignRun
        The design file with its box (loaded from the cache or built once) and its changes.
    names : list of str
        (n_vars,) design-variable names, ``c<index>.<kind>[<j>]`` as in ``ffd grad``.
    values : ndarray, shape (n_vars,)
        Their current values (degrees for angles, factors, mesh units for offsets and shape).
    bounds : ffdcli.parameterization.bounds.Bounds
        Natural (open) and user (``bounds:``, closed) bounds; :attr:`lower` and :attr:`upper`.
    """

    def __init__(self, run, comm=None):
        """``comm`` (:mod:`ffdcli.parallel.comm`; default the run's, else serial): under MPI every rank
        holds the same model (names, values, surface); point sets are per rank (each adds its own
        mesh partition's points) and their reverse products are summed over the ranks."""

        self.run = run
        self.comm = comm or getattr(run, "comm", None) or SerialComm()
        self.names, self.values = run.variables()
        self.units = [u for c in run.components for u in design_units(list(c.changes))]
        natural = np.concatenate([design_bounds(c.P0, c.box.frame, list(c.changes)) for c in run.components]) \
            if run.components else np.zeros((0, 2))
        design = run.design
        spec = (getattr(design, "data", None) or {}).get("bounds")
        error = getattr(design, "error", None)
        self.bounds = make_bounds(self.names, natural, spec, values=self.values, error=error)
        self._B = None
        self._cache = {}            # what depends on the values (cleared by set_values)
        self._static = {}           # what does not (constraint geometry on the baseline)
        self._point_sets = {}

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

    def set_values(self, values) -> None:
        """New values of the design variables: an array (n_vars,) in ``names`` order, or {name: value}.

        Raises :class:`~ffdcli.errors.InputError` naming the variable for NaN, inf, a value out of its
        bounds (:attr:`lower`, :attr:`upper`; chord and span factors > 0), an unknown name or a wrong
        length; the model is then unchanged."""
        if isinstance(values, dict):
            unknown = [k for k in values if k not in self.names]
            if unknown:
                raise InputError(f"unknown design variable(s) {', '.join(unknown)}; the variables are "
                                 f"{', '.join(self.names)}")
            v = self.values.copy()
            for k, x in values.items():
                v[self.names.index(k)] = float(x)
            values = v
        values = self.comm.run(self.bounds.check, values)     # a refusal on one rank stops every rank
        if self.comm.size > 1:      # one design on every rank, or the partitions disagree silently
            ranks = self.comm.allgather(values.tobytes())
            if any(r != ranks[0] for r in ranks):
                raise InputError("set_values: the MPI ranks were given different design values; every rank "
                                 "must set the same values")
        self.run.set_values(values)
        self.values = values.copy()
        self._cache.clear()

    def _check_dv(self, dv, what: str) -> np.ndarray:
        dv = np.asarray(dv, dtype=float)
        if dv.shape != (self.n_vars,):
            raise InputError(f"{what}: dv must have shape ({self.n_vars},) (one value per design variable, "
                             f"in names order), got {dv.shape}")
        return dv

    # -- point sets ----------------------------------------------------------------------------
    def add_points(self, name: str, X, progress=None) -> dict:
        """Embed points ``X`` (k, 3) in the design's lattice under ``name`` (replacing a set of that name).

        Returns ``{"points": k, "outside": count, "outside_ids": [...], "outside_worst": distance}``:
        points outside the lattice are kept and never move."""

        ps = PointSet.embed(str(name), self.run.box, X, progress=progress)
        self._point_sets[str(name)] = ps
        return {"points": ps.n_points, **ps.outside_report()}

    @property
    def point_sets(self) -> list[str]:
        """Names of the point sets added with :meth:`add_points`, in order."""
        return list(self._point_sets)

    def point_set(self, name: str):
        """The :class:`ffdcli.lattice.pointset.PointSet` named ``name``."""
        try:
            return self._point_sets[name]
        except KeyError:
            have = ", ".join(self._point_sets) or "(none)"
            raise InputError(f"no point set named {name!r}; the point sets are: {have}") from None

    def _dP(self) -> np.ndarray:
        return (self.lattice() - self.run.P0).reshape(-1, 3)

    def points(self, name: str) -> np.ndarray:
        """(k, 3) the points of set ``name`` moved by the current design."""
        return self.point_set(name).points(self._dP())

    def points_jvp(self, name: str, dv) -> np.ndarray:
        """(k, 3) dX/dv @ dv for the points of set ``name`` and ``dv`` (n_vars,)."""
        ps = self.point_set(name)
        return ps.jvp(self.lattice_jacobian(), self._check_dv(dv, f"points_jvp({name!r})"))

    def points_vjp(self, name: str, g) -> np.ndarray:
        """(n_vars,) dJ/dv for ``g`` = dJ/dX (k, 3) at the points of set ``name``.

        Under MPI (``comm``) a collective: each rank passes its own points' ``g`` and every rank gets
        the sum over all ranks' points (forward products, :meth:`points_jvp`, stay local)."""
        local = self.comm.run(self.point_set(name).vjp, self.lattice_jacobian(), g)
        return self.comm.allreduce_sum(np.asarray(local, dtype=np.float64))

    # -- constraints ---------------------------------------------------------------------------
    @property
    def constraints(self) -> list:
        """The constraint objects of the design file's ``constraints:`` (:mod:`ffdcli.constraints.geometric`),
        built once on the baseline surface and lattice; several components: every component's, in
        component order (see :attr:`constraint_groups`)."""
        return [c for _, group in self.constraint_groups for c in group]

    @property
    def constraint_groups(self) -> list[tuple[int, list]]:
        """``[(component index, its constraint objects)]``: each component's ``constraints:`` built on its
        own box and surface (the single-component form: one group, the file's ``constraints:``)."""
        if "constraints" not in self._static:
            data = getattr(self.run.design, "data", None) or {}
            if "components" in data:
                specs = [item.get("constraints") or [] for item in data["components"]]
            else:
                specs = [data.get("constraints") or []]
            self._static["constraints"] = [(c, self._build_constraints(s, c)) for c, s in enumerate(specs)]
        return self._static["constraints"]

    def set_constraints(self, specs, component: int = 0) -> None:
        """Replace the constraints of one component (default the first) by a ``constraints:`` list."""
        groups = [g for g in self.constraint_groups if g[0] != component]
        groups.append((component, self._build_constraints(specs, component)))
        self._static["constraints"] = sorted(groups, key=lambda g: g[0])
        self._cache.clear()

    def _build_constraints(self, specs, c: int = 0) -> list:

        comp = self.run.components[c]
        design_error = getattr(self.run.design, "error", None)
        error = None if design_error is None else (lambda message, key: design_error(message, comp.spec.subkey(key)))
        return build_constraints(specs, comp.box, comp.prep.surface, list(comp.changes), error=error)

    @property
    def constraint_names(self) -> list[str]:
        """(C,) ``k<index>.<kind>[<j>]`` of every constraint item (``<component>.k...`` with components)."""

        return [self.run.components[c].spec.prefix + n for c, group in self.constraint_groups
                for n in constraint_names(group)]

    @property
    def constraint_lower(self) -> np.ndarray:
        """(C,) lower bounds of the constraint items (``-inf``: none)."""

        return constraint_bounds(self.constraints)[0]

    @property
    def constraint_upper(self) -> np.ndarray:
        """(C,) upper bounds of the constraint items (``inf``: none)."""

        return constraint_bounds(self.constraints)[1]

    def _constraint_inputs(self, c: int = 0):
        """What component ``c``'s constraints read: its lattice, its rows of dP'/dv (every variable's
        column), its surface points and basis."""

        if self.run.single:
            emb = self.run.prep.embedding
            rmatvec = emb.rmatvec if self.run.box.dim == 3 else None       # 3D: core = mesh coordinates
            return ConstraintInputs(self.lattice(), self.run.P0, self.values, self.lattice_jacobian,
                                    self.surface_points, lambda: self.basis, rmatvec)
        comp, lay = self.run.components[c], self.run.layout
        o0, o1, rows = lay.ctrl_offsets[c], lay.ctrl_offsets[c + 1], lay.rows[c]
        emb = comp.prep.embedding
        return ConstraintInputs(self.lattices()[c], comp.P0, self.values,
                                lambda: self.lattice_jacobian()[3 * o0:3 * o1],
                                lambda: self.surface_points()[rows],
                                lambda: emb.basis_matrix().tocsr(), emb.rmatvec if comp.box.dim == 3 else None)

    def _evaluate_constraints(self, jacobian: bool):

        vals, jacs = [np.zeros(0)], [np.zeros((0, self.n_vars))]
        for c, group in self.constraint_groups:
            v, j = evaluate(group, self._constraint_inputs(c), jacobian=jacobian)
            vals.append(v)
            if jacobian:
                jacs.append(j)
        return np.concatenate(vals), (np.concatenate(jacs, axis=0) if jacobian else None)

    def constraint_values(self) -> np.ndarray:
        """(C,) the constraint items at the current values."""
        if "cv" not in self._cache:
            self._cache["cv"] = self._evaluate_constraints(False)[0]
        return self._cache["cv"]

    def constraint_jacobian(self) -> np.ndarray:
        """(C, n_vars) exact d(constraint item)/d(design variable) at the current values."""
        if "cj" not in self._cache:
            self._cache["cv"], self._cache["cj"] = self._evaluate_constraints(True)
        return self._cache["cj"]

    # -- reports (what ffd vars / ffd constraints print) ------------------------------------------
    def variables_table(self) -> list[dict]:
        """One ``{"name", "value", "unit", "lower", "upper"}`` per design variable (None: no bound)."""
        lo, hi = self.lower, self.upper
        return [{"name": n, "value": float(v), "unit": u, "lower": _finite_or_none(a), "upper": _finite_or_none(b)}
                for n, v, u, a, b in zip(self.names, self.values, self.units, lo, hi, strict=True)]

    def constraints_table(self) -> list[dict]:
        """One ``{"name", "value", "lower", "upper", "satisfied"}`` per constraint item (None: no bound)."""

        v = self.constraint_values()
        lo, hi = self.constraint_lower, self.constraint_upper
        ok = satisfied(v, lo, hi)
        return [{"name": n, "value": float(x), "lower": _finite_or_none(a), "upper": _finite_or_none(b),
                 "satisfied": bool(s)}
                for n, x, a, b, s in zip(self.constraint_names, v, lo, hi, ok, strict=True)]

    def constraint_jacobian_arrays(self) -> dict[str, np.ndarray]:
        """The arrays of ``ffd constraints --jacobian FILE.npz`` (SPEC): ``names`` (C), ``variables`` (V),
        ``values`` (C), ``lower`` (C), ``upper`` (C) (``-inf``/``inf``: none) and ``jacobian`` (C x V)."""
        return dict(names=np.array(self.constraint_names, dtype=str), variables=np.array(self.names, dtype=str),
                    values=self.constraint_values(), lower=self.constraint_lower, upper=self.constraint_upper,
                    jacobian=self.constraint_jacobian())

    def write_constraint_jacobian(self, path) -> None:
        """Write :meth:`constraint_jacobian_arrays` as ``.npz``, whole or not at all."""

        arrays = self.constraint_jacobian_arrays()
        with atomic_write(path, "wb") as f:
            np.savez(f, **arrays)

    # -- evaluation --------------------------------------------------------------------------
    @property
    def surface_ids(self) -> np.ndarray:
        """(S,) mesh node ids of the surface points (every component's, sorted), in the row order of
        :meth:`surface_points`."""
        return self.run.surface_ids

    @property
    def basis(self):
        """B (S, n_ctrl) CSR: surface displacement = B @ (P' - P0).reshape(-1, 3).

        Several components: block diagonal, the columns of the components' lattices one after the
        other (file order), the rows as ``surface_ids``."""
        if self._B is None:

            comps = self.run.components
            if len(comps) == 1:
                self._B = comps[0].prep.embedding.basis_matrix().tocsr()
            else:
                lay = self.run.layout
                S, K = len(lay.surface_ids), lay.ctrl_offsets[-1]
                r, c, d = [], [], []
                for comp, rows, off in zip(comps, lay.rows, lay.ctrl_offsets, strict=False):
                    b = comp.prep.embedding.basis_matrix().tocoo()
                    r.append(rows[b.row])
                    c.append(b.col + off)
                    d.append(b.data)
                self._B = sp.csr_matrix((np.concatenate(d), (np.concatenate(r), np.concatenate(c))), shape=(S, K))
        return self._B

    def lattices(self) -> list[np.ndarray]:
        """Deformed control points of every component (file order)."""
        if "Ps" not in self._cache:
            self._cache["Ps"] = self.run.lattices_after()
        return self._cache["Ps"]

    def lattice(self):
        """Deformed control points (n, m, l, 3); several components: the list of every component's."""
        Ps = self.lattices()
        return Ps[0] if self.run.single else Ps

    def surface_points(self) -> np.ndarray:
        """(S, 3) deformed surface points (the rows of ``surface_ids``)."""
        X0 = self.run.prep.mesh.points[self.surface_ids] if not self.run.single else self.run.prep.surface.points
        return X0 + self.run.surface_displacement(self.lattices())

    def lattice_jacobian(self) -> np.ndarray:
        """dP'/dv (n_ctrl*3, n_vars); several components: block diagonal (``basis`` column order)."""
        if "J" not in self._cache:
            comps = self.run.components
            blocks = [c.lattice_jacobian() for c in comps]
            if len(blocks) == 1:
                self._cache["J"] = blocks[0]
            else:
                lay = self.run.layout
                J = np.zeros((3 * lay.ctrl_offsets[-1], lay.var_offsets[-1]))
                for blk, c0, v0 in zip(blocks, lay.ctrl_offsets, lay.var_offsets, strict=False):
                    J[3 * c0:3 * c0 + blk.shape[0], v0:v0 + blk.shape[1]] = blk
                self._cache["J"] = J
        return self._cache["J"]

    def jacobian_factors(self):
        """(B, D): dX/dv = B @ D reshaped, B (S, n_ctrl) sparse, D (n_ctrl*3, n_vars) dense.

        The product for point s, coordinate c, variable v is ``(B @ D.reshape(n_ctrl, 3*n_vars))
        [s, c*n_vars + v]``; :func:`ffdcli.parameterization.derivatives.surface_jacobian` forms it."""
        return self.basis, self.lattice_jacobian()

    def surface_jvp(self, dv) -> np.ndarray:
        """(S, 3) surface motion dX/dv @ dv for ``dv`` (n_vars,)."""

        return surface_jvp(self.basis, self.lattice_jacobian(), self._check_dv(dv, "surface_jvp"))

    def surface_vjp(self, g) -> np.ndarray:
        """(n_vars,) dJ/dv for g = dJ/dX at the surface points (S, 3)."""

        g = np.asarray(g, dtype=float)
        if g.shape != (len(self.surface_ids), 3):
            raise InputError(f"surface_vjp: g must have shape ({len(self.surface_ids)}, 3) (one row per "
                             f"surface point, surface_ids order), got {g.shape}")
        # one component: the embedding's compiled B.T @ g (its rows are the surface points)
        B = self.run.components[0].prep.embedding if self.run.single else self.basis
        return vjp(B, g, self.lattice_jacobian())

    # -- whole mesh ---------------------------------------------------------------------------
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
        picture) as ``ffd deform -o MESH --lattice LATTICE [--plot] [--force]`` does: every output
        checked before the work (:func:`ffdcli.io.outputs.plan_deform`), the quality gate
        (:func:`ffdcli.quality.gate.enforce`: nothing written unless ``force``), all outputs
        written together or none. ``mesh=None``: the design file's ``output:``. Returns {kind: path}."""

        design = self.run.design
        plan = plan_deform(design, mesh=mesh, lattice=lattice, plot=plot)
        result = deform(self.run, P=self.lattice(), progress=progress)
        enforce(result.quality, mesh_path=design.mesh, design_path=design.path, force=force)
        return self.comm.root_then_bcast(write_outputs, self.run, result, plan=plan, progress=progress)

    def _frame_jacobian(self):
        """d(frame)/dv (n_vars, S, 3, 3) at the surface points (zero for points outside the lattice):
        the derivative of :meth:`ffdcli.app.pipeline.DesignRun.surface_frames` (``volume.carry``)."""
        if "dR" not in self._cache:
            self._cache["dR"] = self._frame_jacobian_uncached()
        return self._cache["dR"]

    def _frame_jacobian_uncached(self):

        run = self.run
        lay = run.layout
        gradient = run.warp_settings.carry == "gradient"
        out = np.zeros((self.n_vars, len(self.surface_ids), 3, 3))
        for c, (comp, P1) in enumerate(zip(run.components, self.lattices(), strict=True)):
            box, emb = comp.box, comp.prep.embedding
            rows = lay.rows[c] if not run.single else np.arange(len(emb.inside))
            ins, F, n0 = frame_gradient_inputs(comp, P1)
            nv = lay.var_offsets[c + 1] - lay.var_offsets[c]
            if not len(ins) or not nv:
                continue
            J0inv = np.linalg.inv(derivatives(box.lattice(comp.P0), emb.params[ins]))
            D = comp.lattice_jacobian().reshape(*P1.shape, nv)
            if not gradient:
                Fs = surface_frame_gradient(F, n0)
                if box.dim == 3:
                    R = rotations_from_deformation_gradient(Fs)
                else:
                    Fs3 = full3(box, Fs)
            for k in range(nv):
                v = lay.var_offsets[c] + k
                dF = derivatives(box.lattice(D[..., k]), emb.params[ins]) @ J0inv
                if gradient:          # the frame is F itself: linear in the control points
                    dF3 = full3(box, dF)
                    if box.dim == 2:
                        dF3[:, box.axes.span, box.axes.span] = 0.0
                    out[v, rows[ins]] = dF3
                    continue
                dFs = surface_frame_gradient_jvp(F, n0, dF)
                if box.dim == 3:
                    out[v, rows[ins]] = polar_rotation_derivative(Fs, R, dFs)
                else:
                    dFs3 = full3(box, dFs)
                    dFs3[:, box.axes.span, box.axes.span] = 0.0
                    out[v, rows[ins]] = planar_rotation_derivative(Fs3, dFs3, box.axes.span)
        return out

    def mesh_jvp(self, dv, progress=None) -> np.ndarray:
        """(N, 3) motion of every mesh node for ``dv`` (n_vars,), through the volume motion when it is IDW.

        The warp is a fixed linear map of the surface translations and frame parts ``M = F - I``
        (:func:`ffdcli.volume.warp.warp`), so the product is the warp of ``(dX_s/dv dv, I + dF/dv dv)``; the
        surface nodes get ``dX_s/dv dv`` exactly. The transpose of :meth:`mesh_vjp`."""
        dv = self._check_dv(dv, "mesh_jvp")
        ids = self.surface_ids
        dXs = self.surface_jvp(dv)
        out = np.zeros((self.run.prep.mesh.n_points, 3))
        if self.uses_volume():

            dR = np.tensordot(dv, self._frame_jacobian(), axes=1)
            out = warp(self._warp_model(progress), dXs, np.eye(3) + dR, progress=progress)
        out[ids] = dXs
        return out

    def mesh_vjp(self, g, progress=None) -> np.ndarray:
        """dJ/dv for g = dJ/dX at every mesh node (N, 3), through the volume motion when it is IDW.

        dJ/dv = (dX_s/dv)^T [g_s + (dX_v/db)^T g_v] + sum_s <(dX_v/dM_s)^T g_v, dR_s/dv>."""
        g = np.asarray(g, dtype=float)
        mesh = self.run.prep.mesh
        if g.shape != (mesh.n_points, 3):
            raise InputError(f"mesh_vjp: g must be ({mesh.n_points}, 3), got {g.shape}")
        ids = self.surface_ids
        if not self.uses_volume():
            return self.surface_vjp(g[ids])

        gs = g.copy()
        gs[ids] = 0.0          # surface nodes are placed by the FFD exactly; the warp's own value there is overwritten
        comm = self.comm if self.comm.size > 1 else None      # each rank sums its share of the volume
        g_b, g_M = warp_vjp(self._warp_model(progress), gs, progress=progress, comm=comm)
        g_b = g_b + g[ids] - gs[ids]
        out = self.surface_vjp(g_b)
        dR = self._frame_jacobian()
        out += np.einsum("sij,vsij->v", g_M, dR)
        return out


def constraints_report(run) -> list[dict]:
    """:meth:`DesignModel.constraints_table` of a :class:`ffdcli.app.pipeline.DesignRun` (``ffd deform --json``)."""
    return DesignModel(run).constraints_table()


def _finite_or_none(x: float) -> float | None:
    return float(x) if np.isfinite(x) else None


def read_sensitivity_for(model: DesignModel, path, *, points=None):
    """Read a sensitivity file against the deformed mesh of ``model`` (SPEC: coordinates of the
    design being differentiated). Returns (g (N, 3) dense, Sensitivity)."""
    mesh = model.run.prep.mesh
    pts = model.mesh_points() if points is None else points
    sens = read_sensitivity(path, pts, mesh.dim)
    return sens.to_dense(mesh.n_points), sens


@dataclass(frozen=True)
class Gradient:
    """dJ/dv from a sensitivity file (:func:`gradient_from_file`).

    values
        {variable name: dJ/dv} in the order of the model's variables.
    sensitivity
        The file's rows as matched to the mesh (``matched_by``, ``worst_distance``).
    surface_nodes, volume_nodes
        How many rows are on the surface marker(s), and how many elsewhere in the mesh.
    through_volume
        Whether the volume rows were pulled back through the volume-mesh motion (a volume method and
        volume rows); otherwise only the surface rows count.
    """

    values: dict[str, float]
    sensitivity: Sensitivity
    surface_nodes: int
    volume_nodes: int
    through_volume: bool


def gradient_from_file(model: DesignModel, path, *, progress=None) -> Gradient:
    """dJ/dv of every design variable of ``model`` by the chain rule from a sensitivity file (dJ/dX at
    the nodes of the deformed mesh). The file must cover every surface node (InputError otherwise);
    volume rows go through the volume-mesh motion's exact transpose when the design moves the volume."""
    g, sens = read_sensitivity_for(model, path)
    sens.check_covers(model.surface_ids, path)
    on_surface = np.isin(sens.ids, model.surface_ids)
    volume_nodes = int((~on_surface).sum())
    through = bool(volume_nodes and model.uses_volume())
    grad = model.mesh_vjp(g, progress=progress) if through else model.surface_vjp(g[model.surface_ids])
    return Gradient(values={name: float(v) for name, v in zip(model.names, grad, strict=True)},
                    sensitivity=sens, surface_nodes=int(on_surface.sum()), volume_nodes=volume_nodes,
                    through_volume=through)


__all__ = ["DesignModel", "Gradient", "gradient_from_file", "read_sensitivity_for", "polar_rotation_derivative",
           "planar_rotation_derivative", "Path"]
