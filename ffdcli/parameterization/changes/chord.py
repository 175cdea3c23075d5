"""Chord: each section scales in its own plane about its trailing-edge point."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ffdcli.parameterization.changes.base import (
    CHANGES,
    SectionMap,
    about,
    check_sections,
    per_section,
)
from ffdcli.schema_parts import positive, positive_list, root_tip


@dataclass(frozen=True, eq=False)
class Chord(SectionMap):
    """Scale section j by ``values[j]`` in its own plane (chord and thickness) about its TE point.

    ``law`` is a :class:`SectionLaw` or a sequence of factors per section (root first).
    Thickness-to-chord is kept; the span coordinate does not change.
    """

    kind = "chord"
    default_root = 1.0
    unit = "factor"

    @classmethod
    def schema(cls) -> dict:
        return {"description": "scale factors > 0: a list (one per section, root first), {tip: F} or "
                               "{root: F, tip: F} (root default 1); in 2D one number",
                "anyOf": [positive(), positive_list(), root_tip(positive())]}

    def bounds(self, P, frame):
        """Every factor of the written law (list item, root, tip) must be > 0 (a section of no or
        negative chord is folded)."""
        out = super().bounds(P, frame)
        out[:, 0] = 0.0
        return out

    def _scales(self, frame):
        return np.eye(3) + (self.values - 1.0)[:, None, None] * frame.plane()

    def maps(self, P, frame):
        check_sections(P, self.law.base.size, "chord")
        return about(frame.ref_points(P), self._scales(frame))

    def jacobian_own(self, P, frame):
        check_sections(P, self.law.base.size, "chord")
        Y = (P - per_section(frame.ref_points(P))) @ frame.plane()
        return np.einsum("jq,ijkd->qijkd", self.law.basis, Y)

    def jvp_P(self, P, frame, dP):
        S = self._scales(frame)
        dp = per_section(frame.ref_points(dP))
        return np.einsum("jab,...ijkb->...ijka", S, dP - dp) + dp


CHANGES.register(Chord)
