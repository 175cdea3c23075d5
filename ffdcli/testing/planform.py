"""Parametric wing planforms in exact closed form (a fixture: geometry oracles for the tests).

A wing is described in local coordinates ``(c, t, s)``: chordwise, thickness ("up") and spanwise
distance from the root plane. :class:`Planform` maps them to mesh axes (``sections="xy"``: chord x,
thickness y, span z; ``"xz"``: chord x, thickness z, span y; any choice of
:data:`ffdcli.geometry.axes.SECTION_CHOICES`), a span sign (+1: the wing grows along +span axis, -1 a
left wing growing along -span) and a root offset. Sections lie in planes normal to the span axis; the
spanwise station is ``eta`` in [0, 1] (0 = root plane, 1 = tip plane), at span distance
``eta * semi_span``. The sections are NACA 4-digit (:mod:`ffdcli.testing.naca`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ffdcli.geometry.axes import SECTION_CHOICES, parse_sections
from ffdcli.testing.naca import naca4, parse_naca4


@dataclass(frozen=True)
class Planform:
    """A straight-tapered wing with optional trailing-edge kink, in exact closed form.

    semi_span
        Span distance from the root plane to the tip plane (mesh length units).
    root_chord, taper
        Root chord and tip/root chord ratio of the reference trapezoid: the chord without the kink
        extension is ``root_chord * (1 + (taper - 1) * eta)``.
    le_sweep_deg, dihedral_deg
        Angle of the leading-edge line in the chord-span plane (positive: tip aft) and in the
        span-thickness plane (positive: tip up). Sections stay in planes normal to the span axis;
        sweep and dihedral are shears, so with ``twist_axis = 0`` the leading-edge points of all
        sections lie exactly on the line through the root leading edge with these two angles.
    twist_root_deg, twist_tip_deg, twist_axis
        Section incidence, linear in ``eta``, positive nose up (leading edge raised). Each section
        is rotated about the axis parallel to the span through its chord-line point at chord
        fraction ``twist_axis`` (0 = leading edge, the default, 0.25 = quarter chord, 1 = trailing
        edge).
    root_airfoil, tip_airfoil
        NACA 4-digit codes; the unit-chord coordinates are blended linearly in ``eta`` (same point
        count and spacing), so thickness and camber may vary along the span. ``tip_airfoil=None``
        uses the root section everywhere.
    kink_eta, kink_te_extension
        Optional trailing-edge kink (the CRM "Yehudi"): inboard of ``kink_eta`` the trailing edge
        is the straight line from the trapezoid's trailing edge at the kink to a root trailing edge
        moved aft by ``kink_te_extension`` (length units); outboard it follows the taper. The
        leading edge is unchanged. The root chord is then ``root_chord + kink_te_extension``.
    closed_te
        Sharp (True) or blunt trailing edge of the NACA sections.
    sections, span_sign, root_offset
        Mesh axes (``"xy"``: chord x, thickness y, span z), direction of growth along the span axis
        (+1 or -1 for a left wing) and the mesh position of the root leading edge.
    """

    semi_span: float = 3.0
    root_chord: float = 1.0
    taper: float = 1.0
    le_sweep_deg: float = 0.0
    dihedral_deg: float = 0.0
    twist_root_deg: float = 0.0
    twist_tip_deg: float = 0.0
    twist_axis: float = 0.0
    root_airfoil: str = "0012"
    tip_airfoil: str | None = None
    kink_eta: float | None = None
    kink_te_extension: float = 0.0
    closed_te: bool = True
    sections: str = "xy"
    span_sign: float = 1.0
    root_offset: tuple[float, float, float] = field(default=(0.0, 0.0, 0.0))

    def __post_init__(self):
        if not self.semi_span > 0 or not self.root_chord > 0 or not self.taper > 0:
            raise ValueError("semi_span, root_chord and taper must be positive")
        if not (abs(self.le_sweep_deg) < 90 and abs(self.dihedral_deg) < 90):
            raise ValueError("sweep and dihedral must be between -90 and 90 degrees")
        if self.span_sign not in (1, -1):
            raise ValueError(f"span_sign must be +1 or -1, got {self.span_sign}")
        if self.kink_eta is not None and not 0 < self.kink_eta < 1:
            raise ValueError(f"kink_eta must be strictly between 0 and 1, got {self.kink_eta}")
        if self.kink_te_extension < 0 or (self.kink_te_extension > 0 and self.kink_eta is None):
            raise ValueError("kink_te_extension must be >= 0 and needs kink_eta")
        parse_naca4(self.root_airfoil)
        if self.tip_airfoil is not None:
            parse_naca4(self.tip_airfoil)
        if str(self.sections).strip().lower() not in SECTION_CHOICES:
            raise ValueError(f"sections must be one of {', '.join(SECTION_CHOICES)}, got {self.sections!r}")
        if len(self.root_offset) != 3:
            raise ValueError("root_offset must have 3 coordinates")

    # -- axes ---------------------------------------------------------------------------------
    @property
    def axes(self) -> tuple[int, int, int]:
        """Mesh column of the (chord, thickness, span) directions."""
        return parse_sections(self.sections)

    def frame(self) -> np.ndarray:
        """(3, 3) matrix whose rows are the mesh directions of local c, t and s."""
        c, t, s = self.axes
        m = np.zeros((3, 3))
        m[0, c] = 1.0
        m[1, t] = 1.0
        m[2, s] = float(self.span_sign)
        return m

    @property
    def handedness(self) -> float:
        """+1 if local (c, t, s) maps to a right-handed mesh frame, -1 if it is mirrored."""
        return float(np.sign(np.linalg.det(self.frame())))

    def to_mesh(self, local: np.ndarray) -> np.ndarray:
        """Local ``(..., 3)`` (c, t, s) coordinates -> mesh coordinates."""
        return np.asarray(local, dtype=np.float64) @ self.frame() + np.asarray(self.root_offset, float)

    # -- spanwise distributions -----------------------------------------------------------------
    def chord(self, eta) -> np.ndarray:
        """Chord length at ``eta`` (trapezoid plus the inboard trailing-edge extension)."""
        eta = np.asarray(eta, dtype=np.float64)
        c = self.root_chord * (1.0 + (self.taper - 1.0) * eta)
        if self.kink_eta is not None and self.kink_te_extension > 0:
            c = c + self.kink_te_extension * np.clip(1.0 - eta / self.kink_eta, 0.0, None)
        return c

    def twist(self, eta) -> np.ndarray:
        """Twist in degrees at ``eta`` (nose up positive), linear from root to tip."""
        eta = np.asarray(eta, dtype=np.float64)
        return self.twist_root_deg + (self.twist_tip_deg - self.twist_root_deg) * eta

    def _reference_le(self, eta) -> np.ndarray:
        """Local (c, t, s) of the untwisted leading edge at ``eta``: (..., 3)."""
        s = np.asarray(eta, dtype=np.float64) * self.semi_span
        return np.stack([s * np.tan(np.radians(self.le_sweep_deg)),
                         s * np.tan(np.radians(self.dihedral_deg)), s], axis=-1)

    def local_points(self, eta, coords) -> np.ndarray:
        """Local (c, t, s) coordinates of unit-chord section points.

        ``eta`` (k,) stations; ``coords`` (n, 2) or (k, n, 2) chord fractions (x along the chord
        from the leading edge, y up). Returns (k, n, 3): scaled by the chord, rotated nose-up by the
        twist about the chord point at ``twist_axis``, placed at the reference leading edge.
        """
        eta = np.atleast_1d(np.asarray(eta, dtype=np.float64))
        coords = np.asarray(coords, dtype=np.float64)
        if coords.ndim == 2:
            coords = np.broadcast_to(coords, (len(eta), *coords.shape))
        c = self.chord(eta)[:, None]
        th = np.radians(self.twist(eta))[:, None]
        dx = (coords[..., 0] - self.twist_axis) * c
        dy = coords[..., 1] * c
        # nose-up rotation: a point ahead of the axis (dx < 0) goes up
        rx = dx * np.cos(th) + dy * np.sin(th)
        ry = -dx * np.sin(th) + dy * np.cos(th)
        ref = self._reference_le(eta)
        out = np.empty((*coords.shape[:-1], 3))
        out[..., 0] = ref[:, None, 0] + self.twist_axis * c + rx
        out[..., 1] = ref[:, None, 1] + ry
        out[..., 2] = ref[:, None, 2]
        return out

    def section_points(self, eta, coords) -> np.ndarray:
        """Mesh coordinates (k, n, 3) of unit-chord section points, see :meth:`local_points`."""
        return self.to_mesh(self.local_points(eta, coords))

    def leading_edge(self, eta) -> np.ndarray:
        """Mesh coordinates (k, 3) of the chord line's leading-edge point (chord fraction 0)."""
        return self.section_points(eta, np.array([[0.0, 0.0]]))[:, 0]

    def trailing_edge(self, eta) -> np.ndarray:
        """Mesh coordinates (k, 3) of the chord line's trailing-edge point (chord fraction 1).

        For a sharp trailing edge this is the trailing-edge point of the surface; for a blunt NACA
        section it is the mid-point of the upper and lower trailing-edge points.
        """
        return self.section_points(eta, np.array([[1.0, 0.0]]))[:, 0]

    def airfoil_coords(self, eta, n: int) -> np.ndarray:
        """Unit-chord section coordinates (k, n, 2) at ``eta``: root and tip NACA blended linearly."""
        eta = np.atleast_1d(np.asarray(eta, dtype=np.float64))
        root = naca4(self.root_airfoil, n, closed_te=self.closed_te)
        if self.tip_airfoil is None:
            return np.broadcast_to(root, (len(eta), n, 2)).copy()
        tip = naca4(self.tip_airfoil, n, closed_te=self.closed_te)
        w = eta[:, None, None]
        return (1.0 - w) * root + w * tip

    def stations(self, n_span: int) -> np.ndarray:
        """``n_span`` stations from 0 to 1 (exactly), uniform on each side of the kink, which is one
        of them when there is a kink."""
        if n_span < 2:
            raise ValueError("n_span must be at least 2")
        if self.kink_eta is None:
            eta = np.linspace(0.0, 1.0, n_span)
        else:
            if n_span < 3:
                raise ValueError("a kinked wing needs n_span >= 3 (root, kink, tip)")
            n_in = int(np.clip(round((n_span - 1) * self.kink_eta), 1, n_span - 2))
            eta = np.concatenate([np.linspace(0.0, self.kink_eta, n_in + 1)[:-1],
                                  np.linspace(self.kink_eta, 1.0, n_span - n_in)])
        eta[0], eta[-1] = 0.0, 1.0
        return eta


def rect_wing_planform(**kw) -> Planform:
    """The paper's rectangular wing: NACA 0012, chord 1 along x, thickness y, span z, semi-span 3."""
    args = dict(semi_span=3.0, root_chord=1.0, root_airfoil="0012", sections="xy")
    args.update(kw)
    return Planform(**args)


def crm_planform(**kw) -> Planform:
    """A CRM-like transport wing in metres: chord x, span y, thickness z (as the NASA CRM).

    Semi-span 29.38, leading-edge sweep 35 deg, trailing-edge kink ("Yehudi") at 37 % semi-span,
    reference trapezoid root chord 9.93 and taper 0.275 (tip chord 2.73), root trailing edge moved
    aft by 3.69 (root chord 13.62, kink chord 7.26: close to the CRM's), dihedral 5 deg, washout
    from +4 deg at the root to -2 deg at the tip (about the leading edge), NACA 2414 at the root
    blending to NACA 2410 at the tip.
    """
    args = dict(semi_span=29.38, root_chord=9.93, taper=0.275, le_sweep_deg=35.0, dihedral_deg=5.0,
                twist_root_deg=4.0, twist_tip_deg=-2.0, root_airfoil="2414", tip_airfoil="2410",
                kink_eta=0.37, kink_te_extension=3.69, sections="xz")
    args.update(kw)
    return Planform(**args)
