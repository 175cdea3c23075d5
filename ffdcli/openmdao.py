"""An OpenMDAO component of a design file: design variables in, surface, mesh, point sets and constraints out.

Needs the ``[openmdao]`` extra (``pip install 'ffdcli[openmdao]'``).

>>> import openmdao.api as om
>>> from ffdcli.openmdao import FFDComponent
>>> prob = om.Problem()
>>> prob.model.add_subsystem("ffd", FFDComponent(design="wing.yaml"), promotes=["*"])
>>> prob.setup(); prob.run_model(); prob["surface"]          # (S, 3)

Inputs: one per change item of the design file, named from its variables (``c0.twist.tip`` ->
``c0_twist``; a component's ``wing.c0.twist`` -> ``wing_c0_twist``), of the size of that change
(``(2,)`` for ``twist: {root, tip}``, ``(2n,)`` for a shape with upper and lower), with the design
file's values as defaults; :meth:`FFDComponent.design_var_bounds` (and :func:`add_design_vars`) give
their bounds for ``add_design_var`` (an open natural bound such as a factor > 0 moved inside by
``OPEN_INSET``). Outputs: ``surface`` (S, 3) in the order of
``DesignModel.surface_ids``; ``mesh`` (N, 3) when ``mesh=True``; one (k, 3) output per point set
given in ``points={name: X}``; one output per ``constraints:`` item, ``k<index>_<kind>`` of its size
(a component's: ``<component>_k<index>_<kind>``). Every name is unique and reversible
(:func:`input_parts`) for every design the file format allows.

Every call hands the inputs' values down the chain (``DesignModel.evaluate(values)``: nothing is set on
the model, as OpenMDAO's ``compute`` receives its inputs). Derivatives are matrix-free
(``compute_jacvec_product``): forward products are ``surface_jvp``/``mesh_jvp``/``points_jvp`` and
``J @ dv`` for the constraints, reverse products the vector-Jacobian products; nothing of size
S x n_vars is formed.
"""

from __future__ import annotations

import re

import numpy as np
import openmdao.api as om

from ffdcli.api import DesignModel
from ffdcli.errors import InputError

#: Natural bounds are open (a factor must be > 0): an optimiser gets them moved inside by this much.
OPEN_INSET = 1e-6
#: What OpenMDAO is given for "no bound".
NO_BOUND = 1e30


def optimiser_bounds(bounds) -> tuple[np.ndarray, np.ndarray]:
    """(lower, upper) (n_vars,) closed bounds for an optimiser from :class:`ffdcli.parameterization.bounds.Bounds`."""
    lo, hi = bounds.lower.copy(), bounds.upper.copy()
    lo_open = (bounds.natural[:, 0] >= bounds.user[:, 0]) & np.isfinite(lo)
    hi_open = (bounds.natural[:, 1] <= bounds.user[:, 1]) & np.isfinite(hi)
    lo[lo_open] += OPEN_INSET * np.maximum(1.0, np.abs(lo[lo_open]))
    hi[hi_open] -= OPEN_INSET * np.maximum(1.0, np.abs(hi[hi_open]))
    return np.where(np.isfinite(lo), lo, -NO_BOUND), np.where(np.isfinite(hi), hi, NO_BOUND)


#: A variable name: ``[<component>.]c<index>.<kind><rest>``; the component part is greedy, so a component
#: named like a change (``c1``) is still told apart (``c1.c0.twist.tip``).
_VARIABLE = re.compile(r"^(?:(?P<comp>.*)\.)?c(?P<index>\d+)\.(?P<kind>[A-Za-z_]+)(?:[.\[].*)?$")


def input_name(variable: str) -> str:
    """The input of the change a variable belongs to: ``c3.shape.upper[2]`` -> ``c3_shape``,
    ``wing.c0.twist.tip`` -> ``wing_c0_twist``, ``c1.c0.twist.tip`` (component ``c1``) -> ``c1_c0_twist``.

    Unique and reversible for every design the file allows: component names are letters, digits, ``_``
    and ``-`` (all legal in OpenMDAO names, kept as written) and the name ends in ``c<index>_<kind>``,
    so :func:`input_parts` reads the component, change index and kind back from the right."""
    m = _VARIABLE.match(variable)
    if m is None:
        raise ValueError(f"not a design-variable name: {variable!r}")
    head = f"c{m['index']}_{m['kind']}"
    return f"{m['comp']}_{head}" if m["comp"] else head


def input_parts(name: str) -> tuple[str | None, int, str]:
    """(component name or None, change index, kind) of an input name (the inverse of :func:`input_name`)."""
    m = re.match(r"^(?:(?P<comp>.*)_)?c(?P<index>\d+)_(?P<kind>[A-Za-z]+(?:_[A-Za-z]+)*)$", name)
    if m is None:
        raise ValueError(f"not an input name of FFDComponent: {name!r}")
    return m["comp"], int(m["index"]), m["kind"]


def constraint_output(component: str, index: int, kind: str) -> str:
    """The output of constraint item ``index`` of a component (``""`` the single form): ``k0_volume``,
    ``wing_k0_volume``: unique across components."""
    return f"{component}_k{index}_{kind}" if component else f"k{index}_{kind}"


def constraint_items(model: DesignModel) -> list[tuple[str, slice, object]]:
    """``(output name, slice of model.constraint_names, constraint object)`` of every constraint item of
    ``model`` that has values (an ``le_te`` of a design without shape moves has none), in order."""
    items, at = [], 0
    for ci, group in model.constraint_groups:
        comp = model.component_names[ci] or ""
        for c in group:
            if c.size:
                items.append((constraint_output(comp, c.index, c.kind), slice(at, at + c.size), c))
            at += c.size
    return items


class FFDComponent(om.ExplicitComponent):
    """The FFD of a design file as an :class:`openmdao.api.ExplicitComponent` (see the module docstring).

    Options
    -------
    design : str
        The design file.
    overrides : list of str
        ``KEY=VALUE`` items as ``ffd deform --set``.
    mesh : bool
        Also output ``mesh`` (N, 3), every node as ``ffd deform`` places it (volume motion included).
    points : dict of str -> (k, 3) array
        Point sets to embed and output.
    constraints : list of dict or None
        A ``constraints:`` list to use instead of the design file's.
    cache_dir : str or None
        Where the box cache lives.
    design_vars : bool
        Declare every input as a design variable with its bounds (inputs left unconnected).
    """

    def initialize(self):
        self.options.declare("design", types=str, desc="the design file (YAML)")
        self.options.declare("overrides", default=(), desc="KEY=VALUE items as ffd deform --set")
        self.options.declare("mesh", default=False, types=bool, desc="also output every mesh node")
        self.options.declare("points", default=None, allow_none=True, types=dict, desc="point sets {name: (k, 3)}")
        self.options.declare("constraints", default=None, allow_none=True, types=list,
                             desc="constraints: list instead of the design file's")
        self.options.declare("cache_dir", default=None, allow_none=True, desc="where the box cache lives")
        self.options.declare("design_vars", default=False, types=bool,
                             desc="declare every input as a design variable with its bounds")
        self.model = None

    def setup(self):
        model = DesignModel.from_file(self.options["design"], list(self.options["overrides"]),
                                      cache_dir=self.options["cache_dir"])
        if self.options["constraints"] is not None:
            model.set_constraints(self.options["constraints"])
        for name, X in (self.options["points"] or {}).items():
            model.add_points(name, X)
        self.model = model
        self._var_index = {}                           # input name -> indices into model.values
        for k, name in enumerate(model.names):
            self._var_index.setdefault(input_name(name), []).append(k)
        lo, hi = optimiser_bounds(model.bounds)
        self._var_bounds = {}
        for name, idx in self._var_index.items():
            idx = np.array(idx)
            self._var_index[name] = idx
            self.add_input(name, val=model.values[idx], desc=", ".join(model.names[i] for i in idx))
            self._var_bounds[name] = (lo[idx], hi[idx])
            if self.options["design_vars"]:
                self.add_design_var(name, lower=lo[idx], upper=hi[idx])
        self.add_output("surface", shape=(len(model.surface_ids), 3), desc="deformed surface points")
        if self.options["mesh"]:
            self.add_output("mesh", shape=(model.n_points, 3), desc="every mesh node")
        for name in model.point_sets:
            self.add_output(name, shape=(model.point_set(name).n_points, 3), desc=f"point set {name}")
        self._con_slices = []                       # (output name, slice of model.constraint_names)
        for out, sl, c in constraint_items(model):
            self.add_output(out, shape=(c.size,), desc=", ".join(c.names))
            self._con_slices.append((out, sl))

    def design_var_bounds(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        """(lower, upper) of input ``name`` for ``add_design_var`` (+-1e30 where there is no bound)."""
        return self._var_bounds[name]

    def input_variables(self, name: str) -> list[str]:
        """The design-variable names (``DesignModel.names``) of input ``name``, in its order."""
        return [self.model.names[k] for k in self._var_index[name]]

    @property
    def input_names(self) -> list[str]:
        """The inputs, one per change item, in the order of the design file."""
        return list(self._var_index)

    def design_values(self, inputs) -> np.ndarray:
        """(n_vars,) the design values in ``model.names`` order from ``inputs``: the component's inputs
        vector, or anything indexed by its input names (a ``Problem`` whose inputs are promoted). The
        component holds no values of its own: each call hands them down the chain."""
        v = np.empty(self.model.n_vars)
        for name, idx in self._var_index.items():
            v[idx] = np.asarray(inputs[name]).reshape(-1)
        return v

    def compute(self, inputs, outputs):
        try:
            at = self.model.evaluate(self.design_values(inputs))     # the values the driver holds, down the chain
        except InputError as e:              # a value out of its bounds: the driver may step back
            raise om.AnalysisError(str(e)) from None
        outputs["surface"] = at.surface_points()
        if self.options["mesh"]:
            outputs["mesh"] = at.mesh_points()
        for name in self.model.point_sets:
            outputs[name] = at.points(name)
        if self._con_slices:
            vals = at.constraint_values()
            for out, sl in self._con_slices:
                outputs[out] = vals[sl]

    def compute_jacvec_product(self, inputs, d_inputs, d_outputs, mode):
        m = self.model
        at = m.evaluate(self.design_values(inputs))
        outs = [n for n in ["surface", "mesh", *m.point_sets] if n in d_outputs]
        cons = [(o, sl) for o, sl in self._con_slices if o in d_outputs]
        if mode == "fwd":
            dv = np.zeros(m.n_vars)
            for name, idx in self._var_index.items():
                if name in d_inputs:
                    dv[idx] = np.asarray(d_inputs[name]).reshape(-1)
            if not dv.any():
                return
            for name in outs:
                if name == "surface":
                    d_outputs[name] += at.surface_jvp(dv)
                elif name == "mesh":
                    d_outputs[name] += at.mesh_jvp(dv)
                else:
                    d_outputs[name] += at.points_jvp(name, dv)
            if cons:
                Jdv = at.constraint_jacobian() @ dv
                for o, sl in cons:
                    d_outputs[o] += Jdv[sl]
        else:
            g = np.zeros(m.n_vars)
            for name in outs:
                d = np.asarray(d_outputs[name])
                if not d.any():
                    continue
                if name == "surface":
                    g += at.surface_vjp(d)
                elif name == "mesh":
                    g += at.mesh_vjp(d)
                else:
                    g += at.points_vjp(name, d)
            if cons:
                J = at.constraint_jacobian()
                for o, sl in cons:
                    g += np.asarray(d_outputs[o]) @ J[sl]
            for name, idx in self._var_index.items():
                if name in d_inputs:
                    d_inputs[name] += g[idx]


def add_design_vars(problem_model, component: FFDComponent, prefix: str = "", scaler=None) -> list[str]:
    """``add_design_var`` for every input of ``component`` with its bounds; returns the names used.

    ``prefix`` is the path the inputs are reached by (``""`` when promoted, else ``"ffd."``)."""
    names = []
    for name in component.input_names:
        lo, hi = component.design_var_bounds(name)
        problem_model.add_design_var(prefix + name, lower=lo, upper=hi, scaler=scaler)
        names.append(prefix + name)
    return names
