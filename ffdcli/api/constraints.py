"""The design file's ``constraints:`` on a :class:`~ffdcli.api.DesignModel`: values, bounds and exact
Jacobians, and the tables ``ffd vars`` and ``ffd constraints`` print."""

from __future__ import annotations

import numpy as np

from ffdcli.constraints import (
    ConstraintInputs,
    build_constraints,
    constraint_bounds,
    constraint_names,
    evaluate,
    satisfied,
)
from ffdcli.design.schema import constraints_schema
from ffdcli.design.validate import validate_section
from ffdcli.errors import InputError
from ffdcli.io.atomic import atomic_write


def finite_or_none(x: float) -> float | None:
    """``x`` as a float, or None for an infinite bound (JSON has no infinity)."""
    return float(x) if np.isfinite(x) else None


class ConstraintsMixin:
    """The constraints part of :class:`~ffdcli.api.DesignModel` (``_static["constraints"]``: built once
    on the baseline; ``_cache``: values and Jacobian at the current values)."""

    @property
    def constraints(self) -> list:
        """The constraint objects of the design file's ``constraints:`` (:mod:`ffdcli.constraints`),
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
        """Replace the constraints of one component (default the first, by index) by a ``constraints:``
        list. Checked as a design file's ``constraints:`` is (the schema's words, the key path): an
        :class:`~ffdcli.errors.InputError` for a bad item or a component that does not exist."""
        n = len(self.run.components)
        if isinstance(component, bool) or not isinstance(component, (int, np.integer)) or not 0 <= component < n:
            raise InputError(f"set_constraints: component {component!r} does not exist; the design has {n} "
                             f"component{'s' if n > 1 else ''} (index 0{f' to {n - 1}' if n > 1 else ''})")
        at = ("components", int(component), "constraints") if "components" in (self.run.design.data or {}) \
            else ("constraints",)
        validate_section(specs, constraints_schema(), at)
        groups = [g for g in self.constraint_groups if g[0] != component]
        groups.append((component, self._build_constraints(specs, component)))
        self._static["constraints"] = sorted(groups, key=lambda g: g[0])
        self._cache.clear()

    def _build_constraints(self, specs, c: int = 0) -> list:

        comp = self.run.components[c]
        design_error = getattr(self.run.design, "error", None)
        error = None if design_error is None else (lambda message, key: design_error(message, comp.spec.subkey(key)))
        return build_constraints(specs, comp.box, comp.prep.surface, list(comp.changes), error=error,
                                 mesh=self.run.prep.mesh)

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

    def _mesh_points_cached(self) -> np.ndarray:
        """:meth:`mesh_points` once per design values (what ``mesh_quality`` reads)."""
        if "mesh" not in self._cache:
            self._cache["mesh"] = self.mesh_points()
        return self._cache["mesh"]

    def _constraint_inputs(self, c: int = 0):
        """What component ``c``'s constraints read: its lattice, its rows of dP'/dv (every variable's
        column), its surface points and basis, and the whole mesh's motion (``mesh_quality``)."""

        mesh = {"mesh_points": self._mesh_points_cached, "mesh_vjp": self.mesh_vjp,
                "design_map": self.design_map_points, "design_map_vjp": self.design_map_vjp}
        if self.run.single:
            emb = self.run.prep.embedding
            rmatvec = emb.rmatvec if self.run.box.dim == 3 else None       # 3D: core = mesh coordinates
            return ConstraintInputs(self.lattice(), self.run.P0, self.values, self.lattice_jacobian,
                                    self.surface_points, lambda: self.basis, rmatvec, **mesh)
        comp, lay = self.run.components[c], self.run.layout
        o0, o1, rows = lay.ctrl_offsets[c], lay.ctrl_offsets[c + 1], lay.rows[c]
        emb = comp.prep.embedding
        return ConstraintInputs(self.lattices()[c], comp.P0, self.values,
                                lambda: self.lattice_jacobian()[3 * o0:3 * o1],
                                lambda: self.surface_points()[rows],
                                lambda: emb.basis_matrix().tocsr(), emb.rmatvec if comp.box.dim == 3 else None,
                                **mesh)

    def _evaluate_constraints(self, jacobian: bool):
        """Values (C,) and (``jacobian``) the Jacobian (C, n_vars); a value or derivative that is not a
        finite number (design values so large that the geometry overflows) is an InputError naming
        the item and the design file: no command reports or writes a non-finite result."""
        vals, jacs = [np.zeros(0)], [np.zeros((0, self.n_vars))]
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            for c, group in self.constraint_groups:
                v, j = evaluate(group, self._constraint_inputs(c), jacobian=jacobian)
                vals.append(v)
                if jacobian:
                    jacs.append(j)
        vals = np.concatenate(vals)
        jac = np.concatenate(jacs, axis=0) if jacobian else None
        bad = ~np.isfinite(vals) if jac is None else ~(np.isfinite(vals) & np.isfinite(jac).all(axis=1))
        if bad.any():
            k = int(np.flatnonzero(bad)[0])
            raise InputError(f"constraint {self.constraint_names[k]} is not a finite number at these design values "
                             f"({', '.join(f'{n} = {v:g}' for n, v in zip(self.names[:4], self.values[:4]))}"
                             f"{' ...' if len(self.names) > 4 else ''}); are they far too large?",
                             path=getattr(self.run.design, "path", None))
        return vals, jac

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
        return [{"name": n, "value": float(v), "unit": u, "lower": finite_or_none(a), "upper": finite_or_none(b)}
                for n, v, u, a, b in zip(self.names, self.values, self.units, lo, hi, strict=True)]

    def constraints_table(self) -> list[dict]:
        """One ``{"name", "value", "lower", "upper", "satisfied"}`` per constraint item (None: no bound)."""

        v = self.constraint_values()
        lo, hi = self.constraint_lower, self.constraint_upper
        ok = satisfied(v, lo, hi)
        return [{"name": n, "value": float(x), "lower": finite_or_none(a), "upper": finite_or_none(b),
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

