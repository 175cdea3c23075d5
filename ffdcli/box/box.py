"""The automatic box: a B-spline lattice fitted to a wing, section by section.

The user gives the wing surface and the number of control points; :func:`fit_box` does the rest:

1. Detect the axes (chord, thickness, span) and the root side (:mod:`ffdcli.geometry.axes`), and which end of
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

The section cuts are :mod:`ffdcli.geometry.sections`; a lattice from a file (pyGeo/DAFoam) is
:mod:`ffdcli.box.imported`; both end in :func:`assemble_box`, the one place a :class:`Box` is made.

A 2D airfoil is the same with one section (``m = 1``) and the core B-spline working in the mesh plane.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, replace

import numpy as np

from ffdcli.box.frame import LatticeFrame
from ffdcli.errors import InputError
from ffdcli.geometry.axes import Axes, detect_axes
from ffdcli.geometry.sections import (
    Cutter,
    Section,
    analyse_section,
    edge_points,
    leading_edge_sign,
    repair_ends,
    section_frame_2d,
)
from ffdcli.lattice.embedding import embed
from ffdcli.lattice.lattice import Lattice
from ffdcli.lattice.spline import basis, clamped_knots
from ffdcli.mesh import diagonal
from ffdcli.progress import no_progress
from ffdcli.settings import BoxSettings

#: Largest number of rebuilds when growing margins to contain the surface.
MAX_REBUILDS = 12


@dataclass(frozen=True, eq=False)
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
    settings
        The (checked) :class:`BoxSettings` the box was made with.
    imported
        True for a lattice read from a file (:mod:`ffdcli.box.imported`).
    base_sections
        (m0, 7) the stations, leading- and trailing-edge points of the sections the box was fitted
        with, when knots added sections since (:mod:`ffdcli.box.refine`): the baseline chord at a span
        fraction is read off these, so it does not depend on the refinement. None: the box's own.

    A box is a value: nothing changes it after :func:`assemble_box` made it. :meth:`to_arrays` and
    :meth:`from_arrays` are how it is stored (the cache).
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
    base_sections: np.ndarray | None = None

    def sections_table(self) -> np.ndarray:
        """(m0, 7) stations, leading-edge and trailing-edge points of the fitted sections."""
        if self.base_sections is not None:
            return self.base_sections
        return np.column_stack([self.stations, self.le_points, self.te_points])

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
        """The core :class:`ffdcli.lattice.lattice.Lattice` of control points ``P`` (default: the box's own)."""
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
        """The :class:`ffdcli.parameterization.changes.LatticeFrame` the design changes act in."""
        return LatticeFrame(chord_dir=self.chord_dir, thickness_dir=self.thickness_dir,
                            span_dir=self.span_dir, ref_weights=self.ref_weights,
                            le_rows=self.le_rows, dim=self.dim,
                            le_weights=section_weights(self, self.le_points))

    def to_arrays(self) -> dict[str, np.ndarray]:
        """Every field as named arrays (for ``numpy.savez``); :meth:`from_arrays` is the inverse."""
        a = self.axes
        arrays = {
            "control_points": self.control_points,
            "degree": np.asarray(self.degree, dtype=np.int64),
            "axes": np.array([a.chord, a.thickness, a.span, 0 if a.root == "min" else 1, int(a.guessed)],
                             dtype=np.int64),
            "dim": np.int64(self.dim),
            "chord_sign": np.float64(self.chord_sign),
            "stations": self.stations,
            "le_points": self.le_points,
            "te_points": self.te_points,
            "margins": self.margins,
            "ref_weights": self.ref_weights,
            "le_rows": self.le_rows if self.le_rows is not None else np.zeros((0, 0)),
            "settings": np.frombuffer(json.dumps(self.settings.as_dict()).encode(), dtype=np.uint8),
            "imported": np.int64(self.imported),
        }
        if self.base_sections is not None:
            arrays["base_sections"] = self.base_sections
        for i, k in enumerate(self.knots):
            arrays[f"knots{i}"] = k
        return arrays

    @classmethod
    def from_arrays(cls, arrays) -> Box:
        """The box stored by :meth:`to_arrays` (a mapping of arrays, e.g. the arrays of an ``.npz``).

        Raises KeyError, ValueError or TypeError for arrays that do not make a box."""
        dim = int(arrays["dim"])
        ax = arrays["axes"]
        axes = Axes(chord=int(ax[0]), thickness=int(ax[1]), span=int(ax[2]),
                    root="min" if ax[3] == 0 else "max", guessed=bool(ax[4]))
        knots = tuple(np.asarray(arrays[f"knots{i}"]) for i in range(3 if dim == 3 else 2))
        le_rows = arrays["le_rows"] if arrays["le_rows"].size else None
        settings = BoxSettings.from_dict(json.loads(bytes(arrays["settings"]).decode()))
        box = cls(control_points=arrays["control_points"], degree=tuple(int(d) for d in arrays["degree"]),
                  knots=knots, axes=axes, dim=dim, chord_sign=float(arrays["chord_sign"]),
                  stations=arrays["stations"], le_points=arrays["le_points"], te_points=arrays["te_points"],
                  margins=arrays["margins"], ref_weights=arrays["ref_weights"], le_rows=le_rows,
                  settings=settings, imported=bool(arrays["imported"]),
                  base_sections=arrays["base_sections"] if "base_sections" in arrays else None)
        n, m, l = box.shape
        if len(box.degree) != len(knots) or box.ref_weights.shape != (m, n, l) \
                or box.le_points.shape != (m, 3) or box.te_points.shape != (m, 3) \
                or box.stations.shape != (m,) or box.margins.shape != (m, 4) \
                or (le_rows is not None and le_rows.shape != (2, n * m * l)):
            raise ValueError("the arrays of a box do not fit together")
        return box

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
# Fitting a box to a surface
# ----------------------------------------------------------------------------------------------

def fit_box(points: np.ndarray, faces=(), settings: BoxSettings | None = None, *, dim: int = 3,
            path=None, progress=None, comm=None):
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
    comm
        :mod:`ffdcli.parallel.comm` communicator: every rank fits the same box, each embeds its block of
        the points (a collective; the result is the serial one on every rank).

    Returns
    -------
    (box, embedding, report)
        ``report`` has ``rebuilds``, ``warnings`` and ``notes`` (lists of str: notes are what went as
        designed, e.g. a rounded tip cap repaired), ``outside`` (count after the last
        rebuild: 0 unless the surface could not be contained).
    """
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
    notes: list[str] = []
    if axes.guessed and settings.sections is None:
        warnings.append(f"the surface is not clearly wing-shaped: axes guessed as {axes.as_dict()} "
                        f"(chord, thickness, span); set box.sections / --sections to choose")
    if dim == 3:
        sections, stations, chord_sign, sign_clear, extra, notes = _fit_sections_3d(pts, faces, axes, settings,
                                                                                 path)
        warnings += extra
    else:
        chord_sign, sign_clear = leading_edge_sign([pts[:, [axes.chord, axes.thickness]]])
        sec = analyse_section(section_frame_2d(axes, pts, chord_sign))
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
    core = None
    report = {"rebuilds": 0, "warnings": warnings, "notes": notes, "outside": 0}
    with progress("fitting the box", MAX_REBUILDS + 1) as bar:
        for attempt in range(MAX_REBUILDS + 1):
            P = _lattice_points(sections, stations, margins, axes, chord_sign, n, l, dim)
            box = assemble_box(P, settings, axes, dim, chord_sign, stations, sections, margins=margins)
            core = embed(box.lattice(), box.core_points(pts), progress=progress, comm=comm)
            bar.update(1)
            outside = ~core.inside
            if not outside.any():
                break
            report["rebuilds"] = attempt + 1
            if attempt == MAX_REBUILDS:
                break
            margins = _grow_margins(margins, core, outside, sections, box, settings)
    report["outside"] = int((~core.inside).sum())
    if dim == 3:
        rows, inside = le_basis_rows(box, box.le_points[[0, -1]])
        if not inside:        # a leading-edge point must lie in the lattice (it has margins)
            raise RuntimeError("leading-edge reference points fell outside the lattice")
        box = replace(box, le_rows=rows)
    return box, core, report


def _fit_sections_3d(pts, faces, axes: Axes, settings: BoxSettings, path):
    """Sections (list of Section), stations (m,), chord sign, whether it was clear, warnings, notes."""
    m = settings.points[1]
    eta = axes.span_sign * pts[:, axes.span]
    root, tip = float(eta.min()), float(eta.max())
    span = tip - root
    if not span > 1e-12 * diagonal(pts):
        raise InputError("the surface has no extent along the span axis "
                         f"({'xyz'[axes.span]}); for an airfoil mesh use a 2D mesh", path=path)
    etas = root + span * np.arange(m) / (m - 1)
    cutter = Cutter.of(pts, faces, axes, slab=0.5 * span / (4 * (m - 1)))
    chord_sign, clear = cutter.chord_sign()
    sections = cutter.sections(etas, chord_sign)
    warnings: list[str] = []
    notes: list[str] = []
    repair_ends(sections, etas, cutter, chord_sign, span, warnings, notes)
    if any(s is None for s in sections):
        bad = [j for j, s in enumerate(sections) if s is None]
        raise InputError(f"could not find the airfoil at sections {bad} of the surface; is it a wing? "
                         "(try box.sections / --sections to set the axes)", path=path)
    return sections, etas, chord_sign, clear, warnings, notes


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


def _grow_margins(margins, core, outside, sections, box, settings):
    """Grow the margins of the sides where points fell out, at the sections nearest to them."""
    margins = margins.copy()
    params = core.params[outside]
    dist = core.residual[outside]
    m = margins.shape[0]
    step0 = max(settings.margin, 0.01)
    if box.dim == 3:
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


# ----------------------------------------------------------------------------------------------
# Making a box (both paths: fitted here, imported in ffdcli.box.imported)
# ----------------------------------------------------------------------------------------------

def assemble_box(P: np.ndarray, settings: BoxSettings, axes: Axes, dim: int, chord_sign: float,
                 stations: np.ndarray, sections: list[Section], *, margins: np.ndarray | None = None,
                 le_rows: np.ndarray | None = None, imported: bool = False) -> Box:
    """The :class:`Box` of control points ``P`` (n, m, l, 3) and the sections it was made for.

    ``settings`` are checked ones (points and degree filled in); ``stations`` (m,) are signed span
    coordinates of the sections (``axes.span_sign`` times the mesh coordinate; 2D: the plane's);
    ``sections`` the airfoils read at them. Knots, edge points and the reference weights of each
    section's trailing-edge point follow from these. ``margins`` (m, 4) default to zeros (an
    imported lattice); ``le_rows`` are set once the lattice exists (:func:`le_basis_rows`).
    """
    P = np.ascontiguousarray(P, dtype=np.float64)
    n, m, l, _ = P.shape
    degree = settings.degrees()
    sizes = (n, m, l) if dim == 3 else (n, l)
    knots = tuple(clamped_knots(s, d) for s, d in zip(sizes, degree, strict=True))
    le_pts, te_pts = edge_points(sections, stations, axes, chord_sign, dim)
    return Box(control_points=P, degree=tuple(degree), knots=knots, axes=axes, dim=dim,
               chord_sign=chord_sign,
               stations=np.asarray(stations, dtype=np.float64) * (axes.span_sign if dim == 3 else 1.0),
               le_points=le_pts, te_points=te_pts,
               margins=np.zeros((m, 4)) if margins is None else np.array(margins, dtype=np.float64),
               ref_weights=reference_weights(P, sections, axes, chord_sign), le_rows=le_rows,
               settings=settings, imported=imported)


def reference_weights(P: np.ndarray, sections: list[Section], axes: Axes, chord_sign: float) -> np.ndarray:
    """(m, n, l) weights of each section's trailing-edge point in the corners of its lattice section.

    ``te_j = sum_ik w[j, i, k] P[i, j, k]`` with only the four corners non-zero: the bilinear
    coordinates of the trailing-edge point in the quadrilateral of corners (exact for the rectangles
    of a fitted box, Newton's method for an imported lattice's sections).
    """
    n, m, l, _ = P.shape
    ref = np.zeros((m, n, l))
    for j, s in enumerate(sections):
        corners = P[[0, -1, 0, -1], j, [0, 0, -1, -1]]          # A B C D
        c2 = np.stack([chord_sign * corners[:, axes.chord], corners[:, axes.thickness]], 1)
        a, b = _bilinear_inverse(c2, s.te)
        ref[j, 0, 0], ref[j, -1, 0] = (1 - a) * (1 - b), a * (1 - b)
        ref[j, 0, -1], ref[j, -1, -1] = (1 - a) * b, a * b
    return ref


def le_basis_rows(box: Box, points: np.ndarray) -> tuple[np.ndarray, bool]:
    """Basis rows (2, n*m*l) of two leading-edge points (2, 3) (root, tip) in the box's lattice, and
    whether both are inside it."""
    e = embed(box.lattice(), box.core_points(points))
    return e.basis_matrix().toarray(), bool(e.inside.all())


def section_weights(box: Box, points: np.ndarray) -> np.ndarray:
    """(m, n, l) weights w with ``points[j] = sum_ik w[j, i, k] P[i, j, k]`` (P the box's control
    points): bilinear in the four corner points of section j, as the trailing-edge reference
    weights are, so the point follows its section under every change exactly (an affine combination).

    ``points`` (m, 3) lie in their sections' planes (e.g. ``box.le_points``)."""
    P = box.control_points
    n, m, l, _ = P.shape
    c, t = box.axes.chord, box.axes.thickness
    w = np.zeros((m, n, l))
    for j in range(m):              # m sections: tens at most
        corners = P[[0, -1, 0, -1], j, [0, 0, -1, -1]]
        a, b = _bilinear_inverse(corners[:, [c, t]], np.asarray(points[j])[[c, t]])
        w[j, 0, 0], w[j, -1, 0] = (1 - a) * (1 - b), a * (1 - b)
        w[j, 0, -1], w[j, -1, -1] = (1 - a) * b, a * b
    return w


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
