"""Pictures of a design: original surface (black), deformed surface (red), and the lattice.

Headless: matplotlib's Agg backend, no display needed. A 3D wing gets

- a planform (streamwise chord axis to the right, span upwards from the root) and a front view
  (span to the right, thickness up), each drawn as OUTLINES: leading and trailing edge, root and tip,
  and a few section lines, the original in black over the deformed in red;
- the change itself: the thickness-wise displacement of the surface along the chord at the root,
  mid and tip sections, in % of the local chord (so a 1 % chord shape change fills the panel);
- the airfoil sections at the root, mid and tip lattice sections, labelled by lattice index ``j``
  and span fraction ``eta`` (0 root, 1 tip), with the lattice points of that section.

A 2D airfoil gets the airfoil with its lattice (and a target airfoil when given, e.g. by a fit) and
the change panel. Sections are the same material curves before and after: the original surface is
cut by a plane, and each cut point is carried by the deformation of the two nodes of its edge.

The drawing works on :class:`Part` values (one wing surface with its box), so that a design of
several components can pass one part per component.
"""

from __future__ import annotations

import os
import textwrap
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ffdcli.errors import InputError
from ffdcli.geometry.sections import surface_edges
from ffdcli.io.atomic import atomic_path
from ffdcli.parameterization.fit import place_target
from ffdcli.viz.render3d import render_3d

BLACK, RED, GREY, VIOLET = "#000000", "#d62728", "#7f7f7f", "#9400d3"
#: Colours of the root, mid and tip curves of the change panel.
STATION_COLORS = ("#1f77b4", "#2ca02c", "#ff7f0e")
AXIS = "xyz"
#: Span bins of the planform/front outlines.
OUTLINE_BINS = 80


@dataclass(frozen=True)
class Part:
    """One wing to draw: its surface before (``X0``) and after (``X1``), (S, 3); ``edges`` (E, 2)
    local point ids; the lattice before/after ``P0``/``P1`` (n, m, l, 3); its :class:`~ffdcli.box.box.Box`."""

    name: str
    X0: np.ndarray
    X1: np.ndarray
    edges: np.ndarray
    P0: np.ndarray
    P1: np.ndarray
    box: object
    #: ((kind, (E, 3) hinge points), ...) of the flaps and slats, on the original lattice.
    hinges: tuple = ()


def run_parts(run, result) -> list[Part]:
    """The parts of a design run (``ffdcli.app.pipeline``): one per component, in file order."""
    Ps = [result.lattice] if run.single else list(result.lattice)
    out = []
    for comp, P1 in zip(run.components, Ps, strict=True):
        surf = comp.prep.surface
        hinges = tuple((ch.kind, ch.hinge_line(comp.P0)) for ch in comp.changes if hasattr(ch, "hinge_line"))
        out.append(Part(name=comp.name or ", ".join(surf.names), X0=surf.points, X1=result.points[surf.ids],
                        edges=surface_edges(surf.faces), P0=comp.P0, P1=P1, box=comp.box, hinges=hinges))
    return out


# --------------------------------------------------------------------------------------------------
# Geometry of the pictures (pure NumPy)
# --------------------------------------------------------------------------------------------------

def _edge_cut(points: np.ndarray, edges: np.ndarray, axis: int, value: float):
    """Edges crossing the plane ``points[:, axis] == value``: (a, b, t) with cut = a + t (b - a)."""
    s = points[:, axis] - value
    sa, sb = s[edges[:, 0]], s[edges[:, 1]]
    cross = (sa * sb <= 0) & (sa != sb)
    a, b = edges[cross, 0], edges[cross, 1]
    t = sa[cross] / (sa[cross] - sb[cross])
    return a, b, t


def _order_loop(q: np.ndarray) -> np.ndarray:
    """Order section points (K, 2) around their centroid (a display aid for airfoil loops)."""
    if len(q) < 3:
        return np.arange(len(q))
    c = q.mean(0)
    return np.argsort(np.arctan2(q[:, 1] - c[1], q[:, 0] - c[0]))


def _lattice_segments(P2: np.ndarray) -> np.ndarray:
    """Line segments (E, 2, 2) joining neighbouring control points of an (n, m, l, 2) lattice."""
    segs = []
    for ax in range(3):
        if P2.shape[ax] < 2:
            continue
        a = np.take(P2, np.arange(P2.shape[ax] - 1), axis=ax).reshape(-1, 2)
        b = np.take(P2, np.arange(1, P2.shape[ax]), axis=ax).reshape(-1, 2)
        segs.append(np.stack([a, b], axis=1))
    return np.concatenate(segs) if segs else np.zeros((0, 2, 2))


def span_fraction(box, value: float) -> float:
    """Span fraction (0 root, 1 tip) of a span coordinate, measured on the lattice sections."""
    st = np.asarray(box.stations, dtype=np.float64)
    lo, hi = st[0], st[-1]
    return round(float((value - lo) / (hi - lo)), 12) + 0.0 if hi != lo else 0.0   # no "-0.00"


def section_stations(box) -> list[tuple[str, int, float]]:
    """(label, lattice section j, span coordinate of the cut) of the root, mid and tip panels.

    The root and mid cuts lie on their lattice section; the tip cut lies 2 % of the span inboard of
    the last section, which sits at the very tip, where a closed tip has no airfoil left to cut (and
    the root cut moves 2 % outboard when the root is open at its plane, a symmetry plane: the panels'
    titles say "near")."""
    m = len(box.stations)
    st = np.asarray(box.stations, dtype=np.float64)
    jm = (m - 1) // 2 if m > 2 else 0
    tip = st[-1] - 0.02 * (st[-1] - st[0])
    return [("root", 0, float(st[0])), ("mid-span", jm, float(st[jm])), ("tip", m - 1, float(tip))]


def section_curves(run, result) -> dict:
    """The airfoil sections drawn: {label: (span coordinate, lattice section j, original (K, 2),
    deformed (K, 2))} in (chord, thickness) mesh coordinates; the same material points before/after."""
    return _section_curves(run_parts(run, result)[0])


def _section_curves(part: Part) -> dict:
    box = part.box
    c, t, s = box.axes.chord, box.axes.thickness, box.axes.span
    X0, X1 = part.X0, part.X1
    if box.dim == 2:               # the airfoil itself: every surface point
        return {"airfoil": (0.0, 0, X0[:, [c, t]], X1[:, [c, t]])}
    out = {}
    st = np.asarray(box.stations, dtype=np.float64)
    for label, j, value in section_stations(box):
        if len(part.edges):
            a, b, w = _edge_cut(X0, part.edges, s, value)
            cut = X0[a] + w[:, None] * (X0[b] - X0[a])
            if label == "root" and (len(a) < 3 or np.ptp(cut[:, c]) <= 1e-3 * abs(st[-1] - st[0])):
                # a root open at its plane (a symmetry plane) leaves no airfoil there: 2 % outboard
                value = float(st[0] + 0.02 * (st[-1] - st[0]))
                a, b, w = _edge_cut(X0, part.edges, s, value)
            q0 = (X0[a] + w[:, None] * (X0[b] - X0[a]))[:, [c, t]]
            q1 = (X1[a] + w[:, None] * (X1[b] - X1[a]))[:, [c, t]]
        else:
            span = np.ptp(X0[:, s]) or 1.0
            near = np.abs(X0[:, s] - value) <= 0.01 * span
            q0, q1 = X0[near][:, [c, t]], X1[near][:, [c, t]]
        out[label] = (float(value), j, q0, q1)
    return out


def section_change(box, j: int, q0: np.ndarray, q1: np.ndarray):
    """The change of one section as the panel draws it.

    Returns (x/c (K,), delta (K,), upper (K,) bool): each cut point's chord fraction on the original
    cut's own chord line (its leading edge, the cut point furthest forward, 0; its trailing edge,
    the furthest aft, 1: the airfoil an aerodynamicist reads off that cut), its thickness-wise
    displacement in % of that local chord, and whether it lies on the upper side of the chord line.
    Sorted by x/c. ``j`` (the lattice section) gives the chord line when the cut has < 2 points."""
    c, t = box.axes.chord, box.axes.thickness
    if len(q0) >= 2:
        fwd = box.chord_sign * q0[:, 0]
        le, te = q0[int(np.argmin(fwd))], q0[int(np.argmax(fwd))]
    else:
        le, te = box.le_points[j][[c, t]], box.te_points[j][[c, t]]
    chord = float(np.hypot(*(te - le))) or 1.0
    e1 = (te - le) / chord
    e2 = np.array([-e1[1], e1[0]])
    if e2[1] < 0:
        e2 = -e2
    xc = (q0 - le) @ e1 / chord
    delta = 100.0 * (q1[:, 1] - q0[:, 1]) / chord
    upper = (q0 - le) @ e2 >= 0
    order = np.argsort(xc, kind="stable")
    return xc[order], delta[order], upper[order]


def outline(points: np.ndarray, along: int, across: int, bins: int = OUTLINE_BINS) -> np.ndarray:
    """Closed outline (K, 2) of points projected on the (along, across) plane: the min and max of
    ``across`` in ``bins`` slices of ``along`` (e.g. span slices: leading and trailing edge), joined
    at both ends (root and tip lines). Columns: (along, across)."""
    a, b = points[:, along], points[:, across]
    lo, hi = float(a.min()), float(a.max())
    if hi <= lo:
        return np.array([[lo, b.min()], [lo, b.max()]])
    k = np.minimum(((a - lo) / (hi - lo) * bins).astype(np.int64), bins - 1)
    bmin = np.full(bins, np.inf)
    bmax = np.full(bins, -np.inf)
    np.minimum.at(bmin, k, b)
    np.maximum.at(bmax, k, b)
    asum = np.bincount(k, weights=a, minlength=bins)
    cnt = np.bincount(k, minlength=bins)
    have = cnt > 0
    centre = np.where(have, asum / np.maximum(cnt, 1), 0.0)[have]
    centre[0], centre[-1] = a.min(), a.max()          # the root and tip lines at the real ends
    low = np.c_[centre, bmin[have]]
    high = np.c_[centre, bmax[have]]
    return np.concatenate([low, high[::-1], low[:1]])


def section_lines(points: np.ndarray, along: int, across: int, values) -> np.ndarray:
    """Segments (K, 2, 2) across the outline at the slices nearest ``values`` of ``along``."""
    a, b = points[:, along], points[:, across]
    width = 0.01 * (np.ptp(a) or 1.0)
    segs = []
    for v in values:
        near = np.abs(a - v) <= width
        if near.any():
            segs.append([[v, b[near].min()], [v, b[near].max()]])
    return np.array(segs, dtype=np.float64).reshape(-1, 2, 2)


# --------------------------------------------------------------------------------------------------
# Panels
# --------------------------------------------------------------------------------------------------

def _draw_outlines(ax, part: Part, along: int, across: int, *, swap: bool, lattice: bool = True):
    """Outline of the original (black, on top) and deformed (red) surface, with section lines at the
    lattice sections; ``swap`` draws ``across`` horizontally (the planform's chord to the right)."""
    from matplotlib.collections import LineCollection  # noqa: PLC0415 (drawn only when asked)

    def xy(q):
        return q[..., ::-1] if swap else q

    box = part.box
    for X, color, lw, z in ((part.X1, RED, 1.8, 2), (part.X0, BLACK, 1.0, 3)):
        o = outline(X, along, across)
        ax.plot(*xy(o).T, "-", color=color, lw=lw, zorder=z)
        st = box.stations if X is part.X0 else _deformed_stations(part)
        segs = section_lines(X, along, across, st[1:-1])
        if len(segs):
            ax.add_collection(LineCollection(xy(segs), colors=color, linewidths=0.6 * lw, zorder=z))
    if lattice:
        for P, color, style in ((part.P0, GREY, "--"), (part.P1, RED, "-")):
            Q = P[..., [along, across]]
            ax.add_collection(LineCollection(xy(_lattice_segments(Q)), colors=color, linewidths=0.4,
                                             linestyles=style, alpha=0.45, zorder=1))
            ax.plot(*xy(Q.reshape(-1, 2)).T, "o", ms=2, color=color, alpha=0.6, zorder=1)


def _draw_hinges(ax, part: Part, along: int, across: int, *, swap: bool):
    """The hinge lines of the part's flaps and slats (violet dash-dot; a cross in 2D)."""
    for kind, H in part.hinges:
        q = H[:, [along, across]]
        q = q[:, ::-1] if swap else q
        ax.plot(*q.T, "-." if len(q) > 1 else "x", color=VIOLET, lw=1.6, ms=9, zorder=5,
                label=f"{kind} hinge")


def _deformed_stations(part: Part) -> np.ndarray:
    """Span coordinate of each deformed lattice section (mean of its control points)."""
    s = part.box.axes.span
    return part.P1[:, :, :, s].mean(axis=(0, 2))


def _orient(ax, part: Part, *, chord_on_x: bool):
    """Streamwise (leading to trailing edge) to the right; root at the bottom/left."""
    box = part.box
    if chord_on_x:
        if box.chord_sign < 0:
            ax.invert_xaxis()
        if box.axes.root == "max":
            ax.invert_yaxis()
    elif box.axes.root == "max":
        ax.invert_xaxis()


def _change_panel(ax, part: Part, curves: dict):
    """Delta thickness-wise coordinate along the chord (% local chord) at root, mid and tip."""
    box = part.box
    big = 0.0
    for color, (label, (value, j, q0, q1)) in zip(STATION_COLORS, curves.items(), strict=False):
        if not len(q0):
            continue
        xc, d, up = section_change(box, j, q0, q1)
        eta = span_fraction(box, value)
        name = label if box.dim == 3 else "airfoil"
        where = f"{name}, j = {j}, \u03b7 = {eta:.2f}" if box.dim == 3 else name
        ax.plot(xc[up], d[up], "-", color=color, lw=1.4, label=f"{where}: upper")
        ax.plot(xc[~up], d[~up], "--", color=color, lw=1.2, label=f"{where}: lower")
        big = max(big, float(np.abs(d).max()))
    ax.axhline(0.0, color=GREY, lw=0.6)
    ax.set_xlim(-0.02, 1.02)
    if big == 0.0:
        ax.set_ylim(-1, 1)
        ax.text(0.5, 0.6, "no thickness-wise change (a planform change: see the planform)",
                transform=ax.transAxes, ha="center", color=GREY)
    t = AXIS[box.axes.thickness]
    ax.set_xlabel("x/c (chord fraction of the original cut: its own leading and trailing edge)")
    ax.set_ylabel(f"\u0394{t} / c  (% of local chord)")
    ax.set_title(f"the change: thickness-wise ({t}) displacement of the surface, largest "
                 f"{big:.3g} % chord")
    ax.grid(alpha=0.3)
    if big:
        ax.legend(fontsize=7, ncol=3 if box.dim == 3 else 2, loc="best")


def _section_panel(ax, part: Part, label: str, value: float, j: int, q0, q1, names):
    box = part.box
    c, t = box.axes.chord, box.axes.thickness
    for q2, color, lw, z in ((q1, RED, 1.4, 2), (q0, BLACK, 0.9, 3)):
        if not len(q2):
            continue
        if box.dim == 2 and len(part.edges):        # the airfoil's own edges
            from matplotlib.collections import LineCollection  # noqa: PLC0415 (drawn only when asked)

            ax.add_collection(LineCollection(np.stack([q2[part.edges[:, 0]], q2[part.edges[:, 1]]], 1),
                                             colors=color, linewidths=lw, zorder=z))
            ax.autoscale_view()
        else:
            # the cut points are material points: the deformed section in the original's order (a
            # drooped flap is not star-shaped about its centroid)
            o = _order_loop(q0) if len(q0) == len(q2) else _order_loop(q2)
            ax.plot(np.r_[q2[o, 0], q2[o[:1], 0]], np.r_[q2[o, 1], q2[o[:1], 1]], "-", lw=lw,
                    color=color, zorder=z)
    for P, color in ((part.P0, GREY), (part.P1, RED)):
        Q = P[:, j, :, :][..., [c, t]]
        ax.plot(Q[..., 0].ravel(), Q[..., 1].ravel(), "o", ms=2.5, color=color, alpha=0.8)
    if box.dim == 3:
        eta = span_fraction(box, value)
        on = "on" if abs(value - float(box.stations[j])) <= 1e-9 * abs(box.stations[-1] - box.stations[0]) else "near"
        ax.set_title(f"{label}: cut {on} lattice section j = {j}, \u03b7 = {eta:.2f}", fontsize=10)
    ax.set_xlabel(names[0])
    ax.set_ylabel(names[1])
    ax.set_aspect("equal", adjustable="datalim")
    if box.chord_sign < 0:
        ax.invert_xaxis()


def _target_curve(box, target: np.ndarray) -> np.ndarray:
    """A unit-chord target airfoil (K, 2) placed on section 0's chord line, in (chord, thickness)."""
    c, t = box.axes.chord, box.axes.thickness
    le, te = box.le_points[0][[c, t]], box.te_points[0][[c, t]]
    chord = float(np.hypot(*(te - le)))
    e1 = (te - le) / chord
    e2 = np.array([-e1[1], e1[0]])
    if e2[1] < 0:
        e2 = -e2
    poly, _, _ = place_target(target)
    return le + chord * (poly[:, :1] * e1 + poly[:, 1:] * e2)


# --------------------------------------------------------------------------------------------------
# The picture
# --------------------------------------------------------------------------------------------------

def plot_design(run, result, path, *, title: str | None = None, dpi: int = 110,
                target: np.ndarray | None = None, note: str | None = None) -> Path:
    """Write a PNG of the design ``run`` deformed into ``result`` (``ffdcli.app.pipeline``). Returns the path.

    ``target``: a unit-chord airfoil (K, 2) drawn on the airfoil view (2D, e.g. the target of a
    fit). ``note``: a line printed under the title in red (e.g. that the quality gate refuses it).
    """
    title = title or f"{Path(run.design.path).name}: original (black), deformed (red)"
    if note is None and result.quality is not None and not result.quality.ok:
        note = f"refused by the quality gate: {result.quality.summary()}"
    parts = run_parts(run, result)
    if len(parts) > 1:
        return plot_components(parts, path, title=title, dpi=dpi, note=note)
    return plot_parts(parts, path, title=title, dpi=dpi, target=target, note=note)


def load_pyplot():
    """matplotlib.pyplot on the Agg backend; an unusable ``MPLBACKEND`` in the environment (which
    matplotlib checks on import) is the user's environment, said so, not a bug."""
    try:
        import matplotlib  # noqa: PLC0415 (drawn only when asked)
    except ValueError as e:
        backend = os.environ.get("MPLBACKEND")
        if backend is not None and "backend" in str(e):
            raise InputError(f"the environment variable MPLBACKEND={backend!r} is not a matplotlib backend; "
                             "unset it (ffd draws off-screen with Agg whatever it says)",
                             hint="env -u MPLBACKEND ffd ...") from None
        raise
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415 (drawn only when asked)

    return plt


def plot_parts(parts: list[Part], path, *, title: str, dpi: int = 110, target=None,
               note: str | None = None) -> Path:
    """Write the PNG of ``parts`` (:class:`Part`): every part's outlines in the planform and front
    views (in the first part's axes), the first part's change panel and sections."""
    plt = load_pyplot()

    part = parts[0]
    box = part.box
    c, t, s = box.axes.chord, box.axes.thickness, box.axes.span
    names = [f"{AXIS[i]} ({w})" for i, w in ((c, "chord"), (t, "thickness"), (s, "span"))]
    curves = _section_curves(part)

    if box.dim == 2:
        fig = plt.figure(figsize=(11, 9))
        grid = fig.add_gridspec(2, 1, height_ratios=[1.3, 1])
        ax = fig.add_subplot(grid[0])
        label, (value, j, q0, q1) = "airfoil", next(iter(curves.values()))
        _section_panel(ax, part, label, value, 0, q0, q1, names)
        from matplotlib.collections import LineCollection  # noqa: PLC0415 (drawn only when asked)

        for P, color, style in ((part.P0, GREY, "--"), (part.P1, RED, "-")):
            Q = P[..., [c, t]]
            ax.add_collection(LineCollection(_lattice_segments(Q), colors=color, linewidths=0.6,
                                             linestyles=style, alpha=0.6))
        if target is not None:
            tq = _target_curve(box, target)
            ax.plot(tq[:, 0], tq[:, 1], "--", color=VIOLET, lw=1.4, label="target", zorder=4)
        _draw_hinges(ax, part, c, t, swap=False)
        ax.plot([], [], "-", color=BLACK, label="original")
        ax.plot([], [], "-", color=RED, label="deformed")
        ax.legend(fontsize=8, loc="upper right")
        ax.set_title("airfoil and lattice (grey dashed original, red deformed)")
        _change_panel(fig.add_subplot(grid[1]), part, {"airfoil": (value, 0, q0, q1)})
    else:
        fig = plt.figure(figsize=(14, 12))
        grid = fig.add_gridspec(3, 3, height_ratios=[1.25, 1, 0.9])
        ax_plan = fig.add_subplot(grid[0:2, 0])
        for other in parts:              # every component in the planform and front views
            _draw_outlines(ax_plan, other, s, c, swap=True)
            _draw_hinges(ax_plan, other, s, c, swap=True)
        if part.hinges:
            ax_plan.legend(fontsize=8, loc="best")
        ax_plan.set_xlabel(names[0] + ", streamwise \u2192")
        ax_plan.set_ylabel(names[2] + ", root to tip")
        ax_plan.set_aspect("equal", adjustable="datalim")
        _orient(ax_plan, part, chord_on_x=True)
        ax_plan.set_title("planform")
        ax_front = fig.add_subplot(grid[0, 1:])
        for other in parts:
            _draw_outlines(ax_front, other, s, t, swap=False)
        ax_front.set_xlabel(names[2] + ", root to tip")
        ax_front.set_ylabel(names[1])
        ax_front.set_aspect("equal", adjustable="datalim")
        _orient(ax_front, part, chord_on_x=False)
        ax_front.set_title("front view (from ahead)")
        _change_panel(fig.add_subplot(grid[1, 1:]), part, curves)
        for col, (label, (value, j, q0, q1)) in enumerate(curves.items()):
            _section_panel(fig.add_subplot(grid[2, col]), part, label, value, j, q0, q1, names)
    if note:                       # a long quality summary: wrapped, never cut at the figure's edge

        note = "\n".join(textwrap.wrap(note, 150 if box.dim == 3 else 120))
    fig.suptitle(title + (f"\n{note}" if note else ""), color=BLACK if not note else RED)
    fig.tight_layout()
    p = Path(path)
    with atomic_path(p) as tmp:
        fig.savefig(tmp, dpi=dpi, format="png")
    plt.close(fig)
    return p


def plot_3d(run, result, path) -> Path | None:
    """The 3D view (pyvista, off-screen, in a subprocess) of a 3D design; None when not possible."""
    if run.box.dim != 3 or not run.single:
        return None
    part = run_parts(run, result)[0]
    surf = run.prep.surface
    box = part.box
    axes = np.array([box.chord_dir, box.thickness_dir, box.span_dir])
    lines0, lines1 = section_polylines_3d(part)
    return render_3d(part.X0, part.X1, surf.faces, part.P0, part.P1, path,
                     title=f"{Path(run.design.path).name}: original grey with black sections, "
                           "deformed red", axes=axes, lines0=lines0, lines1=lines1)


def section_polylines_3d(part: Part, count: int = 5):
    """3D section loops of the original and the deformed surface at ``count`` span stations from
    root to near tip: two lists of (K, 3) closed polylines (the same material points)."""
    box = part.box
    s = box.axes.span
    st = np.asarray(box.stations, dtype=np.float64)
    values = st[0] + np.linspace(0.0, 0.98, count) * (st[-1] - st[0])
    c, t = box.axes.chord, box.axes.thickness
    out0, out1 = [], []
    if not len(part.edges):
        return out0, out1
    for v in values:
        a, b, w = _edge_cut(part.X0, part.edges, s, v)
        if len(a) < 3:
            continue
        q0 = part.X0[a] + w[:, None] * (part.X0[b] - part.X0[a])
        q1 = part.X1[a] + w[:, None] * (part.X1[b] - part.X1[a])
        o = _order_loop(q0[:, [c, t]])
        o = np.r_[o, o[:1]]
        out0.append(q0[o])
        out1.append(q1[o])
    return out0, out1


def _draw_part_view(ax, part: Part, cols) -> None:
    """One component in the view of mesh columns ``cols`` (horizontal, vertical): its outline with
    section lines when its span axis is in the view, else the outline of its projection."""
    from matplotlib.collections import LineCollection  # noqa: PLC0415 (drawn only when asked)

    s = part.box.axes.span
    if s in cols:
        across = cols[1] if cols[0] == s else cols[0]
        _draw_outlines(ax, part, s, across, swap=cols[0] != s)
        return
    a, b = cols
    for X, color, lw, z in ((part.X1, RED, 1.8, 2), (part.X0, BLACK, 1.0, 3)):
        o = outline(X, a, b)
        ax.plot(o[:, 0], o[:, 1], "-", color=color, lw=lw, zorder=z)
    for P, color, style in ((part.P0, GREY, "--"), (part.P1, RED, "-")):
        Q = P[..., [a, b]]
        ax.add_collection(LineCollection(_lattice_segments(Q), colors=color, linewidths=0.4, linestyles=style,
                                         alpha=0.45, zorder=1))


def plot_components(parts: list[Part], path, *, title: str, dpi: int = 110, note: str | None = None) -> Path:
    """The PNG of a design with several components: top, front and side views (mesh axes of the first
    component) of every component's outline and lattice, original black, deformed red."""
    import matplotlib  # noqa: PLC0415 (drawn only when asked)

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415 (drawn only when asked)

    ax0 = parts[0].box.axes
    c, t, s = ax0.chord, ax0.thickness, ax0.span
    label = {c: f"{AXIS[c]} (chord)", t: f"{AXIS[t]} (thickness)", s: f"{AXIS[s]} (span of {parts[0].name})"}
    views = (("top view", (s, c)), ("front view", (s, t)), ("side view", (c, t)))
    fig, axs = plt.subplots(1, 3, figsize=(17, 5.5))
    for ax, (name, cols) in zip(axs, views, strict=True):
        for part in parts:
            _draw_part_view(ax, part, cols)
            P = part.P1 if name == "top view" else part.P0
            at = P.reshape(-1, 3).max(axis=0)
            ax.annotate(part.name, (at[cols[0]], at[cols[1]]), fontsize=8, color=BLACK)
        ax.set_xlabel(label[cols[0]])
        ax.set_ylabel(label[cols[1]])
        ax.set_aspect("equal", adjustable="datalim")
        ax.autoscale_view()
        ax.set_title(name)
    fig.suptitle(title + (f"\n{note}" if note else ""), color=BLACK if not note else RED)
    fig.tight_layout()
    p = Path(path)
    with atomic_path(p) as tmp:
        fig.savefig(tmp, dpi=dpi, format="png")
    plt.close(fig)
    return p
