"""The automatic box: a B-spline lattice fitted to a wing, section by section.

The user gives the wing surface and the number of control points; :func:`fit_box` does the rest:

1. Detect the axes (chord, thickness, span) and the root side (:mod:`ffdcli.axes`), and which end of
   the chord axis is the leading edge (the airfoil is thickest nearer its leading edge).
2. Place ``m`` sections at equal spacing from the root plane to the tip plane (the root section *at*
   the root, so a fixed root section keeps the root airfoil fixed; the tip section at the tip, so the
   tip airfoil follows the tip section exactly).
3. Cut the surface with each section plane and read the local airfoil off the cut: trailing-edge point
   (the section's reference point), leading-edge point (farthest from the trailing edge), chord line,
   upper and lower extent. A tip (or root) cut that misses the airfoil (a rounded tip cap) is replaced
   by the planform extrapolated from the nearest good cut.
4. Each lattice section is a rectangle in its plane, aligned with the local chord line (so the lattice
   follows sweep, taper, dihedral and twist), from ``margin`` chords ahead of the leading edge to
   ``margin`` chords behind the trailing edge and from ``margin`` chords below the lower surface to
   above the upper one, with ``n x l`` control points equally spaced.
5. Embed every surface point. Where points fall outside (the smooth spanwise B-spline cuts a kinked
   edge, a thick region between two thin sections), the margin of that side of the nearby sections is
   grown and the lattice rebuilt, until the box contains the whole surface.

A 2D airfoil is the same with one section (``m = 1``) and the core B-spline working in the mesh plane.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from ffdcli.axes import Axes, detect_axes
from ffdcli.errors import InputError
from ffdcli.progress import no_progress
from ffdcli.settings import BoxSettings

#: Largest number of rebuilds when growing margins to contain the surface.
MAX_REBUILDS = 12
#: Where the first cut inboard of a degenerate tip cut is searched, as fractions of the span.
_TIP_SEARCH = (0.0025, 0.005, 0.01, 0.02, 0.04, 0.08, 0.16)


@dataclass
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


@dataclass
class Box:
    """A lattice fitted to a wing, with what the design changes need to know about it.

    control_points
        (n, m, l, 3) in mesh coordinates; ``m = 1`` for a 2D airfoil.
    degree, knots
        Of the core B-spline: 3 entries (i, j, k) in 3D, 2 (i, k) in 2D.
    axes
        Chord, thickness and span columns and the root side.
    chord_sign
        +1 when the leading edge is at the low end of the chord axis.
    stations
        (m,) mesh coordinate of each section along the span axis (2D: the plane's).
    le_points, te_points
        (m, 3) leading- and trailing-edge points of each section's airfoil (te = reference point).
    margins
        (m, 4) final clearances (front, back, lower, upper) in local chords.
    ref_weights
        (m, n, l): te_points[j] = sum_ik ref_weights[j, i, k] * control_points[i, j, k].
    le_rows
        (2, n*m*l) B-spline basis rows of the surface leading-edge points at root and tip (3D), so the
        current leading-edge line is ``le_rows @ P.reshape(-1, 3)``; None in 2D.
    """

    control_points: np.ndarray
    degree: tuple[int, ...]
    knots: tuple[np.ndarray, ...]
    axes: Axes
    dim: int
    chord_sign: float
    stations: np.ndarray
    le_points: np.ndarray
    te_points: np.ndarray
    margins: np.ndarray
    ref_weights: np.ndarray
    le_rows: np.ndarray | None
    settings: BoxSettings
    imported: bool = False
    notes: list[str] = field(default_factory=list)

    @property
    def shape(self) -> tuple[int, int, int]:
        """(n, m, l) of ``control_points`` (m = 1 in 2D)."""
        n, m, l, _ = self.control_points.shape
        return n, m, l

    @property
    def lattice_shape(self) -> tuple[int, ...]:
        """The lattice as the user counts it: (n, m, l) in 3D, (n, l) in 2D."""
        n, m, l = self.shape
        return (n, m, l) if self.dim == 3 else (n, l)

    @property
    def plane_axes(self) -> list[int]:
        """Mesh columns the core B-spline works in: all three in 3D, (chord, thickness) in 2D."""
        return [0, 1, 2] if self.dim == 3 else [self.axes.chord, self.axes.thickness]

    @property
    def chord_dir(self) -> np.ndarray:
        e = np.zeros(3)
        e[self.axes.chord] = self.chord_sign
        return e

    @property
    def thickness_dir(self) -> np.ndarray:
        e = np.zeros(3)
        e[self.axes.thickness] = 1.0
        return e

    @property
    def span_dir(self) -> np.ndarray:
        e = np.zeros(3)
        e[self.axes.span] = self.axes.span_sign
        return e

    def core_control_points(self, P: np.ndarray | None = None) -> np.ndarray:
        """Control points in the core's form: (n, m, l, 3) in 3D, (n, l, 2) in 2D."""
        P = self.control_points if P is None else np.asarray(P, dtype=np.float64)
        if self.dim == 3:
            return P
        return P[:, 0, :, :][..., self.plane_axes]

    def lattice(self, P: np.ndarray | None = None):
        """The core :class:`ffdcli.lattice.Lattice` of control points ``P`` (default: the box's own)."""
        from ffdcli.lattice import Lattice

        return Lattice(control_points=self.core_control_points(P), degree=tuple(self.degree),
                       knots=tuple(self.knots))

    def core_points(self, X: np.ndarray) -> np.ndarray:
        """Mesh points (N, 3) in the core's coordinates: (N, 3) in 3D, (N, 2) in 2D."""
        X = np.asarray(X, dtype=np.float64)
        return X if self.dim == 3 else X[:, self.plane_axes]

    def mesh_vectors(self, V: np.ndarray) -> np.ndarray:
        """Core-coordinate vectors (N, gdim) as mesh vectors (N, 3) (zero off-plane in 2D)."""
        V = np.asarray(V, dtype=np.float64)
        if self.dim == 3:
            return V
        out = np.zeros((len(V), 3))
        out[:, self.plane_axes] = V
        return out

    @property
    def frame(self):
        """The :class:`ffdcli.changes.LatticeFrame` the design changes act in."""
        from ffdcli.changes import LatticeFrame

        return LatticeFrame(chord_dir=self.chord_dir, thickness_dir=self.thickness_dir,
                            span_dir=self.span_dir, ref_weights=self.ref_weights,
                            le_rows=self.le_rows, dim=self.dim)

    def summary(self) -> dict:
        return {
            "lattice": list(self.lattice_shape),
            "degree": list(self.degree),
            "axes": self.axes.as_dict(),
            "root": self.axes.root,
            "leading_edge": "min" if self.chord_sign > 0 else "max",
            "margins": {
                "front": float(self.margins[:, 0].max()), "back": float(self.margins[:, 1].max()),
                "lower": float(self.margins[:, 2].max()), "upper": float(self.margins[:, 3].max()),
            },
        }


# ----------------------------------------------------------------------------------------------
# Section cuts
# ----------------------------------------------------------------------------------------------

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
    key = np.unique(e[:, 0] * n + e[:, 1])          # 1D unique: far faster than unique(axis=0)
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


# ----------------------------------------------------------------------------------------------
# Building the box
# ----------------------------------------------------------------------------------------------

def _section_frame_2d(axes: Axes, points: np.ndarray, chord_sign: float) -> np.ndarray:
    """(N, 2) coordinates (chord', thickness) of mesh points."""
    return np.stack([chord_sign * points[:, axes.chord], points[:, axes.thickness]], axis=1)


def fit_box(points: np.ndarray, faces=(), settings: BoxSettings | None = None, *, dim: int = 3,
            path=None, progress=None):
    """Fit a lattice to a wing surface and embed the surface points in it.

    Parameters
    ----------
    points
        (N, 3) surface points (the wing marker's nodes).
    faces
        The surface's boundary faces (CellBlocks in local indices into ``points``; lines in 2D).
        Used to cut exact sections; without faces, thin slabs of points are used.
    settings
        :class:`BoxSettings`; checked against ``dim``.
    dim
        3 for a wing, 2 for an airfoil mesh.

    Returns
    -------
    (box, embedding, report)
        ``report`` has ``rebuilds``, ``warnings`` (list of str), ``outside`` (count after the last
        rebuild: 0 unless the surface could not be contained).
    """
    from ffdcli.embedding import embed

    progress = progress or no_progress
    settings = (settings or BoxSettings()).checked(dim, path=path)
    pts = np.asarray(points, dtype=np.float64)
    if len(pts) < 3:
        raise InputError(f"the surface has {len(pts)} points; a box needs a wing (or airfoil) surface",
                         path=path)
    if not np.all(np.isfinite(pts)):
        raise InputError("the surface has non-finite coordinates", path=path)
    axes = detect_axes(pts, dim, sections=settings.sections, root=settings.root, path=path, faces=faces)
    warnings: list[str] = []
    if axes.guessed and settings.sections is None:
        warnings.append(f"the surface is not clearly wing-shaped: axes guessed as {axes.as_dict()} "
                        f"(chord, thickness, span); set box.sections / --sections to choose")
    edges = surface_edges(faces, unique=False)
    size = float(np.linalg.norm(pts.max(0) - pts.min(0)))
    tol = 1e-9 * size

    if dim == 3:
        sections, stations, chord_sign, sign_clear, extra = _fit_sections_3d(pts, edges, axes, settings,
                                                                          tol, size, path)
        warnings += extra
    else:
        q2 = np.stack([pts[:, axes.chord], pts[:, axes.thickness]], axis=1)
        chord_sign, sign_clear = leading_edge_sign([q2])
        sec = analyse_section(_section_frame_2d(axes, pts, chord_sign))
        if sec is None:
            raise InputError("could not find an airfoil in the surface (it has no chordwise extent)",
                             path=path)
        sections = [sec]
        stations = np.array([float(np.mean(pts[:, axes.span]))])
    if not sign_clear:
        warnings.append("could not tell the leading edge from the trailing edge; assumed the leading "
                        f"edge at the {'low' if chord_sign > 0 else 'high'} end of the chord axis")

    n = settings.points[0]
    l = settings.points[-1]
    m = len(sections)
    margins = np.tile(np.full(4, settings.margin, dtype=np.float64), (m, 1))
    degree = settings.degrees()
    core = None
    report = {"rebuilds": 0, "warnings": warnings, "outside": 0}
    with progress("fitting the box", MAX_REBUILDS + 1) as bar:
        for attempt in range(MAX_REBUILDS + 1):
            P = _lattice_points(sections, stations, margins, axes, chord_sign, n, l, dim)
            box = _assemble(P, degree, axes, dim, chord_sign, stations, sections, margins, settings)
            lat = box.lattice()
            core = embed(lat, box.core_points(pts), progress=progress)
            bar.update(1)
            outside = ~core.inside
            if not outside.any():
                break
            report["rebuilds"] = attempt + 1
            if attempt == MAX_REBUILDS:
                break
            margins = _grow_margins(margins, core, outside, sections, box, settings)
    report["outside"] = int((~core.inside).sum())
    box.le_rows = _le_rows(box) if dim == 3 else None
    return box, core, report


def _fit_sections_3d(pts, edges, axes: Axes, settings: BoxSettings, tol, size, path):
    """Sections (list of Section), stations (m,), chord sign, whether it was clear, warnings."""
    m = settings.points[1]
    s_ax = axes.span
    eta = axes.span_sign * pts[:, s_ax]
    root, tip = float(eta.min()), float(eta.max())
    span = tip - root
    if not span > 1e-12 * size:
        raise InputError("the surface has no extent along the span axis "
                         f"({'xyz'[s_ax]}); for an airfoil mesh use a 2D mesh", path=path)
    etas = root + span * np.arange(m) / (m - 1)
    slab = 0.5 * span / (4 * (m - 1))

    def cut_at(e):
        q = cut(pts, edges, s_ax, axes.span_sign * e, tol=tol, slab=slab)
        return q

    # Leading-edge side from cuts across the span (skip the ends).
    probe = [cut_at(root + f * span) for f in (0.2, 0.35, 0.5, 0.65, 0.8)]
    chord_sign, clear = leading_edge_sign([np.stack([q[:, axes.chord], q[:, axes.thickness]], 1)
                                           for q in probe])
    sections: list[Section | None] = []
    for e in etas:
        q = cut_at(e)
        sections.append(analyse_section(_section_frame_2d(axes, q, chord_sign)) if len(q) else None)
    warnings = []
    _repair_ends(sections, etas, cut_at, axes, chord_sign, span, warnings)
    if any(s is None for s in sections):
        bad = [j for j, s in enumerate(sections) if s is None]
        raise InputError(f"could not find the airfoil at sections {bad} of the surface; is it a wing? "
                         "(try box.sections / --sections to set the axes)", path=path)
    return sections, etas, chord_sign, clear, warnings


def _predict(sections, etas, j, toward):
    """Linear extrapolation of section ``j`` from its two neighbours on the ``toward`` side."""
    a, b = j + toward, j + 2 * toward
    if not (0 <= a < len(sections)) or sections[a] is None:
        return None
    sa = sections[a]
    if not (0 <= b < len(sections)) or sections[b] is None:
        return sa.le, sa.te, sa.chord
    sb = sections[b]
    f = (etas[j] - etas[a]) / (etas[a] - etas[b])
    le = sa.le + f * (sa.le - sb.le)
    te = sa.te + f * (sa.te - sb.te)
    return le, te, float(np.hypot(*(te - le)))


def _repair_ends(sections, etas, cut_at, axes, chord_sign, span, warnings):
    """Replace a root/tip section whose cut misses the airfoil (rounded cap) by an extrapolation."""
    m = len(sections)
    for j, toward in ((m - 1, -1), (0, +1)):
        pred = _predict(sections, etas, j, toward)
        sec = sections[j]
        ref = pred[2] if pred is not None else None
        if sec is not None and (ref is None or sec.chord >= 0.9 * ref):
            continue
        # Search inward for a complete airfoil, then extrapolate the planform from it.
        good = None
        for f in _TIP_SEARCH:
            e = etas[j] + toward * f * span
            if toward * (e - etas[j + toward]) >= 0:
                break
            q = cut_at(e)
            s2 = analyse_section(_section_frame_2d(axes, q, chord_sign)) if len(q) else None
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
        warnings.append(f"the {'tip' if j else 'root'} cut misses the airfoil (rounded cap?): "
                        f"section {j} extrapolated from the planform at {abs(e - etas[j]) / span:.1%} "
                        "span inboard")


def _interp_chord(pred, nb, etas, j, toward, e):
    """Chord expected at station ``e`` between the neighbour section and the prediction at j."""
    if nb is None:
        return pred[2]
    w = (e - etas[j + toward]) / (etas[j] - etas[j + toward])
    return (1 - w) * nb.chord + w * pred[2]


def _lattice_points(sections, stations, margins, axes, chord_sign, n, l, dim):
    """(n, m, l, 3) control points: a chord-aligned rectangle per section."""
    m = len(sections)
    P = np.zeros((n, m, l, 3))
    a = np.linspace(0.0, 1.0, n)[:, None]
    b = np.linspace(0.0, 1.0, l)[None, :]
    for j, s in enumerate(sections):
        L = s.chord
        front = s.front - margins[j, 0] * L
        back = s.back + margins[j, 1] * L
        lower = s.lower - margins[j, 2] * L
        upper = s.upper + margins[j, 3] * L
        along = front + (back - front) * a          # (n, 1)
        across = lower + (upper - lower) * b        # (1, l)
        q = s.le[None, None, :] + along[..., None] * s.direction + across[..., None] * s.normal
        P[:, j, :, axes.chord] = chord_sign * q[..., 0]
        P[:, j, :, axes.thickness] = q[..., 1]
        P[:, j, :, axes.span] = axes.span_sign * stations[j] if dim == 3 else stations[j]
    return P


def _edge_points(sections, stations, axes: Axes, chord_sign: float, dim: int):
    """(m, 3) leading- and trailing-edge points in mesh coordinates of the sections' 2D cuts."""
    m = len(sections)
    le_pts, te_pts = np.zeros((m, 3)), np.zeros((m, 3))
    for j, s in enumerate(sections):
        for arr, q in ((le_pts, s.le), (te_pts, s.te)):
            arr[j, axes.chord] = chord_sign * q[0]
            arr[j, axes.thickness] = q[1]
            arr[j, axes.span] = axes.span_sign * stations[j] if dim == 3 else stations[j]
    return le_pts, te_pts


def _assemble(P, degree, axes, dim, chord_sign, stations, sections, margins, settings) -> Box:
    from ffdcli.spline import clamped_knots

    n, m, l, _ = P.shape
    sizes = (n, m, l) if dim == 3 else (n, l)
    knots = tuple(clamped_knots(s, d) for s, d in zip(sizes, degree))
    le_pts, te_pts = _edge_points(sections, stations, axes, chord_sign, dim)
    ref = np.zeros((m, n, l))
    for j, s in enumerate(sections):
        # the reference point in the rectangle's own (along, across) fractions: bilinear in corners
        L = s.chord
        front = s.front - margins[j, 0] * L
        back = s.back + margins[j, 1] * L
        lower = s.lower - margins[j, 2] * L
        upper = s.upper + margins[j, 3] * L
        fa = (L - front) / (back - front)
        fb = (0.0 - lower) / (upper - lower)
        ref[j, 0, 0] = (1 - fa) * (1 - fb)
        ref[j, -1, 0] = fa * (1 - fb)
        ref[j, 0, -1] = (1 - fa) * fb
        ref[j, -1, -1] = fa * fb
    return Box(control_points=P, degree=tuple(degree), knots=knots, axes=axes, dim=dim,
               chord_sign=chord_sign,
               stations=np.asarray(stations, dtype=np.float64) * (axes.span_sign if dim == 3 else 1.0),
               le_points=le_pts, te_points=te_pts, margins=margins.copy(), ref_weights=ref,
               le_rows=None, settings=settings)


def _grow_margins(margins, core, outside, sections, box, settings):
    """Grow the margins of the sides where points fell out, at the sections nearest to them."""
    margins = margins.copy()
    params = core.params[outside]
    dist = core.residual[outside]
    m = margins.shape[0]
    step0 = max(settings.margin, 0.01)
    if box.dim == 3:
        from ffdcli.spline import basis

        first, vals = basis(box.knots[1], box.degree[1], params[:, 1])
        js = first[:, None] + np.arange(vals.shape[1])[None, :]
        near = vals > 0.05
    else:
        js = np.zeros((len(params), 1), dtype=int)
        near = np.ones((len(params), 1), dtype=bool)
    u, w = params[:, 0], params[:, -1]
    eps = 1e-7
    sides = np.stack([u <= eps, u >= 1 - eps, w <= eps, w >= 1 - eps], axis=1)
    none = ~sides.any(axis=1)
    sides[none] = True                       # no active bound: grow every side a little
    chords = np.array([s.chord for s in sections])
    grow = np.zeros_like(margins)
    for side in range(4):
        hit = sides[:, side]
        if not hit.any():
            continue
        jj = js[hit][near[hit]]
        dd = np.repeat(dist[hit], near[hit].sum(axis=1))
        need = np.zeros(m)
        np.maximum.at(need, jj, 1.5 * dd / chords[jj] + 0.5 * step0)
        grow[:, side] = need
    return margins + grow


def _le_rows(box: Box) -> np.ndarray:
    """Basis rows (2, n*m*l) of the leading-edge points of the root and tip sections."""
    from ffdcli.embedding import embed

    lat = box.lattice()
    e = embed(lat, box.core_points(box.le_points[[0, -1]]))
    rows = e.basis_matrix().toarray()
    if not e.inside.all():        # a leading-edge point must lie in the lattice (it has margins)
        raise RuntimeError("leading-edge reference points fell outside the lattice")
    return rows


# ----------------------------------------------------------------------------------------------
# Imported lattices (pyGeo/DAFoam Plot3D files)
# ----------------------------------------------------------------------------------------------

def import_box(file, points: np.ndarray, faces=(), settings: BoxSettings | None = None, *,
               dim: int = 3, path=None, progress=None):
    """Use a single-block Plot3D lattice (a pyGeo FFD file) as the box, and embed the surface in it.

    The block's index directions are matched to chord, span and thickness by their alignment with
    the mesh axes, and flipped so that ``i`` runs from leading to trailing edge, ``j`` from root to
    tip and ``k`` upward. Points outside the lattice are reported, never snapped: they keep their
    position when the lattice moves. The number of control points comes from the file; degrees
    default to min(3, points - 1) as for an automatic box.
    """
    from ffdcli.embedding import embed
    from ffdcli.formats.plot3d import read_plot3d

    settings = settings or BoxSettings()
    blocks = read_plot3d(file)
    if len(blocks) != 1:
        raise InputError(f"the lattice file has {len(blocks)} blocks; ffd takes a single-block lattice "
                         "(split the file, one box per wing)", path=file)
    blk = blocks[0]
    pts = np.asarray(points, dtype=np.float64)
    axes = detect_axes(pts, dim, sections=settings.sections, root=settings.root, path=path, faces=faces)
    edges = surface_edges(faces, unique=False)
    size = float(np.linalg.norm(pts.max(0) - pts.min(0)))
    span_len = np.ptp(pts[:, axes.span])
    slab = 0.02 * span_len if span_len > 0 else 0.0

    def cut_at(e):
        return cut(pts, edges, axes.span, axes.span_sign * e, tol=1e-9 * size, slab=slab)

    if dim == 3:
        eta = axes.span_sign * pts[:, axes.span]
        root, tip = float(eta.min()), float(eta.max())
        probe = [cut_at(root + f * (tip - root)) for f in (0.2, 0.35, 0.5, 0.65, 0.8)]
        chord_sign, _ = leading_edge_sign([np.stack([q[:, axes.chord], q[:, axes.thickness]], 1)
                                           for q in probe])
    else:
        chord_sign, _ = leading_edge_sign([pts[:, [axes.chord, axes.thickness]]])
    dirs = {"chord": np.eye(3)[axes.chord] * chord_sign, "span": np.eye(3)[axes.span] * axes.span_sign,
            "thickness": np.eye(3)[axes.thickness]}
    mean_edge = []
    for a in range(3):
        if blk.shape[a] < 2:
            mean_edge.append(np.zeros(3))
            continue
        d = np.diff(blk, axis=a).reshape(-1, 3).mean(axis=0)
        mean_edge.append(d / (np.linalg.norm(d) or 1.0))
    mean_edge = np.array(mean_edge)
    order = {}
    left = [0, 1, 2]
    for name in ("span", "chord", "thickness"):
        score = [abs(mean_edge[a] @ dirs[name]) for a in left]
        a = left[int(np.argmax(score))]
        order[name] = a
        left.remove(a)
    P = blk.transpose(order["chord"], order["span"], order["thickness"], 3)
    for ax, name in ((0, "chord"), (1, "span"), (2, "thickness")):
        if P.shape[ax] > 1 and np.diff(P, axis=ax).reshape(-1, 3).mean(axis=0) @ dirs[name] < 0:
            P = np.flip(P, axis=ax)
    if dim == 2:
        P = P[:, :1, :, :].copy()
        P[..., axes.span] = float(np.mean(pts[:, axes.span]))
    P = np.ascontiguousarray(P)
    n, m, l, _ = P.shape
    want = (n, m, l) if dim == 3 else (n, l)
    if settings.points is not None and tuple(settings.points) != want:
        raise InputError(f"box.points {list(settings.points)} does not match the lattice in "
                         f"{file} ({' x '.join(map(str, want))}); leave points out with box.file",
                         path=path, key="box.points")
    settings = replace(settings, points=want).checked(dim, path=path)
    degree = settings.degrees()

    # Sections at the lattice's stations (clamped to the surface's span) for the reference points.
    if dim == 3:
        stations = (axes.span_sign * P[..., axes.span]).mean(axis=(0, 2))
        secs = []
        for e in np.clip(stations, root, tip):
            q = cut_at(e)
            secs.append(analyse_section(_section_frame_2d(axes, q, chord_sign)) if len(q) else None)
        etas = np.clip(stations, root, tip)
        warnings: list[str] = []
        _repair_ends(secs, etas, cut_at, axes, chord_sign, tip - root, warnings)
        for j, s in enumerate(secs):
            if s is None:
                near = [k for k in range(m) if secs[k] is not None]
                if not near:
                    raise InputError("the lattice does not overlap the wing's span", path=file)
                secs[j] = secs[min(near, key=lambda k: abs(k - j))]
    else:
        stations = np.array([float(np.mean(pts[:, axes.span]))])
        secs = [analyse_section(_section_frame_2d(axes, pts, chord_sign))]
        warnings = []
    le_pts, te_pts = _edge_points(secs, stations, axes, chord_sign, dim)
    ref = np.zeros((m, n, l))
    for j, s in enumerate(secs):
        corners = P[[0, -1, 0, -1], j, [0, 0, -1, -1]]          # A B C D
        c2 = np.stack([chord_sign * corners[:, axes.chord], corners[:, axes.thickness]], 1)
        a, b = _bilinear_inverse(c2, s.te)
        ref[j, 0, 0], ref[j, -1, 0] = (1 - a) * (1 - b), a * (1 - b)
        ref[j, 0, -1], ref[j, -1, -1] = (1 - a) * b, a * b
    from ffdcli.spline import clamped_knots

    sizes = (n, m, l) if dim == 3 else (n, l)
    knots = tuple(clamped_knots(s_, d) for s_, d in zip(sizes, degree))
    box = Box(control_points=P, degree=tuple(degree), knots=knots, axes=axes, dim=dim,
              chord_sign=chord_sign, stations=np.asarray(stations, float) * (axes.span_sign if dim == 3 else 1.0),
              le_points=le_pts,
              te_points=te_pts, margins=np.zeros((m, 4)), ref_weights=ref, le_rows=None,
              settings=settings, imported=True)
    core = embed(box.lattice(), box.core_points(pts), progress=progress)
    n_out = int((~core.inside).sum())
    if n_out:
        warnings.append(f"{n_out} surface points are outside the imported lattice {file}; they will "
                        f"not move (worst distance {core.residual[~core.inside].max():.3g})")
    if dim == 3:
        # the leading-edge line of the surface (root and tip), for sweep and dihedral
        r_le, t_le = _surface_le(cut_at, root, tip, axes, chord_sign)
        e = embed(box.lattice(), box.core_points(np.array([r_le, t_le])))
        if not e.inside.all():
            warnings.append("the wing's leading edge at the root or tip is outside the imported lattice: "
                            "sweep and dihedral measure the angle from the lattice's own leading edge")
        box.le_rows = e.basis_matrix().toarray()
    return box, core, {"rebuilds": 0, "warnings": warnings, "outside": n_out}


def _surface_le(cut_at, root, tip, axes, chord_sign):
    """Leading-edge points (3,) of the surface's root and tip airfoils."""
    etas = np.array([root, tip])
    secs = []
    for e in etas:
        q = cut_at(e)
        secs.append(analyse_section(_section_frame_2d(axes, q, chord_sign)) if len(q) else None)
    mid = [cut_at(root + f * (tip - root)) for f in (0.5,)]
    secs_full = [secs[0], analyse_section(_section_frame_2d(axes, mid[0], chord_sign)), secs[1]]
    etas3 = np.array([root, 0.5 * (root + tip), tip])
    _repair_ends(secs_full, etas3, cut_at, axes, chord_sign, tip - root, [])
    out = []
    for s, e in ((secs_full[0], root), (secs_full[2], tip)):
        if s is None:
            raise InputError("could not find the airfoil at the wing's root or tip")
        p = np.zeros(3)
        p[axes.chord], p[axes.thickness], p[axes.span] = chord_sign * s.le[0], s.le[1], axes.span_sign * e
        out.append(p)
    return out


def _bilinear_inverse(c: np.ndarray, x: np.ndarray) -> tuple[float, float]:
    """(a, b) with (1-a)(1-b) c0 + a(1-b) c1 + (1-a) b c2 + a b c3 = x (Newton; exact for rectangles)."""
    a = b = 0.5
    for _ in range(50):
        f = (1 - a) * (1 - b) * c[0] + a * (1 - b) * c[1] + (1 - a) * b * c[2] + a * b * c[3] - x
        ja = -(1 - b) * c[0] + (1 - b) * c[1] - b * c[2] + b * c[3]
        jb = -(1 - a) * c[0] - a * c[1] + (1 - a) * c[2] + a * c[3]
        J = np.stack([ja, jb], axis=1)
        try:
            da, db = np.linalg.solve(J, -f)
        except np.linalg.LinAlgError:
            break
        a, b = a + da, b + db
        if abs(da) + abs(db) < 1e-15:
            break
    return float(a), float(b)
