"""The automatic box: a B-spline lattice fitted to a wing, section by section.

(Settings only for now; the builder arrives with the automatic-box issue.)
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class BoxSettings:
    """What the user chooses about the lattice (``box:`` in the design file, options of ``ffd box``).

    points
        (n, m, l) in 3D, (n, l) in 2D: chordwise, spanwise, thickness control points.
    degree
        Per direction; ``None`` means min(3, points - 1).
    sections
        ``"xy"`` etc. (chord axis, thickness axis); ``None`` = detected.
    margin
        Clearance between the surface and the lattice, as a fraction of the local chord.
    root
        ``"min"``/``"max"``: the end of the span axis where the root is; ``None`` = detected.
    file
        A Plot3D lattice to use instead of building one (pyGeo/DAFoam users' boxes).
    """

    points: tuple[int, ...] = (6, 8, 2)
    degree: tuple[int, ...] | None = None
    sections: str | None = None
    margin: float = 0.02
    root: str | None = None
    file: str | None = None

    def degrees(self) -> tuple[int, ...]:
        if self.degree is not None:
            return tuple(self.degree)
        return tuple(min(3, p - 1) for p in self.points)
