"""A pipeline of changes: apply them in order, name and set their design variables, and build
them from the design file."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ffdcli.box.frame import LatticeFrame
from ffdcli.parameterization.changes.base import CHANGES, Change, SpecContext


def apply_changes(P0: np.ndarray, frame: LatticeFrame, changes: Sequence[Change]) -> np.ndarray:
    """The lattice after ``changes`` applied in order to ``P0`` (n, m, l, 3); ``P0`` is not modified."""
    P = np.array(P0, dtype=float, copy=True)
    for change in changes:
        P = change.apply(P, frame)
    return P


def design_variables(changes: Sequence[Change]) -> tuple[list[str], np.ndarray]:
    """Names (``c<index>.<name>``, e.g. ``c0.twist[7]``) and values of every design variable."""
    names, values = [], []
    for index, change in enumerate(changes):
        for name, value in change.variables():
            names.append(f"c{index}.{name}")
            values.append(value)
    return names, np.array(values, dtype=float)


def design_units(changes: Sequence[Change]) -> list[str]:
    """The unit of every design variable (order of :func:`design_variables`)."""
    return [u for change in changes for u in change.units()]


def design_bounds(P0: np.ndarray, frame: LatticeFrame, changes: Sequence[Change]) -> np.ndarray:
    """(n_vars, 2) natural open bounds of every design variable (order of :func:`design_variables`).

    Each change's bounds are taken at its input lattice for the current values of the changes
    before it (a sweep angle's limit depends on the leading-edge line it starts from)."""
    P = np.array(P0, dtype=float, copy=True)
    out = [np.zeros((0, 2))]
    for change in changes:
        out.append(change.bounds(P, frame))
        P = change.apply(P, frame)
    return np.concatenate(out, axis=0)


def set_design_variables(changes: Sequence[Change], values) -> list[Change]:
    """The changes with new values of all design variables (in the order of :func:`design_variables`)."""
    vals = np.asarray(values, dtype=float).reshape(-1)
    sizes = [c.size for c in changes]
    if vals.size != sum(sizes):
        raise ValueError(f"expected {sum(sizes)} design-variable values, got {vals.size}")
    out, at = [], 0
    for change, size in zip(changes, sizes, strict=True):
        out.append(change.with_values(vals[at:at + size]))
        at += size
    return out


def changes_from_spec(specs, n: int, m: int, l: int, dim: int, error=None, *, box=None,
                      surface=None) -> list[Change]:
    """The change objects of a ``changes`` list (as written in a design file) for a lattice of
    n x m x l points (2D: m = 1).

    ``error(message, key) -> Exception`` makes the error of a change the lattice refuses (default: an
    :class:`InputError` naming the key, ``changes[2].twist``). Each item has one key, its kind.
    ``box`` and ``surface`` (the wing's points) are what a flap or slat reads its hinge from.
    """
    out = []
    for index, item in enumerate(specs):
        (kind, spec), = item.items()
        ctx = SpecContext(n=n, m=m, l=l, dim=dim, key=f"changes[{index}].{kind}", error=error,
                          box=box, surface=surface)
        cls = CHANGES.get(kind)
        if cls is None:                         # pragma: no cover (the schema rejects it)
            raise ctx.fail(CHANGES.unknown(kind))
        out.append(cls.from_spec(spec, ctx))
    return out
