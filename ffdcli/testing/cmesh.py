"""Structured 2D C-meshes of quads around an airfoil with a sharp trailing edge, for RANS (plain NumPy).

The grid line ``j = 0`` runs from the outflow along the wake cut to the trailing edge, round the
airfoil (lower surface, leading edge, upper surface) and back along the cut to the outflow; ``j``
grows outward to the far field: a half circle about the trailing edge in front, straight lines
above and below the wake, and the outflow plane. The two sides of the wake cut are the same points
(the mesh is conforming across it: an interior line, no marker), as is the trailing edge.

Each grid line ``i`` leaves its wall point (or cut point) along the wall normal (straight down or
up from the cut) and bends into the straight line to its far-field point (a cubic Hermite curve),
with the points placed along its arc length by geometric growth from ``first_cell``: the wall cells
are orthogonal and exactly ``first_cell`` high. Near the trailing edge the start directions are
averaged over a few hundredths of a chord (no two lines cross where the surfaces meet). Along the
cut the first cell grows downstream: ``first_cell + wake_growth * x`` at ``x`` behind the trailing edge
(``WAKE_GROWTH`` = 1e-3: 1e-4 chord at 0.1 chord, 1e-3 at 1, 0.1 at the outflow), the extra height added
as ``wake_growth * x * j`` fading to nothing at the far field (:func:`_lines`), so the far field does
not move and neighbouring cut lines' points differ by at most ``wake_growth * j`` per unit of their
spacing (no shear); the wall's lines keep ``first_cell``.

``python -m benchmarks.adodg.case2_meshes --out out/adodg`` writes the RAE2822's (ADODG Case 2).

Limit, measured: with the wall's first cell carried down the whole cut (``wake_growth=0``: cells 1e-6
chord high and up to 12 chords long at the outflow) SU2 8.1's RANS flow (SA, JST, 3-level W multigrid,
CFL 50) on ``rae2822_s1`` (ADODG Case 2) diverged at iteration 185 from an odd-even oscillation of the
density on the cut 0.1 to 0.5 chord behind the trailing edge (with 2 or 3 multigrid levels; 0 or 1
did not diverge but did not converge either); with the default growth the same solve converges to
rms[Rho] -8 (docs/adodg-case2.md). On a coarse mesh (97 points around, 25 along each side of the cut,
49 out, first cell 1e-5 chord) with the cut at the wall's first cell the flow stalled near rms[Rho]
-7.5 and diverged after 250-420 iterations; not run again with the growing cut.
"""

from __future__ import annotations

import numpy as np
from scipy.interpolate import CubicSpline

from ffdcli.mesh import CellBlock, Mesh
from ffdcli.testing.cells import quad_areas
from ffdcli.testing.naca import polygon_area

#: Half-width (chords) over which the start directions are averaged at the trailing edge.
TE_BLEND = 0.03
#: The start tangent's length (chords) of each line's Hermite curve: how far it follows the normal.
NORMAL_REACH = 0.5
#: Growth of the wake cut's first cell with the distance behind the trailing edge (chord per chord).
WAKE_GROWTH = 1e-3


def read_airfoil(path) -> np.ndarray:
    """Airfoil coordinates (n, 2) of a Selig-format file (a title line, then ``x y`` rows)."""
    rows = []
    with open(path, encoding="utf-8", errors="replace") as fh:
        for line in fh:
            parts = line.split()
            try:
                rows.append((float(parts[0]), float(parts[1])))
            except (ValueError, IndexError):
                continue
    return np.asarray(rows, dtype=np.float64)


def close_trailing_edge(xy: np.ndarray) -> np.ndarray:
    """Selig-order coordinates (n, 2) with a sharp trailing edge: each surface sheared linearly in x
    (zero at the leading edge) so that both end at the mid-point of the two given trailing-edge
    points; a closed trailing edge is returned unchanged. The thickness changes by the base
    thickness times (x - x_le)/(x_te - x_le), the camber line not at all at the leading edge."""
    xy = np.array(xy, dtype=np.float64)
    if np.array_equal(xy[0], xy[-1]):
        return xy
    le = int(np.argmin(xy[:, 0]))
    mid = 0.5 * (xy[0] + xy[-1])
    x_le = xy[le, 0]
    for part, end in ((slice(0, le + 1), xy[0]), (slice(le, None), xy[-1])):
        frac = (xy[part, 0] - x_le) / (end[0] - x_le)
        xy[part] += frac[:, None] * (mid - end)
    xy[0] = xy[-1] = mid
    return xy


def _resample(xy: np.ndarray, n: int) -> np.ndarray:
    """``n`` points (n odd: the leading edge is one) along a closed-TE airfoil in Selig order, cosine
    spaced in arc length on each side of the leading edge (the point of least x), a cubic spline
    through the input; the trailing edge first and last."""
    keep = np.r_[True, np.any(np.diff(xy, axis=0) != 0, axis=1)]
    xy = xy[keep]
    s = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(xy, axis=0), axis=1))]
    le = int(np.argmin(xy[:, 0]))
    spline = CubicSpline(s, xy, axis=0)
    half = (n + 1) // 2
    b = 0.5 * (1 - np.cos(np.linspace(0.0, np.pi, half)))
    t = np.concatenate([s[le] * b, s[le] + (s[-1] - s[le]) * b[1:]])
    out = spline(t)
    out[0], out[-1] = xy[0], xy[-1]
    return out


def _geometric(first: np.ndarray, total: np.ndarray, cells: int) -> np.ndarray:
    """Cumulative distances (L, cells + 1) from 0 to ``total`` (L,) whose first step is ``first`` (L,)
    and whose steps grow by one ratio per line (bisection, all lines at once)."""
    lo, hi = np.full(len(first), 1.0 + 1e-12), np.full(len(first), 4.0)
    for _ in range(100):
        r = 0.5 * (lo + hi)
        short = first * (r ** cells - 1) / (r - 1) < total
        lo, hi = np.where(short, r, lo), np.where(short, hi, r)
    r = 0.5 * (lo + hi)
    d = first[:, None] * (r[:, None] ** np.arange(cells + 1) - 1) / (r[:, None] - 1)
    return d * (total / d[:, -1])[:, None]


def _wall_normals(ring: np.ndarray) -> np.ndarray:
    """Unit normals (m, 2) on the right of an open polyline ``ring`` (the C's j = 0 line, which runs
    clockwise round the airfoil: its right is the fluid), from central differences (one-sided at the
    ends)."""
    tang = np.gradient(ring, axis=0)
    tang /= np.linalg.norm(tang, axis=1, keepdims=True)
    return np.stack([-tang[:, 1], tang[:, 0]], axis=1)


def _cut_and_wall(airfoil_xy, n_around: int, n_wake: int, farfield: float):
    """The C's j = 0 line (I, 2): the cut from the outflow to the trailing edge (geometric from the
    trailing edge's spacing), the airfoil clockwise from the trailing edge, the cut out again; with the
    trailing edge's two line indices and the chord."""
    xy = _resample(close_trailing_edge(np.asarray(airfoil_xy, dtype=np.float64)), n_around)
    if polygon_area(xy[:-1]) < 0:
        raise ValueError("the airfoil coordinates run clockwise; expected Selig order (upper side first)")
    te = xy[0]
    chord = float(te[0] - xy[:, 0].min())
    wall = xy[::-1]                                     # lower TE -> LE -> upper TE: clockwise
    ds_te = float(np.linalg.norm(wall[1] - wall[0]))
    cut = te[0] + _geometric(np.array([ds_te]), np.array([farfield * chord]), n_wake)[0, 1:]
    line0 = np.concatenate([np.stack([cut[::-1], np.full(n_wake, te[1])], axis=1), wall,
                            np.stack([cut, np.full(n_wake, te[1])], axis=1)])
    return line0, n_wake, n_wake + len(wall) - 1, chord


def _arc(line: np.ndarray) -> np.ndarray:
    """Cumulative arc length (m,) along a polyline (m, 2)."""
    return np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(line, axis=0), axis=1))]


def _start_directions(line0: np.ndarray, w0: int, w1: int, chord: float) -> np.ndarray:
    """Unit start directions (I, 2): the wall normals into the fluid, straight down and up from the cut,
    averaged (a Gaussian in arc length, each side of the cut on its own) over ``TE_BLEND`` chords at the
    trailing edge, fading to none 10 ``TE_BLEND`` ahead of it."""
    normal = _wall_normals(line0)
    normal[:w0] = (0.0, -1.0)
    normal[w1 + 1:] = (0.0, 1.0)
    s0 = _arc(line0)
    te_x = line0[w0, 0]
    near = np.clip((line0[:, 0] - (te_x - 10 * TE_BLEND * chord)) / (10 * TE_BLEND * chord), 0.0, 1.0)
    width = TE_BLEND * chord * near + 1e-12
    lower = np.arange(len(line0)) <= (w0 + w1) // 2
    for side in (lower, ~lower):
        idx = np.flatnonzero(side)
        kern = np.exp(-0.5 * ((s0[idx][:, None] - s0[idx][None, :]) / width[idx][:, None]) ** 2)
        normal[idx] = kern @ normal[idx]
    return normal / np.linalg.norm(normal, axis=1, keepdims=True)


def _far_points(line0: np.ndarray, w0: int, w1: int, length: float) -> np.ndarray:
    """Each line's far-field point (I, 2): straight below and above the cut's points, and round the
    half circle of radius ``length`` about the trailing edge for the airfoil's (by arc length: 270 deg
    below the trailing edge, 180 ahead, 90 above)."""
    te = line0[w0]
    outer = np.empty_like(line0)
    outer[:w0] = np.stack([line0[:w0, 0], np.full(w0, te[1] - length)], axis=1)
    outer[w1 + 1:] = np.stack([line0[w1 + 1:, 0], np.full(len(line0) - w1 - 1, te[1] + length)], axis=1)
    s0 = _arc(line0)
    frac = (s0[w0:w1 + 1] - s0[w0]) / (s0[w1] - s0[w0])
    theta = 1.5 * np.pi - np.pi * frac
    outer[w0:w1 + 1] = te + length * np.stack([np.cos(theta), np.sin(theta)], axis=1)
    return outer


def _lines(line0: np.ndarray, normal: np.ndarray, outer: np.ndarray, chord: float, first: float,
           n_normal: int, extra: np.ndarray) -> np.ndarray:
    """The grid (I, n_normal, 2): each line a cubic Hermite curve from its start point (tangent
    ``NORMAL_REACH`` chords along its start direction) to its far-field point, sampled finely near its
    start, its points placed by arc length with geometric growth from ``first``, plus ``extra`` (I,)
    times ``j (1 - d_j / L)`` at its point ``j`` (``d_j`` the geometric distance, ``L`` the line's
    length): a first cell ``first + extra`` that fades into the geometric one, the far field's point
    unchanged, and neighbouring lines' points shifted by ``j`` times their difference in ``extra``."""
    t = np.linspace(0.0, 1.0, 4001) ** 3
    h00, h10, h01, h11 = 2 * t**3 - 3 * t**2 + 1, t**3 - 2 * t**2 + t, -2 * t**3 + 3 * t**2, t**3 - t**2
    curve = (h00[None, :, None] * line0[:, None] + h10[None, :, None] * (NORMAL_REACH * chord * normal)[:, None]
             + h01[None, :, None] * outer[:, None] + h11[None, :, None] * (outer - line0)[:, None])
    arc = np.concatenate([np.zeros((len(line0), 1)),
                          np.cumsum(np.linalg.norm(np.diff(curve, axis=1), axis=2), axis=1)], axis=1)
    dist = _geometric(np.full(len(line0), first), arc[:, -1], n_normal - 1)
    dist += extra[:, None] * np.arange(n_normal) * (1.0 - dist / dist[:, -1:])
    grid = np.empty((len(line0), n_normal, 2))
    for c in range(2):                                  # per coordinate, line by line (not point by point)
        grid[..., c] = np.array([np.interp(dist[i], arc[i], curve[i, :, c]) for i in range(len(line0))])
    grid[:, 0] = line0
    return grid


def c_grid(airfoil_xy, n_around: int = 257, n_wake: int = 65, n_normal: int = 97, first_cell: float = 1.5e-6,
           farfield: float = 100.0, wake_growth: float = WAKE_GROWTH
           ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The structured C-grid (see the module docstring) and its boundary lines.

    Parameters
    ----------
    airfoil_xy : (n, 2) array
        Airfoil coordinates in Selig order, chord along x from about 0 to about 1; a blunt trailing
        edge is closed (:func:`close_trailing_edge`).
    n_around : int
        Points on the airfoil from the trailing edge round to it, both ends counted (as
        :func:`ffdcli.testing.ogrid.airfoil_ogrid`; made odd: the leading edge is a point).
    n_wake : int
        Points along the cut behind the trailing edge (the trailing edge not counted).
    n_normal : int
        Points on each line from the wall or cut (j = 0) to the far field.
    first_cell : float
        Height of the wall cells (chords).
    farfield : float
        Distance (chords) of the far field from the trailing edge: the radius of the half circle in
        front, the height of the lines above and below the cut, the length of the cut.
    wake_growth : float
        The cells on the wake cut are ``first_cell + wake_growth * x`` high, ``x`` the distance behind
        the trailing edge (chords; 0 carries the wall's first cell down the whole cut).

    Returns
    -------
    grid : (I, n_normal, 2) float64
        The grid points, ``I = n_around + 2 n_wake`` lines, the trailing edge at two lines and
        each cut point at two.
    ids : (I, n_normal) int64
        Each grid point's index into ``points`` (the cut's two sides and the trailing edge share one).
    points : (N, 2) float64
    quads : (Q, 4) int64
        Counter-clockwise (positive area in the x-y plane).
    boundary : dict of str to (E, 2) int64
        ``airfoil`` and ``farfield`` line segments, each with the fluid on its left.
    """
    n_around += 1 - n_around % 2
    line0, w0, w1, chord = _cut_and_wall(airfoil_xy, n_around, n_wake, farfield)
    normal = _start_directions(line0, w0, w1, chord)
    outer = _far_points(line0, w0, w1, farfield * chord)
    if not wake_growth >= 0:
        raise ValueError(f"wake_growth {wake_growth}: expected >= 0")
    behind = np.clip(line0[:, 0] - line0[w0, 0], 0.0, None)
    behind[w0:w1 + 1] = 0.0                             # the wall's lines keep their first cell
    grid = _lines(line0, normal, outer, chord, first_cell * chord, n_normal, wake_growth * behind)
    n_lines = len(line0)
    # one index per point: the cut's two sides and the trailing edge's two lines share theirs
    ids = np.arange(n_lines * n_normal).reshape(n_lines, n_normal)
    ids[w1:, 0] = ids[w0::-1, 0]
    used, ids = np.unique(ids, return_inverse=True)
    ids = ids.reshape(n_lines, n_normal)
    points = np.empty((len(used), 2))
    points[ids.ravel()] = grid.reshape(-1, 2)
    quads = np.stack([ids[:-1, :-1], ids[1:, :-1], ids[1:, 1:], ids[:-1, 1:]], axis=-1).reshape(-1, 4)
    areas = quad_areas(points, quads)
    if areas.min() <= 0:
        raise ValueError(f"{int(np.sum(areas.min(axis=1) <= 0))} C-mesh cells are inverted; try more points "
                         "around, a larger first_cell or fewer normal points")
    # boundary segments in their quads' counter-clockwise order: the fluid on the left
    airfoil = np.stack([ids[w0:w1, 0], ids[w0 + 1:w1 + 1, 0]], axis=1)
    far = np.concatenate([np.stack([ids[0, 1:], ids[0, :-1]], axis=1),          # outflow, below the cut
                          np.stack([ids[1:, -1], ids[:-1, -1]], axis=1),        # the C
                          np.stack([ids[-1, :-1], ids[-1, 1:]], axis=1)])       # outflow, above
    return grid, ids, points, quads.astype(np.int64), {"airfoil": airfoil.astype(np.int64),
                                                       "farfield": far.astype(np.int64)}


def cmesh(airfoil_xy, n_around: int = 257, n_wake: int = 65, n_normal: int = 97, first_cell: float = 1.5e-6,
          farfield: float = 100.0, wake_growth: float = WAKE_GROWTH) -> Mesh:
    """:func:`c_grid` as a 2D :class:`~ffdcli.mesh.Mesh`: ``dim=2``, points (N, 3) with z = 0, one
    ``quad`` block, markers ``airfoil`` and ``farfield`` (``line`` blocks; the cut has none)."""
    _, _, xy, quads, lines = c_grid(airfoil_xy, n_around, n_wake, n_normal, first_cell, farfield, wake_growth)
    pts = np.zeros((len(xy), 3))
    pts[:, :2] = xy
    return Mesh(points=pts, dim=2, cells=[CellBlock("quad", quads)],
                markers={name: [CellBlock("line", seg)] for name, seg in lines.items()})
