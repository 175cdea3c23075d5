"""The common ground of the design changes: the :class:`Change` protocol, homogeneous coordinates,
rotations in the section plane and the per-section laws of the numbers a user writes.

See :mod:`ffdcli.parameterization.changes` for the protocol every change follows.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ffdcli.box.frame import LatticeFrame
from ffdcli.errors import InputError
from ffdcli.registry import Registry

#: Radians per degree: angles are given and differentiated in degrees.
DEG = math.pi / 180.0
#: The change kinds of ``changes:``, each registered by its own module (:mod:`ffdcli.registry`).
CHANGES = Registry("change")
#: Largest leading-edge sweep/dihedral angle a change may produce (tan grows without bound at 90).
MAX_SHEAR_ANGLE = 85.0


# --------------------------------------------------------------------------------------------------
# Homogeneous coordinates
# --------------------------------------------------------------------------------------------------

def homogeneous(A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(..., 4, 4) matrices of the affine maps x -> A x + b (A (..., 3, 3), b (..., 3))."""
    A = np.asarray(A, dtype=float)
    b = np.asarray(b, dtype=float)
    M = np.zeros(A.shape[:-2] + (4, 4))
    M[..., :3, :3] = A
    M[..., :3, 3] = b
    M[..., 3, 3] = 1.0
    return M


def translation(p: np.ndarray) -> np.ndarray:
    """(..., 4, 4) T(p)."""
    p = np.asarray(p, dtype=float)
    return homogeneous(np.broadcast_to(np.eye(3), p.shape[:-1] + (3, 3)), p)


def about(p: np.ndarray, A: np.ndarray) -> np.ndarray:
    """(..., 4, 4) ``T(p) A T(-p)``: the linear map ``A`` about the point ``p``."""
    return translation(p) @ homogeneous(A, np.zeros(np.shape(p))) @ translation(-np.asarray(p))


def apply_homogeneous(M: np.ndarray, P: np.ndarray) -> np.ndarray:
    """Apply one (4, 4) map to every point, or (m, 4, 4) maps section by section, to P (n, m, l, 3)."""
    Ph = np.concatenate([P, np.ones(P.shape[:-1] + (1,))], axis=-1)
    if M.ndim == 2:
        out = Ph @ M.T
    else:
        out = np.einsum("jab,ijkb->ijka", M, Ph)
    return out[..., :3]


def rotation(frame: LatticeFrame, theta: np.ndarray) -> np.ndarray:
    """(m, 3, 3) rotations about the span axis by ``theta`` (radians), positive = nose up.

    In the (chord, thickness) components: c' = c cos + t sin, t' = -c sin + t cos, so a point
    ahead of the axis (c < 0, the leading edge) moves in +thickness for theta > 0.
    """
    c, t = frame.chord_dir, frame.thickness_dir
    C = frame.plane()
    K = np.outer(c, t) - np.outer(t, c)
    cos = np.cos(theta)[:, None, None]
    sin = np.sin(theta)[:, None, None]
    return np.eye(3) + (cos - 1.0) * C + sin * K


def rotation_derivative(frame: LatticeFrame, theta: np.ndarray) -> np.ndarray:
    """(m, 3, 3) d rotation / d theta (per radian)."""
    c, t = frame.chord_dir, frame.thickness_dir
    C = frame.plane()
    K = np.outer(c, t) - np.outer(t, c)
    return -np.sin(theta)[:, None, None] * C + np.cos(theta)[:, None, None] * K


def per_section(a: np.ndarray) -> np.ndarray:
    """(..., m, 3) -> (..., 1, m, 1, 3): broadcast a per-section vector over a lattice."""
    return a[..., None, :, None, :]


# --------------------------------------------------------------------------------------------------
# Per-section values as written
# --------------------------------------------------------------------------------------------------

@dataclass(frozen=True, eq=False)
class SectionLaw:
    """Per-section values as an affine function of the numbers the user wrote.

    ``values = base + basis @ params``; ``suffixes[q]`` names ``params[q]`` relative to the change
    (``"[3]"`` for a list item, ``".tip"``/``".root"`` for ``{root, tip}``, ``""`` for a scalar).
    """

    suffixes: tuple[str, ...]
    params: np.ndarray
    base: np.ndarray
    basis: np.ndarray

    @classmethod
    def listed(cls, values) -> SectionLaw:
        """One value per section, root first (``twist: [0, 5, 10]``)."""
        v = np.array(values, dtype=float).reshape(-1)
        m = v.size
        return cls(tuple(f"[{j}]" for j in range(m)), v, np.zeros(m), np.eye(m))

    @classmethod
    def root_tip(cls, m: int, tip: float, root: float | None = None,
                 default_root: float = 0.0, fractions=None) -> SectionLaw:
        """Linear in the section index from ``root`` (or ``default_root``) at j = 0 to ``tip``; with
        ``fractions`` (m,) (the sections' span fractions, for a box refined spanwise, whose sections
        are not evenly spaced) linear in those."""
        s = np.arange(m) / max(m - 1, 1) if fractions is None else np.asarray(fractions, dtype=float)
        if root is None:
            return cls((".tip",), np.array([float(tip)]), default_root * (1.0 - s), s[:, None].copy())
        return cls((".root", ".tip"), np.array([float(root), float(tip)]), np.zeros(m),
                   np.stack([1.0 - s, s], axis=1))

    @classmethod
    def scalar(cls, value: float, m: int = 1) -> SectionLaw:
        """One number for every section (2D: the whole airfoil)."""
        return cls(("",), np.array([float(value)]), np.zeros(m), np.ones((m, 1)))

    @property
    def values(self) -> np.ndarray:
        """(m,) the value of every section."""
        return self.base + self.basis @ self.params

    def with_params(self, params) -> SectionLaw:
        p = np.array(params, dtype=float).reshape(-1)
        if p.shape != self.params.shape:
            raise ValueError(f"expected {self.params.size} values, got {p.size}")
        return replace(self, params=p)


def as_law(value) -> SectionLaw:
    return value if isinstance(value, SectionLaw) else SectionLaw.listed(value)


# --------------------------------------------------------------------------------------------------
# The changes
# --------------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class SpecContext:
    """What building a change from its YAML needs: the lattice size and where the change is written.

    n, m, l
        Chordwise, spanwise (sections; 1 in 2D) and thickness control points.
    dim
        3 for a wing, 2 for an airfoil.
    key
        The change's key path in the design file (``changes[2].twist``).
    error
        ``error(message, key) -> Exception``: the error to raise (the design file's, with its line).
    box, surface
        The :class:`ffdcli.box.box.Box` and the wing's surface points (N, 3), for the changes that
        read the geometry (the control surfaces); None where no change needs them.
    """

    n: int
    m: int
    l: int
    dim: int
    key: str = "changes"
    error: Callable[[str, str], Exception] | None = None
    box: Any = None
    surface: np.ndarray | None = None

    @property
    def fractions(self) -> np.ndarray | None:
        """(m,) span fractions of the sections of a box refined spanwise (its sections are not evenly
        spaced); None for evenly spaced sections (the section index is the span fraction)."""
        if self.box is None or self.box.dim != 3 or self.box.base_sections is None:
            return None
        st = self.box.stations
        return (st - st[0]) / (st[-1] - st[0])

    @property
    def sections_words(self) -> str:
        """"8 sections (box.points[1])", or where knots were inserted (box.refine, a flap or slat) how
        the box came to have more sections than box.points[1] says."""
        base = getattr(self.box, "base_sections", None)
        if base is None or len(base) == self.m:
            return f"{self.m} sections (box.points[1])"
        return (f"{self.m} sections ({len(base)} of box.points[1] and {self.m - len(base)} inserted by box.refine "
                f"or a flap/slat)")

    def fail(self, message: str, key: str | None = None) -> Exception:
        """The exception for ``message`` at ``key`` (default: the change's own key)."""
        key = self.key if key is None else key
        if self.error is None:
            return InputError(message, key=key)
        return self.error(message, key)


class Change(ABC):
    """Common interface (see the module docstring). Subclasses are frozen dataclasses; a kind implements
    the abstract methods (:meth:`from_spec`, :meth:`apply`, :meth:`variables`, :meth:`with_values`,
    :meth:`jacobian_own`, :meth:`jvp_P`).

    ``from_spec(spec, ctx)`` (a classmethod) builds the change from its YAML value ``spec`` (already
    valid against the schema of :mod:`ffdcli.design.schema`) and checks what needs the lattice
    (list lengths, section indices, the 2D rules); ``ctx`` is a :class:`SpecContext`.
    """

    kind: str = ""
    #: Unit of the variables: ``deg`` (angles), ``factor`` (scale factors), ``length`` (mesh units).
    unit: str = "length"

    def units(self) -> list[str]:
        """The unit of each variable (``deg``, ``factor`` or ``length``)."""
        return [self.unit] * self.size

    @classmethod
    @abstractmethod
    def from_spec(cls, spec, ctx: SpecContext) -> Change:
        """The change of the YAML value ``spec`` (the class docstring)."""

    @abstractmethod
    def apply(self, P: np.ndarray, frame: LatticeFrame) -> np.ndarray:
        """(n, m, l, 3) the lattice ``P`` after the change."""

    @abstractmethod
    def variables(self) -> list[tuple[str, float]]:
        """``[(name, value)]`` of the change's design variables."""

    @abstractmethod
    def with_values(self, values) -> Change:
        """The same change with its variables set to ``values`` (k,)."""

    @abstractmethod
    def jacobian_own(self, P: np.ndarray, frame: LatticeFrame) -> np.ndarray:
        """(k, n, m, l, 3) dP'/d(own variables) at the input lattice ``P``."""

    @abstractmethod
    def jvp_P(self, P: np.ndarray, frame: LatticeFrame, dP: np.ndarray) -> np.ndarray:
        """dP' for a change ``dP`` of the input lattice (the variables held)."""

    def bounds(self, P: np.ndarray, frame: LatticeFrame) -> np.ndarray:
        """(k, 2) natural (lower, upper) bounds of this change's variables at its input lattice ``P``.

        Open intervals: a value must lie strictly between them (``-inf``/``inf``: unbounded)."""
        out = np.empty((self.size, 2))
        out[:, 0], out[:, 1] = -np.inf, np.inf
        return out

    def jvp(self, P: np.ndarray, frame: LatticeFrame, dvalues) -> np.ndarray:
        """dP' for a change ``dvalues`` (k,) of this change's variables (angles in degrees)."""
        d = np.asarray(dvalues, dtype=float).reshape(-1)
        return np.tensordot(d, self.jacobian_own(P, frame), axes=1)

    @property
    def size(self) -> int:
        """Number of design variables."""
        return len(self.variables())


def check_sections(P: np.ndarray, m: int, what: str):
    if P.ndim != 4 or P.shape[-1] != 3:
        raise ValueError(f"a lattice must have shape (n, m, l, 3), got {P.shape}")
    if P.shape[1] != m:
        raise InputError(f"{what} has {m} values but the lattice has {P.shape[1]} sections")


@dataclass(frozen=True, eq=False)
class SectionMap(Change):
    """A change that maps each section j by a 4 x 4 homogeneous matrix from a :class:`SectionLaw`
    of per-section values (twist, chord): ``maps(P, frame)`` gives the (m, 4, 4) matrices."""

    law: SectionLaw
    #: The root value of ``{tip: T}`` (no change at the root).
    default_root = 0.0

    def __post_init__(self):
        object.__setattr__(self, "law", as_law(self.law))

    @classmethod
    def from_spec(cls, spec, ctx: SpecContext) -> SectionMap:
        """One number in 2D; in 3D a list (one per section, root first) or ``{tip: }``/``{root:, tip:}``."""
        kind, m = cls.kind, ctx.m
        if ctx.dim == 2:
            if isinstance(spec, (int, float)):
                return cls(SectionLaw.scalar(spec, 1))
            raise ctx.fail(f"in 2D {kind} takes one number (the whole airfoil, about its trailing edge)")
        if isinstance(spec, list):
            if len(spec) != m:
                raise ctx.fail(f"has {len(spec)} values but the box has {ctx.sections_words}; give one value "
                               "per section, root first, or {tip: value} / {root: value, tip: value}")
            return cls(SectionLaw.listed(spec))
        if isinstance(spec, dict):
            return cls(SectionLaw.root_tip(m, tip=spec["tip"], root=spec.get("root"),
                                           default_root=cls.default_root, fractions=ctx.fractions))
        raise ctx.fail(f"in 3D {kind} takes a list of {m} values (one per section, root first) or "
                       "{tip: value} / {root: value, tip: value}")

    @property
    def values(self) -> np.ndarray:
        return self.law.values

    @abstractmethod
    def maps(self, P, frame) -> np.ndarray:
        """(m, 4, 4) the homogeneous map of each section."""

    def apply(self, P, frame):
        return apply_homogeneous(self.maps(P, frame), P)

    def variables(self):
        return [(self.kind + s, float(v)) for s, v in zip(self.law.suffixes, self.law.params, strict=True)]

    def with_values(self, values):
        return replace(self, law=self.law.with_params(values))


def not_in_2d(kind: str) -> str:
    """The one wording of "this change needs a span": span, sweep and dihedral on an airfoil."""
    return f"{kind} is not defined for a 2D (airfoil) mesh; use twist, chord or shape"


def refuse_2d(frame: LatticeFrame, kind: str):
    if frame.dim == 2:
        raise InputError(not_in_2d(kind))


