"""``thickness`` and ``thickness_to_chord``: thickness ratios at a chord x span grid.

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
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ffdcli.constraints.base import CONSTRAINTS, Constraint, item_schema, surface_segments, surface_triangles
from ffdcli.lattice.pointset import PointSet
from ffdcli.schema_parts import fraction

#: Span fractions 0 and 1 (the root and tip edges of the surface) are read this far inside.
END_INSET = 1e-6


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

    kind = "thickness"

    @classmethod
    def schema(cls) -> dict:
        # chord stations strictly inside: at the leading edge (and a sharp trailing edge) the thickness
        # is zero and a ratio to it has no meaning; span stations 0 and 1 are read just inside the ends
        inner = {"type": "number", "exclusiveMinimum": 0, "exclusiveMaximum": 1}
        grid = {"chord": {"type": "array", "items": inner, "minItems": 1,
                          "description": "chord fractions of the local section strictly between 0 (leading "
                                         "edge) and 1 (trailing edge): the thickness is zero at the edges"},
                "span": {"type": "array", "items": fraction(), "minItems": 1,
                         "description": "span fractions, 0 = root, 1 = tip (3D only)"}}
        what = ("thickness between the upper and lower surface along the thickness axis" if cls.kind == "thickness"
                else "thickness over the local chord")
        return item_schema(f"{what} at a chord x span grid, as a ratio to the baseline", grid, ["chord"])

    @classmethod
    def from_spec(cls, spec: dict, ctx) -> Thickness:
        """Built on the baseline (see the module docstring)."""
        return build_thickness(cls, spec, ctx)

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


def _fractions(spec, name, key, error) -> np.ndarray:
    """The stations of ``name`` (the schema's rule, for callers that skip the schema: the API): span
    in [0, 1], chord strictly inside (0, 1) (the thickness is zero at the leading edge)."""
    v = np.asarray(spec[name], dtype=float).reshape(-1)
    for q, x in enumerate(v):
        if name == "chord" and not 0.0 < x < 1.0:
            raise error(f"must be greater than 0 and less than 1, got {x:g}: chord stations lie strictly between "
                        "the leading edge (0) and the trailing edge (1), where the thickness is zero",
                        f"{key}.{name}[{q}]")
        if not 0.0 <= x <= 1.0:
            raise error(f"{x:g} is not a fraction: {name} stations run from 0 to 1", f"{key}.{name}[{q}]")
    return v


def build_thickness(cls, spec, ctx) -> Thickness:
    """The :class:`Thickness` or :class:`ThicknessToChord` (``cls``) of an item on the baseline."""
    kind, key, index, box, error = cls.kind, ctx.key, ctx.index, ctx.box, ctx.fail
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
    U, L, ok = project_thickness(ctx.surface.points, ctx.surface.faces, box, Q)
    if not ok.all():
        j = int(np.flatnonzero(~ok)[0])
        where = f"chord {grid[j, 0]:g}" + ("" if box.dim == 2 else f", span {grid[j, 1]:g}")
        edge = "the leading edge" if grid[j, 0] < 0.5 else "the trailing edge"
        raise error(f"the grid point at {where} misses the surface: the line through it along the thickness "
                    f"axis does not cross an upper and a lower surface (is it too close to {edge}"
                    f"{'' if box.dim == 2 else ' or beyond a rounded tip'}?)", key)
    G = len(Q)
    pairs = PointSet.embed(f"k{index}.{kind}", box, np.vstack([U, L]), progress=ctx.progress)
    chords = None
    if kind == "thickness_to_chord":
        chords = PointSet.embed(f"k{index}.{kind}.chord", box, np.vstack([LE, TE]), progress=ctx.progress)
    for ps in (pairs, chords):
        if ps is not None and not ps.inside.all():
            j = int(np.flatnonzero(~ps.inside)[0]) % G
            raise error(f"the grid point at chord {grid[j, 0]:g}, span {grid[j, 1]:g} is outside the lattice "
                        "(it would not move with the design)", key)
    t0 = np.linalg.norm(U - L, axis=1)
    base = t0 if chords is None else t0 / np.linalg.norm(LE - TE, axis=1)
    return cls(index=index, lower=ctx.lower, upper=ctx.upper, pairs=pairs, chords=chords, base=base, grid=grid)


@dataclass(frozen=True, eq=False)
class ThicknessToChord(Thickness):
    """``thickness_to_chord``: :class:`Thickness` over the moved local chord (``chords`` is set)."""

    kind = "thickness_to_chord"


CONSTRAINTS.register(Thickness)
CONSTRAINTS.register(ThicknessToChord)

