"""Span: every point's span distance from the root section is scaled."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ffdcli.parameterization.changes.base import (
    CHANGES,
    Change,
    SpecContext,
    about,
    apply_homogeneous,
    not_in_2d,
    refuse_2d,
)
from ffdcli.schema_parts import positive


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
    def schema(cls) -> dict:
        return {"description": "a span scale factor > 0 about the root section", **positive()}

    @classmethod
    def from_spec(cls, spec, ctx: SpecContext) -> Span:
        """A scale factor > 0; not in 2D."""
        if ctx.dim == 2:
            raise ctx.fail(not_in_2d(cls.kind))
        return cls(float(spec))

    def maps(self, P, frame):
        refuse_2d(frame, "span")
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
        refuse_2d(frame, "span")
        e = frame.span_dir
        d = (P - frame.ref_points(P)[0]) @ e
        return (d[..., None] * e)[None]

    def jvp_P(self, P, frame, dP):
        e = frame.span_dir
        dp0 = frame.ref_points(dP)[..., 0, :]
        dd = (dP - dp0[..., None, None, None, :]) @ e
        return dP + (self.scale - 1.0) * dd[..., None] * e


CHANGES.register(Span)
