"""``FFDGeometry``: ffd as the geometry component of an MPhys problem, in place of pyGeo's ``OM_DVGEOCOMP``.

Needs the ``[mphys]`` extra (``pip install 'ffdcli[mphys]'``: MPhys 2 and OpenMDAO).

>>> from mphys import MPhysVariables
>>> geo = FFDGeometry(design="wing.yaml")                # or FFDGeometry() and the solver's surface points
>>> # in the run script's configure(), as with pyGeo:
>>> geo.nom_add_discipline_coords(MPhysVariables.Aerodynamics.Surface.Geometry, points)
>>> geo.nom_addGlobalDV("twist", value=np.zeros(geo.nom_addRefAxis("wing") - 1), func=None)
>>> geo.nom_addLocalDV("thickness", axis="z")
>>> geo.nom_addThicknessConstraints2D("thickcon", leList, teList, nSpan=10, nChord=10)

Inputs: the solver's coordinates of each point set added from a discipline (MPhys 2.0's names:
``x_aero0_geometry_input``, ``x_struct0_geometry_input``, ``x_thermal0_geometry_input``; distributed,
tagged ``mphys_coordinates``) and one input per design variable added. Outputs: the moved points
(``x_aero0_geometry_output`` ...) and one output per constraint. The design variables and the
constraints are ffd's (``DesignModel.names``, ``constraints:`` kinds); pyGeo's methods map onto them
(:mod:`ffdcli.mphys.pygeo_methods`), and where pyGeo asks for something ffd makes automatic (the FFD
file, a reference axis) the call is accepted and an :class:`FFDNote` warning says what ffd does instead.

Derivatives are exact and matrix-free (``compute_jacvec_product``): ``DesignModel.points_jvp`` /
``points_vjp`` for the points and the exact ``constraint_jacobian`` for the constraints. Under MPI each
rank embeds its own part of a distributed point set, and reverse products are summed over the ranks.
The points do not depend on the input coordinates in the derivatives (as with pyGeo): the mesh
coordinates are not design variables.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import openmdao.api as om

from ffdcli.api import DesignModel
from ffdcli.errors import InputError
from ffdcli.mesh.numbers import as_numbers
from ffdcli.mphys.design import from_design_file, from_points
from ffdcli.mphys.names import FFDNote
from ffdcli.mphys.pygeo_methods import PyGeoMethods
from ffdcli.mphys.variables import VariablesAndConstraints
from ffdcli.openmdao import constraint_items
from ffdcli.parallel.comm import MPIComm, SerialComm

#: Extensions of a design file; any other ``file`` is taken as an FFD lattice (Plot3D), ffd's ``box.file``.
DESIGN_SUFFIXES = (".yaml", ".yml")


@dataclass
class PointSetInfo:
    """A point set of the component: the input it is read from (None: given once), whether its output is
    distributed, and the points embedded (this rank's; None until the first compute)."""

    input: str | None
    distributed: bool
    points: np.ndarray | None = None


class FFDGeometry(PyGeoMethods, VariablesAndConstraints, om.ExplicitComponent):
    """The geometry of an MPhys problem by ffd (see the module docstring).

    Options
    -------
    design : str or None
        A design file (``ffd init MESH`` writes one); its mesh may be the flow solver's own grid.
        None: the box is fitted to the first point set given with its points.
    file, type, options
        pyGeo's options: ``file`` a design file (``.yaml``) or an FFD lattice (Plot3D), taken as ffd's
        ``box: {file: ...}`` around the solver's surface points; ``type`` must be ``"ffd"``;
        ``options`` is ignored with a note.
    box : dict or None
        The ``box:`` settings of a box fitted to surface points (``{"points": [8, 6, 2]}``).
    overrides : list of str
        ``KEY=VALUE`` items as ``ffd deform --set``.
    disciplines : sequence
        Disciplines whose coordinates are added at setup (their size from the connection):
        ``("aero", "struct")`` or MPhys geometry classes. (A builder's component uses it.)
    dvs : dict or None
        ``{input name: variable names or name prefixes}``: inputs declared at setup.
    design_vars : bool
        Every change item of the design file as an input, named as ``FFDComponent`` names them (``c0_twist``).
    work_dir : str
        Where the design files the component evaluates are written (default ``ffd-mphys``).
    cache_dir : str or None
        Where the box cache lives (default beside the mesh).
    comm : mpi4py communicator or None
        The ranks a distributed point set is split over (default: the component's own). Given when each
        rank evaluates an OpenMDAO problem of its own (``Problem(comm=MPI.COMM_SELF)``, e.g. where
        OpenMDAO's distributed vectors, which need PETSc, are not installed) and the ranks together
        hold the solver's surface.
    """

    def initialize(self):
        self.options.declare("design", default=None, allow_none=True, desc="the design file (YAML)")
        self.options.declare("file", default=None, allow_none=True, desc="pyGeo's: a design file or an FFD file")
        self.options.declare("type", default="ffd", allow_none=True, desc="pyGeo's: must be 'ffd'")
        self.options.declare("options", default=None, allow_none=True, desc="pyGeo's DVGeometry options (ignored)")
        self.options.declare("DVGeoInfo", default=None, allow_none=True, desc="pyGeo's several DVGeos (refused)")
        self.options.declare("box", default=None, allow_none=True, types=dict, desc="box: settings for surface points")
        self.options.declare("overrides", default=(), desc="KEY=VALUE items as ffd deform --set")
        self.options.declare("disciplines", default=(), desc="disciplines whose coordinates are added at setup")
        self.options.declare("dvs", default=None, allow_none=True, types=dict, desc="{input: variable names}")
        self.options.declare("design_vars", default=False, types=bool, desc="every change item as an input")
        self.options.declare("work_dir", default="ffd-mphys", desc="where the evaluated design files go")
        self.options.declare("cache_dir", default=None, allow_none=True, desc="where the box cache lives")
        self.options.declare("comm", default=None, allow_none=True, recordable=False,
                             desc="the communicator of the distributed point sets (default: the component's)")
        self.notes: list[str] = []
        self.model = None

    # -- setup -------------------------------------------------------------------------------------
    def setup(self):
        self.model = None
        self._source = None
        self._box_file = None
        self._sets: dict[str, PointSetInfo] = {}
        self._dvs: dict[str, tuple[str, ...]] = {}
        self._cons: dict[str, tuple[str, np.ndarray | None]] = {}    # output -> (item, rows)
        self._con_specs: list | None = None                         # None: the design file's
        self._index: dict[str, int] = {}
        comm = self.options["comm"] or self.comm
        self._ffd_comm = SerialComm() if comm.size == 1 else MPIComm(comm)
        opts = self.options
        if opts["DVGeoInfo"] is not None:
            raise InputError("DVGeoInfo (several DVGeos): ffd takes several components in one design file "
                             "(components:, each with its own automatic box); give design='design.yaml'")
        if opts["type"] is not None and str(opts["type"]).lower() != "ffd":
            raise InputError(f"type={opts['type']!r}: ffd is an FFD parameterization; give type='ffd' (or none)")
        if opts["options"]:
            self._note(f"options {sorted(opts['options'])} are DVGeometry's; ffd has none of them (ignored)")
        design = opts["design"]
        if opts["file"] is not None:
            if design is not None:
                raise InputError("give design= or file=, not both")
            if Path(opts["file"]).suffix.lower() in DESIGN_SUFFIXES:
                design = opts["file"]
            else:
                self._box_file = str(Path(opts["file"]).resolve())
                self._note(f"{opts['file']}: taken as the lattice of ffd's box (box.file) around the surface "
                           "points the first point set gives; ffd's own automatic box needs no FFD file")
        if design is not None:
            self._source = from_design_file(design, opts["overrides"])
            self._build()
            for out, _, _c in constraint_items(self.model):      # the design file's constraints
                self._constraint_output(out, out, None)
        for d in opts["disciplines"]:
            self.nom_add_discipline_coords(d)
        if opts["design_vars"]:
            self.nom_add_design_variables()
        for name, names in (opts["dvs"] or {}).items():
            self.nom_add_variables(name, names)

    def _note(self, message: str, depth: int = 0) -> None:
        """Record a note and warn once (rank 0); ``depth``: calls between the run script and the caller."""
        self.notes.append(message)
        if self._ffd_comm.is_root:
            warnings.warn(f"ffd: {message}", FFDNote, stacklevel=3 + depth)

    def _require_model(self, what: str) -> DesignModel:
        if self.model is None:
            raise InputError(f"{what}: the geometry is not known yet: give design='wing.yaml', or the surface "
                             "points first (nom_add_discipline_coords(discipline, points))")
        return self.model

    def _build(self) -> None:
        """(Re)load the model from the design source; re-embed the point sets, re-set the constraints."""
        work = Path(self.options["work_dir"])
        path = self._ffd_comm.root_then_bcast(self._source.write, work)
        comm = self._ffd_comm if self._ffd_comm.size > 1 else None
        model = DesignModel.from_file(path, cache_dir=self.options["cache_dir"], comm=comm)
        if self._con_specs is not None:
            model.set_constraints(self._con_specs)
        for name, info in self._sets.items():
            if info.points is not None:
                model.add_points(name, info.points)
        self.model = model
        self._index = {n: k for k, n in enumerate(model.names)}

    def _build_from_points(self, X) -> None:
        """The box fitted to a surface point set (every rank's part gathered)."""
        whole = self._ffd_comm.allgather_rows(np.ascontiguousarray(X, dtype=np.float64).reshape(-1, 3))
        box = dict(self.options["box"] or {})
        if self._box_file:
            box["file"] = self._box_file
        self._source = self._ffd_comm.root_then_bcast(from_points, whole, Path(self.options["work_dir"]), box=box)
        self._build()

    def _add_change(self, spec: dict) -> str:
        """Append a change item to the design and reload; returns its variables' prefix ``c<index>.``."""
        self._require_model("adding a design variable")
        before = self._source
        self._source = before.with_change(spec)
        k = self._source.n_base_changes + len(self._source.added) - 1
        try:
            self._build()
        except InputError as e:
            self._source = before                # the model is the one before: nothing half-added
            if "sections" in str(e) and any(kind in spec for kind in ("flap", "slat")):
                raise InputError(f"{e} (a device adds sections to the box: add devices before the per-section "
                                 "variables such as twist and chord)") from None
            raise
        return f"c{k}."

    # -- point sets -----------------------------------------------------------------------------------
    def _point_set(self, name: str, points, input_name_: str | None, distributed: bool) -> None:
        """Declare point set ``name`` (its output, and its input if read from one)."""
        if name in self._sets:
            raise InputError(f"a point set named {name!r} exists already")
        info = PointSetInfo(input_name_, distributed)
        self._sets[name] = info
        tags = ["mphys_coordinates"] if input_name_ is not None else []
        if points is None:
            self.add_input(input_name_, distributed=True, shape_by_conn=True, tags=tags)
            self.add_output(name, distributed=True, copy_shape=input_name_, tags=tags)
            return
        X = as_numbers(np.reshape(points, (-1, 3)) if np.size(points) % 3 == 0 else points, (None, 3),
                       f"the points of {name!r}", hint="(N, 3) or (3N,) coordinates")
        if self.model is None:
            self._build_from_points(X)
            self._note(f"the automatic box is fitted to the point set {name!r} ({self._ffd_comm.allreduce_sum(len(X))}"
                       " points, every rank's)")
        self._embed(name, X)
        if input_name_ is not None:
            self.add_input(input_name_, val=X.ravel(), distributed=True, tags=tags)
        self.add_output(name, val=X.ravel(), distributed=distributed, tags=tags)

    def _embed(self, name: str, X: np.ndarray) -> None:
        report = self.model.add_points(name, X)
        self._sets[name].points = X.copy()
        outside = self._ffd_comm.allreduce_sum(int(report["outside"]))
        if outside:
            self._note(f"{outside} points of {name!r} are outside the box: they never move")

    # -- evaluation -------------------------------------------------------------------------------------
    def _design(self, inputs):
        """The design at the component's inputs (the variables it does not expose at the design file's
        values): a :class:`~ffdcli.api.model.DesignPoint`, nothing set on the model (the values arrive
        on every call, as OpenMDAO hands them)."""
        m = self.model
        v = m.values.copy()
        for name, names in self._dvs.items():
            v[self._indices(names)] = np.asarray(inputs[name]).reshape(-1)
        return m.evaluate(v)

    def _update_points(self, inputs) -> None:
        for name, info in self._sets.items():
            if info.input is None:
                continue
            X = np.asarray(inputs[info.input], dtype=np.float64).reshape(-1, 3)
            if self.model is None:
                self._build_from_points(X)
            if info.points is None or not np.array_equal(X, info.points):
                self._embed(name, X)

    def compute(self, inputs, outputs):
        self._update_points(inputs)
        self._require_model("compute")
        try:
            at = self._design(inputs)
        except InputError as e:              # a value out of its bounds: the driver may step back
            raise om.AnalysisError(str(e)) from None
        for name in self._sets:
            outputs[name] = at.points(name).reshape(-1)
        if self._cons:
            vals = at.constraint_values()
            for name, rows in self._constraint_rows().items():
                outputs[name] = vals[rows]

    def compute_jacvec_product(self, inputs, d_inputs, d_outputs, mode):
        self._update_points(inputs)
        m = self.model
        at = self._design(inputs)
        sets = [n for n in self._sets if n in d_outputs]
        cons = {n: r for n, r in self._constraint_rows().items() if n in d_outputs} if self._cons else {}
        if mode == "fwd":
            dv = np.zeros(m.n_vars)
            for name, names in self._dvs.items():
                if name in d_inputs:
                    dv[self._indices(names)] += np.asarray(d_inputs[name]).reshape(-1)
            for name in sets:
                d_outputs[name] += at.points_jvp(name, dv).reshape(-1)
            if cons:
                Jdv = at.constraint_jacobian() @ dv
                for name, rows in cons.items():
                    d_outputs[name] += Jdv[rows]
        else:
            g = np.zeros(m.n_vars)
            for name in sets:        # a collective under MPI: every rank, every set, in one order
                g += at.points_vjp(name, np.asarray(d_outputs[name]).reshape(-1, 3))
            if cons:
                J = at.constraint_jacobian()
                for name, rows in cons.items():
                    g += np.asarray(d_outputs[name]) @ J[rows]
            for name, names in self._dvs.items():
                if name in d_inputs:
                    d_inputs[name] += g[self._indices(names)]
