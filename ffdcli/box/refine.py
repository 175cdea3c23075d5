"""More control points where they are needed: a box refined by exact knot insertion.

Inserting knots into a B-spline lattice (Boehm's algorithm, :func:`ffdcli.lattice.spline.refinement_matrix`)
gives more control points and the *same* map: every embedded point keeps its parameters and its
position (to rounding, ~1e-16 of the lattice), only the basis it is expressed in changes. So a
refined box needs no new embedding (:func:`refine_embedding` recomputes the basis at the same
parameters), and a design on it starts from exactly the surface it started from before.

Two users: ``box.refine`` (:func:`refine_knots`: more sections between two span fractions, more
chordwise points between two chord fractions) and the control surfaces of
:mod:`ffdcli.parameterization.changes.control_surfaces` (the knots at a hinge and at a device's ends).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ffdcli.box.box import Box, le_basis_rows, section_weights
from ffdcli.errors import InputError
from ffdcli.lattice.embedding import Embedding, embed
from ffdcli.lattice.spline import refinement_matrix

#: Two knots closer than this (in parameter) are one knot: an insertion there is skipped.
SAME_KNOT = 1e-9


def new_knots(knots: np.ndarray, degree: int, wanted) -> np.ndarray:
    """The knots of ``wanted`` (parameters in [0, 1]) that ``knots`` lacks: those at 0 or 1, within
    :data:`SAME_KNOT` of an existing knot or of each other are dropped (a refined knot keeps
    multiplicity 1)."""
    out: list[float] = []
    have = list(np.asarray(knots, dtype=float))
    for u in np.sort(np.asarray(wanted, dtype=float).reshape(-1)):
        if not SAME_KNOT < u < 1.0 - SAME_KNOT:
            continue
        if min(abs(u - k) for k in have + out) < SAME_KNOT:
            continue
        out.append(float(u))
    return np.array(out)


def _apply_axis(P: np.ndarray, A: np.ndarray, axis: int) -> np.ndarray:
    return np.moveaxis(np.tensordot(A, P, axes=([1], axis)), 0, axis)


def refine_box(box: Box, chord=(), span=(), thickness=()) -> tuple[Box, np.ndarray | None]:
    """The box with knots inserted (parameters along the chordwise ``i``, spanwise ``j`` and
    thickness ``k`` axes of the lattice; knots it has already are skipped) and the (m', m) matrix of
    the new sections in terms of the old (None when no section was added).

    The control points are the old ones combined by the insertion matrices (the same map); the
    sections' stations, edge points and margins are combined by the spanwise matrix (a new section
    lies between its two neighbours), and the reference weights of each section's edge points are
    recomputed in its (new) corners. ``box.le_rows`` (the root and tip leading-edge points) are
    re-embedded in the refined lattice.
    """
    n, m, l = box.shape
    dims = [0, 1, 2] if box.dim == 3 else [0, 2]
    wanted = {0: chord, 1: span, 2: thickness}
    P = box.control_points
    knots = list(box.knots)
    As = {}
    for slot, axis in enumerate(dims):
        add = new_knots(knots[slot], box.degree[slot], wanted[axis])
        if add.size:
            knots[slot], As[axis] = refinement_matrix(knots[slot], box.degree[slot], add)
            P = _apply_axis(P, As[axis], axis)
    if not As:
        return box, None
    if P.shape[0] > 64 or P.shape[1] > 64 or P.shape[2] > 64:
        raise InputError(f"the refined lattice would have {list(P.shape[:3])} control points; at most 64 "
                         "per direction", key="box.refine")
    Av = As.get(1)
    out = replace(box, control_points=np.ascontiguousarray(P), knots=tuple(knots))
    if Av is not None:
        out = replace(out, base_sections=box.sections_table(), stations=Av @ box.stations, le_points=Av @ box.le_points,
                      te_points=Av @ box.te_points, margins=Av @ box.margins)
    ref = section_weights(out, out.te_points)
    out = replace(out, ref_weights=ref)
    if box.dim == 3 and box.le_rows is not None:
        rows, _ = le_basis_rows(out, box.le_rows @ box.control_points.reshape(-1, 3))
        out = replace(out, le_rows=rows)
    return out, Av


def refine_embedding(box: Box, emb: Embedding) -> Embedding:
    """The embedding ``emb`` (of the same points in the unrefined box) in the refined ``box``: the
    same parameters, the basis of the refined lattice (the same positions, to rounding)."""
    if tuple(emb.shape) == tuple(box.lattice().shape) and all(
            np.array_equal(a, b) for a, b in zip(emb.knots, box.knots, strict=True)):
        return emb
    return Embedding.from_params(box.lattice(), emb.params, emb.inside, emb.residual, tolerance=emb.tolerance)


def edges_at(box: Box, fraction: float) -> tuple[np.ndarray, np.ndarray]:
    """(le, te) (3,) the baseline leading- and trailing-edge points at span ``fraction`` (root 0, tip
    1: the station ``stations[0] + fraction (stations[-1] - stations[0])``), interpolated linearly
    between the sections the box was fitted with (:meth:`Box.sections_table`); in 2D the airfoil's."""
    if box.dim == 2:
        return box.le_points[0], box.te_points[0]
    table = box.sections_table()
    st = table[:, 0]
    fr = (st - st[0]) / (st[-1] - st[0])          # increasing (the stations decrease on a left wing)
    return np.array([np.interp(fraction, fr, table[:, c]) for c in range(1, 7)]).reshape(2, 3)


def span_fractions(box: Box, X: np.ndarray) -> np.ndarray:
    """(k,) span fraction (root 0, tip 1) of points ``X`` (k, 3): where their span coordinate lies
    between the root and tip sections the box was fitted with."""
    st = box.sections_table()[:, 0]
    return (np.asarray(X)[..., box.axes.span] - st[0]) / (st[-1] - st[0])


def lattice_params(box: Box, points: np.ndarray, what: str = "a point") -> np.ndarray:
    """(k, pdim) lattice parameters of ``points`` (k, 3); InputError when one is outside the box."""
    e = embed(box.lattice(), box.core_points(np.asarray(points, dtype=float)))
    if not e.inside.all():
        raise InputError(f"{what} lies outside the box")
    return e.params


def region_knots(box: Box, regions) -> tuple[np.ndarray, np.ndarray]:
    """(chordwise, spanwise) knots of ``box.refine`` regions (:attr:`BoxSettings.refine`): ``N``
    knots equally spaced in parameter strictly between the parameters of the region's two span
    fractions (at mid-chord) or two chord fractions (the mean over the sections)."""
    chord, span = [], []
    for what, a, b, count in regions:
        inner = np.arange(1, count + 1) / (count + 1)
        if what == "span":
            pts = [le + 0.5 * (te - le) for le, te in (edges_at(box, a), edges_at(box, b))]
            v = lattice_params(box, np.array(pts), "a refine region")[:, 1]
            v[0] = 0.0 if a <= 0 else v[0]
            v[1] = 1.0 if b >= 1 else v[1]
            span.extend(v[0] + (v[1] - v[0]) * inner)
        else:
            le, te = box.le_points, box.te_points
            ends = []
            for f in (a, b):
                u = lattice_params(box, le + f * (te - le), "a refine region")[:, 0]
                ends.append(float(np.mean(u)))
            chord.extend(ends[0] + (ends[1] - ends[0]) * inner)
    return np.array(chord), np.array(span)


def apply_refine(box: Box, emb: Embedding, regions) -> tuple[Box, Embedding]:
    """The box refined in ``regions`` (``box.refine``) and the embedding in it (the same parameters)."""
    if not regions:
        return box, emb
    chord, span = region_knots(box, regions)
    out, _ = refine_box(box, chord=chord, span=span)
    return out, refine_embedding(out, emb)
