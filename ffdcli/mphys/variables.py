"""The design variables and constraints of :class:`~ffdcli.mphys.geometry.FFDGeometry` (mixed into it): ffd's
own ways to add them (by variable name, by change item, every change of the design file), the inputs'
bounds, and the constraint outputs (a ``constraints:`` item, or the rows of one)."""

from __future__ import annotations

import numpy as np

from ffdcli.errors import InputError
from ffdcli.openmdao import constraint_items, input_name, optimiser_bounds


class VariablesAndConstraints:
    """Inputs over ffd's design variables (``_dvs``: input -> variable names) and outputs over its
    constraint items (``_cons``: output -> (item output, rows))."""

    # -- design variables (ffd's own) -----------------------------------------------------------------
    def resolve_variables(self, names) -> list[str]:
        """The model's variable names matching ``names`` (one or a list; each a name or a name prefix such
        as ``c0.twist``), in the model's order; an InputError names one that matches nothing."""
        model = self._require_model("design variables")
        names = [names] if isinstance(names, str) else list(names)
        picked = []
        for want in names:
            hits = [n for n in model.names if n == want or n.startswith(want + ".") or n.startswith(want + "[")]
            if not hits:
                raise InputError(f"no design variable named {want!r} (nor starting with it); the variables are "
                                 f"{', '.join(model.names[:12])}{' ...' if len(model.names) > 12 else ''}")
            picked += [n for n in hits if n not in picked]
        return sorted(picked, key=self._index.__getitem__)

    def nom_add_variables(self, dvName: str, names, value=None) -> int:
        """ffd's own: an input ``dvName`` over ffd design variables (names or name prefixes, e.g.
        ``"c0.twist"``, ``["c2.flap.angle"]``); returns its size. ``value``: its initial value (default the
        design's)."""
        if dvName in self._dvs:
            raise InputError(f"a design variable named {dvName!r} exists already")
        picked = tuple(self.resolve_variables(names))
        taken = {n: other for other, ns in self._dvs.items() for n in ns}
        if any(n in taken for n in picked):
            n = next(n for n in picked if n in taken)
            raise InputError(f"design variable {dvName!r}: {n} is already moved by the input {taken[n]!r}; one "
                             "input per variable")
        idx = self._indices(picked)
        val = self.model.values[idx] if value is None else np.broadcast_to(np.asarray(value, float), (len(idx),))
        self._dvs[dvName] = picked
        self.add_input(dvName, val=np.array(val, dtype=float), distributed=False, desc=", ".join(picked))
        return len(picked)

    def nom_add_design_variables(self) -> list[str]:
        """ffd's own: every change item of the design an input, named as ``FFDComponent`` names them
        (``c0_twist``, ``wing_c1_span``); returns the input names."""
        model = self._require_model("nom_add_design_variables")
        groups: dict[str, list[str]] = {}
        for n in model.names:
            groups.setdefault(input_name(n), []).append(n)
        for name, names in groups.items():
            self.nom_add_variables(name, names)
        return list(groups)

    def nom_add_change(self, dvName: str, change: dict, value=None, hold=()) -> int:
        """ffd's own: add a change item (as in a design file's ``changes:``, e.g. ``{"flap": {"span": [0.6,
        0.9], "hinge": 0.75, "angle": 0}}``) and an input ``dvName`` over its variables, but for the
        positions ``hold`` (indices into the change's variables, held at their values); returns its size."""
        prefix = self._add_change(change)
        names = [n for n in self.model.names if n.startswith(prefix)]
        keep = [n for q, n in enumerate(names) if q not in set(int(h) for h in hold)]
        return self.nom_add_variables(dvName, keep, value)

    def _indices(self, names) -> np.ndarray:
        return np.array([self._index[n] for n in names], dtype=np.int64)

    @property
    def input_names(self) -> list[str]:
        """The design-variable inputs, in the order added."""
        return list(self._dvs)

    def input_variables(self, name: str) -> list[str]:
        """The ffd variable names (``DesignModel.names``) of input ``name``, in its order."""
        return list(self._dvs[name])

    def design_var_bounds(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        """(lower, upper) of input ``name`` for ``add_design_var`` (+-1e30 where there is no bound);
        :func:`ffdcli.openmdao.add_design_vars` takes this component too."""
        lo, hi = optimiser_bounds(self.model.bounds)
        idx = self._indices(self._dvs[name])
        return lo[idx], hi[idx]

    # -- constraints -----------------------------------------------------------------------------------
    def _add_constraint(self, name: str, spec: dict, rows=None, reuse: str | None = None) -> int:
        """Add a ``constraints:`` item (or reuse the first of kind ``reuse``) and an output ``name`` of its
        values (``rows(constraint object)``: a mask of the items kept); returns the output's size."""
        model = self._require_model(f"constraint {name!r}")
        if self._source.components:
            raise InputError(f"constraint {name!r}: a design of several components takes its constraints in "
                             "the design file (a component's constraints:)")
        if name in self._cons:
            raise InputError(f"a constraint named {name!r} exists already")
        before = list(self._source.data.get("constraints") or []) if self._con_specs is None else self._con_specs
        at = next((k for k, s in enumerate(before) if reuse and reuse in s), None)
        specs = before if at is not None else before + [spec]
        model.set_constraints(specs)            # checked as a design file's item (the schema's words)
        at = len(specs) - 1 if at is None else at
        item = next((o for o, _, c in constraint_items(model) if c.index == at), None)
        if item is None:
            model.set_constraints(before)
            raise InputError(f"constraint {name!r}: it has no values for this design (an le_te needs a shape "
                             "variable first: nom_addLocalDV)")
        self._con_specs = specs
        return self._constraint_output(name, item, rows)

    def _constraint_output(self, name: str, item: str, rows) -> int:
        c = next(c for o, _, c in constraint_items(self.model) if o == item)
        mask = None if rows is None else np.asarray(rows(c), dtype=bool)
        size = c.size if mask is None else int(mask.sum())
        self._cons[name] = (item, mask)
        self.add_output(name, shape=(size,), distributed=False, desc=", ".join(np.asarray(c.names)[
            slice(None) if mask is None else mask]))
        return size

    def _constraint_rows(self):
        """{output: index array into model.constraint_names} at the current model."""
        where = {o: np.arange(sl.start, sl.stop) for o, sl, _ in constraint_items(self.model)}
        return {name: where[item] if mask is None else where[item][mask] for name, (item, mask) in self._cons.items()}

