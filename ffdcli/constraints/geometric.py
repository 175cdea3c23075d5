"""Geometric constraints of a design with exact derivatives: thickness, t/c, volume, LE/TE, fold-free.

Each constraint item of a design file's ``constraints:`` becomes one object here, built once on the
baseline (undeformed) surface and lattice; its values are ratios to the baseline unless said
otherwise. Every object has

``value(inp) -> (c,)`` and ``jacobian(inp) -> (c, n_vars)``
    for the current design, ``inp`` a :class:`ConstraintInputs` (the deformed lattice ``P``, its
    Jacobian ``D = dP'/dv`` (n_ctrl*3, n_vars), the deformed surface points and the basis ``B``).

The kinds
---------
thickness
    A chord x span grid: at each span fraction (root 0 -> tip 1) the local baseline chord line
    (leading-edge to trailing-edge point, interpolated between the box's sections) is sampled at the
    chord fractions, and each sample is projected along the box's thickness axis onto the upper and
    lower surface (the highest and lowest crossing of the surface triangles). The point pairs are a
    :class:`ffdcli.lattice.pointset.PointSet`, embedded in the lattice, so they move with it. Value:
    ``|U' - L'| / |U0 - L0|`` (the distance of the moved pair: a rotation of the section does not
    change it). Item ``j`` runs over chord fastest: ``j = span_index * n_chord + chord_index``.
thickness_to_chord
    The same pairs divided by the local chord ``|LE' - TE'|`` of the moved leading- and
    trailing-edge points of the local chord line (embedded as well), as a ratio to the baseline.
volume
    Volume enclosed by the surface triangles (quads split in two), by the divergence theorem
    ``V = 1/6 sum (a - o) . ((b - o) x (c - o))`` with ``o`` on the root plane: the open root of a
    half wing lies in that plane, where ``(x - o) . n = 0``, so the symmetry plane closes the wing
    exactly and contributes nothing. A closed surface gives its volume for any ``o``. In 2D: the area
    enclosed by the airfoil. Ratio to the baseline.
le_te
    Linear, in mesh units: for the first (leading-edge) and last (trailing-edge) chordwise control
    points of each section, the sum of the shape moves of the upper (k = l-1) and lower (k = 0)
    point; ``= 0`` (the default bounds) means they move by equal and opposite amounts, so the
    shape variables cannot shear the section. One item per (section, edge) that some shape variable
    moves, root to tip, leading edge before trailing edge.
fold_free
    ``min over u of det J'(u) / det J0(u)``: the Jacobian determinant of the lattice map after the
    changes over that of the baseline, i.e. ``det F`` of the deformation of the box, > 0 when the
    FFD volume (and so the mesh inside it) does not fold. Sampled (not a guaranteed bound) on a
    parameter grid of ``samples`` points per knot span and direction plus every knot, so it includes
    every corner, edge and face of the box; between samples ``det F`` is a smooth rational function
    whose dips of less than a sample spacing are not seen. Exact for affine changes (span, sweep,
    dihedral, uniform chord: ``det F`` constant). The derivative is that of the smallest sample; where
    several samples tie for the smallest (regions that no shape variable reaches keep one ratio), it
    is that of one of them (a one-sided derivative, as for any minimum).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
from numba import njit

from ffdcli.errors import InputError
from ffdcli.lattice.embedding import sample_grid
from ffdcli.lattice.lattice import _axis_tables, derivatives
from ffdcli.lattice.pointset import PointSet
from ffdcli.parameterization.changes import Shape

#: The kinds of ``constraints:`` items, in the order of the docs.
CONSTRAINT_KINDS = ("thickness", "thickness_to_chord", "volume", "le_te", "fold_free")
#: A constraint value within this of a bound is satisfied (the values are ratios near 1).
SATISFIED_TOL = 1e-9
#: Span fractions 0 and 1 (the root and tip edges of the surface) are read this far inside.
END_INSET = 1e-6
#: Samples per knot span and direction of ``fold_free`` by default.
FOLD_SAMPLES = 4


class ConstraintInputs:
    """What the constraints read of the current design, computed once and only when asked for.

    Parameters
    ----------
    P : ndarray, shape (n, m, l, 3)
        The deformed lattice.
    P0 : ndarray, shape (n, m, l, 3)
        The baseline lattice.
    values : ndarray, shape (n_vars,)
        The design-variable values.
    lattice_jacobian : callable () -> ndarray (n_ctrl*3, n_vars)
        ``dP'/dv`` (:func:`ffdcli.parameterization.derivatives.lattice_jacobian`).
    surface_points : callable () -> ndarray (S, 3)
        The deformed surface points.
    basis : callable () -> sparse (S, n_ctrl)
        The surface basis ``B``.
    rmatvec : callable (G (S, 3)) -> (n_ctrl, 3), optional
        ``B.T @ G`` by a faster route than ``basis`` (e.g. :meth:`ffdcli.lattice.embedding.Embedding.rmatvec`).
    """

    def __init__(self, P, P0, values, lattice_jacobian: Callable, surface_points: Callable, basis: Callable,
                 rmatvec: Callable | None = None):
        self.P = np.asarray(P, dtype=float)
        self.P0 = np.asarray(P0, dtype=float)
        self.values = np.asarray(values, dtype=float)
        self._D, self._X, self._B, self._rmatvec = lattice_jacobian, surface_points, basis, rmatvec

    def rmatvec(self, G: np.ndarray) -> np.ndarray:
        """(n_ctrl, 3) ``B.T @ G`` for ``G`` (S, 3) (a compiled product when one was given)."""
        if self._rmatvec is not None:
            return self._rmatvec(G)
        return np.asarray(self.B.T @ G)

    @cached_property
    def dP(self) -> np.ndarray:
        """(n_ctrl, 3) ``(P' - P0).reshape(-1, 3)``."""
        return (self.P - self.P0).reshape(-1, 3)

    @cached_property
    def D(self) -> np.ndarray:
        """(n_ctrl*3, n_vars)."""
        return self._D()

    @cached_property
    def X(self) -> np.ndarray:
        """(S, 3)."""
        return self._X()

    @cached_property
    def B(self):
        """(S, n_ctrl) sparse."""
        return self._B()


# --------------------------------------------------------------------------------------------------
# Geometry of the baseline: triangles, local chord lines, projection along the thickness axis
# --------------------------------------------------------------------------------------------------

def surface_triangles(faces) -> np.ndarray:
    """(T, 3) local point indices of the triangles of triangle and quad blocks (quads split 0-1-2, 0-2-3)."""
    out = [np.zeros((0, 3), dtype=np.int64)]
    for b in faces:
        d = np.asarray(b.data, dtype=np.int64)
        if b.type == "triangle":
            out.append(d)
        elif b.type == "quad":
            out += [d[:, [0, 1, 2]], d[:, [0, 2, 3]]]
    return np.concatenate(out)


def surface_segments(faces) -> np.ndarray:
    """(E, 2) local point indices of the line blocks (a 2D surface)."""
    out = [np.zeros((0, 2), dtype=np.int64)]
    out += [np.asarray(b.data, dtype=np.int64) for b in faces if b.type == "line"]
    return np.concatenate(out)


def chord_lines(box, span_fractions) -> tuple[np.ndarray, np.ndarray]:
    """(le, te), each (k, 3): the box's leading- and trailing-edge points interpolated linearly
    between its sections at span fractions ``span_fractions`` (k,) (0 = root, 1 = tip)."""
    eta = np.asarray(span_fractions, dtype=float)
    m = box.le_points.shape[0]
    if m == 1:
        return np.repeat(box.le_points, len(eta), 0), np.repeat(box.te_points, len(eta), 0)
    x = eta * (m - 1)
    j = np.clip(np.floor(x).astype(int), 0, m - 2)
    w = (x - j)[:, None]
    le = (1 - w) * box.le_points[j] + w * box.le_points[j + 1]
    te = (1 - w) * box.te_points[j] + w * box.te_points[j + 1]
    return le, te


def project_thickness(points, faces, box, Q) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Project points ``Q`` (k, 3) along the thickness axis onto the upper and lower surface.

    Returns ``(upper (k, 3), lower (k, 3), ok (k,) bool)``: the highest and lowest crossing of the
    line through each point parallel to the thickness axis with the surface (triangles in 3D,
    segments in 2D); ``ok`` is False where the line crosses the surface fewer than twice.
    """
    t_ax = box.axes.thickness
    Q = np.asarray(Q, dtype=float)
    k = len(Q)
    up = np.full(k, -np.inf)
    lo = np.full(k, np.inf)
    P0 = box.control_points.reshape(-1, 3)
    scale = float(np.ptp(P0, axis=0).max()) or 1.0          # the box's size (cheap: control points)
    if box.dim == 3:
        a_ax, s_ax = box.axes.chord, box.axes.span
        tri = surface_triangles(faces)
        us = points[:, s_ax][tri]                           # (T, 3) span coordinates only
        smin, smax = us.min(axis=1), us.max(axis=1)
        order = np.argsort(smin, kind="stable")
        smin_sorted = smin[order]
        width = float((smax - smin).max(initial=0.0))
        eps = 1e-9 * scale
        for s_val in np.unique(Q[:, s_ax]):
            # triangles whose span interval holds s_val: smin in [s_val - width, s_val] (a sorted range)
            a0, a1 = np.searchsorted(smin_sorted, [s_val - width - eps, s_val + eps], side="left")
            cand = order[a0:a1]
            band = cand[smax[cand] >= s_val - eps]
            rows = np.flatnonzero(Q[:, s_ax] == s_val)
            if not band.size:
                continue
            p = points[tri[band]]                                          # (b, 3, 3)
            A, S, T = p[..., a_ax], p[..., s_ax], p[..., t_ax]
            det = (A[:, 1] - A[:, 0]) * (S[:, 2] - S[:, 0]) - (A[:, 2] - A[:, 0]) * (S[:, 1] - S[:, 0])
            keep = np.abs(det) > 1e-14 * scale * scale
            A, S, T, det = A[keep], S[keep], T[keep], det[keep]
            qa = Q[rows, a_ax][:, None]                                    # (r, 1)
            qs = Q[rows, s_ax][:, None]
            l1 = ((qa - A[:, 0]) * (S[:, 2] - S[:, 0]) - (A[:, 2] - A[:, 0]) * (qs - S[:, 0])) / det
            l2 = ((A[:, 1] - A[:, 0]) * (qs - S[:, 0]) - (qa - A[:, 0]) * (S[:, 1] - S[:, 0])) / det
            l0 = 1.0 - l1 - l2
            tol = 1e-9
            hit = (l0 >= -tol) & (l1 >= -tol) & (l2 >= -tol)               # (r, b)
            tq = l0 * T[:, 0] + l1 * T[:, 1] + l2 * T[:, 2]
            up[rows] = np.where(hit, tq, -np.inf).max(axis=1, initial=-np.inf)
            lo[rows] = np.where(hit, tq, np.inf).min(axis=1, initial=np.inf)
    else:
        a_ax = box.axes.chord
        seg = surface_segments(faces)
        p = points[seg]                                     # (E, 2, 3)
        A, T = p[..., a_ax], p[..., t_ax]
        dA = A[:, 1] - A[:, 0]
        keep = np.abs(dA) > 0
        A, T, dA = A[keep], T[keep], dA[keep]
        qa = Q[:, a_ax][:, None]
        s = (qa - A[:, 0]) / dA
        hit = (s >= -1e-9) & (s <= 1 + 1e-9)
        tq = T[:, 0] + s * (T[:, 1] - T[:, 0])
        up = np.where(hit, tq, -np.inf).max(axis=1, initial=-np.inf)
        lo = np.where(hit, tq, np.inf).min(axis=1, initial=np.inf)
    ok = np.isfinite(up) & np.isfinite(lo) & (up - lo > 1e-9 * scale)
    U, L = Q.copy(), Q.copy()
    U[:, t_ax] = np.where(ok, up, Q[:, t_ax])
    L[:, t_ax] = np.where(ok, lo, Q[:, t_ax])
    return U, L, ok


# --------------------------------------------------------------------------------------------------
# The constraint kinds
# --------------------------------------------------------------------------------------------------

@dataclass(frozen=True, eq=False)
class Constraint:
    """Common part: the position in ``constraints``, the kind, the bounds and the item names."""

    index: int
    lower: float
    upper: float

    kind = ""

    @property
    def size(self) -> int:  # pragma: no cover
        raise NotImplementedError

    @property
    def scalar(self) -> bool:
        """True when the constraint is one number named without brackets."""
        return False

    @property
    def names(self) -> list[str]:
        """``k<index>.<kind>`` or ``k<index>.<kind>[<j>]`` per item."""
        base = f"k{self.index}.{self.kind}"
        return [base] if self.scalar else [f"{base}[{j}]" for j in range(self.size)]

    def value(self, inp: ConstraintInputs) -> np.ndarray:  # pragma: no cover
        raise NotImplementedError

    def jacobian(self, inp: ConstraintInputs) -> np.ndarray:  # pragma: no cover
        raise NotImplementedError

    def value_and_jacobian(self, inp: ConstraintInputs) -> tuple[np.ndarray, np.ndarray]:
        """Both at once ((c,), (c, n_vars)); kinds that share the work override it."""
        return self.value(inp), self.jacobian(inp)


def _norm_jac(d: np.ndarray, Jd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(|d| (k,), d|d|/dv (k, nv)) for vectors d (k, 3) with derivatives Jd (k, 3, nv)."""
    r = np.linalg.norm(d, axis=1)
    return r, np.einsum("kc,kcv->kv", d / r[:, None], Jd)


@dataclass(frozen=True, eq=False)
class Thickness(Constraint):
    """Thickness ratios at a chord x span grid (also ``thickness_to_chord`` with ``per_chord``).

    pairs
        :class:`ffdcli.lattice.pointset.PointSet` of 2G points: the upper points then the lower points.
    chords
        PointSet of 2G points (leading-edge, then trailing-edge points of each item's chord line)
        for ``thickness_to_chord``; None for ``thickness``.
    base
        (G,) the baseline value of the unscaled quantity (thickness, or thickness over chord).
    """

    pairs: object = None
    chords: object = None
    base: np.ndarray = field(default=None)
    grid: np.ndarray = field(default=None)        # (G, 2) chord and span fraction of each item

    @property
    def kind(self):
        return "thickness" if self.chords is None else "thickness_to_chord"

    @property
    def size(self) -> int:
        return len(self.base)

    def value(self, inp):
        G = self.size
        X = self.pairs.points(inp.dP)
        t = np.linalg.norm(X[:G] - X[G:], axis=1)
        if self.chords is not None:
            C = self.chords.points(inp.dP)
            t = t / np.linalg.norm(C[:G] - C[G:], axis=1)
        return t / self.base

    def jacobian(self, inp):
        G = self.size
        X = self.pairs.points(inp.dP)
        JX = self.pairs.jacobian(inp.D)
        t, dt = _norm_jac(X[:G] - X[G:], JX[:G] - JX[G:])
        if self.chords is None:
            return dt / self.base[:, None]
        C = self.chords.points(inp.dP)
        JC = self.chords.jacobian(inp.D)
        c, dc = _norm_jac(C[:G] - C[G:], JC[:G] - JC[G:])
        return ((dt * c[:, None] - t[:, None] * dc) / (c * c)[:, None]) / self.base[:, None]


@njit(cache=True)
def _volume_nb(X, tri, o, want_grad, G):
    """Compiled :func:`_enclosed`: the volume; the gradient is accumulated into ``G`` (zeroed) if asked."""
    vol = 0.0
    for t in range(tri.shape[0]):
        i0, i1, i2 = tri[t, 0], tri[t, 1], tri[t, 2]
        ax, ay, az = X[i0, 0] - o[0], X[i0, 1] - o[1], X[i0, 2] - o[2]
        bx, by, bz = X[i1, 0] - o[0], X[i1, 1] - o[1], X[i1, 2] - o[2]
        cx, cy, cz = X[i2, 0] - o[0], X[i2, 1] - o[1], X[i2, 2] - o[2]
        bcx, bcy, bcz = by * cz - bz * cy, bz * cx - bx * cz, bx * cy - by * cx
        vol += ax * bcx + ay * bcy + az * bcz
        if want_grad:
            G[i0, 0] += bcx
            G[i0, 1] += bcy
            G[i0, 2] += bcz
            G[i1, 0] += cy * az - cz * ay
            G[i1, 1] += cz * ax - cx * az
            G[i1, 2] += cx * ay - cy * ax
            G[i2, 0] += ay * bz - az * by
            G[i2, 1] += az * bx - ax * bz
            G[i2, 2] += ax * by - ay * bx
    return vol / 6.0


def enclosed_volume(X: np.ndarray, tri: np.ndarray, o: np.ndarray, grad: bool = False):
    """Volume ``1/6 sum (a - o) . ((b - o) x (c - o))`` of triangles ``tri`` (T, 3) of points ``X`` (S, 3)
    and, if ``grad``, its gradient (S, 3) with respect to the points (compiled; see :func:`_enclosed`)."""
    X = np.ascontiguousarray(X, dtype=np.float64)
    G = np.zeros_like(X) if grad else np.zeros((0, 3))
    vol = _volume_nb(X, np.ascontiguousarray(tri, dtype=np.int64), np.asarray(o, dtype=np.float64), grad, G)
    if grad:
        G /= 6.0
    return vol, (G if grad else None)


def _enclosed(X: np.ndarray, cells: np.ndarray, o: np.ndarray, dim: int, grad: bool):
    """NumPy reference of :func:`enclosed_volume`: volume of triangles (T, 3) relative to ``o``, and its
    gradient (S, 3) with respect to the points if ``grad``."""
    if dim == 3:
        a, b, c = (X[cells[:, q]] - o for q in range(3))
        bc = np.cross(b, c)
        vol = float(np.einsum("ij,ij->", a, bc)) / 6.0
        if not grad:
            return vol, None
        G = np.zeros_like(X)
        for q, v in ((0, bc), (1, np.cross(c, a)), (2, np.cross(a, b))):
            for d in range(3):
                G[:, d] += np.bincount(cells[:, q], weights=v[:, d], minlength=len(X))
        return vol, G / 6.0
    raise AssertionError("2D areas use _area")  # pragma: no cover


def _area(X: np.ndarray, seg: np.ndarray, o: np.ndarray, ax: tuple[int, int], grad: bool):
    """Signed area 1/2 sum (a - o) x (b - o) of segments (E, 2) in the plane of mesh axes ``ax``."""
    i, j = ax
    a, b = X[seg[:, 0]] - o, X[seg[:, 1]] - o
    area = 0.5 * float(np.sum(a[:, i] * b[:, j] - a[:, j] * b[:, i]))
    if not grad:
        return area, None
    G = np.zeros_like(X)
    n = len(X)
    G[:, i] += 0.5 * (np.bincount(seg[:, 0], b[:, j], n) - np.bincount(seg[:, 1], a[:, j], n))
    G[:, j] += 0.5 * (np.bincount(seg[:, 1], a[:, i], n) - np.bincount(seg[:, 0], b[:, i], n))
    return area, G


@dataclass(frozen=True, eq=False)
class Volume(Constraint):
    """Enclosed volume (2D: area) of the surface as a ratio to the baseline (see the module docstring).

    cells
        (T, 3) triangles (3D) or (E, 2) segments (2D) of the surface, local point indices.
    origin
        (3,) a point on the root plane.
    base
        The baseline volume (signed: the face orientation's sign cancels in the ratio).
    """

    cells: np.ndarray = None
    origin: np.ndarray = None
    base: float = 1.0
    dim: int = 3
    plane: tuple[int, int] = (0, 1)

    kind = "volume"

    @property
    def size(self) -> int:
        return 1

    @property
    def scalar(self) -> bool:
        return True

    def measure(self, X, grad=False):
        """(volume or area, gradient (S, 3) or None) of surface points ``X`` (S, 3)."""
        if self.dim == 3:
            return enclosed_volume(X, self.cells, self.origin, grad)
        return _area(X, self.cells, self.origin, self.plane, grad)

    def value(self, inp):
        return np.array([self.measure(inp.X)[0] / self.base])

    def jacobian(self, inp):
        return self.value_and_jacobian(inp)[1]

    def value_and_jacobian(self, inp):
        vol, G = self.measure(inp.X, grad=True)
        gP = inp.rmatvec(G).reshape(-1)
        return np.array([vol / self.base]), (gP @ inp.D)[None, :] / self.base


@dataclass(frozen=True, eq=False)
class LeTe(Constraint):
    """Linear: ``A @ values`` (c,), the summed upper + lower shape moves at each section's edges.

    A
        (c, n_vars) constant.
    rows
        (c, 2) (section j, edge 0 = leading / 1 = trailing) of each item.
    """

    A: np.ndarray = None
    rows: np.ndarray = None

    kind = "le_te"

    @property
    def size(self) -> int:
        return self.A.shape[0]

    def value(self, inp):
        return self.A @ inp.values

    def jacobian(self, inp):
        return self.A.copy()


@dataclass(frozen=True, eq=False)
class FoldFree(Constraint):
    """``min det F`` over a parameter grid of the box (see the module docstring).

    box
        :class:`ffdcli.box.box.Box` (its core lattice and how control points map to it).
    params
        (N, pdim) sample parameters.
    det0
        (N,) baseline det J at the samples (never 0).
    """

    box: object = None
    params: np.ndarray = None
    det0: np.ndarray = None

    kind = "fold_free"

    @property
    def size(self) -> int:
        return 1

    @property
    def scalar(self) -> bool:
        return True

    def ratios(self, P) -> np.ndarray:
        """(N,) det J'(u) / det J0(u) at the samples for control points ``P`` (n, m, l, 3)."""

        J = derivatives(self.box.lattice(P), self.params)
        return np.linalg.det(J) / self.det0

    def value(self, inp):
        return np.array([self.ratios(inp.P).min()])

    def jacobian(self, inp):

        box = self.box
        r = self.ratios(inp.P)
        q = int(np.argmin(r))
        u = self.params[q:q + 1]
        J = derivatives(box.lattice(inp.P), u)[0]                        # (gdim, pdim)
        nv = inp.D.shape[1]
        D = inp.D.reshape(*inp.P.shape, nv)                               # (n, m, l, 3, nv)
        t = _axis_tables(box.lattice(), u, 1)                             # per axis (2, 1, n_axis)
        if box.dim == 3:
            a, b, c = (t[k][:, 0] for k in range(3))
            dJ = np.stack([np.einsum("i,j,k,ijkdv->vd", a[1], b[0], c[0], D),
                           np.einsum("i,j,k,ijkdv->vd", a[0], b[1], c[0], D),
                           np.einsum("i,j,k,ijkdv->vd", a[0], b[0], c[1], D)], axis=-1)
        else:
            Dc = D[:, 0][:, :, box.plane_axes, :]                        # (n, l, 2, nv)
            a, c = t[0][:, 0], t[1][:, 0]
            dJ = np.stack([np.einsum("i,k,ikdv->vd", a[1], c[0], Dc),
                           np.einsum("i,k,ikdv->vd", a[0], c[1], Dc)], axis=-1)
        # d det J = det J tr(J^-1 dJ); as a ratio to det J0: r tr(J^-1 dJ)
        out = r[q] * np.einsum("ab,vba->v", np.linalg.inv(J), dJ)
        return out[None, :]


# --------------------------------------------------------------------------------------------------
# Building them from the design file
# --------------------------------------------------------------------------------------------------

def _bound(spec: dict, key: str, default):
    v = spec.get(key, default)
    return -np.inf if v is None and key == "lower" else np.inf if v is None else float(v)


def build_constraints(specs: Sequence[dict], box, surface, changes, *, error=None, progress=None) -> list:
    """The constraint objects of a ``constraints:`` list on the baseline ``box`` and ``surface``.

    Parameters
    ----------
    specs : list of dict
        The items as written (each with exactly one key, the kind).
    box : ffdcli.box.box.Box
    surface : ffdcli.geometry.surface.Surface
        The baseline surface (points (S, 3) and faces).
    changes : list of ffdcli.parameterization.changes.Change
        The design's changes (``le_te`` reads which control points the shape variables move).
    error : callable (message, key) -> Exception
        Makes the error naming the design file's key and line; default :class:`InputError`.
    """

    if error is None:
        def error(message, key):
            return InputError(message, key=key)
    out = []
    for index, item in enumerate(specs or []):
        if not isinstance(item, dict) or len(item) != 1:
            raise error("each constraint is one key (the kind) with its settings, e.g. volume: {lower: 1}",
                        f"constraints[{index}]")
        (kind, spec), = item.items()
        key = f"constraints[{index}].{kind}"
        spec = dict(spec or {})
        if kind not in CONSTRAINT_KINDS:
            raise error(f"unknown constraint '{kind}'; the kinds are {', '.join(CONSTRAINT_KINDS)}",
                        f"constraints[{index}]")
        default = 0.0 if kind == "le_te" else None
        lower, upper = _bound(spec, "lower", default), _bound(spec, "upper", default)
        if lower > upper:
            raise error(f"lower {lower:g} is above upper {upper:g}", key)
        if kind in ("thickness", "thickness_to_chord"):
            out.append(_thickness(kind, spec, key, index, lower, upper, box, surface, error, PointSet, progress))
        elif kind == "volume":
            out.append(_volume(index, lower, upper, box, surface, key, error))
        elif kind == "le_te":
            out.append(_le_te(index, lower, upper, box, changes))
        else:
            out.append(_fold_free(index, lower, upper, box, int(spec.get("samples", FOLD_SAMPLES)), key, error))
    return out


def _fractions(spec, name, key, error) -> np.ndarray:
    v = np.asarray(spec[name], dtype=float).reshape(-1)
    for q, x in enumerate(v):
        if not 0.0 <= x <= 1.0:
            raise error(f"{x:g} is not a fraction: {name} stations run from 0 to 1", f"{key}.{name}[{q}]")
    return v


def _thickness(kind, spec, key, index, lower, upper, box, surface, error, PointSet, progress):
    if "chord" not in spec:
        raise error("needs chord: [fractions of the local chord, 0 = leading edge, 1 = trailing edge]", key)
    xi = _fractions(spec, "chord", key, error)
    if box.dim == 2:
        if "span" in spec:
            raise error("span stations have no meaning on a 2D (airfoil) mesh; give chord fractions only",
                        f"{key}.span")
        eta = np.zeros(1)
    else:
        if "span" not in spec:
            raise error("needs span: [fractions of the span, 0 = root, 1 = tip]", key)
        eta = _fractions(spec, "span", key, error)
    # The root and tip are where the surface ends: stations 0 and 1 are read END_INSET of the span
    # inside, so that the line along the thickness axis crosses the surface faces, not their edges.
    le, te = chord_lines(box, np.clip(eta, END_INSET, 1.0 - END_INSET))     # (ns, 3)
    nc = len(xi)
    grid = np.stack(np.meshgrid(xi, eta, indexing="xy"), axis=-1).reshape(-1, 2)  # chord fastest
    LE = np.repeat(le, nc, axis=0)
    TE = np.repeat(te, nc, axis=0)
    Q = LE + grid[:, :1] * (TE - LE)
    U, L, ok = project_thickness(surface.points, surface.faces, box, Q)
    if not ok.all():
        j = int(np.flatnonzero(~ok)[0])
        where = f"chord {grid[j, 0]:g}" + ("" if box.dim == 2 else f", span {grid[j, 1]:g}")
        raise error(f"the grid point at {where} misses the surface: the line through it along the thickness "
                    "axis does not cross an upper and a lower surface (is it beyond the tip or the trailing "
                    "edge?)", key)
    G = len(Q)
    pairs = PointSet.embed(f"k{index}.{kind}", box, np.vstack([U, L]), progress=progress)
    chords = None
    if kind == "thickness_to_chord":
        chords = PointSet.embed(f"k{index}.{kind}.chord", box, np.vstack([LE, TE]), progress=progress)
    for ps in (pairs, chords):
        if ps is not None and not ps.inside.all():
            j = int(np.flatnonzero(~ps.inside)[0]) % G
            raise error(f"the grid point at chord {grid[j, 0]:g}, span {grid[j, 1]:g} is outside the lattice "
                        "(it would not move with the design)", key)
    t0 = np.linalg.norm(U - L, axis=1)
    base = t0 if chords is None else t0 / np.linalg.norm(LE - TE, axis=1)
    return Thickness(index=index, lower=lower, upper=upper, pairs=pairs, chords=chords, base=base, grid=grid)


def _volume(index, lower, upper, box, surface, key, error):
    X = surface.points
    if box.dim == 3:
        cells = surface_triangles(surface.faces)
        plane = (0, 1)
    else:
        cells = surface_segments(surface.faces)
        plane = (box.axes.chord, box.axes.thickness)
    if not len(cells):
        raise error("the surface has no faces to enclose a volume", key)
    origin = np.asarray(box.te_points[0], dtype=float).copy()     # on the root plane (3D)
    vol = Volume(index=index, lower=lower, upper=upper, cells=cells, origin=origin, base=1.0, dim=box.dim,
                 plane=plane)
    v0 = vol.measure(X)[0]
    size = float(np.ptp(box.control_points.reshape(-1, 3), axis=0).max()) or 1.0
    if not abs(v0) > 1e-12 * size ** box.dim:
        raise error("the surface encloses no volume (an open surface whose opening is not the root plane?)", key)
    return Volume(index=index, lower=lower, upper=upper, cells=cells, origin=origin, base=v0, dim=box.dim,
                  plane=plane)


def _le_te(index, lower, upper, box, changes):

    P0 = box.control_points
    frame = box.frame
    n, m, l, _ = P0.shape
    sizes = [c.size for c in changes]
    nv = sum(sizes)
    A = np.zeros((2, m, nv))              # (edge, section, variable)
    at = 0
    for change, size in zip(changes, sizes, strict=True):
        if isinstance(change, Shape):
            amounts = change.jacobian_own(P0, frame) @ frame.thickness_dir        # (size, n, m, l)
            for e, i in enumerate((0, n - 1)):
                A[e, :, at:at + size] = (amounts[:, i, :, l - 1] + amounts[:, i, :, 0]).T
        at += size
    A = A.transpose(1, 0, 2).reshape(2 * m, nv)           # section-major, LE before TE
    rows = np.stack(np.meshgrid(np.arange(m), np.arange(2), indexing="ij"), -1).reshape(-1, 2)
    keep = np.abs(A).max(axis=1) > 0
    return LeTe(index=index, lower=lower, upper=upper, A=A[keep], rows=rows[keep])


def _fold_free(index, lower, upper, box, samples, key, error):

    if not 1 <= samples <= 64:
        raise error(f"samples per knot span must be 1 to 64, got {samples}", f"{key}.samples")
    lat = box.lattice()
    params = sample_grid(lat, samples)
    det0 = np.linalg.det(derivatives(lat, params))
    if not np.all(np.abs(det0) > 0) or not (np.all(det0 > 0) or np.all(det0 < 0)):
        raise error("the baseline lattice is already folded (its Jacobian determinant changes sign)", key)
    return FoldFree(index=index, lower=lower, upper=upper, box=box, params=params, det0=det0)


# --------------------------------------------------------------------------------------------------
# Evaluation of a list
# --------------------------------------------------------------------------------------------------

def constraint_names(constraints) -> list[str]:
    """Every item name, in order."""
    return [n for c in constraints for n in c.names]


def constraint_bounds(constraints) -> tuple[np.ndarray, np.ndarray]:
    """(lower (C,), upper (C,)) of every item (``-inf``/``inf``: none)."""
    lo = np.concatenate([np.full(c.size, c.lower) for c in constraints] or [np.zeros(0)])
    hi = np.concatenate([np.full(c.size, c.upper) for c in constraints] or [np.zeros(0)])
    return lo, hi


def evaluate(constraints, inp: ConstraintInputs, jacobian: bool = False):
    """(values (C,), jacobian (C, n_vars) or None) of every item."""
    if not jacobian:
        vals = [c.value(inp) for c in constraints]
        return (np.concatenate(vals) if vals else np.zeros(0)), None
    both = [c.value_and_jacobian(inp) for c in constraints]
    if not both:
        return np.zeros(0), np.zeros((0, len(inp.values)))
    return np.concatenate([b[0] for b in both]), np.concatenate([b[1] for b in both], axis=0)


def satisfied(values, lower, upper, tol: float = SATISFIED_TOL) -> np.ndarray:
    """(C,) bool: ``lower - tol <= value <= upper + tol``."""
    values = np.asarray(values, dtype=float)
    return (values >= lower - tol) & (values <= upper + tol)
