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

import numpy as np
import scipy.sparse as sp

from ffdcli.api.constraints import ConstraintsMixin
from ffdcli.api.pointsets import PointSetsMixin
from ffdcli.api.volume import VolumeMixin
from ffdcli.app.run import load_run
from ffdcli.design import load_design
from ffdcli.errors import InputError
from ffdcli.mesh.numbers import as_numbers
from ffdcli.parallel.comm import SerialComm
from ffdcli.parameterization.changes import design_units
from ffdcli.parameterization.components import variable_bounds
from ffdcli.parameterization.derivatives import surface_jvp, vjp


class DesignModel(PointSetsMixin, ConstraintsMixin, VolumeMixin):
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
        self.bounds = variable_bounds(run.components, run.design)
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
                v[self.names.index(k)] = as_numbers(x, (), f"set_values: {k}")
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
        return as_numbers(dv, (self.n_vars,), f"{what}: dv", hint="one value per design variable, in names order")

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

        g = as_numbers(g, (len(self.surface_ids), 3), "surface_vjp: g",
                       hint="one row per surface point, surface_ids order")
        # one component: the embedding's compiled B.T @ g (its rows are the surface points)
        B = self.run.components[0].prep.embedding if self.run.single else self.basis
        return vjp(B, g, self.lattice_jacobian())


def constraints_report(run, mesh_points: np.ndarray | None = None) -> list[dict]:
    """:meth:`DesignModel.constraints_table` of a :class:`ffdcli.app.run.DesignRun` (``ffd deform --json``).

    ``mesh_points``: (N, 3) the mesh as deformed already (``mesh_quality`` reads it instead of
    deforming the mesh once more)."""
    model = DesignModel(run)
    if mesh_points is not None:
        model._cache["mesh"] = np.asarray(mesh_points, dtype=float)
    return model.constraints_table()
