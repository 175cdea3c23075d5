"""The design file's ``constraints:`` on a :class:`~ffdcli.api.DesignModel`: the constraint objects
(built once on the baseline), their values and exact Jacobians at the values asked about, through the
chain (:mod:`ffdcli.chain`)."""

from __future__ import annotations

import numpy as np

from ffdcli.chain import DesignChain, Memo, digest
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


class ConstraintSet:
    """The constraints of a design, per component: ``groups`` ``[(component index, objects)]`` (the
    single-component form: one group, the file's ``constraints:``).

    Parameters
    ----------
    run : ffdcli.app.run.DesignRun
        The loaded design (its file's ``constraints:``, its components' boxes and surfaces).
    groups : list, optional
        Groups already built (default: built from the design file on first use).
    """

    def __init__(self, run, groups=None):
        self.run = run
        self._groups = groups
        self._values = Memo()
        self._jacobian = Memo()

    @property
    def groups(self) -> list[tuple[int, list]]:
        if self._groups is None:
            data = getattr(self.run.design, "data", None) or {}
            if "components" in data:
                specs = [item.get("constraints") or [] for item in data["components"]]
            else:
                specs = [data.get("constraints") or []]
            self._groups = [(c, self._build(s, c)) for c, s in enumerate(specs)]
        return self._groups

    def replaced(self, specs, component: int = 0) -> ConstraintSet:
        """A new set with one component's constraints replaced by a ``constraints:`` list, checked as a
        design file's (the schema's words, the key path)."""
        n = len(self.run.components)
        if isinstance(component, bool) or not isinstance(component, (int, np.integer)) or not 0 <= component < n:
            raise InputError(f"set_constraints: component {component!r} does not exist; the design has {n} "
                             f"component{'s' if n > 1 else ''} (index 0{f' to {n - 1}' if n > 1 else ''})")
        at = ("components", int(component), "constraints") if "components" in (self.run.design.data or {}) \
            else ("constraints",)
        validate_section(specs, constraints_schema(), at)
        groups = [g for g in self.groups if g[0] != component]
        groups.append((component, self._build(specs, component)))
        return ConstraintSet(self.run, sorted(groups, key=lambda g: g[0]))

    def _build(self, specs, c: int = 0) -> list:
        comp = self.run.components[c]
        design_error = getattr(self.run.design, "error", None)
        error = None if design_error is None else (lambda message, key: design_error(message, comp.spec.subkey(key)))
        return build_constraints(specs, comp.box, comp.prep.surface, list(comp.changes), error=error,
                                 mesh=self.run.prep.mesh)

    @property
    def objects(self) -> list:
        return [c for _, group in self.groups for c in group]

    @property
    def names(self) -> list[str]:
        return [self.run.components[c].spec.prefix + n for c, group in self.groups for n in constraint_names(group)]

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        return constraint_bounds(self.objects)

    # -- evaluation ------------------------------------------------------------------------------
    def inputs(self, chain: DesignChain, values: np.ndarray, c: int = 0, mesh_points=None) -> ConstraintInputs:
        """What component ``c``'s constraints read at ``values``: its lattice, its rows of dP'/dv (every
        variable's column), its surface points and basis, and the whole mesh's motion (``mesh_quality``)."""
        mesh = {"quality": lambda measures, jacobian: chain.quality_of(measures, values, jacobian, mesh_points)}
        comp = chain.components[c]
        P = chain.lattices.forward(values)[c]
        emb = comp.prep.embedding
        rmatvec = emb.rmatvec if comp.box.dim == 3 else None       # 3D: core = mesh coordinates
        if chain.single:
            return ConstraintInputs(P, comp.P0, values, lambda: chain.lattices.jacobian(values),
                                    lambda: chain.surface_points(values), lambda: chain.surface.block_basis(),
                                    rmatvec, **mesh)
        lay = chain.layout
        o0, o1, rows = lay.ctrl_offsets[c], lay.ctrl_offsets[c + 1], lay.rows[c]
        return ConstraintInputs(P, comp.P0, values, lambda: chain.lattices.jacobian(values)[3 * o0:3 * o1],
                                lambda: chain.surface_points(values)[rows], lambda: chain.surface.basis(c),
                                rmatvec, **mesh)

    def evaluate(self, chain: DesignChain, values: np.ndarray, jacobian: bool, names=(), mesh_points=None):
        """Values (C,) and (``jacobian``) the Jacobian (C, n_vars) at ``values``; a value or derivative that
        is not a finite number (design values so large that the geometry overflows) is an InputError
        naming the item and the design file: no command reports or writes a non-finite result.
        ``names``: the variables' names (the message); ``mesh_points``: ``() -> (N, 3)`` the mesh as
        deformed already."""
        n_vars = len(values)
        vals, jacs = [np.zeros(0)], [np.zeros((0, n_vars))]
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            for c, group in self.groups:
                v, j = evaluate(group, self.inputs(chain, values, c, mesh_points), jacobian=jacobian)
                vals.append(v)
                if jacobian:
                    jacs.append(j)
        vals = np.concatenate(vals)
        jac = np.concatenate(jacs, axis=0) if jacobian else None
        bad = ~np.isfinite(vals) if jac is None else ~(np.isfinite(vals) & np.isfinite(jac).all(axis=1))
        if bad.any():
            k = int(np.flatnonzero(bad)[0])
            raise InputError(f"constraint {self.names[k]} is not a finite number at these design values "
                             f"({', '.join(f'{n} = {v:g}' for n, v in zip(names[:4], values[:4]))}"
                             f"{' ...' if len(names) > 4 else ''}); are they far too large?",
                             path=getattr(self.run.design, "path", None))
        return vals, jac

    def values(self, chain: DesignChain, values: np.ndarray, names=()) -> np.ndarray:
        """(C,) at ``values`` (kept while the values repeat)."""
        return self._values.get(digest(values), lambda: self.evaluate(chain, values, False, names)[0])

    def jacobian(self, chain: DesignChain, values: np.ndarray, names=()) -> np.ndarray:
        """(C, n_vars) at ``values`` (kept while the values repeat)."""
        def both():
            v, j = self.evaluate(chain, values, True, names)
            self._values.get(digest(values), lambda: v)
            return j
        return self._jacobian.get(digest(values), both)


# -- the tables of ffd vars and ffd constraints, methods of DesignModel ------------------------------
def variables_table(model) -> list[dict]:
    """One ``{"name", "value", "unit", "lower", "upper"}`` per design variable (None: no bound)."""
    lo, hi = model.lower, model.upper
    return [{"name": n, "value": float(v), "unit": u, "lower": finite_or_none(a), "upper": finite_or_none(b)}
            for n, v, u, a, b in zip(model.names, model.values, model.units, lo, hi, strict=True)]


def constraints_table(model, values=None, mesh_points=None) -> list[dict]:
    """One ``{"name", "value", "lower", "upper", "satisfied"}`` per constraint item (None: no bound), at
    the held values (or ``values``); ``mesh_points`` (N, 3): the mesh as deformed already (what
    ``mesh_quality`` reads instead of deforming it once more)."""
    v = model.values if values is None else np.asarray(values, dtype=float)
    cs = model.constraint_set
    if mesh_points is None:
        vals = cs.values(model.chain, v, model.names)
    else:
        X = np.asarray(mesh_points, dtype=float)
        vals = cs.evaluate(model.chain, v, False, model.names, mesh_points=lambda: X)[0]
    lo, hi = cs.bounds
    ok = satisfied(vals, lo, hi)
    return [{"name": n, "value": float(x), "lower": finite_or_none(a), "upper": finite_or_none(b),
             "satisfied": bool(s)}
            for n, x, a, b, s in zip(cs.names, vals, lo, hi, ok, strict=True)]


def constraint_jacobian_arrays(model) -> dict[str, np.ndarray]:
    """The arrays of ``ffd constraints --jacobian FILE.npz`` (SPEC): ``names`` (C), ``variables`` (V),
    ``values`` (C), ``lower`` (C), ``upper`` (C) (``-inf``/``inf``: none) and ``jacobian`` (C x V)."""
    return dict(names=np.array(model.constraint_names, dtype=str), variables=np.array(model.names, dtype=str),
                values=model.constraint_values(), lower=model.constraint_lower, upper=model.constraint_upper,
                jacobian=model.constraint_jacobian())


def write_constraint_jacobian(model, path) -> None:
    """Write :func:`constraint_jacobian_arrays` as ``.npz``, whole or not at all."""
    arrays = constraint_jacobian_arrays(model)
    with atomic_write(path, "wb") as f:
        np.savez(f, **arrays)
