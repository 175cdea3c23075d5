"""The design changes: twist, span, sweep, dihedral, chord and shape as maps of lattice sections.

A lattice ``P`` has shape ``(n, m, l, 3)``: ``i`` chordwise (0 = leading-edge side), ``j`` spanwise
(0 = root section), ``k`` thickness (0 = lower side), in mesh coordinates. A 2D lattice has
``m = 1``. The directions and reference points the changes need are held by a :class:`LatticeFrame`.

Each change is a frozen dataclass with

``apply(P, frame) -> P'``
    the change itself, as affine maps in homogeneous coordinates (4 x 4 ``T(p) R T(-p)`` per
    section for twist and chord, one 4 x 4 scale or shear for span, sweep and dihedral) plus
    translations for sweep/dihedral offsets and shape;
``variables() -> [(name, value), ...]``
    its design variables, named relative to the change as written in the design file
    (``twist[7]`` for a list, ``twist.tip`` for ``{tip: }``, ``span`` for a scalar);
``with_values(values) -> change``
    the same change with new values of its variables;
``jacobian_own(P, frame) -> (k, n, m, l, 3)``, ``jvp(P, frame, dvalues) -> dP'``
    the derivative of ``apply`` with respect to its own variables (per degree for angles);
``jvp_P(P, frame, dP) -> dP'``
    the derivative with respect to the input lattice (the trailing-edge points and the sweep and
    dihedral angles depend on ``P``); ``dP`` may carry leading batch axes ``(..., n, m, l, 3)``;
``bounds(P, frame) -> (k, 2)``
    the natural bounds of its variables as an open interval (lower, upper) per variable: chord and
    span factors > 0, a sweep or dihedral angle that keeps the leading-edge line within
    +-``MAX_SHEAR_ANGLE`` of the span axis; twist, offsets and shape moves are unbounded.

All derivatives are analytic. :func:`apply_changes`, :func:`design_variables` and
:func:`set_design_variables` work on a whole pipeline (a list of changes applied in order).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import numpy as np

from ffdcli.box.frame import LatticeFrame
from ffdcli.errors import InputError

#: Radians per degree: angles are given and differentiated in degrees.
DEG = math.pi / 180.0
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


def _section(a: np.ndarray) -> np.ndarray:
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
                 default_root: float = 0.0) -> SectionLaw:
        """Linear in the section index from ``root`` (or ``default_root``) at j = 0 to ``tip``."""
        s = np.arange(m) / max(m - 1, 1)
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


def _law(value) -> SectionLaw:
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
    """

    n: int
    m: int
    l: int
    dim: int
    key: str = "changes"
    error: Callable[[str, str], Exception] | None = None

    def fail(self, message: str, key: str | None = None) -> Exception:
        """The exception for ``message`` at ``key`` (default: the change's own key)."""
        key = self.key if key is None else key
        if self.error is None:
            return InputError(message, key=key)
        return self.error(message, key)


class Change:
    """Common interface (see the module docstring). Subclasses are frozen dataclasses.

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
    def from_spec(cls, spec, ctx: SpecContext) -> Change:  # pragma: no cover
        raise NotImplementedError

    def apply(self, P: np.ndarray, frame: LatticeFrame) -> np.ndarray:  # pragma: no cover
        raise NotImplementedError

    def variables(self) -> list[tuple[str, float]]:  # pragma: no cover
        raise NotImplementedError

    def with_values(self, values) -> Change:  # pragma: no cover
        raise NotImplementedError

    def jacobian_own(self, P: np.ndarray, frame: LatticeFrame) -> np.ndarray:  # pragma: no cover
        raise NotImplementedError

    def jvp_P(self, P: np.ndarray, frame: LatticeFrame, dP: np.ndarray) -> np.ndarray:  # pragma: no cover
        raise NotImplementedError

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


def _check_sections(P: np.ndarray, m: int, what: str):
    if P.ndim != 4 or P.shape[-1] != 3:
        raise ValueError(f"a lattice must have shape (n, m, l, 3), got {P.shape}")
    if P.shape[1] != m:
        raise InputError(f"{what} has {m} values but the lattice has {P.shape[1]} sections")


@dataclass(frozen=True, eq=False)
class _SectionMap(Change):
    """A change that maps each section j by a 4 x 4 homogeneous matrix from a :class:`SectionLaw`
    of per-section values (twist, chord): ``maps(P, frame)`` gives the (m, 4, 4) matrices."""

    law: SectionLaw
    #: The root value of ``{tip: T}`` (no change at the root).
    default_root = 0.0

    def __post_init__(self):
        object.__setattr__(self, "law", _law(self.law))

    @classmethod
    def from_spec(cls, spec, ctx: SpecContext) -> _SectionMap:
        """One number in 2D; in 3D a list (one per section, root first) or ``{tip: }``/``{root:, tip:}``."""
        kind, m = cls.kind, ctx.m
        if ctx.dim == 2:
            if isinstance(spec, (int, float)):
                return cls(SectionLaw.scalar(spec, 1))
            raise ctx.fail(f"in 2D {kind} takes one number (the whole airfoil, about its trailing edge)")
        if isinstance(spec, list):
            if len(spec) != m:
                raise ctx.fail(f"has {len(spec)} values but the box has {m} sections (box.points[1]); "
                               "give one value per section, root first")
            return cls(SectionLaw.listed(spec))
        if isinstance(spec, dict):
            return cls(SectionLaw.root_tip(m, tip=spec["tip"], root=spec.get("root"),
                                           default_root=cls.default_root))
        raise ctx.fail(f"in 3D {kind} takes a list of {m} values (one per section, root first) or "
                       "{tip: value} / {root: value, tip: value}")

    @property
    def values(self) -> np.ndarray:
        return self.law.values

    def maps(self, P, frame) -> np.ndarray:  # pragma: no cover
        raise NotImplementedError

    def apply(self, P, frame):
        return apply_homogeneous(self.maps(P, frame), P)

    def variables(self):
        return [(self.kind + s, float(v)) for s, v in zip(self.law.suffixes, self.law.params, strict=True)]

    def with_values(self, values):
        return replace(self, law=self.law.with_params(values))


@dataclass(frozen=True, eq=False)
class Twist(_SectionMap):
    """Rotate section j by ``values[j]`` degrees about the span axis through its axis point.

    ``law`` is a :class:`SectionLaw` or a sequence of degrees per section (root first).
    P' = T(p_j) R(theta_j) T(-p_j) P; positive = nose up (the leading edge moves in +thickness).
    ``axis`` is the chord fraction of p_j on the section's chord line: 1 (default) the
    trailing-edge point (the paper's axis), 0.25 the quarter chord, 0 the leading edge. It is a
    setting, not a design variable.
    """

    axis: float = 1.0
    kind = "twist"
    unit = "deg"

    @classmethod
    def from_spec(cls, spec, ctx: SpecContext) -> Twist:
        """The forms of :meth:`_SectionMap.from_spec`, and with an axis: ``{tip, axis}``,
        ``{root, tip, axis}``, ``{values: [...], axis}`` (the list form) and in 2D
        ``{angle: A, axis}`` (the one-number form)."""
        if not isinstance(spec, dict):
            return super().from_spec(spec, ctx)
        spec = dict(spec)
        axis = float(spec.pop("axis", 1.0))
        if "values" in spec:
            spec, ctx = spec["values"], replace(ctx, key=ctx.key + ".values")
        elif "angle" in spec:
            if ctx.dim == 3:
                raise ctx.fail("{angle: A} is the 2D form; in 3D give {tip: T} or {values: [...]} with "
                               "the axis")
            spec, ctx = spec["angle"], replace(ctx, key=ctx.key + ".angle")
        return replace(super().from_spec(spec, ctx), axis=axis)

    def __post_init__(self):
        super().__post_init__()
        a = float(self.axis)
        if not math.isfinite(a):
            raise InputError(f"twist axis must be a finite chord fraction, got {self.axis!r}")
        object.__setattr__(self, "axis", a)

    def maps(self, P, frame) -> np.ndarray:
        """(m, 4, 4) homogeneous maps of the sections."""
        _check_sections(P, self.law.base.size, "twist")
        return about(frame.chord_points(P, self.axis), rotation(frame, self.values * DEG))

    def jacobian_own(self, P, frame):
        _check_sections(P, self.law.base.size, "twist")
        p = frame.chord_points(P, self.axis)
        dR = rotation_derivative(frame, self.values * DEG)
        Y = np.einsum("jab,ijkb->ijka", dR, P - _section(p))
        return np.einsum("jq,ijkd->qijkd", self.law.basis * DEG, Y)

    def jvp_P(self, P, frame, dP):
        R = rotation(frame, self.values * DEG)
        dp = _section(frame.chord_points(dP, self.axis))
        return np.einsum("jab,...ijkb->...ijka", R, dP - dp) + dp


@dataclass(frozen=True, eq=False)
class Chord(_SectionMap):
    """Scale section j by ``values[j]`` in its own plane (chord and thickness) about its TE point.

    ``law`` is a :class:`SectionLaw` or a sequence of factors per section (root first).
    Thickness-to-chord is kept; the span coordinate does not change.
    """

    kind = "chord"
    default_root = 1.0
    unit = "factor"

    def bounds(self, P, frame):
        """Every factor of the written law (list item, root, tip) must be > 0 (a section of no or
        negative chord is folded)."""
        out = super().bounds(P, frame)
        out[:, 0] = 0.0
        return out

    def _scales(self, frame):
        return np.eye(3) + (self.values - 1.0)[:, None, None] * frame.plane()

    def maps(self, P, frame):
        _check_sections(P, self.law.base.size, "chord")
        return about(frame.ref_points(P), self._scales(frame))

    def jacobian_own(self, P, frame):
        _check_sections(P, self.law.base.size, "chord")
        Y = (P - _section(frame.ref_points(P))) @ frame.plane()
        return np.einsum("jq,ijkd->qijkd", self.law.basis, Y)

    def jvp_P(self, P, frame, dP):
        S = self._scales(frame)
        dp = _section(frame.ref_points(dP))
        return np.einsum("jab,...ijkb->...ijka", S, dP - dp) + dp


def not_in_2d(kind: str) -> str:
    """The one wording of "this change needs a span": span, sweep and dihedral on an airfoil."""
    return f"{kind} is not defined for a 2D (airfoil) mesh; use twist, chord or shape"


def _no_2d(frame: LatticeFrame, kind: str):
    if frame.dim == 2:
        raise InputError(not_in_2d(kind))


@dataclass(frozen=True, eq=False)
class Span(Change):
    """Multiply every point's span coordinate, measured from the root section, by ``scale``.

    The root plane is the span coordinate of the root's trailing-edge point p_0:
    x' = x + (s - 1) ((x - p_0) . e_span) e_span, i.e. T(p_0) (I + (s-1) e e^T) T(-p_0).
    """

    scale: float
    kind = "span"
    unit = "factor"

    @classmethod
    def from_spec(cls, spec, ctx: SpecContext) -> Span:
        """A scale factor > 0; not in 2D."""
        if ctx.dim == 2:
            raise ctx.fail(not_in_2d(cls.kind))
        return cls(float(spec))

    def maps(self, P, frame):
        _no_2d(frame, "span")
        e = frame.span_dir
        return about(frame.ref_points(P)[0], np.eye(3) + (self.scale - 1.0) * np.outer(e, e))

    def apply(self, P, frame):
        return apply_homogeneous(self.maps(P, frame), P)

    def variables(self):
        return [(self.kind, float(self.scale))]

    def bounds(self, P, frame):
        """The span factor must be > 0."""
        return np.array([[0.0, np.inf]])

    def with_values(self, values):
        (v,) = np.asarray(values, dtype=float).reshape(-1)
        return replace(self, scale=float(v))

    def jacobian_own(self, P, frame):
        _no_2d(frame, "span")
        e = frame.span_dir
        d = (P - frame.ref_points(P)[0]) @ e
        return (d[..., None] * e)[None]

    def jvp_P(self, P, frame, dP):
        e = frame.span_dir
        dp0 = frame.ref_points(dP)[..., 0, :]
        dd = (dP - dp0[..., None, None, None, :]) @ e
        return dP + (self.scale - 1.0) * dd[..., None] * e


@dataclass(frozen=True, eq=False)
class _Shear(Change):
    """Sweep (shift along chord) and dihedral (shift along thickness): an angle or offsets.

    ``delta`` (degrees): a shear x' = x + k d e, d = (x - p_0) . e_span the span distance from the
    root section, k = tan(L + delta) - tan(L), L the angle of the leading-edge line (root -> tip
    leading-edge points of the surface) towards e in the plane of e and the span axis. The
    leading-edge line's angle becomes exactly L + delta.
    ``offsets`` (a :class:`SectionLaw` or a list per section, mesh units): section j moves by
    offsets[j] along e.
    Exactly one of the two is given.
    """

    delta: float | None = None
    offsets: SectionLaw | None = None

    def __post_init__(self):
        if (self.delta is None) == (self.offsets is None):
            raise ValueError(f"{self.kind}: give exactly one of delta and offsets")
        if self.offsets is not None:
            object.__setattr__(self, "offsets", _law(self.offsets))

    @classmethod
    def from_spec(cls, spec, ctx: SpecContext) -> _Shear:
        """Degrees, or ``{offsets: [one per section]}``; not in 2D."""
        if ctx.dim == 2:
            raise ctx.fail(not_in_2d(cls.kind))
        if isinstance(spec, dict):
            offsets = spec["offsets"]
            if len(offsets) != ctx.m:
                raise ctx.fail(f"has {len(offsets)} values but the box has {ctx.m} sections (box.points[1])",
                               ctx.key + ".offsets")
            return cls(offsets=SectionLaw.listed(offsets))
        return cls(delta=float(spec))

    def _dir(self, frame) -> np.ndarray:  # pragma: no cover
        raise NotImplementedError

    def angle(self, P, frame) -> float:
        """The current angle of the leading-edge line, radians."""
        le = frame.le_points(P)
        v = le[1] - le[0]
        return math.atan2(float(v @ self._dir(frame)), float(v @ frame.span_dir))

    def _k(self, P, frame):
        lam = self.angle(P, frame)
        if abs(lam + self.delta * DEG) >= MAX_SHEAR_ANGLE * DEG:
            raise InputError(f"{self.kind} {self.delta:g}: the leading-edge angle would become "
                             f"{math.degrees(lam) + self.delta:.1f} degrees; it must stay within "
                             f"+-{MAX_SHEAR_ANGLE:g}")
        return lam, math.tan(lam + self.delta * DEG) - math.tan(lam)

    def maps(self, P, frame):
        """(4, 4) for an angle, (m, 4, 4) translations for offsets."""
        _no_2d(frame, self.kind)
        e = self._dir(frame)
        if self.offsets is not None:
            _check_sections(P, self.offsets.base.size, f"{self.kind} offsets")
            return translation(self.offsets.values[:, None] * e)
        _, k = self._k(P, frame)
        return about(frame.ref_points(P)[0], np.eye(3) + k * np.outer(e, frame.span_dir))

    def apply(self, P, frame):
        return apply_homogeneous(self.maps(P, frame), P)

    def variables(self):
        if self.offsets is not None:
            return [(f"{self.kind}.offsets{s}", float(v))
                    for s, v in zip(self.offsets.suffixes, self.offsets.params, strict=True)]
        return [(self.kind, float(self.delta))]

    def units(self):
        return ["length" if self.offsets is not None else "deg"] * self.size

    def bounds(self, P, frame):
        """An angle: the leading-edge line must stay within +-``MAX_SHEAR_ANGLE`` of the span axis,
        so ``delta`` lies in (-MAX - L, MAX - L) for the current angle L of ``P``; offsets: none."""
        if self.offsets is not None:
            return super().bounds(P, frame)
        lam = math.degrees(self.angle(P, frame))
        return np.array([[-MAX_SHEAR_ANGLE - lam, MAX_SHEAR_ANGLE - lam]])

    def with_values(self, values):
        if self.offsets is not None:
            return replace(self, offsets=self.offsets.with_params(values))
        (v,) = np.asarray(values, dtype=float).reshape(-1)
        return replace(self, delta=float(v))

    def jacobian_own(self, P, frame):
        _no_2d(frame, self.kind)
        e = self._dir(frame)
        if self.offsets is not None:
            _check_sections(P, self.offsets.base.size, f"{self.kind} offsets")
            n, m, l, _ = P.shape
            per = self.offsets.basis.T[:, None, :, None, None] * e        # (q, 1, m, 1, 3)
            return np.broadcast_to(per, (per.shape[0], n, m, l, 3)).copy()
        lam, _ = self._k(P, frame)
        d = (P - frame.ref_points(P)[0]) @ frame.span_dir
        sec2 = 1.0 / math.cos(lam + self.delta * DEG) ** 2
        return (sec2 * DEG * d[..., None] * e)[None]

    def jvp_P(self, P, frame, dP):
        if self.offsets is not None:
            return np.array(dP, dtype=float, copy=True)
        e, s = self._dir(frame), frame.span_dir
        lam, k = self._k(P, frame)
        le = frame.le_points(P)
        v = le[1] - le[0]
        ve, vs = float(v @ e), float(v @ s)
        dle = frame.le_points(dP)
        dv = dle[..., 1, :] - dle[..., 0, :]
        dlam = (vs * (dv @ e) - ve * (dv @ s)) / (vs * vs + ve * ve)              # (...)
        dk = (1.0 / math.cos(lam + self.delta * DEG) ** 2 - 1.0 / math.cos(lam) ** 2) * dlam
        p0 = frame.ref_points(P)[0]
        d = (P - p0) @ s                                                           # (n, m, l)
        dp0 = frame.ref_points(dP)[..., 0, :]
        dd = (dP - dp0[..., None, None, None, :]) @ s                              # (..., n, m, l)
        dk = np.asarray(dk)[..., None, None, None]
        return dP + (dd * k + d * dk)[..., None] * e


@dataclass(frozen=True, eq=False)
class Sweep(_Shear):
    """Sweep: ``delta`` degrees added to the leading-edge sweep angle, or chordwise ``offsets``."""

    kind = "sweep"

    def _dir(self, frame):
        return frame.chord_dir


@dataclass(frozen=True, eq=False)
class Dihedral(_Shear):
    """Dihedral: ``delta`` degrees added to the dihedral angle (tip up is positive), or ``offsets``
    along the thickness axis."""

    kind = "dihedral"

    def _dir(self, frame):
        return frame.thickness_dir


@dataclass(frozen=True, eq=False)
class Shape(Change):
    """Move control points along the thickness axis (mesh units).

    upper, lower
        (n,) one value per chordwise index for the upper (k = l-1) / lower (k = 0) row of every
        section in ``sections``; or (n, m) one value per point and section (a random shape
        expanded at load time; ``sections`` is then ignored). ``None``: that side does not move.
    sections
        Section indices, or None for all sections.
    rows
        (l, n) one value per thickness row k (0 = lower ... l-1 = upper) and chordwise index i, for
        every section in ``sections`` (an extension: ``ffd fit --rows all`` moves every row).
    Variables: ``shape.upper[i]`` / ``shape.lower[i]``; for (n, m) arrays ``shape.upper[i,j]``;
    ``shape.rows[k][i]``.
    """

    upper: np.ndarray | None = None
    lower: np.ndarray | None = None
    sections: tuple[int, ...] | None = None
    rows: np.ndarray | None = None
    kind = "shape"

    @classmethod
    def from_spec(cls, spec, ctx: SpecContext) -> Shape:
        """``{upper: [n], lower: [n], sections: all | [j, ...]}``, ``{rows: [l lists of n]}`` or
        ``{random: A, seed: S}`` (``default_rng(S).uniform(-A, A, size=(2, n, m))``: upper, lower)."""
        n, m, l, key = ctx.n, ctx.m, ctx.l, ctx.key
        if "random" in spec:
            rng = np.random.default_rng(int(spec.get("seed", 0)))
            try:
                upper, lower = rng.uniform(-spec["random"], spec["random"], size=(2, n, m))
            except OverflowError:
                raise ctx.fail(f"{spec['random']:g} is too large for a uniform draw", key + ".random") from None
            return cls(upper, lower)
        for side in ("upper", "lower"):
            if side in spec and len(spec[side]) != n:
                raise ctx.fail(f"has {len(spec[side])} values but the box has {n} chordwise points "
                               "(box.points[0])", f"{key}.{side}")
        sections = spec.get("sections", "all")
        if sections == "all":
            sections = None
        else:
            for q, j in enumerate(sections):
                if not 0 <= j < m:
                    raise ctx.fail(f"section {j} does not exist: sections run from 0 (root) to {m - 1}",
                                   f"{key}.sections[{q}]")
        rows = spec.get("rows")
        if rows is not None:
            if len(rows) != l:
                raise ctx.fail(f"has {len(rows)} rows but the box has {l} thickness points (box.points[-1])",
                               f"{key}.rows")
            for k, row in enumerate(rows):
                if len(row) != n:
                    raise ctx.fail(f"has {len(row)} values but the box has {n} chordwise points "
                                   "(box.points[0])", f"{key}.rows[{k}]")
        return cls(spec.get("upper"), spec.get("lower"), sections, rows=rows)

    def __post_init__(self):
        for side in ("upper", "lower"):
            v = getattr(self, side)
            if v is not None:
                v = np.array(v, dtype=float)
                if v.ndim not in (1, 2):
                    raise ValueError(f"shape.{side} must have shape (n,) or (n, m)")
                object.__setattr__(self, side, v)
        if self.rows is not None:
            r = np.array(self.rows, dtype=float)
            if r.ndim != 2:
                raise ValueError("shape.rows must have shape (l, n)")
            object.__setattr__(self, "rows", r)
        if self.upper is None and self.lower is None and self.rows is None:
            raise ValueError("shape: give upper, lower or both (or rows)")
        if self.sections is not None:
            object.__setattr__(self, "sections", tuple(int(j) for j in self.sections))

    def _sides(self):
        out = [(side, k, getattr(self, side)) for side, k in (("upper", -1), ("lower", 0))
               if getattr(self, side) is not None]
        if self.rows is not None:
            out += [(f"rows[{k}]", k, row) for k, row in enumerate(self.rows)]
        return out

    def _check(self, P):
        n, m = P.shape[0], P.shape[1]
        if self.rows is not None and self.rows.shape != (P.shape[2], n):
            raise InputError(f"shape.rows has shape {self.rows.shape} but the lattice has l={P.shape[2]}, n={n}")
        for side, _, v in self._sides():
            if v.shape[0] != n or (v.ndim == 2 and v.shape[1] != m):
                raise InputError(f"shape.{side} has shape {v.shape} but the lattice has n={n}, m={m}")
        if self.sections is not None and any(not 0 <= j < m for j in self.sections):
            raise InputError(f"shape.sections {list(self.sections)}: section indices run from 0 to {m - 1}")

    def _cols(self, m):
        return list(range(m)) if self.sections is None else list(self.sections)

    def amounts(self, P) -> np.ndarray:
        """(n, m, l) displacement of every control point along the thickness axis."""
        self._check(P)
        n, m, l, _ = P.shape
        a = np.zeros((n, m, l))
        for _, k, v in self._sides():
            if v.ndim == 2:
                a[:, :, k] += v
            else:
                a[:, self._cols(m), k] += v[:, None]
        return a

    def apply(self, P, frame):
        return P + self.amounts(P)[..., None] * frame.thickness_dir

    def variables(self):
        out = []
        for side, _, v in self._sides():
            if v.ndim == 2:
                out += [(f"shape.{side}[{i},{j}]", float(v[i, j]))
                        for i in range(v.shape[0]) for j in range(v.shape[1])]
            else:
                out += [(f"shape.{side}[{i}]", float(x)) for i, x in enumerate(v)]
        return out

    def with_values(self, values):
        vals = np.asarray(values, dtype=float).reshape(-1)
        if vals.size != self.size:
            raise ValueError(f"shape: expected {self.size} values, got {vals.size}")
        new, at = {}, 0
        rows = None if self.rows is None else self.rows.copy()
        for side, k, v in self._sides():
            if side.startswith("rows["):
                rows[k] = vals[at:at + v.size]
            else:
                new[side] = vals[at:at + v.size].reshape(v.shape)
            at += v.size
        if rows is not None:
            new["rows"] = rows
        return replace(self, **new)

    def jacobian_own(self, P, frame):
        self._check(P)
        n, m, l, _ = P.shape
        J = np.zeros((self.size, n, m, l, 3))
        q = 0
        for _, k, v in self._sides():
            if v.ndim == 2:
                for i in range(v.shape[0]):
                    for j in range(v.shape[1]):
                        J[q, i, j, k] = frame.thickness_dir
                        q += 1
            else:
                cols = self._cols(m)
                for i in range(v.shape[0]):
                    J[q, i, cols, k] = frame.thickness_dir
                    q += 1
        return J

    def jvp_P(self, P, frame, dP):
        return np.array(dP, dtype=float, copy=True)


# --------------------------------------------------------------------------------------------------
# A pipeline
# --------------------------------------------------------------------------------------------------

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


# --------------------------------------------------------------------------------------------------
# Changes from the design file
# --------------------------------------------------------------------------------------------------

#: The change class of each kind of the design file (``changes: - twist: ...``).
CHANGE_CLASSES: dict[str, type[Change]] = {c.kind: c for c in (Twist, Span, Sweep, Dihedral, Chord, Shape)}


def changes_from_spec(specs, n: int, m: int, l: int, dim: int, error=None) -> list[Change]:
    """The change objects of a ``changes`` list (as written in a design file) for a lattice of
    n x m x l points (2D: m = 1).

    ``error(message, key) -> Exception`` makes the error of a change the lattice refuses (default: an
    :class:`InputError` naming the key, ``changes[2].twist``). Each item has one key, its kind.
    """
    out = []
    for index, item in enumerate(specs):
        (kind, spec), = item.items()
        ctx = SpecContext(n=n, m=m, l=l, dim=dim, key=f"changes[{index}].{kind}", error=error)
        cls = CHANGE_CLASSES.get(kind)
        if cls is None:                         # pragma: no cover (the schema rejects it)
            raise ctx.fail(f"unknown change '{kind}'")
        out.append(cls.from_spec(spec, ctx))
    return out
