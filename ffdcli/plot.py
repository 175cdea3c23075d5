"""Pictures of a design: original surface (black), deformed surface (red), and the lattice.

Headless: matplotlib's Agg backend, no display needed. 3D wings get a planform view (chord x span),
a front view (span x thickness) and the airfoil sections at the root, mid-span and tip; a 2D airfoil
gets one view of the airfoil with its lattice. Sections are the same material curves before and
after: the original surface is cut by a plane, and each cut point is carried by the deformation of
the two nodes of the edge it lies on.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ffdcli.atomic import atomic_path

BLACK, RED, GREY = "#000000", "#d62728", "#7f7f7f"
AXIS = "xyz"


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


def _segments(points2: np.ndarray, edges: np.ndarray) -> np.ndarray:
    return np.stack([points2[edges[:, 0]], points2[edges[:, 1]]], axis=1)


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


def _draw_view(ax, X0, X1, edges, P0, P1, cols, labels, max_edges=60000):
    from matplotlib.collections import LineCollection

    if len(edges) > max_edges:          # keep big surfaces legible and fast: a regular subset
        edges = edges[:: int(np.ceil(len(edges) / max_edges))]
    for X, color, lw in ((X0, BLACK, 0.3), (X1, RED, 0.3)):
        if len(edges):
            ax.add_collection(LineCollection(_segments(X[:, cols], edges), colors=color, linewidths=lw))
        else:
            ax.plot(X[:, cols[0]], X[:, cols[1]], ".", ms=1, color=color)
    for P, color, style in ((P0, GREY, "--"), (P1, RED, "-")):
        Q = P[..., cols]
        ax.add_collection(LineCollection(_lattice_segments(Q), colors=color, linewidths=0.6,
                                         linestyles=style, alpha=0.7))
        ax.plot(Q[..., 0].ravel(), Q[..., 1].ravel(), "o", ms=2.5, color=color, alpha=0.8)
    ax.set_xlabel(labels[0])
    ax.set_ylabel(labels[1])
    ax.set_aspect("equal", adjustable="datalim")
    ax.autoscale_view()


def section_curves(run, result, fractions=(("root", 0.0), ("mid-span", 0.5), ("tip", 0.97))) -> dict:
    """The airfoil sections drawn: {label: (span coordinate, nearest lattice section j, original (K, 2),
    deformed (K, 2))} in (chord, thickness) mesh coordinates; the same material points before/after."""
    from ffdcli.box import surface_edges

    box, surf = run.box, run.prep.surface
    X0, X1 = surf.points, result.points[surf.ids]
    edges = surface_edges(surf.faces)
    c, t, s = box.axes.chord, box.axes.thickness, box.axes.span
    lo, hi = X0[:, s].min(), X0[:, s].max()
    out = {}
    for label, frac in fractions:
        value = lo + frac * (hi - lo) if box.axes.root == "min" else hi - frac * (hi - lo)
        if len(edges):
            a, b, w = _edge_cut(X0, edges, s, value)
            q0 = (X0[a] + w[:, None] * (X0[b] - X0[a]))[:, [c, t]]
            q1 = (X1[a] + w[:, None] * (X1[b] - X1[a]))[:, [c, t]]
        else:
            near = np.abs(X0[:, s] - value) <= 1e-9 * (hi - lo)
            q0, q1 = X0[near][:, [c, t]], X1[near][:, [c, t]]
        j = int(np.argmin(np.abs(box.stations - value)))
        out[label] = (float(value), j, q0, q1)
    return out


def plot_3d(run, result, path) -> Path | None:
    """The 3D view (pyvista, off-screen, in a subprocess) of a 3D design; None when not possible."""
    from ffdcli.render3d import render_3d

    if run.box.dim != 3:
        return None
    surf = run.prep.surface
    box = run.box
    axes = np.array([box.chord_dir, box.thickness_dir, box.span_dir])
    return render_3d(surf.points, result.points[surf.ids], surf.faces, run.P0, result.lattice, path,
                     title=f"{Path(run.design.path).name}: original grey, deformed red", axes=axes)


def plot_design(run, result, path, *, title: str | None = None, dpi: int = 110) -> Path:
    """Write a PNG of the design ``run`` deformed into ``result`` (``ffdcli.pipeline``). Returns the path."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ffdcli.box import surface_edges

    box, surf = run.box, run.prep.surface
    X0 = surf.points
    X1 = result.points[surf.ids]
    edges = surface_edges(surf.faces)
    P0, P1 = run.P0, result.lattice
    c, t, s = box.axes.chord, box.axes.thickness, box.axes.span
    names = [f"{AXIS[i]} ({w})" for i, w in ((c, "chord"), (t, "thickness"), (s, "span"))]
    title = title or f"{Path(run.design.path).name}: original (black), deformed (red)"

    if box.dim == 2:
        fig, ax = plt.subplots(figsize=(10, 5))
        _draw_view(ax, X0, X1, edges, P0, P1, [c, t], [names[0], names[1]])
        ax.set_title("airfoil and lattice")
    else:
        fig = plt.figure(figsize=(13, 9))
        grid = fig.add_gridspec(2, 3)
        ax_plan = fig.add_subplot(grid[0, :2])
        _draw_view(ax_plan, X0, X1, edges, P0, P1, [s, c], [names[2], names[0]])
        ax_plan.set_title("planform")
        ax_front = fig.add_subplot(grid[0, 2])
        _draw_view(ax_front, X0, X1, edges, P0, P1, [s, t], [names[2], names[1]])
        ax_front.set_title("front")
        curves = section_curves(run, result)
        for col, (label, (value, j, q0, q1)) in enumerate(curves.items()):
            ax = fig.add_subplot(grid[1, col])
            for q2, color in ((q0, BLACK), (q1, RED)):
                if len(q2):
                    o = _order_loop(q2)
                    ax.plot(np.r_[q2[o, 0], q2[o[:1], 0]], np.r_[q2[o, 1], q2[o[:1], 1]], "-", lw=0.9,
                            color=color)
            for P, color in ((P0, GREY), (P1, RED)):
                Q = P[:, j, :, :][..., [c, t]]
                ax.plot(Q[..., 0].ravel(), Q[..., 1].ravel(), "o", ms=2.5, color=color, alpha=0.8)
            ax.set_title(f"{label} section ({AXIS[s]} = {value:.3g})")
            ax.set_xlabel(names[0])
            ax.set_ylabel(names[1])
            ax.set_aspect("equal", adjustable="datalim")
    fig.suptitle(title)
    fig.tight_layout()
    p = Path(path)
    with atomic_path(p) as tmp:
        fig.savefig(tmp, dpi=dpi, format="png")
    plt.close(fig)
    return p
