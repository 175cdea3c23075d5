"""Where a control surface sits in the box: its hinge, its ends and the knots it needs.

A device (:mod:`ffdcli.parameterization.changes.control_surfaces`) is written as span fractions,
hinge chord fractions and widths; this module turns them into lattice facts, in two steps:

1. :func:`device_knots`: the knots the lattice needs (on the box as fitted). Chordwise: ``p + 1``
   knots (``p`` the chordwise degree) from the hinge's parameter to the end of the transition
   (``transition`` local chords behind a flap's hinge, ahead of a slat's); spanwise (3D): ``2 q + 1``
   knots across each blend (``q`` the spanwise degree; :data:`BLEND_INTERVALS`). The box is then
   refined by exact knot insertion (:func:`ffdcli.box.refine.refine_box`): the surface does not move.
2. :func:`device_geometry`: on the refined box, which chordwise rows of control points turn (every
   row whose basis function starts at or behind the hinge knot: a point ahead of it depends on no
   turning row and does not move; a point behind the transition depends on turning rows only and
   turns rigidly), by what share of the angle each section turns (:func:`section_weights`: all of
   it where its basis function reaches into the device's span, none where it reaches beyond a
   blend, so a point outside the device and its blends does not move, a straight ramp between), and
   the basis rows of the hinge points at the device's ends.

A hinge given as a list (a design variable) cannot have knots at its value: ``ffd deform`` and the
derivatives must see one lattice whatever the value, or the derivative of what ``deform`` writes
would need the derivative of every basis function by its knots. Such a device gets its lattice from
its ``hinge_range`` (the fractions the hinge may take, :data:`HINGE_RANGE` by default), never from
the value: chordwise knots evenly spaced across every place its hinge and transition can be
(:func:`ramp_knots`), and its rows turn by a share of the angle that is a function of the hinge
(:class:`HingeRamp`): none for a row whose basis function reaches ahead of the hinge, all of it for
one reaching behind the transition, a smooth step between. So a point ahead of the hinge still
does not move and one behind the transition still turns rigidly, and the share, hence the mesh, is a
smooth function of the hinge with an exact derivative.

Span fraction ``f`` is the station ``stations[0] + f (stations[-1] - stations[0])`` (root 0, tip 1);
the local baseline chord there is interpolated linearly between the box's sections, and the hinge
point lies at chord fraction ``h`` of it, at mid-thickness (halfway between the upper and lower
surface along the thickness axis, read off the surface points near it).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from ffdcli.box.box import Box
from ffdcli.box.refine import edges_at, lattice_params, span_fractions
from ffdcli.errors import InputError
from ffdcli.lattice.embedding import embed
from ffdcli.lattice.lattice import evaluate
from ffdcli.parameterization.changes.hinge_ramp import HingeRamp, make_ramp

#: Default span width (span fraction) over which a device's rotation fades at each end.
DEFAULT_BLEND = 0.2
#: Default chord width of the transition behind a flap's hinge (ahead of a slat's), local chords.
DEFAULT_TRANSITION = 0.1
#: The largest deflection (degrees) of a device: in a design file and as an optimiser's bound alike.
MAX_ANGLE = 60.0
#: Knot intervals across each blend per spanwise degree ``q``: ``2 q`` intervals leave ``q`` sections
#: whose basis functions lie inside the blend, which turn by a share of the angle (:func:`section_weights`).
BLEND_INTERVALS = 2
#: The chord fractions a hinge given as a list (a design variable) may take unless ``hinge_range`` says.
HINGE_RANGE = {"flap": (0.6, 0.85), "slat": (0.1, 0.3)}
#: Tolerance (parameter) when reading which knots are a device's.
KNOT_TOL = 1e-9
#: A parameter this close to a knot is that knot (:func:`snap`).
SNAP = 1e-6


@dataclass(frozen=True)
class DeviceSpec:
    """A device as written: ``kind`` ``flap`` or ``slat``; ``span`` (a, b) span fractions (None in
    2D); ``hinge`` chord fractions at the inner and outer end (one in 2D); ``blend`` span fraction;
    ``transition`` local chords; ``hinge_range`` (lo, hi) the fractions a variable hinge may take (None:
    the hinge is fixed)."""

    kind: str
    span: tuple[float, float] | None
    hinge: tuple[float, ...]
    blend: float
    transition: float
    hinge_range: tuple[float, float] | None = None

    @property
    def reference_hinge(self) -> tuple[float, ...]:
        """The fractions the device's lattice facts are read at: the hinge when fixed, the middle of
        ``hinge_range`` at every end when variable (never the value)."""
        if self.hinge_range is None:
            return self.hinge
        return (0.5 * (self.hinge_range[0] + self.hinge_range[1]),) * len(self.hinge)

    @property
    def sign(self) -> float:
        """+1 for a flap (the device is aft of the hinge), -1 for a slat (ahead of it)."""
        return 1.0 if self.kind == "flap" else -1.0


def _mid_thickness(box: Box, surface: np.ndarray | None, point: np.ndarray, chord: float) -> np.ndarray:
    """``point`` moved along the thickness axis to halfway between the upper and lower surface
    near it (the surface points within a growing window around it); unchanged without a surface."""
    if surface is None or not len(surface):
        return point
    c, t, s = box.chord_dir, box.thickness_dir, box.span_dir
    X = surface - point
    dc, dt = X @ c, X @ t
    ds = X @ s if box.dim == 3 else np.zeros(len(X))
    for width in (0.01, 0.02, 0.04, 0.08):
        near = (np.abs(dc) < width * chord) & (np.abs(ds) < 2 * width * chord)
        up, low = near & (dt > 0), near & (dt < 0)
        if up.any() and low.any():
            return point + 0.5 * (dt[up].max() + dt[low].min()) * t
    return point


def end_points(box: Box, surface, spec: DeviceSpec) -> np.ndarray:
    """(E, 3, 3) per device end (E = 2 inner, outer; 1 in 2D): the baseline leading-edge point, the
    trailing-edge point and the hinge point (chord fraction ``hinge[e]``, mid-thickness)."""
    fractions = spec.span if spec.span is not None else (0.0,)
    out = []
    for e, f in enumerate(fractions):
        le, te = edges_at(box, f)
        h = spec.reference_hinge[e]
        chord = float(np.linalg.norm(te - le))
        out.append([le, te, _mid_thickness(box, surface, le + h * (te - le), chord)])
    return np.array(out)


def _params(box: Box, points: np.ndarray) -> np.ndarray:
    return lattice_params(box, points, "a control surface's hinge (is the hinge fraction or the span range right?)")


#: Points along the hinge line where the device's parameters are read (3D).
HINGE_SAMPLES = 17


def hinge_samples(box: Box, ends: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(k, 3) points along the straight hinge line between the ends' hinge points and (k, 3) the
    local baseline chord vector (leading to trailing edge) at each; in 2D the one hinge point."""
    if len(ends) == 1:
        return ends[:, 2], ends[:, 1] - ends[:, 0]
    s = np.linspace(0.0, 1.0, HINGE_SAMPLES)[:, None]
    H = ends[0, 2] + s * (ends[1, 2] - ends[0, 2])
    f = span_fractions(box, H)
    chords = np.array([np.subtract(*edges_at(box, x)[::-1]) for x in f])
    return H, chords


def _hinge_params(box: Box, surface, spec: DeviceSpec):
    """(hinge u, transition-end u, end points, hinge samples' parameters): the knot at the hinge is
    the largest (flap; slat: smallest) chordwise parameter of the hinge line, the end of the
    transition the largest (smallest) parameter of the points ``transition`` local chords behind
    (ahead of) it, so that every point ahead of (behind) the hinge line depends on no turning row and
    every point behind (ahead of) the transition on turning rows only."""
    ends = end_points(box, surface, spec)
    H, chords = hinge_samples(box, ends)
    ahead = H + spec.sign * spec.transition * chords
    k = len(H)
    params = _params(box, np.concatenate([H, ahead]))
    u = params[:, 0]
    pick = np.max if spec.sign > 0 else np.min
    return float(pick(u[:k])), float(pick(u[k:])), ends, params[:k]


def blend_widths(spec: DeviceSpec) -> tuple[float | None, float | None]:
    """(inner, outer) span widths the rotation fades over: ``blend``, less where the root or tip
    is nearer (the fade is then steeper); None where the device reaches the root or tip (no blend)."""
    a, b = spec.span
    return (None if a <= 0.0 else min(spec.blend, a), None if b >= 1.0 else min(spec.blend, 1.0 - b))


def _span_params(box: Box, surface, spec: DeviceSpec, *, ends: bool = False) -> list:
    """Spanwise parameter intervals of the blends (inner, outer) that need knots; ``ends``: one per
    device end, None at a root or tip end (no blend there)."""
    a, b = spec.span
    out = []
    for f, g, w in zip((a, b), (max(a - spec.blend, 0.0), min(b + spec.blend, 1.0)), blend_widths(spec)):
        if w is None:                   # the device reaches the root or tip: no blend there
            if ends:
                out.append(None)
            continue
        pts = []
        for x in (f, g):
            le, te = edges_at(box, x)
            pts.append(le + spec.reference_hinge[0 if f == a else 1] * (te - le))
        v = _params(box, np.array(pts))[:, 1]
        v[1] = 0.0 if g <= 0.0 else 1.0 if g >= 1.0 else v[1]
        out.append((min(v), max(v)))
    return out


def _blend_ends(box: Box, surface, spec: DeviceSpec, knots: np.ndarray) -> tuple[float | None, float | None]:
    """The spanwise parameters where the inner and outer blend end (away from the device; None: no
    blend at that end), snapped onto the knots inserted there."""
    inner, outer = _span_params(box, surface, spec, ends=True)
    return (None if inner is None else snap(knots, inner[0]),
            None if outer is None else snap(knots, outer[1]))


def section_weights(v: np.ndarray, q: int, device: tuple[float, float],
                    blends: tuple[float | None, float | None]) -> np.ndarray:
    """(m,) the share of the device's angle each section turns by.

    ``v`` the spanwise knots (degree ``q``, m sections), ``device`` its span ``(va, vb)`` and
    ``blends`` where its inner and outer blend end (None: none at that end), all parameters.
    A section whose basis function reaches into the device's span turns fully (1: a point inside
    the span turns rigidly); one whose function reaches beyond a blend not at all (0: a point
    outside the device and its blends does not move). The sections whose functions lie inside a
    blend turn by a straight ramp between their two neighbours, at their Greville abscissae (the
    mean of a function's inner knots). B-splines reproduce straight lines and never turn steeper
    than their control polygon, so the angle fades along the span as that ramp, rounded off at its
    ends: at most ``1 / (1 - 2 / (BLEND_INTERVALS q))`` times the blend's mean slope, where one basis
    function's tail (the blend before the ramp) was over twice it."""
    m = len(v) - q - 1
    j = np.arange(m)
    start, end = v[j], v[j + q + 1]
    va, vb = device
    w = ((end > va + KNOT_TOL) & (start < vb - KNOT_TOL)).astype(float)
    greville = sliding_window_view(v[1:], q).mean(axis=1)[:m] if q else start
    lo, hi = blends
    if hi is not None and hi > vb + KNOT_TOL:
        ramp = np.flatnonzero((start >= vb - KNOT_TOL) & (end <= hi + KNOT_TOL))
        if ramp.size:
            g1 = greville[ramp[0] - 1]                      # the last section that turns fully
            g0 = greville[ramp[-1] + 1] if ramp[-1] + 1 < m else hi
            w[ramp] = np.clip((g0 - greville[ramp]) / (g0 - g1), 0.0, 1.0)
    if lo is not None and lo < va - KNOT_TOL:
        ramp = np.flatnonzero((end <= va + KNOT_TOL) & (start >= lo - KNOT_TOL))
        if ramp.size:
            g1 = greville[ramp[-1] + 1]                     # the first section that turns fully
            g0 = greville[ramp[0] - 1] if ramp[0] > 0 else lo
            w[ramp] = np.clip((greville[ramp] - g0) / (g1 - g0), 0.0, 1.0)
    return w


def device_knots(box: Box, surface, spec: DeviceSpec) -> tuple[np.ndarray, np.ndarray]:
    """(chordwise knots, spanwise knots) the device needs in ``box`` (empty spanwise in 2D)."""
    p = box.degree[0]
    if spec.hinge_range is not None:
        ends = end_points(box, surface, spec)
        chord = _ramp(box, ends, spec, np.zeros(1)).knots()
    else:
        uh, ut, _, _ = _hinge_params(box, surface, spec)
        if not spec.sign * (ut - uh) > 0:
            raise InputError(f"the {spec.kind}'s transition ({spec.transition:g} chords) leaves the box")
        chord = uh + (ut - uh) * np.arange(p + 1) / p
    span = []
    if box.dim == 3:
        q = box.degree[1]
        n = BLEND_INTERVALS * q
        for lo, hi in _span_params(box, surface, spec):
            span.extend(lo + (hi - lo) * np.arange(n + 1) / n)
    return chord, np.array(span)


@dataclass(frozen=True, eq=False)
class DeviceGeometry:
    """A device's place in a (refined) lattice of n x m x l control points.

    rows
        (n,) bool: the chordwise rows that turn.
    weights
        (m,) the share of the angle each section turns by (:func:`section_weights`): 1 inside the
        device's span, 0 outside it and its blends, a ramp across each blend.
    L, T, M
        (E, n*m*l) basis rows of the baseline leading-edge, trailing-edge and hinge points at the
        device's ends (E = 2; 1 in 2D): ``M @ P.reshape(-1, 3)`` are the hinge points of lattice ``P``.
    hinge0
        (E,) the hinge fractions the rows were made for (the hinge moves along ``T - L`` from them).
    ramp
        A variable hinge's :class:`HingeRamp` (the rows' share of the angle as a function of the
        hinge; ``rows`` are then those that may turn); None for a fixed hinge.
    transition
        (k,) chord width from the hinge line to where the device turns rigidly, in local chords, at
        points along the hinge line (the largest is printed).
    """

    rows: np.ndarray
    weights: np.ndarray
    L: np.ndarray
    T: np.ndarray
    M: np.ndarray
    hinge0: np.ndarray
    transition: np.ndarray
    ramp: HingeRamp | None = None


def _ramp(box: Box, ends: np.ndarray, spec: DeviceSpec, sigma: np.ndarray) -> HingeRamp:
    return make_ramp(box, ends, spec.sign, spec.transition, spec.reference_hinge, spec.hinge_range, sigma)


def _section_positions(box: Box, ends: np.ndarray) -> np.ndarray:
    """(m,) where each section's station lies along the hinge line (0 inner end, 1 outer end,
    clipped); (1,) zero in 2D."""
    if len(ends) == 1:
        return np.zeros(1)
    a, b = ends[:, 2, box.axes.span]
    return np.clip((np.asarray(box.stations) - a) / (b - a), 0.0, 1.0)


def _rows_of(points: np.ndarray, box: Box) -> np.ndarray:
    e = embed(box.lattice(), box.core_points(points))
    return e.basis_matrix().toarray()


def snap(knots: np.ndarray, u: float) -> float:
    """``u`` as the nearest knot when within :data:`SNAP` of it (a parameter read again by Newton
    on the refined lattice differs from the knot inserted for it by the embedding's tolerance)."""
    k = knots[np.argmin(np.abs(knots - u))]
    return float(k) if abs(k - u) < SNAP else float(u)


def device_geometry(box: Box, surface, spec: DeviceSpec) -> DeviceGeometry:
    """The :class:`DeviceGeometry` of ``spec`` in ``box`` (refined with :func:`device_knots`)."""
    n, m, l = box.shape
    uh, ut, ends, hp = _hinge_params(box, surface, spec)
    t = box.knots[0]
    uh, ut = snap(t, uh), snap(t, ut)
    p = box.degree[0]
    ramp = None
    if spec.hinge_range is not None:
        ramp = _ramp(box, ends, spec, _section_positions(box, ends))
        rows = ramp.reachable()
    elif spec.sign > 0:
        rows = t[:n] >= uh - KNOT_TOL
    else:
        rows = t[p + 1:n + p + 1] <= uh + KNOT_TOL
    weights = np.ones(m)
    if box.dim == 3:
        v, q = box.knots[1], box.degree[1]
        a, b = spec.span
        lo = _params(box, ends[:, 2])[:, 1]
        va, vb = (0.0 if a <= 0 else snap(v, lo[0])), (1.0 if b >= 1 else snap(v, lo[1]))
        weights = section_weights(v, q, (va, vb), _blend_ends(box, surface, spec, v))
    E = len(ends)
    B = _rows_of(ends.reshape(-1, 3), box).reshape(E, 3, -1)
    # the transition: from the hinge line to the parameter ut, along the local chord (largest of the samples)
    H, chords = hinge_samples(box, ends)
    hp = hp.copy()
    hp[:, 0] = ut
    lengths = np.linalg.norm(chords, axis=1)
    width = np.abs(np.einsum("kd,kd->k", _lattice_points(box.lattice(), hp, box) - H, chords)) / lengths ** 2
    if ramp is not None:
        width = np.array([spec.transition])
    return DeviceGeometry(rows=rows, weights=weights, L=B[:, 0], T=B[:, 1], M=B[:, 2],
                          hinge0=np.array(spec.reference_hinge, dtype=float), transition=width, ramp=ramp)


def _lattice_points(lat, params, box: Box) -> np.ndarray:
    return box.mesh_vectors(evaluate(lat, params)) if box.dim == 2 else evaluate(lat, params)
