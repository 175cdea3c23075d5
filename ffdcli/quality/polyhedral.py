"""The quality of polyhedral cells (OpenFOAM, CGNS NGON_n/NFACE_n) as checkMesh measures it.

On the geometry of :mod:`ffdcli.polyhedra` (OpenFOAM's face centres and areas, cell centres and
volumes), per face and per cell, with OpenFOAM's definitions (``polyMeshCheck.C``,
``primitiveMeshTools.C``):

- **volume** of each cell (the tetrahedra about its face centres and estimated centre); checkMesh's
  "negative volume" cells have a volume below VSMALL (1e-300).
- **face pyramids**: the pyramid of each face with apex at the owner's (and the neighbour's) centre
  must have a positive volume (checkMesh's "face pyramids" error counts the faces whose pyramid is
  below -SMALL, 1e-15).
- **non-orthogonality** of an internal face: the angle between the line joining its two cell
  centres and its area vector, ``acos(d . S / (|d| |S|))`` in degrees. checkMesh reports the maximum
  over internal faces, the average (of the cosines, over internal faces: ESI v1912), the
  faces above 70 degrees (severe) and those at 90 or more (errors).
- **skewness** of a face: the distance from the face centre to where the line between the cell
  centres crosses the face's plane, divided by the larger of 0.2 x the cell-centre distance and the
  extent of the face in that direction; a boundary face mirrors its owner (0.4 x, the distance to
  the face's plane). checkMesh flags faces above 4.

The per-cell value the gate's rules use (``q``, in the place of the scaled Jacobian of the other
cells): the smallest, over the cell's faces, of the cosine between the face's outward area vector
and the line from the cell centre to the face centre. It is 1 for a box of any aspect ratio, a
regular tetrahedron or a right prism (every face square to its centre's line), falls as the cell is
sheared or a face tilts, and is <= 0 exactly when a face pyramid is empty or reversed (checkMesh's
face-pyramid error, which a negative volume also is). Like the scaled Jacobian it measures angles,
not aspect ratio.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ffdcli.mesh.polyhedra import (
    CHUNK,
    ROOTVSMALL,
    VSMALL,
    Polyhedra,
    cell_centres_volumes,
    face_centres_areas,
    pyramid_volumes,
)
from ffdcli.quality.report import QualityReport
from ffdcli.quality.rules import (
    DEFAULT_COLLAPSE,
    DEFAULT_ORTHO_LOSS,
    DEFAULT_ORTHO_MIN,
    DEFAULT_RELATIVE,
    DEFAULT_THRESHOLD,
    cell_rule,
    collapse_floor,
)

#: checkMesh's thresholds: severe non-orthogonality (degrees), skewness, face pyramids (SMALL).
NON_ORTH_SEVERE = 70.0
SKEW_MAX = 4.0
SMALL = 1.0e-15


@dataclass(frozen=True, eq=False)
class PolyFigures:
    """The figures of a polyhedral mesh at one geometry (arrays of length C cells or F faces).

    volumes (C,), centres (C, 3), q (C,) the gate's per-cell value (module docstring),
    non_orth (F,) degrees (0 on boundary faces), skew (F,), pyramid_errors (F,) bool."""

    volumes: np.ndarray
    centres: np.ndarray
    q: np.ndarray
    non_orth: np.ndarray
    skew: np.ndarray
    pyramid_errors: np.ndarray
    internal: np.ndarray

    def summary(self) -> dict:
        """checkMesh's figures: cells, negative volumes, face-pyramid errors, maximum and average
        non-orthogonality, severely non-orthogonal faces, maximum skewness, skewed faces."""
        inner = self.internal
        cos = np.cos(np.radians(self.non_orth[inner]))
        n_inner = int(inner.sum())
        return {
            "cells": len(self.volumes),
            "negative_volumes": int(np.count_nonzero(self.volumes < VSMALL)),
            "min_volume": float(self.volumes.min()) if len(self.volumes) else None,
            "face_pyramid_errors": int(np.count_nonzero(self.pyramid_errors)),
            "max_non_orthogonality": float(self.non_orth[inner].max()) if n_inner else 0.0,
            "average_non_orthogonality": float(np.degrees(np.arccos(np.clip(cos.mean(), -1, 1))))
            if n_inner else 0.0,
            "severely_non_orthogonal": int(np.count_nonzero(inner & (self.non_orth > NON_ORTH_SEVERE))),
            "max_skewness": float(self.skew.max()) if len(self.skew) else 0.0,
            "skewed_faces": int(np.count_nonzero(self.skew > SKEW_MAX)),
        }


def poly_figures(points: np.ndarray, poly: Polyhedra) -> PolyFigures:
    """The :class:`PolyFigures` of ``poly`` at ``points`` (N, 3)."""
    fc, fa = face_centres_areas(points, poly)
    cc, vol = cell_centres_volumes(poly, fc, fa)
    own_pyr, nei_pyr = pyramid_volumes(poly, fc, fa, cc)
    inner = poly.neighbour >= 0
    errors = (own_pyr < -SMALL) | (inner & (nei_pyr < -SMALL))
    return PolyFigures(volumes=vol, centres=cc, q=cell_q(poly, fc, fa, cc),
                       non_orth=non_orthogonality(poly, fa, cc), skew=skewness(points, poly, fc, fa, cc),
                       pyramid_errors=errors, internal=inner)


def cell_q(poly: Polyhedra, fc: np.ndarray, fa: np.ndarray, cc: np.ndarray) -> np.ndarray:
    """(C,) the gate's value of each cell (module docstring): the smallest over its faces of the
    cosine between the face's outward area vector and the line from the cell centre to the face
    centre (1 when every face is square to its centre's line; <= 0 exactly when a face pyramid is
    empty or reversed)."""
    nc = poly.n_cells
    q = np.full(nc, np.inf)
    inner = np.flatnonzero(poly.neighbour >= 0)
    mag = np.linalg.norm(fa, axis=1)
    for side, cells, faces in ((1.0, poly.owner, slice(None)), (-1.0, poly.neighbour[inner], inner)):
        d = fc[faces] - cc[cells]
        den = mag[faces] * np.linalg.norm(d, axis=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            cos = np.where(den > 0, side * np.einsum("ij,ij->i", fa[faces], d) / np.where(den > 0, den, 1.0), 0.0)
        np.minimum.at(q, cells, cos)
    return np.clip(np.where(np.isfinite(q), q, 0.0), -1.0, 1.0)


def non_orthogonality(poly: Polyhedra, fa: np.ndarray, cc: np.ndarray) -> np.ndarray:
    """(F,) degrees: ``acos(d . S / (|d| |S| + ROOTVSMALL))`` on internal faces, 0 on boundary faces
    (``polyMeshTools::faceOrthogonality``; coupled patches are treated as boundaries)."""
    out = np.zeros(poly.n_faces)
    inner = np.flatnonzero(poly.neighbour >= 0)
    d = cc[poly.neighbour[inner]] - cc[poly.owner[inner]]
    s = fa[inner]
    cos = np.einsum("ij,ij->i", d, s) / (np.linalg.norm(d, axis=1) * np.linalg.norm(s, axis=1) + ROOTVSMALL)
    out[inner] = np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))
    return out


def skewness(points: np.ndarray, poly: Polyhedra, fc: np.ndarray, fa: np.ndarray, cc: np.ndarray) -> np.ndarray:
    """(F,) ``primitiveMeshTools::faceSkewness`` (internal) and ``boundaryFaceSkewness`` (boundary)."""
    own = cc[poly.owner]
    inner = poly.neighbour >= 0
    cpf = fc - own
    d = np.empty_like(cpf)
    d[inner] = cc[poly.neighbour[inner]] - own[inner]
    bnd = ~inner
    if bnd.any():
        mag = np.linalg.norm(fa[bnd], axis=1)
        nrm = fa[bnd] / np.where(mag > 0, mag, 1.0)[:, None]     # OpenFOAM's normalised(): 0 for 0
        d[bnd] = nrm * np.einsum("ij,ij->i", nrm, cpf[bnd])[:, None]
    sv = cpf - (np.einsum("ij,ij->i", fa, cpf) / (np.einsum("ij,ij->i", fa, d) + ROOTVSMALL))[:, None] * d
    sv_mag = np.linalg.norm(sv, axis=1)
    sv_hat = sv / (sv_mag + ROOTVSMALL)[:, None]
    fd = np.where(inner, 0.2, 0.4) * np.linalg.norm(d, axis=1) + ROOTVSMALL
    # the face's extent along sv_hat: the largest |sv_hat . (p - fc)| over its nodes (by chunks of faces)
    extent = np.zeros(poly.n_faces)
    for a in range(0, poly.n_faces, CHUNK):
        b = min(poly.n_faces, a + CHUNK)
        off = poly.face_offsets[a:b + 1]
        fid = np.repeat(np.arange(a, b), np.diff(off))
        along = np.abs(np.einsum("ij,ij->i", sv_hat[fid], points[poly.face_nodes[off[0]:off[-1]]] - fc[fid]))
        extent[a:b] = np.maximum.reduceat(along, off[:-1] - off[0])
    return sv_mag / np.maximum(fd, extent)


# ----------------------------------------------------------------------------------------------
# The gate on polyhedral cells
# ----------------------------------------------------------------------------------------------

def face_rule(fig: PolyFigures, ref: PolyFigures | None, ortho_min: float, ortho_loss: float,
              relative: float) -> np.ndarray:
    """(F,) faces the gate refuses (the one home of the rule on faces, relative to the baseline
    ``ref``): an internal face whose non-orthogonality exceeds ``90 - ortho_min`` (70 degrees by
    default, checkMesh's severe threshold) and the input's worst after growing by more than
    ``ortho_loss`` degrees, or a face whose skewness exceeds checkMesh's 4 and the input's worst
    after growing to more than ``1 / relative`` (2) times its value before. So, as for cells, a mesh
    whose worst face did not get worse is never refused on its faces (the solver already ran on a
    face that bad). Without a baseline nothing is refused here."""
    if ref is None:
        return np.zeros(len(fig.non_orth), dtype=bool)
    inner = ref.internal
    worst_ortho = float(ref.non_orth[inner].max()) if inner.any() else 0.0
    worst_skew = float(ref.skew.max()) if len(ref.skew) else 0.0
    ortho = (fig.internal & (fig.non_orth > max(90.0 - ortho_min, worst_ortho))
             & (fig.non_orth - ref.non_orth > ortho_loss))
    skew = (fig.skew > max(SKEW_MAX, worst_skew)) & (fig.skew * relative > ref.skew)
    return ortho | skew


def gate_counts(poly: Polyhedra, after: np.ndarray, fig: PolyFigures, ref: PolyFigures | None, cell_rule, floor,
                *, threshold: float, relative: float, ortho_min: float, ortho_loss: float, n_worst: int) -> dict:
    """The fields of a :class:`~ffdcli.quality.QualityReport` for polyhedral cells: the cell rules
    (``cell_rule`` of the gate, with ``floor``) on the per-cell value ``q``, the face rule
    (:func:`face_rule`), checkMesh's figures after and before under ``polyhedral``."""
    q = fig.q
    qb = None if ref is None else ref.q
    inverted, below, bad_in, new_inv, worse, failed = cell_rule(q, qb, threshold, relative, floor)
    faces_failed = face_rule(fig, ref, ortho_min, ortho_loss, relative)
    out = {"n_inverted": int(inverted.sum()), "n_below": int(below.sum()),
           "min_after": float(q.min()) if len(q) else None, "min_before": None}
    shapes = _cell_shapes(poly)

    def rows(index, values, coords, with_failed):
        got = []
        for c in index.tolist():
            row = {"cell": int(c), "type": shapes[c], "quality": float(values[c])}
            if with_failed is not None:
                row["quality_before"] = None if qb is None else float(qb[c])
            row["centroid"] = coords[c].tolist()
            if with_failed is not None:
                row["failed"] = bool(with_failed[c])
            got.append(row)
        return got

    if ref is not None:
        out.update(n_inverted_before=int(bad_in.sum()), n_below_before=int((~bad_in & (qb < threshold)).sum()),
                   n_input_bad=int(bad_in.sum()), n_new_inverted=int(new_inv.sum()), n_worse=int(worse.sum()),
                   min_before=float(qb.min()) if len(qb) else None)
        if bad_in.any():
            idx = np.flatnonzero(bad_in)
            out["input_bad"] = rows(idx[np.argsort(qb[idx], kind="stable")][:n_worst], qb, ref.centres, None)
    out["worst"] = rows(np.argsort(q, kind="stable")[:n_worst], q, fig.centres, failed)
    worst_faces = np.flatnonzero(faces_failed)[:n_worst]
    out["n_faces_failed"] = int(faces_failed.sum())
    out["polyhedral"] = {
        "after": fig.summary(), "before": None if ref is None else ref.summary(),
        "faces_failed": int(faces_failed.sum()),
        "worst_faces": [{"face": int(f), "non_orthogonality": float(fig.non_orth[f]),
                         "non_orthogonality_before": float(ref.non_orth[f]), "skewness": float(fig.skew[f]),
                         "skewness_before": float(ref.skew[f]), "owner": int(poly.owner[f])}
                        for f in worst_faces.tolist()] if ref is not None else [],
    }
    return out


def _cell_shapes(poly: Polyhedra) -> _Shapes:
    return _Shapes(poly)


class _Shapes:
    """The shape name of a cell, computed when asked (only for the few cells a report lists)."""

    def __init__(self, poly: Polyhedra):
        self.poly = poly
        self.offsets, self.faces = None, None

    def __getitem__(self, c: int) -> str:
        if self.offsets is None:
            self.offsets, self.faces = self.poly.cell_faces()
        faces = self.faces[self.offsets[c]:self.offsets[c + 1]]
        size = np.sort(self.poly.face_sizes[faces]).tolist()
        return {(4, 4, 4, 4, 4, 4): "hexahedron", (3, 3, 4, 4, 4): "prism", (3, 3, 3, 3, 4): "pyramid",
                (3, 3, 3, 3): "tetrahedron"}.get(tuple(size), f"polyhedron ({len(size)} faces)")


def check_quality_poly(mesh, points_after: np.ndarray | None = None, threshold: float = DEFAULT_THRESHOLD,
                       points_before: np.ndarray | None = None, *, relative: float = DEFAULT_RELATIVE,
                       collapse: float = DEFAULT_COLLAPSE, ortho_min: float = DEFAULT_ORTHO_MIN,
                       ortho_loss: float = DEFAULT_ORTHO_LOSS, orthogonality: bool = True, n_worst: int = 10,
                       reference: PolyFigures | None = None, design_map=None) -> QualityReport:
    """:func:`ffdcli.quality.check_quality` of a mesh of polyhedral cells (``mesh.polyhedra``): the
    same arguments and report, the cells judged on ``q`` (module docstring) by the gate's cell rule,
    the faces by :func:`face_rule`, checkMesh's figures in ``report.polyhedral``. ``reference``: the
    :func:`poly_reference` of the geometry before. ``orthogonality`` and ``design_map`` are not used
    (the faces' non-orthogonality is always computed; no cell is excused as shaped by the design)."""
    poly = mesh.polyhedra
    if points_after is None:
        after, before = mesh.points, points_before
    else:
        after = np.asarray(points_after, dtype=np.float64)
        before = mesh.points if points_before is None else np.asarray(points_before, dtype=np.float64)
    if after.shape != mesh.points.shape:
        raise ValueError(f"points {after.shape} do not match the mesh {mesh.points.shape}")
    kw = {"threshold": float(threshold), "relative": float(relative), "ortho_min": float(ortho_min),
          "ortho_loss_max": float(ortho_loss), "collapse": float(collapse)}
    if poly.n_cells == 0:
        return QualityReport(0, 0, 0, min_before=None, min_after=None, **kw)
    ref = None
    if before is not None:
        ref = reference if reference is not None else poly_reference(mesh, before)
    fig = ref if (ref is not None and after is before) else poly_figures(after, poly)
    floor = None
    if ref is not None:
        valid = ref.q > 0
        floor = collapse_floor(float(ref.q[valid].min()) if valid.any() else None, collapse)
    out = gate_counts(poly, after, fig, ref, cell_rule, floor, threshold=threshold, relative=relative,
                      ortho_min=ortho_min, ortho_loss=ortho_loss, n_worst=n_worst)
    return QualityReport(poly.n_cells, **out, **kw)


def poly_reference(mesh, points: np.ndarray | None = None) -> PolyFigures:
    """The gate's reference of a polyhedral mesh at ``points`` (default its own): its figures."""
    return poly_figures(mesh.points if points is None else np.asarray(points, dtype=np.float64), mesh.polyhedra)
