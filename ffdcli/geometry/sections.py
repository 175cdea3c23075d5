"""Section cuts of a wing surface: where the surface crosses a plane, and the airfoil read off the cut.

A section is the local airfoil of one spanwise station in the section plane's (chord', thickness)
coordinates (:class:`Section`): trailing-edge point, leading-edge point (farthest from the trailing
edge), chord line, upper and lower extent. :class:`Cutter` cuts one surface at spanwise stations;
:func:`repair_ends` replaces a root or tip cut that misses the airfoil (a rounded cap) by the planform
extrapolated from the nearest good cut; :func:`leading_edge_sign` tells which end of the chord axis
is the leading edge (an airfoil is thickest nearer its leading edge).

The automatic box (:mod:`ffdcli.box.box`) and the imported one (:mod:`ffdcli.box.imported`) read their
sections here. Pure geometry: arrays in, arrays out.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ffdcli.geometry.axes import Axes
from ffdcli.mesh import diagonal
from ffdcli.mesh.idsets import unique_ids

#: Where the first cut inboard of a degenerate tip cut is searched, as fractions of the span.
TIP_SEARCH = (0.0025, 0.005, 0.01, 0.02, 0.04, 0.08, 0.16)
#: A repaired end section is only worth a warning when the good cut was farther inboard than this
#: fraction of the span (a large rounded region whose end section is a guess); a usual rounded cap,
#: repaired from a cut a few per cent inboard, is a note (``ffd box -v``, ``--json`` ``notes``).
TIP_WARN_FRACTION = 0.05
#: Fractions of the span where the leading-edge side is probed (the ends are skipped: caps, roots).
PROBE_FRACTIONS = (0.2, 0.35, 0.5, 0.65, 0.8)


@dataclass(frozen=True, eq=False)
class Section:
    """The local airfoil of one section, in the section plane's (chord', thickness) coordinates.

    ``chord'`` is the chord-axis coordinate times the chord sign, so that it grows from the leading
    to the trailing edge. ``le``/``te`` are 2-vectors; ``upper``/``lower`` the extent of the airfoil
    above/below its chord line, and ``front``/``back`` its extent along the chord line measured from
    the leading edge (normally 0 and ``chord``).
    """

    le: np.ndarray
    te: np.ndarray
    upper: float
    lower: float
    front: float
    back: float
    extrapolated: bool = False

    @property
    def chord(self) -> float:
        return float(np.hypot(*(self.te - self.le)))

    @property
    def direction(self) -> np.ndarray:
        d = self.te - self.le
        return d / np.hypot(*d)

    @property
    def normal(self) -> np.ndarray:
        d = self.direction
        return np.array([-d[1], d[0]])


def surface_edges(faces, *, unique: bool = True) -> np.ndarray:
    """Undirected edges (E, 2) of a list of CellBlocks (local point ids).

    ``unique=False`` keeps an edge once per face that has it (interior edges twice): the section cuts
    do not mind, and skipping the sort costs nothing while deduplicating a 1M-point surface costs as
    much as embedding it."""
    edges = []
    for block in faces:
        c = block.data
        k = c.shape[1]
        if k < 2:
            continue
        nxt = np.roll(np.arange(k), -1)
        e = np.stack([c, c[:, nxt]], axis=-1).reshape(-1, 2) if k > 2 else c.reshape(-1, 2)
        edges.append(e)
    if not edges:
        return np.zeros((0, 2), dtype=np.int64)
    e = np.concatenate(edges)
    if not unique:
        return e
    e = np.sort(e, axis=1)
    n = int(e.max()) + 1
    key = unique_ids(e[:, 0] * n + e[:, 1])          # 1D unique: far faster than unique(axis=0)
    return np.stack([key // n, key % n], axis=1)


def cut(points: np.ndarray, edges: np.ndarray, axis: int, value: float, *, tol: float,
        slab: float = 0.0) -> np.ndarray:
    """Points (K, 3) where the surface crosses the plane ``points[:, axis] == value``.

    Edge crossings are interpolated linearly; vertices within ``tol`` of the plane are included.
    Without edges (a marker given only as nodes), the points within ``slab`` of the plane are used.
    """
    s = points[:, axis] - value
    on = np.abs(s) <= tol
    out = [points[on]]
    if len(edges):
        sa, sb = s[edges[:, 0]], s[edges[:, 1]]
        cross = (sa * sb < 0) & (np.abs(sa) > tol) & (np.abs(sb) > tol)
        a, b = edges[cross, 0], edges[cross, 1]
        t = (sa[cross] / (sa[cross] - sb[cross]))[:, None]
        out.append(points[a] + t * (points[b] - points[a]))
    elif slab > 0:
        out.append(points[(np.abs(s) <= slab) & ~on])
    q = np.concatenate(out)
    if len(q):
        q[:, axis] = value
    return q


def analyse_section(q2: np.ndarray) -> Section | None:
    """The airfoil of a cut given as (K, 2) points in (chord', thickness) coordinates, or None.

    Trailing edge: the aft-most points (within 0.5 % of the chordwise extent); for a blunt trailing
    edge the middle of its base. Leading edge: the point farthest from the trailing edge.
    """
    if len(q2) < 3:
        return None
    c, t = q2[:, 0], q2[:, 1]
    extent = c.max() - c.min()
    if not extent > 0:
        return None
    aft = c >= c.max() - 0.005 * extent
    lo, hi = np.argmin(np.where(aft, t, np.inf)), np.argmax(np.where(aft, t, -np.inf))
    te = np.array([c.max(), 0.5 * (t[lo] + t[hi])])  # aft-most point; mid-base if blunt
    le = q2[np.argmax(np.hypot(c - te[0], t - te[1]))]
    chord = np.hypot(*(te - le))
    if not chord > 0:
        return None
    d = (te - le) / chord
    n = np.array([-d[1], d[0]])
    rel = q2 - le
    along, across = rel @ d, rel @ n
    return Section(le=le, te=te, upper=float(across.max()), lower=float(across.min()),
                   front=float(min(along.min(), 0.0)), back=float(max(along.max(), chord)))


def leading_edge_sign(q2_list: list[np.ndarray]) -> tuple[float, bool]:
    """+1 if the leading edge is at the low end of the chord axis, and whether that was clear.

    An airfoil is thickest nearer its leading edge (about 30 % chord) than its trailing edge. Each
    cut votes by the chordwise position of its greatest thickness.
    """
    votes = []
    for q in q2_list:
        if len(q) < 8:
            continue
        c, t = q[:, 0], q[:, 1]
        lo, hi = c.min(), c.max()
        if not hi > lo:
            continue
        nb = 40
        b = np.minimum(((c - lo) / (hi - lo) * nb).astype(int), nb - 1)
        tmax = np.full(nb, -np.inf)
        tmin = np.full(nb, np.inf)
        np.maximum.at(tmax, b, t)
        np.minimum.at(tmin, b, t)
        thick = np.where(np.isfinite(tmax) & np.isfinite(tmin), tmax - tmin, 0.0)
        where = (np.argmax(thick) + 0.5) / nb
        if abs(where - 0.5) > 0.05:
            votes.append(1.0 if where < 0.5 else -1.0)
    if not votes:
        return 1.0, False
    s = float(np.sign(np.sum(votes)) or 1.0)
    clear = abs(np.sum(votes)) >= 0.6 * len(votes)
    return s, bool(clear)


def section_frame_2d(axes: Axes, points: np.ndarray, chord_sign: float) -> np.ndarray:
    """(N, 2) coordinates (chord', thickness) of mesh points (N, 3)."""
    return np.stack([chord_sign * points[:, axes.chord], points[:, axes.thickness]], axis=1)


@dataclass(frozen=True, eq=False)
class Cutter:
    """Cuts of one surface by planes across its span axis.

    points
        (N, 3) surface points.
    edges
        (E, 2) surface edges (:func:`surface_edges`); without edges, slabs of points are used.
    axes
        The surface's axes; stations ``eta`` are span coordinates times ``axes.span_sign``.
    tol
        Vertices within ``tol`` of a plane are on it.
    slab
        Half-width of the slab of points used when there are no edges.
    """

    points: np.ndarray
    edges: np.ndarray
    axes: Axes
    tol: float
    slab: float

    @classmethod
    def of(cls, points: np.ndarray, faces, axes: Axes, *, slab: float) -> Cutter:
        """The cutter of a surface given as points (N, 3) and faces (CellBlocks, local ids)."""
        pts = np.asarray(points, dtype=np.float64)
        return cls(points=pts, edges=surface_edges(faces, unique=False), axes=axes, tol=1e-9 * diagonal(pts),
                   slab=slab)

    @property
    def extent(self) -> tuple[float, float]:
        """(root, tip) stations of the surface: its extent along the signed span axis."""
        eta = self.axes.span_sign * self.points[:, self.axes.span]
        return float(eta.min()), float(eta.max())

    def at(self, eta: float) -> np.ndarray:
        """Points (K, 3) of the cut at station ``eta``."""
        return cut(self.points, self.edges, self.axes.span, self.axes.span_sign * eta, tol=self.tol,
                   slab=self.slab)

    def section(self, eta: float, chord_sign: float) -> Section | None:
        """The airfoil of the cut at station ``eta``, or None if the cut misses it."""
        q = self.at(eta)
        return analyse_section(section_frame_2d(self.axes, q, chord_sign)) if len(q) else None

    def sections(self, etas, chord_sign: float) -> list[Section | None]:
        """:meth:`section` at each station."""
        return [self.section(e, chord_sign) for e in etas]

    def chord_sign(self) -> tuple[float, bool]:
        """:func:`leading_edge_sign` of cuts across the span (:data:`PROBE_FRACTIONS`)."""
        root, tip = self.extent
        probe = [self.at(root + f * (tip - root)) for f in PROBE_FRACTIONS]
        return leading_edge_sign([q[:, [self.axes.chord, self.axes.thickness]] for q in probe])


def _predict(sections, etas, j, toward):
    """Linear extrapolation of section ``j`` from its two neighbours on the ``toward`` side."""
    a, b = j + toward, j + 2 * toward
    if not (0 <= a < len(sections)) or sections[a] is None:
        return None
    sa = sections[a]
    if not (0 <= b < len(sections)) or sections[b] is None:
        return sa.le, sa.te, sa.chord
    sb = sections[b]
    if etas[a] == etas[b]:           # both clamped to the same end of the span: no slope to follow
        return sa.le, sa.te, sa.chord
    f = (etas[j] - etas[a]) / (etas[a] - etas[b])
    le = sa.le + f * (sa.le - sb.le)
    te = sa.te + f * (sa.te - sb.te)
    return le, te, float(np.hypot(*(te - le)))


def repair_ends(sections, etas, cutter: Cutter, chord_sign: float, span: float, warnings: list[str],
                notes: list[str] | None = None):
    """Replace (in the list ``sections``) a root/tip section whose cut misses the airfoil (a rounded
    cap) by the planform extrapolated from the nearest good cut inboard; say so in ``notes``, or in
    ``warnings`` when that cut lies more than :data:`TIP_WARN_FRACTION` of the span inboard."""
    m = len(sections)
    for j, toward in ((m - 1, -1), (0, +1)):
        pred = _predict(sections, etas, j, toward)
        sec = sections[j]
        ref = pred[2] if pred is not None else None
        if sec is not None and (ref is None or sec.chord >= 0.9 * ref):
            continue
        # Search inward for a complete airfoil, then extrapolate the planform from it.
        good = None
        for f in TIP_SEARCH:
            e = etas[j] + toward * f * span
            if toward * (e - etas[j + toward]) >= 0:
                break
            s2 = cutter.section(e, chord_sign)
            if s2 is None:
                continue
            if ref is None or s2.chord >= 0.9 * _interp_chord(pred, sections[j + toward], etas, j, toward, e):
                good = (e, s2)
                break
        if good is None:
            continue
        e, s2 = good
        nb = sections[j + toward]
        f = (etas[j] - e) / (e - etas[j + toward]) if nb is not None else 0.0
        le = s2.le + f * (s2.le - nb.le) if nb is not None else s2.le
        te = s2.te + f * (s2.te - nb.te) if nb is not None else s2.te
        chord = float(np.hypot(*(te - le)))
        scale = chord / s2.chord
        sections[j] = Section(le=le, te=te, upper=s2.upper * scale, lower=s2.lower * scale,
                              front=min(0.0, s2.front * scale), back=max(chord, s2.back * scale),
                              extrapolated=True)
        depth = abs(e - etas[j]) / span
        message = (f"the {'tip' if j else 'root'} cut misses the airfoil (rounded cap?): section {j} "
                   f"extrapolated from the planform at {depth:.1%} span inboard")
        if depth > TIP_WARN_FRACTION or notes is None:
            warnings.append(message)
        else:
            notes.append(message)


def _interp_chord(pred, nb, etas, j, toward, e):
    """Chord expected at station ``e`` between the neighbour section and the prediction at j."""
    if nb is None:
        return pred[2]
    w = (e - etas[j + toward]) / (etas[j] - etas[j + toward])
    return (1 - w) * nb.chord + w * pred[2]


def edge_points(sections, stations, axes: Axes, chord_sign: float, dim: int):
    """(m, 3) leading- and trailing-edge points in mesh coordinates of the sections' 2D cuts."""
    m = len(sections)
    le_pts, te_pts = np.zeros((m, 3)), np.zeros((m, 3))
    for j, s in enumerate(sections):
        for arr, q in ((le_pts, s.le), (te_pts, s.te)):
            arr[j, axes.chord] = chord_sign * q[0]
            arr[j, axes.thickness] = q[1]
            arr[j, axes.span] = axes.span_sign * stations[j] if dim == 3 else stations[j]
    return le_pts, te_pts
