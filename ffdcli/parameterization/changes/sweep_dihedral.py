"""Sweep and dihedral: shears of the lattice along chord or thickness (an angle or offsets)."""

from __future__ import annotations

import math
from abc import abstractmethod
from dataclasses import dataclass, replace

import numpy as np

from ffdcli.errors import InputError
from ffdcli.parameterization.changes.base import (
    CHANGES,
    DEG,
    MAX_SHEAR_ANGLE,
    Change,
    SectionLaw,
    SpecContext,
    about,
    apply_homogeneous,
    as_law,
    check_sections,
    not_in_2d,
    refuse_2d,
    translation,
)
from ffdcli.schema_parts import number, number_list


@dataclass(frozen=True, eq=False)
class Shear(Change):
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
            object.__setattr__(self, "offsets", as_law(self.offsets))

    @classmethod
    def from_spec(cls, spec, ctx: SpecContext) -> Shear:
        """Degrees, or ``{offsets: [one per section]}``; not in 2D."""
        if ctx.dim == 2:
            raise ctx.fail(not_in_2d(cls.kind))
        if isinstance(spec, dict):
            offsets = spec["offsets"]
            if len(offsets) != ctx.m:
                raise ctx.fail(f"has {len(offsets)} values but the box has {ctx.sections_words}",
                               ctx.key + ".offsets")
            return cls(offsets=SectionLaw.listed(offsets))
        return cls(delta=float(spec))

    @abstractmethod
    def _dir(self, frame) -> np.ndarray:
        """(3,) the direction the leading edge is sheared along (chord for sweep, thickness for dihedral)."""

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
        refuse_2d(frame, self.kind)
        e = self._dir(frame)
        if self.offsets is not None:
            check_sections(P, self.offsets.base.size, f"{self.kind} offsets")
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
        refuse_2d(frame, self.kind)
        e = self._dir(frame)
        if self.offsets is not None:
            check_sections(P, self.offsets.base.size, f"{self.kind} offsets")
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
class Sweep(Shear):
    """Sweep: ``delta`` degrees added to the leading-edge sweep angle, or chordwise ``offsets``."""

    kind = "sweep"

    @classmethod
    def schema(cls) -> dict:
        return shear_schema("leading-edge sweep")

    def _dir(self, frame):
        return frame.chord_dir


@dataclass(frozen=True, eq=False)
class Dihedral(Shear):
    """Dihedral: ``delta`` degrees added to the dihedral angle (tip up is positive), or ``offsets``
    along the thickness axis."""

    kind = "dihedral"

    @classmethod
    def schema(cls) -> dict:
        return shear_schema("dihedral (tip up positive)")

    def _dir(self, frame):
        return frame.thickness_dir


def shear_schema(what: str) -> dict:
    """The YAML of a sweep or dihedral: degrees added to the angle, or ``{offsets: [...]}``."""
    return {"description": f"degrees added to the {what} angle, or {{offsets: [one per section]}}"
                           " (mesh length units)",
            "anyOf": [number(), {"type": "object", "properties": {"offsets": number_list()},
                                 "required": ["offsets"], "additionalProperties": False}]}


CHANGES.register(Sweep)
CHANGES.register(Dihedral)
