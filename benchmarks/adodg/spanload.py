"""Span load and span efficiency of a wing from its surface pressures (ADODG Case 3).

Pure functions (NumPy only) on arrays; :func:`surface_load` and :func:`strip_loads` take the wall's
triangles and the pressure coefficient at its nodes (SU2's ``surface_flow.csv`` and the wall marker of the
mesh the flow ran on), the rest take a span load.

Conventions: the span axis is ``span_axis`` (y for the Case 3 meshes), the root at 0 and the wing on the
positive side; the lift direction is ``(-sin a, 0, cos a)`` for angle of attack ``a`` in the x-z plane
(SU2's 3-D convention). Loads are coefficients: ``c cl(y) = (dL/dy) / q_inf`` (length units), so that
``CL = (1 / S_half) * integral_0^s c cl dy`` for a half wing of reference area ``S_half``.

Span efficiency two ways:

- from the drag: ``e = CL^2 / (pi AR CDi)`` with ``CDi = CD - CD0``, ``CD0`` the drag the same mesh gives
  at zero lift (an inviscid solver's spurious drag: entropy made by the discretisation) --
  :func:`span_efficiency`;
- from the load (the Trefftz-plane drag of a flat wake carrying this load, the lifting-line result):
  fit the strip loads with ``c cl(theta) = sum_n A_n sin(n theta)``, ``y = s cos(theta)``, odd ``n``
  (a symmetric wing), then ``e = 1 / (1 + sum_{n>1} n (A_n / A_1)^2)`` -- :func:`load_efficiency`.
  It does not see the spurious drag at all; it sees only the load's shape.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class SpanLoad:
    """Strip loads of a half wing.

    edges : (N + 1,) float64
        Strip boundaries along the span, root (0) to the last wall point.
    ccl : (N,) float64
        Each strip's mean ``c cl`` (its lift coefficient times q-normalised area, divided by its width).
    cl_total : float
        ``sum(ccl * widths)``: ``CL * S_half``.
    """

    edges: np.ndarray
    ccl: np.ndarray
    cl_total: float

    @property
    def centres(self) -> np.ndarray:
        """(N,) strip mid-points."""
        return 0.5 * (self.edges[1:] + self.edges[:-1])

    @property
    def widths(self) -> np.ndarray:
        """(N,) strip widths."""
        return np.diff(self.edges)


def triangle_forces(points: np.ndarray, tris: np.ndarray, cp: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pressure force coefficient of each wall triangle and its centroid.

    Parameters
    ----------
    points : (P, 3) float64
        Mesh points.
    tris : (F, 3) int64
        Wall triangles, each normal pointing out of the fluid (into the body: the mesh's convention).
    cp : (P,) float64
        Pressure coefficient at the points (only the wall's are read), linear on each triangle.

    Returns
    -------
    force : (F, 3) float64
        ``mean(cp) * area * n``: the triangle's force divided by ``q_inf`` (length^2 units).
    centroid : (F, 3) float64
    """
    p = points[tris]
    area_n = 0.5 * np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    return cp[tris].mean(axis=1)[:, None] * area_n, p.mean(axis=1)


def strip_loads(points: np.ndarray, tris: np.ndarray, cp: np.ndarray, *, n_strips: int, alpha_deg: float,
                span_axis: int = 1, span: float | None = None, edges: np.ndarray | None = None) -> SpanLoad:
    """Span load ``c cl`` in ``n_strips`` equal strips from the root to ``span`` (default: the wall's
    largest span coordinate), or in the strips between ``edges`` (N + 1,) (increasing, from 0 to the
    span: e.g. :func:`wall_stations` of a wall meshed in spanwise rows, whose triangles then fall
    whole in their own strip), each triangle's lift counted in the strip of its centroid (a centroid
    beyond the last edge, on a tip cap, in the last strip: the total is every triangle's lift).

    Parameters as :func:`triangle_forces`; ``alpha_deg`` sets the lift direction
    ``(-sin a, 0, cos a)``.

    Returns
    -------
    SpanLoad
        ``ccl`` (n_strips,) = strip lift / q_inf / strip width.
    """
    force, centroid = triangle_forces(points, tris, cp)
    a = np.radians(alpha_deg)
    lift_dir = np.zeros(3)
    lift_dir[0], lift_dir[2] = -np.sin(a), np.cos(a)
    lift = force @ lift_dir
    if edges is None:
        s = float(points[np.unique(tris), span_axis].max()) if span is None else float(span)
        edges = np.linspace(0.0, s, n_strips + 1)
    edges = np.asarray(edges, dtype=float)
    n = len(edges) - 1
    idx = np.clip(np.searchsorted(edges, centroid[:, span_axis], side="right") - 1, 0, n - 1)
    per = np.bincount(idx, weights=lift, minlength=n)
    return SpanLoad(edges=edges, ccl=per / np.diff(edges), cl_total=float(lift.sum()))


def drag_by_region(points: np.ndarray, tris: np.ndarray, cp: np.ndarray, *, alpha_deg: float,
                   x_edges: np.ndarray, span: float, span_axis: int = 1) -> tuple[np.ndarray, float]:
    """Pressure drag (force / q_inf, length^2 units; divide by the reference area for CD) of the wall's
    triangles by chordwise region, the tip cap apart: where a drag that should vanish (an Euler wing at
    zero lift) comes from.

    Parameters as :func:`triangle_forces`; ``alpha_deg`` sets the drag direction ``(cos a, 0, sin a)``;
    ``x_edges`` (R + 1,) increasing chordwise edges (a centroid before the first or after the last is
    counted in the first or last region); ``span``: a triangle whose centroid lies beyond it is the tip
    cap's.

    Returns
    -------
    regions : (R,) float64
        The drag of the wing's triangles (centroid within ``span``) in each chordwise region.
    cap : float
        The drag of the cap's triangles. ``regions.sum() + cap`` is the wall's pressure drag.
    """
    force, centroid = triangle_forces(points, tris, cp)
    a = np.radians(alpha_deg)
    drag = force[:, 0] * np.cos(a) + force[:, 2] * np.sin(a)
    cap = centroid[:, span_axis] > span
    edges = np.asarray(x_edges, dtype=float)
    n = len(edges) - 1
    idx = np.clip(np.searchsorted(edges, centroid[:, 0], side="right") - 1, 0, n - 1)
    return np.bincount(idx[~cap], weights=drag[~cap], minlength=n), float(drag[cap].sum())


def wall_stations(points: np.ndarray, tris: np.ndarray, span: float, *, span_axis: int = 1,
                  most: int = 400) -> np.ndarray | None:
    """The distinct span coordinates (K,) of the wall's nodes from 0 to ``span``, when the wall is
    meshed in spanwise rows (at most ``most`` distinct values, the first 0 and the last ``span``);
    None for an unstructured wall. Values within ``1e-9 span`` of each other are one row (a mesh
    moved by another program, SU2_DEF's, carries its rows' span coordinates with round-off)."""
    tol = 1e-9 * span
    y = np.unique(points[np.unique(tris), span_axis])
    y = y[(y >= -tol) & (y <= span + tol)]
    if len(y) < 2:
        return None
    y = y[np.concatenate([[True], np.diff(y) > tol])]
    if len(y) > most or abs(y[0]) > tol or abs(y[-1] - span) > tol:
        return None
    y[0], y[-1] = 0.0, span
    return y


def ellipse_strips(edges: np.ndarray, cl_total: float, s: float) -> np.ndarray:
    """Mean over each strip of the elliptic load ``c0 sqrt(1 - (y/s)^2)`` of the same total
    ``integral_0^s = cl_total`` (``c0 = 4 cl_total / (pi s)``); zero beyond ``s``.

    edges : (N + 1,) -> (N,) float64
    """
    c0 = 4.0 * cl_total / (np.pi * s)
    t = np.clip(np.asarray(edges, dtype=float) / s, 0.0, 1.0)
    prim = 0.5 * s * (t * np.sqrt(1.0 - t * t) + np.arcsin(t))       # integral_0^y sqrt(1-(y/s)^2) dy
    return c0 * np.diff(prim) / np.diff(edges)


@dataclass(frozen=True)
class EllipseDifference:
    """The load against the ellipse of the same lift, in % of the ellipse's root load ``c0``.

    rms, max_abs : float
        Root mean square and largest |difference| over the strips (%).
    c0 : float
        The ellipse's root load ``4 cl_total / (pi s)``.
    ellipse : (N,) float64
        The ellipse's strip means.
    """

    rms: float
    max_abs: float
    c0: float
    ellipse: np.ndarray


def ellipse_difference(load: SpanLoad, s: float) -> EllipseDifference:
    """Compare ``load`` with the elliptic load over semispan ``s`` carrying the same lift."""
    ell = ellipse_strips(load.edges, load.cl_total, s)
    c0 = 4.0 * load.cl_total / (np.pi * s)
    d = 100.0 * (load.ccl - ell) / c0
    return EllipseDifference(rms=float(np.sqrt(np.mean(d * d))), max_abs=float(np.max(np.abs(d))), c0=c0,
                             ellipse=ell)


def _sin_strip_means(edges: np.ndarray, n: int, s: float) -> np.ndarray:
    """Mean over each strip of ``sin(n theta)`` with ``y = s cos(theta)`` (exact), (N,)."""
    theta = np.arccos(np.clip(np.asarray(edges, dtype=float) / s, 0.0, 1.0))

    def prim(th):   # integral of sin(n th) * s sin(th) dth = (s/2) [sin((n-1)th)/(n-1) - sin((n+1)th)/(n+1)]
        first = th if n == 1 else np.sin((n - 1) * th) / (n - 1)
        return 0.5 * s * (first - np.sin((n + 1) * th) / (n + 1))

    # dy = -s sin(th) dth: integral over y from y0 to y1 = prim(th0) - prim(th1)
    return (prim(theta[:-1]) - prim(theta[1:])) / np.diff(edges)


def fourier_coefficients(load: SpanLoad, s: float, n_terms: int = 6) -> np.ndarray:
    """Least-squares ``A_n`` (odd n = 1, 3, ..., 2 n_terms - 1) of ``c cl = sum A_n sin(n theta)``,
    ``y = s cos(theta)``, fitted to the strip means (exact strip integrals of each mode), strips inside
    ``[0, s]`` only; (n_terms,)."""
    inside = load.edges[1:] <= s * (1.0 + 1e-12)
    edges = load.edges[: int(inside.sum()) + 1]
    basis = np.stack([_sin_strip_means(edges, 2 * k + 1, s) for k in range(n_terms)], axis=1)
    coef, *_ = np.linalg.lstsq(basis, load.ccl[: len(edges) - 1], rcond=None)
    return coef


def load_efficiency(coefficients: np.ndarray) -> float:
    """Span efficiency of a load with odd Fourier coefficients ``A_1, A_3, ...`` (n,):
    ``1 / (1 + sum_{n>1} n (A_n/A_1)^2)``."""
    a = np.asarray(coefficients, dtype=float)
    n = 2 * np.arange(len(a)) + 1
    return float(1.0 / (1.0 + np.sum(n[1:] * (a[1:] / a[0]) ** 2)))


def span_efficiency(cl: float, cd: float, cd0: float, aspect_ratio: float) -> float:
    """``CL^2 / (pi AR (CD - CD0))``: ``CD0`` the zero-lift (spurious) drag of the same mesh."""
    return float(cl * cl / (np.pi * aspect_ratio * (cd - cd0)))
