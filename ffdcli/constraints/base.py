"""The constraints' common part: the protocol every kind follows, what they read of a design, the
baseline surface's triangles, and the evaluation of a list.

Each constraint item of a design file's ``constraints:`` becomes one object (:func:`ffdcli.constraints.
build.build_constraints`), built once on the baseline (undeformed) surface and lattice; its values are
ratios to the baseline unless said otherwise. Every object has

``value(inp) -> (c,)`` and ``jacobian(inp) -> (c, n_vars)``
    for the current design, ``inp`` a :class:`ConstraintInputs` (the deformed lattice ``P``, its
    Jacobian ``D = dP'/dv`` (n_ctrl*3, n_vars), the deformed surface points and the basis ``B``).

The kinds, one module each: :mod:`~ffdcli.constraints.thickness` (``thickness``,
``thickness_to_chord``), :mod:`~ffdcli.constraints.volume`, :mod:`~ffdcli.constraints.le_te`,
:mod:`~ffdcli.constraints.fold_free`, :mod:`~ffdcli.constraints.mesh_quality`. Each declares itself
as every extension kind does (:mod:`ffdcli.registry`): ``kind``, ``schema()`` (the fragment of its
item, :func:`item_schema`), ``from_spec(spec, ctx)`` with ``ctx`` a :class:`ConstraintContext`,
``default_bounds``, and one line ``CONSTRAINTS.register(Kind)`` at the end of its module.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from ffdcli.errors import InputError
from ffdcli.registry import Registry

#: The kinds of ``constraints:`` items, each registered by its own module.
CONSTRAINTS = Registry("constraint")
#: A constraint value within this of a bound is satisfied (the values are ratios near 1).
SATISFIED_TOL = 1e-9


class ConstraintInputs:
    """What the constraints read of the current design, computed once and only when asked for.

    Parameters
    ----------
    P : ndarray, shape (n, m, l, 3)
        The deformed lattice.
    P0 : ndarray, shape (n, m, l, 3)
        The baseline lattice.
    values : ndarray, shape (n_vars,)
        The design-variable values.
    lattice_jacobian : callable () -> ndarray (n_ctrl*3, n_vars)
        ``dP'/dv`` (:func:`ffdcli.parameterization.derivatives.lattice_jacobian`).
    surface_points : callable () -> ndarray (S, 3)
        The deformed surface points.
    basis : callable () -> sparse (S, n_ctrl)
        The surface basis ``B``.
    rmatvec : callable (G (S, 3)) -> (n_ctrl, 3), optional
        ``B.T @ G`` by a faster route than ``basis`` (e.g. :meth:`ffdcli.lattice.embedding.Embedding.rmatvec`).
    quality : callable (measures, jacobian) -> (values (C,), jacobian (C, n_vars) or None), optional
        The value (and ``jacobian``: the exact derivative) of ``mesh_quality`` measures on the mesh as the
        design moves it: the chain's quality stage (:meth:`ffdcli.chain.DesignChain.quality_of`).
    """

    def __init__(self, P, P0, values, lattice_jacobian: Callable, surface_points: Callable, basis: Callable,
                 rmatvec: Callable | None = None, *, quality: Callable | None = None):
        self.P = np.asarray(P, dtype=float)
        self.P0 = np.asarray(P0, dtype=float)
        self.values = np.asarray(values, dtype=float)
        self._D, self._X, self._B, self._rmatvec = lattice_jacobian, surface_points, basis, rmatvec
        self._quality = quality

    def quality(self, measures, jacobian: bool = False):
        """``(values (C,), jacobian (C, n_vars) or None)`` of ``measures`` on the moved volume mesh."""
        if self._quality is None:
            raise InputError("mesh_quality needs the motion of the volume mesh: evaluate it through a design "
                             "model (ffdcli.api.DesignModel, ffd constraints), whose chain moves the mesh")
        return self._quality(tuple(measures), jacobian)

    def rmatvec(self, G: np.ndarray) -> np.ndarray:
        """(n_ctrl, 3) ``B.T @ G`` for ``G`` (S, 3) (a compiled product when one was given)."""
        if self._rmatvec is not None:
            return self._rmatvec(G)
        return np.asarray(self.B.T @ G)

    @cached_property
    def dP(self) -> np.ndarray:
        """(n_ctrl, 3) ``(P' - P0).reshape(-1, 3)``."""
        return (self.P - self.P0).reshape(-1, 3)

    @cached_property
    def D(self) -> np.ndarray:
        """(n_ctrl*3, n_vars)."""
        return self._D()

    @cached_property
    def X(self) -> np.ndarray:
        """(S, 3)."""
        return self._X()

    @cached_property
    def B(self):
        """(S, n_ctrl) sparse."""
        return self._B()


# --------------------------------------------------------------------------------------------------
# Geometry of the baseline: triangles, local chord lines, projection along the thickness axis
# --------------------------------------------------------------------------------------------------

def surface_triangles(faces) -> np.ndarray:
    """(T, 3) local point indices of the triangles of triangle and quad blocks (quads split 0-1-2, 0-2-3)."""
    out = [np.zeros((0, 3), dtype=np.int64)]
    for b in faces:
        d = np.asarray(b.data, dtype=np.int64)
        if b.type == "triangle":
            out.append(d)
        elif b.type == "quad":
            out += [d[:, [0, 1, 2]], d[:, [0, 2, 3]]]
    return np.concatenate(out)


def surface_segments(faces) -> np.ndarray:
    """(E, 2) local point indices of the line blocks (a 2D surface)."""
    out = [np.zeros((0, 2), dtype=np.int64)]
    out += [np.asarray(b.data, dtype=np.int64) for b in faces if b.type == "line"]
    return np.concatenate(out)


@dataclass(frozen=True)
class ConstraintContext:
    """What every kind's ``from_spec(spec, ctx)`` is handed: the item's place, its bounds (read with the
    kind's ``default_bounds``) and the baseline it is built on.

    index, key
        The item's position in ``constraints:`` and its key path (``constraints[2].volume``).
    lower, upper
        The item's bounds (``-inf``/``inf``: none).
    box : ffdcli.box.box.Box
    surface : ffdcli.geometry.surface.Surface
        The baseline surface (points (S, 3) and faces).
    changes : tuple of ffdcli.parameterization.changes.Change
        The design's changes (``le_te`` reads which control points the shape variables move).
    mesh : ffdcli.mesh.Mesh or None
        The input mesh (``mesh_quality`` reads its cells).
    error : callable (message, key) -> Exception, optional
        Makes the error naming the design file's key and line; default :class:`InputError`.
    progress : callable, optional
        A progress factory (:mod:`ffdcli.progress`).
    """

    index: int
    key: str
    lower: float
    upper: float
    box: object
    surface: object
    changes: tuple = ()
    mesh: object = None
    error: Callable | None = None
    progress: object = None

    def fail(self, message: str, key: str | None = None) -> Exception:
        """The exception for ``message`` at ``key`` (default: the item's own key)."""
        key = self.key if key is None else key
        return InputError(message, key=key) if self.error is None else self.error(message, key)


def item_schema(description: str, props: dict | None = None, required=()) -> dict:
    """The schema fragment of a constraint item: null (every default) or an object of ``props`` and the
    bounds every kind has (``lower``, ``upper``: a number or null for none)."""
    bound = {"type": ["number", "null"]}
    common = {"lower": {**bound, "description": "smallest allowed value (null: none)"},
              "upper": {**bound, "description": "largest allowed value (null: none)"}}
    body = {"type": "object", "properties": {**(props or {}), **common}, "additionalProperties": False}
    if required:
        body["required"] = list(required)
    return {"description": description, "anyOf": [{"type": "null"}, body]}


@dataclass(frozen=True, eq=False)
class Constraint(ABC):
    """Common part: the position in ``constraints``, the kind, the bounds and the item names; a kind
    implements the abstract :attr:`size`, :meth:`value` and :meth:`jacobian` (and, when the two share
    work, :meth:`value_and_jacobian`)."""

    index: int
    lower: float
    upper: float

    kind = ""
    #: (lower, upper) when the item gives none (None: no bound).
    default_bounds = (None, None)

    @property
    @abstractmethod
    def size(self) -> int:
        """The number of items (values) of the constraint."""

    @property
    def scalar(self) -> bool:
        """True when the constraint is one number named without brackets."""
        return False

    @property
    def names(self) -> list[str]:
        """``k<index>.<kind>`` or ``k<index>.<kind>[<j>]`` per item."""
        base = f"k{self.index}.{self.kind}"
        return [base] if self.scalar else [f"{base}[{j}]" for j in range(self.size)]

    @abstractmethod
    def value(self, inp: ConstraintInputs) -> np.ndarray:
        """(c,) the items' values for the design of ``inp``."""

    @abstractmethod
    def jacobian(self, inp: ConstraintInputs) -> np.ndarray:
        """(c, n_vars) their exact derivatives with respect to the design variables."""

    def value_and_jacobian(self, inp: ConstraintInputs) -> tuple[np.ndarray, np.ndarray]:
        """Both at once ((c,), (c, n_vars)); kinds that share the work override it."""
        return self.value(inp), self.jacobian(inp)


def read_bounds(spec: dict, lower=None, upper=None) -> tuple[float, float]:
    """(lower, upper) of an item's settings (absent: the defaults given; ``None``: no bound)."""
    return _bound(spec, "lower", lower), _bound(spec, "upper", upper)


def _bound(spec: dict, key: str, default):
    v = spec.get(key, default)
    return -np.inf if v is None and key == "lower" else np.inf if v is None else float(v)


# --------------------------------------------------------------------------------------------------
# Evaluation of a list
# --------------------------------------------------------------------------------------------------

def constraint_names(constraints) -> list[str]:
    """Every item name, in order."""
    return [n for c in constraints for n in c.names]


def constraint_bounds(constraints) -> tuple[np.ndarray, np.ndarray]:
    """(lower (C,), upper (C,)) of every item (``-inf``/``inf``: none)."""
    lo = np.concatenate([np.full(c.size, c.lower) for c in constraints] or [np.zeros(0)])
    hi = np.concatenate([np.full(c.size, c.upper) for c in constraints] or [np.zeros(0)])
    return lo, hi


def evaluate(constraints, inp: ConstraintInputs, jacobian: bool = False):
    """(values (C,), jacobian (C, n_vars) or None) of every item."""
    if not jacobian:
        vals = [c.value(inp) for c in constraints]
        return (np.concatenate(vals) if vals else np.zeros(0)), None
    both = [c.value_and_jacobian(inp) for c in constraints]
    if not both:
        return np.zeros(0), np.zeros((0, len(inp.values)))
    return np.concatenate([b[0] for b in both]), np.concatenate([b[1] for b in both], axis=0)


def satisfied(values, lower, upper, tol: float = SATISFIED_TOL) -> np.ndarray:
    """(C,) bool: ``lower - tol <= value <= upper + tol``."""
    values = np.asarray(values, dtype=float)
    return (values >= lower - tol) & (values <= upper + tol)
