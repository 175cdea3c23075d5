"""NACA sections, parametric wings and airfoil O-grids in plain NumPy (no gmsh).

Used to build the bundled samples (``samples/make_samples.py``) and as exact geometry oracles in
the tests: every function here is a closed-form or vectorised construction whose leading edge,
trailing edge, chord, twist, sweep and dihedral are known exactly.

Conventions
-----------
* Airfoil coordinates are ``(n, 2)`` arrays in *Selig order*: trailing edge -> upper surface ->
  leading edge -> lower surface -> trailing edge, chord from 0 (leading edge) to 1 (trailing
  edge). Seen with chord to the right and thickness up, this runs counter-clockwise.
* A wing is described in local coordinates ``(c, t, s)``: chordwise, thickness ("up") and spanwise
  distance from the root plane. :class:`Planform` maps them to mesh axes (``sections="xy"``: chord
  x, thickness y, span z; ``"xz"``: chord x, thickness z, span y; any choice of
  :data:`ffdcli.geometry.axes.SECTION_CHOICES`), a span sign (+1: the wing grows along +span axis, -1 a left
  wing growing along -span) and a root offset.
* Sections lie in planes normal to the span axis. The spanwise station is ``eta`` in [0, 1]
  (0 = root plane, 1 = tip plane), at span distance ``eta * semi_span``.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

import numpy as np
from scipy.interpolate import CubicSpline
from scipy.optimize import minimize_scalar

from ffdcli.geometry.axes import SECTION_CHOICES, parse_sections
from ffdcli.mesh import CellBlock, Mesh

# ----------------------------------------------------------------------------------------------
# NACA 4-digit sections
# ----------------------------------------------------------------------------------------------

#: Thickness polynomial coefficients of the NACA 4-digit series (a0 multiplies sqrt(x)).
NACA4_COEFFS = (0.2969, -0.1260, -0.3516, 0.2843, -0.1015)
#: Last coefficient that closes the trailing edge (y_t(1) = 0 exactly).
NACA4_CLOSED_TE_A4 = -0.1036


@dataclass(frozen=True)
class Naca4:
    """A parsed NACA 4-digit code: maximum camber ``m`` and its position ``p`` (chord fractions),
    thickness ``t`` (fraction of chord)."""

    m: float
    p: float
    t: float

    @property
    def symmetric(self) -> bool:
        return self.m == 0.0


def parse_naca4(code: str) -> Naca4:
    """``"2412"`` (or ``"NACA 2412"``, ``"naca2412"``) -> Naca4(m=0.02, p=0.4, t=0.12).

    Raises ValueError for anything that is not four digits, for zero thickness and for a cambered
    code with camber position 0 (``"2012"``).
    """
    s = re.sub(r"^\s*naca\s*", "", str(code).strip(), flags=re.IGNORECASE)
    if not re.fullmatch(r"\d{4}", s):
        raise ValueError(f"expected a NACA 4-digit code like '2412', got {code!r}")
    m, p, t = int(s[0]) / 100.0, int(s[1]) / 10.0, int(s[2:]) / 100.0
    if t <= 0:
        raise ValueError(f"NACA {s}: thickness must be positive")
    if (m == 0) != (p == 0):
        raise ValueError(f"NACA {s}: camber and its position must be both zero or both non-zero")
    return Naca4(m, p, t)


def naca4_thickness(code: str, x: np.ndarray, *, closed_te: bool = True) -> np.ndarray:
    """Half-thickness ``y_t(x)`` of a NACA 4-digit section at chord fractions ``x`` in [0, 1].

    ``closed_te`` uses -0.1036 as the last coefficient, which makes ``y_t(1) = 0``; the value at
    ``x == 1`` is then set to exactly 0 (the formula gives 0 up to rounding).
    """
    n = parse_naca4(code)
    x = np.asarray(x, dtype=np.float64)
    a0, a1, a2, a3, a4 = NACA4_COEFFS
    if closed_te:
        a4 = NACA4_CLOSED_TE_A4
    yt = 5.0 * n.t * (a0 * np.sqrt(x) + x * (a1 + x * (a2 + x * (a3 + x * a4))))
    if closed_te:
        yt = np.where(x == 1.0, 0.0, yt)
    return yt


def naca4_camber(code: str, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Camber line ``y_c(x)`` and its slope ``dy_c/dx`` at chord fractions ``x`` in [0, 1].

    ``y_c(0) = y_c(1) = 0`` exactly.
    """
    n = parse_naca4(code)
    x = np.asarray(x, dtype=np.float64)
    if n.symmetric:
        return np.zeros_like(x), np.zeros_like(x)
    m, p = n.m, n.p
    fore = x < p
    yc = np.where(fore, m / p**2 * (2 * p * x - x * x),
                  m / (1 - p) ** 2 * ((1 - 2 * p) + 2 * p * x - x * x))
    dyc = np.where(fore, 2 * m / p**2 * (p - x), 2 * m / (1 - p) ** 2 * (p - x))
    yc = np.where((x == 0.0) | (x == 1.0), 0.0, yc)
    return yc, dyc


def naca4_points(code: str, xc: np.ndarray, *, closed_te: bool = True
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Upper and lower surface points ``(len(xc), 2)`` at camber-line stations ``xc`` in [0, 1].

    The classical construction: thickness laid off normal to the camber line,
    ``x_u = x - y_t sin(theta)``, ``y_u = y_c + y_t cos(theta)``, and the lower surface with the
    opposite signs, ``theta = arctan(dy_c/dx)``. For a cambered code the surface x therefore differs
    from ``xc``; :func:`naca4_surfaces` gives y at a surface x instead.
    """
    xc = np.asarray(xc, dtype=np.float64)
    yt = naca4_thickness(code, xc, closed_te=closed_te)
    yc, dyc = naca4_camber(code, xc)
    theta = np.arctan(dyc)
    s, c = np.sin(theta), np.cos(theta)
    upper = np.stack([xc - yt * s, yc + yt * c], axis=-1)
    lower = np.stack([xc + yt * s, yc - yt * c], axis=-1)
    return upper, lower


def naca4(code: str, n: int = 101, *, closed_te: bool = True, spacing: str = "cosine") -> np.ndarray:
    """NACA 4-digit section as ``(n, 2)`` coordinates in Selig order, chord 0..1.

    The camber-line stations follow one parameter ``beta`` from 0 to ``2 pi`` over the ``n`` points:
    ``x = (1 + cos(beta)) / 2`` for ``spacing="cosine"`` (clustered at both edges) or
    ``x = |1 - beta/pi|`` for ``"uniform"``. ``beta <= pi`` is the upper surface. With ``n`` odd the
    leading edge (0, 0) is point ``(n - 1) // 2``; with ``n`` even it falls between two points.
    The first and last points are the upper and lower trailing-edge points; they are both exactly
    (1, 0) when ``closed_te`` (sharp trailing edge), else the trailing edge is blunt
    (``2 * y_t(1) = 0.0021 * t/0.1`` thick, the classical formula).
    """
    if n < 5:
        raise ValueError(f"an airfoil needs at least 5 points, got n={n}")
    beta = np.linspace(0.0, 2.0 * np.pi, int(n))
    if spacing == "cosine":
        xc = 0.5 * (1.0 + np.cos(beta))
    elif spacing == "uniform":
        xc = np.abs(1.0 - beta / np.pi)
    else:
        raise ValueError(f"spacing must be 'cosine' or 'uniform', got {spacing!r}")
    # exact end and leading-edge stations (cos rounding would leave 1e-17 offsets)
    xc[0] = xc[-1] = 1.0
    if n % 2 == 1:
        xc[(n - 1) // 2] = 0.0
    upper, lower = naca4_points(code, xc, closed_te=closed_te)
    return np.where((beta <= np.pi)[:, None], upper, lower)


def _surface_branch_start(code: str, side: int, closed_te: bool) -> float:
    """Camber station from which the surface x(xc) of one side increases monotonically.

    A cambered upper surface first runs slightly forward of x = 0 (x_u < 0 for xc < ~3e-4 on a
    2412) before turning back; this is the station of its foremost point, 0 for all other cases.
    """
    if parse_naca4(code).symmetric or side < 0:
        return 0.0

    def x_of(xc):
        return naca4_points(code, np.array([xc]), closed_te=closed_te)[0][0, 0]

    res = minimize_scalar(x_of, bounds=(0.0, 0.05), method="bounded",
                          options={"xatol": 1e-16, "maxiter": 500})
    return float(res.x) if res.fun < 0.0 else 0.0


def naca4_surfaces(code: str, x: np.ndarray, *, closed_te: bool = True
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Upper and lower surface ``y`` at surface abscissae ``x`` (chord fractions).

    Exact to rounding: for each ``x`` the camber station ``xc`` with ``x_u(xc) = x`` (and
    ``x_l(xc) = x``) is found by 64 steps of vectorised bisection on the monotone branch of each
    side. For a cambered section, the upper surface's short stretch forward of ``x = 0``
    (|x| < 1e-4 chord for a 2412) is not returned: at ``x = 0`` the upper value is where the
    surface crosses ``x = 0`` after its foremost point. ``x`` outside the range a side covers
    (e.g. ``x = 1`` on the lower side of a blunt cambered section) gives NaN.
    """
    x = np.asarray(x, dtype=np.float64)
    out = []
    for side in (+1, -1):
        lo0 = _surface_branch_start(code, side, closed_te)
        lo = np.full(x.shape, lo0)
        hi = np.ones(x.shape)

        def xs(xc, side=side):
            up, low = naca4_points(code, xc, closed_te=closed_te)
            return (up if side > 0 else low)[..., 0]

        x_lo, x_hi = xs(lo), xs(hi)
        ok = (x >= x_lo) & (x <= x_hi)
        for _ in range(64):  # bisection halves [0, 1] to below 1 ulp of 1 in 53 steps
            mid = 0.5 * (lo + hi)
            right = xs(mid) < x
            lo = np.where(right, mid, lo)
            hi = np.where(right, hi, mid)
        xc = 0.5 * (lo + hi)
        up, low = naca4_points(code, xc, closed_te=closed_te)
        y = (up if side > 0 else low)[..., 1]
        out.append(np.where(ok, y, np.nan))
    return out[0], out[1]


def polygon_area(coords: np.ndarray) -> float:
    """Signed area of the closed polygon through ``coords`` (n, 2) (shoelace; > 0 counter-clockwise).

    A Selig-ordered airfoil has positive area.
    """
    x, y = np.asarray(coords, dtype=np.float64).T
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))


def naca4_symmetric_area(code: str, *, closed_te: bool = True) -> float:
    """Exact cross-section area (chord 1) of a symmetric NACA 4-digit section: 2 * int_0^1 y_t dx."""
    n = parse_naca4(code)
    if not n.symmetric:
        raise ValueError(f"NACA {code}: the closed form here is for symmetric sections only")
    a0, a1, a2, a3, a4 = NACA4_COEFFS
    if closed_te:
        a4 = NACA4_CLOSED_TE_A4
    return 10.0 * n.t * (a0 * 2 / 3 + a1 / 2 + a2 / 3 + a3 / 4 + a4 / 5)


# ----------------------------------------------------------------------------------------------
# Planforms
# ----------------------------------------------------------------------------------------------


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


# ----------------------------------------------------------------------------------------------
# Wing surface mesh
# ----------------------------------------------------------------------------------------------


def _cap_faces(ring: np.ndarray, n_chord: int, blunt: bool) -> tuple[np.ndarray, np.ndarray]:
    """Quads and triangles closing one section, oriented counter-clockwise in the local (c, t)
    plane (normal +s). ``ring`` holds the section's point ids in loop order: ring[0] is the upper
    trailing-edge point, ring[n_chord - 1] the leading edge, then the lower side."""
    le = n_chord - 1
    i = np.arange(n_chord)
    upper = ring[le - i]                  # upper side from the leading edge (i = 0) aft
    lower = ring[(le + i) % len(ring)]    # lower side from the leading edge aft; wraps to ring[0]
    # strip between lower[i], lower[i+1], upper[i+1], upper[i]: counter-clockwise
    last = n_chord - 1 if blunt else n_chord - 2          # sharp TE: the last strip is a triangle
    k = np.arange(1, last)
    quads = np.stack([lower[k], lower[k + 1], upper[k + 1], upper[k]], axis=1)
    tris = [np.array([[lower[0], lower[1], upper[1]]])]   # at the leading edge upper[0] == lower[0]
    if not blunt:
        tris.append(np.array([[lower[last], lower[last + 1], upper[last]]]))  # TE: shared last point
    return quads, np.concatenate(tris)


def _surface_faces(planform: Planform, n_chord: int, n_span: int, tip: str, root: str, eta):
    """Points and (kind, faces) lists of marker ``wing`` and (if closed) ``root``; see wing_surface."""
    for name, val in (("tip", tip), ("root", root)):
        if val not in ("closed", "open"):
            raise ValueError(f"{name} must be 'closed' or 'open', got {val!r}")
    if n_chord < 3:
        raise ValueError("n_chord must be at least 3")
    eta = planform.stations(n_span) if eta is None else np.asarray(eta, dtype=np.float64)
    if eta.ndim != 1 or len(eta) < 2 or np.any(np.diff(eta) <= 0):
        raise ValueError("eta must be an increasing 1D array of at least 2 stations")
    coords = planform.airfoil_coords(eta, 2 * n_chord - 1)
    blunt = not planform.closed_te
    if not blunt:
        coords = coords[:, :-1]          # the lower trailing-edge point repeats the upper one
    n_loop = coords.shape[1]
    pts = planform.section_points(eta, coords).reshape(-1, 3)

    ids = np.arange(len(eta) * n_loop).reshape(len(eta), n_loop)
    a = ids[:-1]
    b = np.roll(ids[:-1], -1, axis=1)    # next point around the loop (wraps over the TE)
    quads = np.stack([a, b, np.roll(ids[1:], -1, axis=1), ids[1:]], axis=-1).reshape(-1, 4)
    wing_q, wing_t = [quads], []
    root_q = root_t = None
    if tip == "closed":
        q, t = _cap_faces(ids[-1], n_chord, blunt)
        wing_q.append(q)
        wing_t.append(t)
    if root == "closed":
        q, t = _cap_faces(ids[0], n_chord, blunt)
        root_q, root_t = q[:, ::-1], t[:, ::-1]      # the root cap faces -s
    flip = planform.handedness < 0

    def faces(arrays, width):
        data = np.concatenate(arrays) if arrays else np.zeros((0, width), dtype=np.int64)
        data = data.astype(np.int64)
        return np.ascontiguousarray(data[:, ::-1]) if flip else data

    out = {"wing": (faces(wing_q, 4), faces(wing_t, 3))}
    if root_q is not None:
        out["root"] = (faces([root_q], 4), faces([root_t], 3))
    return pts, out


def wing_surface(planform: Planform, n_chord: int = 41, n_span: int = 21, *, tip: str = "closed",
                 root: str = "open", eta: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Surface of a wing as quads: the sections joined station to station, flat end caps.

    Parameters
    ----------
    planform
        The wing (:class:`Planform`).
    n_chord
        Points per side from the leading edge to the trailing edge, both included (the section
        has ``2 * n_chord - 2`` distinct points when the trailing edge is sharp, ``2 * n_chord - 1``
        when it is blunt: the blunt base is then one face wide).
    n_span, eta
        Spanwise stations: ``planform.stations(n_span)`` unless ``eta`` (increasing, from 0 to 1)
        is given. Station 0 lies exactly in the root plane and the last in the tip plane.
    tip, root
        ``"closed"`` adds a flat cap of the tip (respectively root) section, ``"open"`` leaves it
        open. The default (tip closed, root open) is the wing of a half-wing CFD mesh, open at the
        symmetry plane; both closed, the surface is watertight.

    Returns
    -------
    points : (N, 3) float64
        Station by station, each section in Selig order without a repeated sharp trailing edge;
        point ``j * n_loop + n_chord - 1`` is the leading edge of station ``j`` (see
        :func:`leading_edge_ids`, :func:`trailing_edge_ids`).
    quads : (F, 4) int64
        Faces with their normal out of the wing (for any axes and span sign), side faces first
        (``(n_span - 1) * n_loop``, station by station), then the tip cap, then the root cap. The
        cap faces at the leading edge (and at a sharp trailing edge) are triangles, stored as
        *collapsed quads* whose last two nodes are equal; the diagonal cross product
        ``(p2 - p0) x (p3 - p1)`` is twice the area vector of every face, collapsed or not.
        :func:`surface_mesh` gives the same surface as a :class:`~ffdcli.mesh.Mesh` with separate
        quad and triangle blocks.
    """
    pts, markers = _surface_faces(planform, n_chord, n_span, tip, root, eta)
    quads = []
    for name in ("wing", "root"):
        if name in markers:
            q, t = markers[name]
            quads += [q, np.concatenate([t, t[:, 2:]], axis=1)]
    return pts, np.concatenate(quads)


def surface_mesh(planform: Planform, n_chord: int = 41, n_span: int = 21, *, tip: str = "closed",
                 root: str = "open", eta: np.ndarray | None = None) -> Mesh:
    """The surface of :func:`wing_surface` as a surface-only :class:`~ffdcli.mesh.Mesh`.

    ``dim=3`` (the dimension of the space the surface lives in), no interior cells, marker ``wing``
    (side faces and tip cap) as a ``quad`` and a ``triangle`` block, and, with ``root="closed"``, a
    separate marker ``root`` (so that ``wing`` stays the wing as a half-wing CFD mesh has it).
    Same points and face orientation as :func:`wing_surface`.
    """
    pts, markers = _surface_faces(planform, n_chord, n_span, tip, root, eta)
    return Mesh(points=pts, dim=3, cells=[],
                markers={name: [CellBlock("quad", q), CellBlock("triangle", t)]
                         for name, (q, t) in markers.items()})


def leading_edge_ids(n_chord: int, n_stations: int, closed_te: bool = True) -> np.ndarray:
    """Point ids of the leading-edge points of each station in a :func:`wing_surface` mesh."""
    n_loop = 2 * n_chord - 2 if closed_te else 2 * n_chord - 1
    return np.arange(n_stations) * n_loop + n_chord - 1


def trailing_edge_ids(n_chord: int, n_stations: int, closed_te: bool = True) -> np.ndarray:
    """Point ids of the (upper) trailing-edge point of each station in a :func:`wing_surface` mesh."""
    n_loop = 2 * n_chord - 2 if closed_te else 2 * n_chord - 1
    return np.arange(n_stations) * n_loop


# ----------------------------------------------------------------------------------------------
# 2D O-grid around an airfoil
# ----------------------------------------------------------------------------------------------


def _resample_airfoil(coords: np.ndarray, n: int) -> np.ndarray:
    """``n`` points along the airfoil curve (Selig order, both trailing-edge ends kept), clustered at
    the leading and trailing edges: cosine spacing in arc length on each side of the leading edge
    (the point farthest from the trailing-edge mid-point), a cubic spline through the input."""

    xy = np.asarray(coords, dtype=np.float64)
    keep = np.r_[True, np.any(np.diff(xy, axis=0) != 0, axis=1)]   # drop repeated points
    xy = xy[keep]
    s = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(xy, axis=0), axis=1))]
    te = 0.5 * (xy[0] + xy[-1])
    le = int(np.argmax(np.linalg.norm(xy - te, axis=1)))
    spline = CubicSpline(s, xy, axis=0)
    n_up = (n + 1) // 2                    # upper side incl. LE; n odd -> LE is a point
    b = 0.5 * (1 - np.cos(np.linspace(0.0, np.pi, n_up)))
    b_low = 0.5 * (1 - np.cos(np.linspace(0.0, np.pi, n - n_up + 1)))[1:]
    t = np.concatenate([s[le] * b, s[le] + (s[-1] - s[le]) * b_low])
    out = spline(t)
    out[0], out[-1] = xy[0], xy[-1]
    return out


def _stretched_heights(first: float, total: float, n_cells: int) -> np.ndarray:
    """Cumulative distances (n_cells + 1,) from 0 to ``total`` with a geometric progression whose
    first step is ``first`` (ratio found by bisection; uniform if ``first >= total / n_cells``)."""
    if first * n_cells >= total:
        return np.linspace(0.0, total, n_cells + 1)
    lo, hi = 1.0, 10.0
    for _ in range(200):
        r = 0.5 * (lo + hi)
        if first * (r**n_cells - 1) / (r - 1) < total:
            lo = r
        else:
            hi = r
    h = first * r ** np.arange(n_cells)
    d = np.r_[0.0, np.cumsum(h)]
    return d * (total / d[-1])


def quad_areas(points: np.ndarray, quads: np.ndarray) -> np.ndarray:
    """Signed areas in the x-y plane of the two triangles of each quad, (n, 2); both > 0 for a valid
    counter-clockwise quad (the minimum is the test of inversion)."""
    p = points[:, :2][quads]

    def tri(a, b, c):
        return 0.5 * ((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0]))

    t = [tri(p[:, 0], p[:, 1], p[:, 2]), tri(p[:, 0], p[:, 2], p[:, 3]),
         tri(p[:, 0], p[:, 1], p[:, 3]), tri(p[:, 1], p[:, 2], p[:, 3])]
    return np.stack([np.minimum(t[0], t[1]), np.minimum(t[2], t[3])], axis=1)


def _ring_normals(ring: np.ndarray) -> np.ndarray:
    """Unit outward normals of a counter-clockwise closed polyline (m, 2): from the central
    difference, or the bisector of the two edges where the ring turns by more than 60 degrees (a
    sharp trailing edge, where the central difference of two nearly coincident neighbours has no
    meaningful direction)."""
    fwd = np.roll(ring, -1, axis=0) - ring
    bwd = np.roll(ring, 1, axis=0) - ring
    fwd /= np.linalg.norm(fwd, axis=1, keepdims=True)
    bwd /= np.linalg.norm(bwd, axis=1, keepdims=True)
    tang = fwd - bwd
    normal = np.stack([tang[:, 1], -tang[:, 0]], axis=1)
    sharp = np.sum(fwd * bwd, axis=1) > -0.5                          # turn > 60 degrees
    normal[sharp] = -(fwd + bwd)[sharp]
    return normal / np.linalg.norm(normal, axis=1, keepdims=True)


def airfoil_ogrid(code_or_coords, n_around: int = 129, n_radial: int = 33, farfield_radius: float = 15.0,
                  first_cell: float = 2e-3, *, closed_te: bool = True, smoothing: int = 20,
                  blend: float = 1.0) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Structured 2D O-grid of quads around an airfoil (chord units of the input).

    Parameters
    ----------
    code_or_coords
        A NACA 4-digit code, or airfoil coordinates (n, 2) in Selig order (resampled with a cubic
        spline, clustered at the leading and trailing edges).
    n_around
        Points along the airfoil from the trailing edge round to the trailing edge, both counted;
        a sharp trailing edge is one grid point, so the grid has ``n_around - 1`` points around.
        A blunt trailing edge keeps both and its base is one cell wide.
    n_radial
        Grid points from the wall (k = 0) to the far field (k = n_radial - 1).
    farfield_radius
        Radius of the circular far field around the mid-chord, in chords.
    first_cell
        Height of the wall cells, in chords; the heights grow geometrically.
    smoothing
        Laplacian smoothing passes per layer of the normal marching.
    blend
        Distance from the wall (in chords) beyond which the grid is the elliptic one alone.

    Construction: the layers are marched from the airfoil along the (smoothed) normals of the
    previous layer, each layer then smoothed along its length, which spreads the cells evenly as
    the front becomes round; the layers are then blended (smoothstep of the squared distance over
    ``blend`` chords) into confocal ellipses that become the far-field circle.

    Limits: the marching is not guaranteed to be fold-free. NACA 4-digit sections from 33 to 257
    points around and the five airfoils of ``shared/data/airfoils`` up to 161 points work (tested);
    many more points around than the input has (e.g. 401 from S1223's 300) can fold the cells
    behind a cusped or blunt trailing edge, which raises ValueError.

    Returns
    -------
    points : (N, 2) float64
        Point ``k * n_ring + i`` is ring point ``i`` of layer ``k`` (layer 0 is the airfoil, in
        Selig order without a repeated sharp trailing edge; ``n_ring = N / n_radial``).
    quads : (n_ring * (n_radial - 1), 4) int64
        Counter-clockwise (positive area in the x-y plane), layer by layer.
    airfoil_lines, farfield_lines : (n_ring, 2) int64
        The boundary edges, each directed along its quad's counter-clockwise order (the fluid is on
        the left of each line).

    Raises ValueError if a cell came out inverted. :func:`airfoil_ogrid_mesh` gives the same grid
    as a :class:`~ffdcli.mesh.Mesh`.
    """
    if isinstance(code_or_coords, str):
        xy = naca4(code_or_coords, n_around, closed_te=closed_te)
    else:
        xy = _resample_airfoil(np.asarray(code_or_coords, dtype=np.float64), n_around)
    sharp = np.allclose(xy[0], xy[-1], rtol=0, atol=1e-12 * float(np.ptp(xy[:, 0])))
    ring0 = xy[:-1] if sharp else xy
    if polygon_area(ring0) < 0:
        raise ValueError("the airfoil coordinates run clockwise; expected Selig order (upper side first)")
    m = len(ring0)
    te = 0.5 * (xy[0] + xy[-1])
    le = xy[int(np.argmax(np.linalg.norm(xy - te, axis=1)))]
    chord = float(np.linalg.norm(te - le))
    e_c = (te - le) / chord                                           # chord direction
    e_t = np.array([-e_c[1], e_c[0]])                                 # thickness direction
    centre = 0.5 * (le + te)
    radius = farfield_radius * chord
    dist = _stretched_heights(first_cell * chord, radius - 0.5 * chord, n_radial - 1)

    # 1. layers marched along the normals of the previous layer
    # corners of the airfoil (sharp trailing edge, the two corners of a blunt base): sliding them
    # along the first layers would pull them round the corner and fold the wall cells there, so
    # their smoothing along the layer starts only at corner_free (in distance from the wall)
    fwd0 = np.roll(ring0, -1, axis=0) - ring0
    bwd0 = np.roll(ring0, 1, axis=0) - ring0
    cosang = np.sum(fwd0 * bwd0, axis=1) / (np.linalg.norm(fwd0, axis=1) * np.linalg.norm(bwd0, axis=1))
    corner = (cosang > -0.5)[:, None]                                 # turn of more than 60 degrees
    corner_free = 0.05 * chord
    layers = [ring0]
    cur = ring0
    for k in range(1, n_radial):
        normal = _ring_normals(cur)
        step = dist[k] - dist[k - 1]
        nxt = cur + step * normal
        for _ in range(smoothing):                                    # relax along the layer
            lap = 0.5 * (np.roll(nxt, 1, axis=0) + np.roll(nxt, -1, axis=0)) - nxt
            chord_vec = np.roll(nxt, -1, axis=0) - np.roll(nxt, 1, axis=0)
            h = 0.5 * np.linalg.norm(chord_vec, axis=1, keepdims=True)
            nrm = np.stack([chord_vec[:, 1], -chord_vec[:, 0]], axis=1) / (2 * h)
            lap_n = np.sum(lap * nrm, axis=1, keepdims=True)
            # along the layer as much as the step allows (the wall layers keep the surface spacing,
            # the outer ones even out); across it only outwards, which fills concave corners and
            # never pulls a convex front (leading edge, sharp trailing edge) back onto its layer
            w = 0.5 * np.clip(step / h, 0.0, 1.0) ** 2
            w = np.where(corner, w * min(1.0, dist[k] / corner_free) ** 2, w)
            nxt = nxt + w * (lap - lap_n * nrm) + 0.5 * np.maximum(lap_n, 0.0) * nrm
        layers.append(nxt)
        cur = nxt
    marched = np.stack(layers)                                        # (n_radial, m, 2)

    # 2. the grid of confocal ellipses around the chord line (the conformal map of a flat plate:
    # cosine-spaced surface points are evenly spaced in its angle theta), the last one made a circle
    theta = 2 * np.pi * (np.arange(m) + (0.0 if sharp else 0.5)) / m
    a = dist + 0.5 * chord                                            # semi-axes along the chord
    b = np.sqrt(np.maximum(a**2 - 0.25 * chord**2, 0.0))              # and across it
    b = b + (a - b) * (dist / dist[-1]) ** 2                          # -> circle of radius R
    ellipses = (centre + (a[:, None] * np.cos(theta))[..., None] * e_c
                + (b[:, None] * np.sin(theta))[..., None] * e_t)

    # 3. marched near the wall, elliptic far away
    wgt = np.clip(dist / (blend * chord), 0.0, 1.0) ** 2
    wgt = (wgt * wgt * (3 - 2 * wgt))[:, None, None]
    grid = (1 - wgt) * marched + wgt * ellipses
    grid[0] = ring0

    pts = grid.reshape(-1, 2)
    ids = np.arange(n_radial * m).reshape(n_radial, m)
    i0, i1 = ids[:-1], np.roll(ids[:-1], -1, axis=1)
    j0, j1 = ids[1:], np.roll(ids[1:], -1, axis=1)
    quads = np.stack([i0, j0, j1, i1], axis=-1).reshape(-1, 4)
    areas = quad_areas(pts, quads)
    if areas.min() <= 0:
        bad = int(np.sum(areas.min(axis=1) <= 0))
        raise ValueError(f"{bad} O-grid cells are inverted; try a larger first_cell, more smoothing "
                         "or more points around")
    airfoil = np.stack([np.roll(ids[0], -1), ids[0]], axis=1)
    farfield = np.stack([ids[-1], np.roll(ids[-1], -1)], axis=1)
    return pts, quads.astype(np.int64), airfoil.astype(np.int64), farfield.astype(np.int64)


def airfoil_ogrid_mesh(code_or_coords, n_around: int = 129, n_radial: int = 33,
                       farfield_radius: float = 15.0, first_cell: float = 2e-3, **kw) -> Mesh:
    """:func:`airfoil_ogrid` as a 2D :class:`~ffdcli.mesh.Mesh`: ``dim=2``, points (N, 3) with
    z = 0, one ``quad`` block, markers ``airfoil`` and ``farfield`` (``line`` blocks)."""
    xy, quads, airfoil, farfield = airfoil_ogrid(code_or_coords, n_around, n_radial, farfield_radius,
                                                 first_cell, **kw)
    pts = np.zeros((len(xy), 3))
    pts[:, :2] = xy
    return Mesh(points=pts, dim=2, cells=[CellBlock("quad", quads)],
                markers={"airfoil": [CellBlock("line", airfoil)], "farfield": [CellBlock("line", farfield)]})


# ----------------------------------------------------------------------------------------------
# Structured hexahedral wing mesh (an O-grid extruded along the span)
# ----------------------------------------------------------------------------------------------


def hex_volumes(points: np.ndarray, hexes: np.ndarray) -> np.ndarray:
    """Smallest signed volume of the 8 corner tetrahedra of each VTK hexahedron, (n,).

    Corner ``c`` spans its three edge neighbours in right-handed order; all eight are positive for a
    valid (convex, correctly ordered) hexahedron, so the minimum is the test of inversion.
    """
    p = np.asarray(points, dtype=np.float64)[hexes]
    # corner -> its three neighbours along the bottom/top loop and up, in right-handed order
    nb = np.array([[1, 3, 4], [2, 0, 5], [3, 1, 6], [0, 2, 7],
                   [7, 5, 0], [4, 6, 1], [5, 7, 2], [6, 4, 3]])
    c = np.arange(8)
    e = p[:, nb] - p[:, c, None]                                      # (n, 8, 3, 3)
    vol = np.einsum("nci,nci->nc", np.cross(e[:, :, 0], e[:, :, 1]), e[:, :, 2]) / 6.0
    return vol.min(axis=1)


def extruded_wing_mesh(planform: Planform | None = None, n_around: int = 49, n_radial: int = 13,
                       n_span: int = 7, farfield_radius: float = 5.0, first_cell: float = 5e-3,
                       **ogrid_kw) -> Mesh:
    """A small structured hexahedral volume mesh of a wing, made without gmsh.

    The O-grid of :func:`airfoil_ogrid` (unit chord, around the planform's root NACA section) is
    placed at each spanwise station exactly as a wing section: scaled by the local chord, twisted,
    swept and raised by :meth:`Planform.local_points`; the stations are joined by hexahedra. The
    wing therefore spans the whole domain, from the root plane (span 0, marker ``symmetry``) to the
    tip plane (span ``semi_span``, marker ``side``), where it meets the outer boundary. With a
    ``tip_airfoil`` the grids of the root and tip sections are blended linearly in ``eta``.

    Parameters
    ----------
    planform
        Default :func:`rect_wing_planform` (NACA 0012, chord 1 along x, thickness y, span z 0..3).
    n_around, n_radial, farfield_radius, first_cell, ogrid_kw
        Passed to :func:`airfoil_ogrid` (``closed_te`` comes from the planform).
    n_span
        Stations from root to tip (``planform.stations``; the kink, if any, is one of them).

    Returns
    -------
    Mesh
        ``dim=3``, one ``hexahedron`` block (VTK order, positive volume), markers ``wing``,
        ``farfield``, ``symmetry``, ``side`` (``quad`` blocks, normals out of the fluid). Point
        ``j * n_plane + p`` is point ``p`` of the O-grid at station ``j``. The defaults give 4 368
        points and 3 456 cells. Raises ValueError if a cell is inverted (e.g. strong twist between
        few stations).
    """
    pf = rect_wing_planform() if planform is None else planform
    xy, quads, airfoil, farfield = airfoil_ogrid(pf.root_airfoil, n_around, n_radial, farfield_radius,
                                                 first_cell, closed_te=pf.closed_te, **ogrid_kw)
    eta = pf.stations(n_span)
    if pf.tip_airfoil is not None and pf.tip_airfoil != pf.root_airfoil:
        xy_tip = airfoil_ogrid(pf.tip_airfoil, n_around, n_radial, farfield_radius, first_cell,
                               closed_te=pf.closed_te, **ogrid_kw)[0]
        grids = (1.0 - eta[:, None, None]) * xy + eta[:, None, None] * xy_tip
    else:
        grids = np.broadcast_to(xy, (len(eta), *xy.shape))
    n_plane = len(xy)
    pts = pf.section_points(eta, grids).reshape(-1, 3)

    lower = quads[None, :, :] + n_plane * np.arange(len(eta) - 1)[:, None, None]   # (n_span-1, F, 4)
    hexes = np.concatenate([lower, lower + n_plane], axis=-1).reshape(-1, 8)
    if pf.handedness < 0:                        # local (c, t, s) -> mesh is mirrored
        hexes = hexes[:, [0, 3, 2, 1, 4, 7, 6, 5]]
    vol = hex_volumes(pts, hexes)
    if vol.min() <= 0:
        raise ValueError(f"{int(np.sum(vol <= 0))} hexahedra are inverted; use more stations or a "
                         "finer O-grid")

    def side_faces(lines):
        a = lines[None, :, :] + n_plane * np.arange(len(eta) - 1)[:, None, None]
        return np.concatenate([a, a[..., ::-1] + n_plane], axis=-1).reshape(-1, 4)

    faces = {"wing": (side_faces(airfoil), np.arange(len(eta) - 1)[:, None] * len(quads)
                      + np.arange(len(airfoil))[None, :]),
             "farfield": (side_faces(farfield), np.arange(len(eta) - 1)[:, None] * len(quads)
                          + (len(quads) - len(farfield)) + np.arange(len(farfield))[None, :]),
             "symmetry": (quads, np.arange(len(quads))),
             "side": (quads + n_plane * (len(eta) - 1), (len(eta) - 2) * len(quads) + np.arange(len(quads)))}
    markers = {}
    for name, (f, cell) in faces.items():
        markers[name] = [CellBlock("quad", _orient_out(pts, f, hexes[np.ravel(cell)]))]
    return Mesh(points=pts, dim=3, cells=[CellBlock("hexahedron", hexes)], markers=markers)


def _orient_out(points: np.ndarray, faces: np.ndarray, cells: np.ndarray) -> np.ndarray:
    """Quads ``faces`` reordered where needed so that their normal points away from the centroid of
    their cell (``cells[f]``), i.e. out of the fluid."""
    p = points[faces]
    normal = np.cross(p[:, 2] - p[:, 0], p[:, 3] - p[:, 1])
    out = np.einsum("ij,ij->i", normal, p.mean(axis=1) - points[cells].mean(axis=1)) > 0
    return np.where(out[:, None], faces, faces[:, ::-1])
