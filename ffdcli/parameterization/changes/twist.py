"""Twist: each section rotates about the span axis through a point of its chord line."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from ffdcli.errors import InputError
from ffdcli.parameterization.changes.base import (
    CHANGES,
    DEG,
    SectionMap,
    SpecContext,
    about,
    check_sections,
    per_section,
    rotation,
    rotation_derivative,
)
from ffdcli.schema_parts import number, number_list


@dataclass(frozen=True, eq=False)
class Twist(SectionMap):
    """Rotate section j by ``values[j]`` degrees about the span axis through its axis point.

    ``law`` is a :class:`SectionLaw` or a sequence of degrees per section (root first).
    P' = T(p_j) R(theta_j) T(-p_j) P; positive = nose up (the leading edge moves in +thickness).
    ``axis`` is the chord fraction of p_j on the section's chord line: 1 (default) the
    trailing-edge point (the paper's axis), 0.25 the quarter chord, 0 the leading edge. It is a
    setting, not a design variable.
    """

    axis: float = 1.0
    kind = "twist"

    @classmethod
    def schema(cls) -> dict:
        axis = {"type": "number", "description": "chord fraction of the twist axis on each section's chord "
                                                 "line: 1 trailing edge (default), 0.25 quarter chord, 0 "
                                                 "leading edge"}
        # one object form; which keys go together ({root, tip} | values | angle) is checked by validate
        form = {"type": "object", "additionalProperties": False,
                "properties": {"root": number(), "tip": number(), "values": number_list(), "angle": number(),
                               "axis": axis}}
        return {"description": "degrees: a list (one per section, root first), {tip: T} or "
                               "{root: R, tip: T}; in 2D one number. About another axis than the trailing "
                               "edge: {tip: T, axis: 0.25}, {values: [...], axis: 0.25}, 2D {angle: A, "
                               "axis: 0.25}",
                "anyOf": [number(), number_list(), form]}
    unit = "deg"

    @classmethod
    def from_spec(cls, spec, ctx: SpecContext) -> Twist:
        """The forms of :meth:`SectionMap.from_spec`, and with an axis: ``{tip, axis}``,
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
        check_sections(P, self.law.base.size, "twist")
        return about(frame.chord_points(P, self.axis), rotation(frame, self.values * DEG))

    def jacobian_own(self, P, frame):
        check_sections(P, self.law.base.size, "twist")
        p = frame.chord_points(P, self.axis)
        dR = rotation_derivative(frame, self.values * DEG)
        Y = np.einsum("jab,ijkb->ijka", dR, P - per_section(p))
        return np.einsum("jq,ijkd->qijkd", self.law.basis * DEG, Y)

    def jvp_P(self, P, frame, dP):
        R = rotation(frame, self.values * DEG)
        dp = per_section(frame.chord_points(dP, self.axis))
        return np.einsum("jab,...ijkb->...ijka", R, dP - dp) + dp


CHANGES.register(Twist)
