"""Structured 2D O-grids of quads around an airfoil, in plain NumPy (a fixture; no gmsh).

The bundled ``samples/naca0012_2d.su2`` is :func:`airfoil_ogrid_mesh` of NACA 0012; the hexahedral
wings of :func:`ffdcli.testing.wings.extruded_wing_mesh` extrude it along the span.
"""

from __future__ import annotations

import numpy as np
from scipy.interpolate import CubicSpline

from ffdcli.mesh import CellBlock, Mesh
from ffdcli.testing.cells import quad_areas
from ffdcli.testing.naca import naca4, polygon_area


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


def _march_layers(ring0: np.ndarray, dist: np.ndarray, chord: float, smoothing: int) -> np.ndarray:
    """Layers (len(dist), m, 2) marched from the airfoil ring ``ring0`` (m, 2) along the normals of
    the previous layer to the distances ``dist``, each smoothed along its length ``smoothing`` times.

    Corners of the airfoil (sharp trailing edge, the two corners of a blunt base): sliding them
    along the first layers would pull them round the corner and fold the wall cells there, so their
    smoothing along the layer starts only at ``corner_free`` (in distance from the wall).
    """
    fwd0 = np.roll(ring0, -1, axis=0) - ring0
    bwd0 = np.roll(ring0, 1, axis=0) - ring0
    cosang = np.sum(fwd0 * bwd0, axis=1) / (np.linalg.norm(fwd0, axis=1) * np.linalg.norm(bwd0, axis=1))
    corner = (cosang > -0.5)[:, None]                                 # turn of more than 60 degrees
    corner_free = 0.05 * chord
    layers = [ring0]
    cur = ring0
    for k in range(1, len(dist)):
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
    return np.stack(layers)


def _ellipse_layers(dist: np.ndarray, chord: float, centre: np.ndarray, e_c: np.ndarray, e_t: np.ndarray,
                    m: int, sharp: bool) -> np.ndarray:
    """The grid (len(dist), m, 2) of confocal ellipses around the chord line, the last one a circle.

    The conformal map of a flat plate: cosine-spaced surface points are evenly spaced in its angle
    theta. ``e_c``, ``e_t``: unit chord and thickness directions; ``centre``: the mid-chord point.
    """
    theta = 2 * np.pi * (np.arange(m) + (0.0 if sharp else 0.5)) / m
    a = dist + 0.5 * chord                                            # semi-axes along the chord
    b = np.sqrt(np.maximum(a**2 - 0.25 * chord**2, 0.0))              # and across it
    b = b + (a - b) * (dist / dist[-1]) ** 2                          # -> circle of radius R
    return (centre + (a[:, None] * np.cos(theta))[..., None] * e_c
            + (b[:, None] * np.sin(theta))[..., None] * e_t)


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

    marched = _march_layers(ring0, dist, chord, smoothing)          # (n_radial, m, 2)
    ellipses = _ellipse_layers(dist, chord, centre, e_c, e_t, m, sharp)

    # marched near the wall, elliptic far away
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
