"""A lattice from a file (pyGeo/DAFoam FFD boxes) used as the box, and the surface embedded in it.

The block's index directions are matched to chord, span and thickness and flipped so that the
lattice keeps the conventions of an automatic box (``i`` leading to trailing edge, ``j`` root to tip,
``k`` upward); sections are read off the surface at the lattice's stations for the trailing-edge
reference points, and :func:`ffdcli.box.box.assemble_box` makes the :class:`~ffdcli.box.box.Box`. Reading the
file is the caller's (:func:`ffdcli.app.pipeline.prepare_box`): this module takes the array.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ffdcli.box.box import assemble_box, le_basis_rows
from ffdcli.errors import InputError
from ffdcli.geometry.axes import detect_axes
from ffdcli.geometry.sections import Cutter, analyse_section, leading_edge_sign, repair_ends, section_frame_2d
from ffdcli.lattice.embedding import embed
from ffdcli.settings import BoxSettings


def import_box(block: np.ndarray, points: np.ndarray, faces=(), settings: BoxSettings | None = None, *,
               dim: int = 3, path=None, source=None, progress=None, comm=None):
    """Use a lattice block (ni, nj, nk, 3) (a pyGeo FFD file's) as the box, and embed the surface in it.

    The block's index directions are matched to chord, span and thickness by their alignment with
    the mesh axes, and flipped so that ``i`` runs from leading to trailing edge, ``j`` from root to
    tip and ``k`` upward. Points outside the lattice are reported, never snapped: they keep their
    position when the lattice moves. The number of control points comes from the file; degrees
    default to min(3, points - 1) as for an automatic box.

    Parameters
    ----------
    block
        (ni, nj, nk, 3) control points as read from the file (the pipeline reads it).
    points, faces
        The surface: (N, 3) points and its faces (CellBlocks, local ids).
    settings
        :class:`BoxSettings` (``points``, if given, must match the block).
    source
        The lattice file, named in messages and warnings.
    comm
        As :func:`ffdcli.box.box.fit_box`: each rank embeds its block of the points.

    Returns
    -------
    (box, embedding, report)
        As :func:`ffdcli.box.box.fit_box`; ``report["outside"]`` counts the surface points outside.
    """
    settings = settings or BoxSettings()
    blk = np.asarray(block, dtype=np.float64)
    if blk.ndim != 4 or blk.shape[-1] != 3:
        raise InputError(f"a lattice block has shape (ni, nj, nk, 3), got {blk.shape}", path=source)
    pts = np.asarray(points, dtype=np.float64)
    axes = detect_axes(pts, dim, sections=settings.sections, root=settings.root, path=path, faces=faces)
    span_len = np.ptp(pts[:, axes.span])
    cutter = Cutter.of(pts, faces, axes, slab=0.02 * span_len if span_len > 0 else 0.0)
    if dim == 3:
        root, tip = cutter.extent
        chord_sign, _ = cutter.chord_sign()
    else:
        chord_sign, _ = leading_edge_sign([pts[:, [axes.chord, axes.thickness]]])
    P = orient_block(blk, axes, chord_sign, dim, pts)
    P = np.ascontiguousarray(P)
    n, m, l, _ = P.shape
    want = (n, m, l) if dim == 3 else (n, l)
    if settings.points is not None and tuple(settings.points) != want:
        raise InputError(f"box.points {list(settings.points)} does not match the lattice in "
                         f"{source} ({' x '.join(map(str, want))}); leave points out with box.file",
                         path=path, key="box.points")
    settings = replace(settings, points=want).checked(dim, path=path)

    # Sections at the lattice's stations (clamped to the surface's span) for the reference points.
    if dim == 3:
        stations = (axes.span_sign * P[..., axes.span]).mean(axis=(0, 2))
        etas = np.clip(stations, root, tip)
        secs = cutter.sections(etas, chord_sign)
        warnings: list[str] = []
        repair_ends(secs, etas, cutter, chord_sign, tip - root, warnings)
        for j, s in enumerate(secs):
            if s is None:
                near = [k for k in range(m) if secs[k] is not None]
                if not near:
                    raise InputError("the lattice does not overlap the wing's span", path=source)
                secs[j] = secs[min(near, key=lambda k: abs(k - j))]
    else:
        stations = np.array([float(np.mean(pts[:, axes.span]))])
        secs = [analyse_section(section_frame_2d(axes, pts, chord_sign))]
        warnings = []
    if any(s is None for s in secs):
        raise InputError("could not find an airfoil in the surface (it has no chordwise extent)", path=path)
    box = assemble_box(P, settings, axes, dim, chord_sign, stations, secs, imported=True)
    core = embed(box.lattice(), box.core_points(pts), progress=progress, comm=comm)
    n_out = int((~core.inside).sum())
    if n_out and n_out == len(core.inside):      # nothing would move: not a lattice of this wing
        raise InputError(f"none of the {n_out} surface points is inside the imported lattice (the nearest "
                         f"{core.residual.min():.3g} mesh units away): it is not around this wing", path=source,
                         hint="compare its position, units and axes with `ffd inspect MESH`")
    if n_out:
        warnings.append(f"{n_out} surface points are outside the imported lattice {source}; they will "
                        f"not move (worst distance {core.residual[~core.inside].max():.3g})")
    if dim == 3:
        # the leading-edge line of the surface (root and tip), for sweep and dihedral
        rows, inside = le_basis_rows(box, _surface_le(cutter, root, tip, chord_sign, path))
        if not inside:
            warnings.append("the wing's leading edge at the root or tip is outside the imported lattice: "
                            "sweep and dihedral measure the angle from the lattice's own leading edge")
        box = replace(box, le_rows=rows)
    return box, core, {"rebuilds": 0, "warnings": warnings, "outside": n_out}


def orient_block(blk: np.ndarray, axes, chord_sign: float, dim: int, pts: np.ndarray) -> np.ndarray:
    """The block (ni, nj, nk, 3) with its index directions matched to chord, span and thickness (by the
    alignment of each direction's mean edge with the mesh axes) and flipped so that ``i`` runs from
    leading to trailing edge, ``j`` from root to tip and ``k`` upward; 2D: one section at the
    surface's plane. Returns the (n, m, l, 3) control points (a view or a copy)."""
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
        # a single layer is the span of a 2D lattice (ffd's own export: one section, (n, 1, l))
        score = [np.inf if name == "span" and blk.shape[a] < 2 else abs(mean_edge[a] @ dirs[name]) for a in left]
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
    return P


def _surface_le(cutter: Cutter, root: float, tip: float, chord_sign: float, path=None) -> np.ndarray:
    """Leading-edge points (2, 3) of the surface's root and tip airfoils (a rounded cap repaired)."""
    axes = cutter.axes
    etas = np.array([root, 0.5 * (root + tip), tip])
    secs = cutter.sections(etas, chord_sign)
    repair_ends(secs, etas, cutter, chord_sign, tip - root, [])
    out = np.zeros((2, 3))
    for row, (s, e) in enumerate(((secs[0], root), (secs[2], tip))):
        if s is None:
            raise InputError("could not find the airfoil at the wing's root or tip", path=path)
        out[row, axes.chord], out[row, axes.thickness] = chord_sign * s.le[0], s.le[1]
        out[row, axes.span] = axes.span_sign * e
    return out
