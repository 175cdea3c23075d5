"""NACA 4-digit sections in closed form (a fixture: exact geometry for the tests and the samples).

Airfoil coordinates are ``(n, 2)`` arrays in *Selig order*: trailing edge -> upper surface -> leading
edge -> lower surface -> trailing edge, chord from 0 (leading edge) to 1 (trailing edge). Seen with
chord to the right and thickness up, this runs counter-clockwise.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize_scalar

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
