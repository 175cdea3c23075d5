"""Cell quality: the scaled Jacobian of every cell, and the gate of ``ffd deform`` / ``ffd check``.

**Measure.** The scaled Jacobian of a cell is the smallest, over its corners, of the corner's
Jacobian determinant divided by the lengths of the corner's edges::

    q = min over corners  c * det[e1, e2, e3] / (|e1| |e2| |e3|)        (3D)
    q = min over corners  c * n . (e1 x e2) / (|e1| |e2|)               (2D, n the mesh-plane normal)

with the corner's edges ``e`` in the order that makes the determinant positive for a cell in VTK
node order, and ``c`` scales the ideal cell to 1: 1 for hexahedra and quads, sqrt(2) for tetrahedra
and pyramids (regular tetrahedron, pyramid with all edges equal), 2/sqrt(3) for wedges and
triangles (equilateral triangles). Values are clipped to [-1, 1]. ``q`` is in [-1, 1]: 1 for an
ideal cell, 0 for a degenerate one (a collapsed corner, or an edge of zero length), negative for an
inverted cell. It measures angles, not aspect ratio: a stretched boundary-layer hexahedron or
prism with right angles has q = 1. Pyramids use their four base corners (an apex pushed through the
base inverts them). The corners are those of the VTK reference cells (hexahedron: base 0-1-2-3
counter-clockwise seen from 4-7; wedge: 0 (0,0,0), 1 (1,0,0), 2 (0,1,0), 3 above 0; pyramid: base
0-1-2-3 counter-clockwise seen from the apex 4; tetrahedron: det[p1-p0, p2-p0, p3-p0] > 0).

**Orientation.** Some writers store a cell type in the mirrored node order (wedges especially). A
block whose cells are mostly negative in the VTK convention is taken to use the mirrored order, and
its sign is flipped (:func:`cell_orientation`, computed once from the undeformed mesh and used for
the deformed one too), so a mesh is judged in its own convention. In 2D the mesh-plane normal is
oriented so that most cells are positive.

**The gate** (:func:`check_quality`). A cell *fails* when after the deformation

- it is inverted or degenerate: ``q_after <= 0``; or
- it is below the threshold and the deformation made it markedly worse:
  ``q_after < threshold`` and ``q_after < relative * q_before`` (default ``relative`` = 0.5).

The second rule lets a mesh whose cells were already poor (anisotropic boundary-layer
tetrahedra have q ~ 1e-3) deform without being blocked, unless their quality halves. Without a
mesh before (``ffd check``) the rule is just ``q < threshold``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ffdcli.mesh import CellBlock, Mesh

#: Default threshold of the scaled Jacobian below which a cell that got worse fails the gate.
DEFAULT_THRESHOLD = 0.05
#: A cell below the threshold fails only if its quality dropped below this fraction of before.
DEFAULT_RELATIVE = 0.5
#: Cells evaluated per vectorised step (bounds the temporary arrays to ~100 MB).
CHUNK = 200_000

# Corners: (corner node, edge-end a, edge-end b, edge-end c) with det[a-p, b-p, c-p] > 0 for a
# cell in VTK order. 2D corners: (node, a, b) with n . ((a-p) x (b-p)) > 0.
_CORNERS = {
    "tetra": np.array([[0, 1, 2, 3], [1, 2, 0, 3], [2, 0, 1, 3], [3, 0, 2, 1]]),
    "hexahedron": np.array([[0, 1, 3, 4], [1, 2, 0, 5], [2, 3, 1, 6], [3, 0, 2, 7],
                            [4, 7, 5, 0], [5, 4, 6, 1], [6, 5, 7, 2], [7, 6, 4, 3]]),
    "wedge": np.array([[0, 1, 2, 3], [1, 2, 0, 4], [2, 0, 1, 5],
                       [3, 5, 4, 0], [4, 3, 5, 1], [5, 4, 3, 2]]),
    "pyramid": np.array([[0, 1, 3, 4], [1, 2, 0, 4], [2, 3, 1, 4], [3, 0, 2, 4]]),
    "triangle": np.array([[0, 1, 2], [1, 2, 0], [2, 0, 1]]),
    "quad": np.array([[0, 1, 3], [1, 2, 0], [2, 3, 1], [3, 0, 2]]),
}
_SCALE = {"tetra": np.sqrt(2.0), "hexahedron": 1.0, "wedge": 2.0 / np.sqrt(3.0),
          "pyramid": np.sqrt(2.0), "triangle": 2.0 / np.sqrt(3.0), "quad": 1.0}
_DIM = {"tetra": 3, "hexahedron": 3, "wedge": 3, "pyramid": 3, "triangle": 2, "quad": 2}


@dataclass
class Orientation:
    """How to read the sign of each block's Jacobians (see the module docstring).

    signs
        One +1/-1 per cell block: -1 where the block uses the mirrored node order.
    normal
        2D only: the unit normal of the mesh plane, oriented so that most cells are positive.
    """

    signs: np.ndarray
    normal: np.ndarray | None = None


def _raw_quality(points: np.ndarray, data: np.ndarray, ctype: str, normal: np.ndarray | None) -> np.ndarray:
    """Scaled Jacobian of cells of one type in VTK order, unflipped and unclipped (vectorised)."""
    corners = _CORNERS[ctype]
    out = np.empty(len(data))
    for lo in range(0, len(data), CHUNK):
        c = data[lo:lo + CHUNK]
        p = points[c[:, corners[:, 0]]]                       # (n, corners, 3)
        e = [points[c[:, corners[:, k]]] - p for k in range(1, corners.shape[1])]
        lengths = np.prod([np.sqrt(np.einsum("nck,nck->nc", v, v)) for v in e], axis=0)
        if len(e) == 3:
            det = np.einsum("nck,nck->nc", np.cross(e[0], e[1]), e[2])
        else:
            det = np.cross(e[0], e[1]) @ normal
        with np.errstate(divide="ignore", invalid="ignore"):
            q = np.where(lengths > 0, det / np.where(lengths > 0, lengths, 1.0), 0.0)
        out[lo:lo + CHUNK] = q.min(axis=1) * _SCALE[ctype]
    return out


def _check_types(cells: list[CellBlock], dim: int):
    for blk in cells:
        if blk.type not in _CORNERS:
            raise ValueError(f"no quality measure for {blk.type} cells")
        if _DIM[blk.type] != dim:
            raise ValueError(f"{blk.type} cells in a {dim}D mesh")


def cell_orientation(points: np.ndarray, cells: list[CellBlock], dim: int = 3) -> Orientation:
    """The sign convention of each block (and the 2D plane normal), from undeformed points."""
    pts = np.asarray(points, dtype=np.float64)
    _check_types(cells, dim)
    normal = None
    if dim == 2:
        total = np.zeros(3)
        for blk in cells:
            d = blk.data
            for lo in range(0, len(d), CHUNK):
                c = d[lo:lo + CHUNK]
                total += np.cross(pts[c[:, 1]] - pts[c[:, 0]], pts[c[:, 2]] - pts[c[:, 0]]).sum(axis=0)
        nrm = np.linalg.norm(total)
        if nrm > 0:
            normal = total / nrm
        else:          # no cells or no area at all: the axis of least extent
            ext = np.ptp(pts, axis=0) if len(pts) else np.ones(3)
            normal = np.eye(3)[int(np.argmin(ext))]
        k = int(np.argmax(np.abs(normal)))
        if abs(normal[k]) >= 1 - 1e-12:                        # a mesh in a coordinate plane
            normal = np.sign(normal[k]) * np.eye(3)[k]
        return Orientation(np.ones(len(cells)), normal)
    return Orientation(_majority_signs([_raw_quality(pts, b.data, b.type, None) for b in cells]), None)


def _majority_signs(raws: list[np.ndarray]) -> np.ndarray:
    """-1 for a block whose cells are mostly negative, else +1."""
    return np.array([-1.0 if np.count_nonzero(q < 0) > np.count_nonzero(q > 0) else 1.0 for q in raws])


def cell_quality(points: np.ndarray, cells: list[CellBlock], dim: int = 3, *,
                 orientation: Orientation | None = None) -> np.ndarray:
    """Scaled Jacobian of every cell, in [-1, 1], for the blocks in order (concatenated).

    Parameters
    ----------
    points
        (N, 3) point coordinates.
    cells
        Interior cell blocks: tetra, hexahedron, wedge, pyramid (``dim`` 3) or triangle, quad
        (``dim`` 2), VTK node order.
    dim
        Topological dimension of the cells.
    orientation
        From :func:`cell_orientation` of the undeformed mesh; default: computed from ``points``.

    Returns
    -------
    (n_cells,) float64: 1 ideal, 0 degenerate, < 0 inverted (see the module docstring).
    """
    pts = np.asarray(points, dtype=np.float64)
    _check_types(cells, dim)
    orientation = orientation or cell_orientation(pts, cells, dim)
    parts = [np.clip(orientation.signs[i] * _raw_quality(pts, blk.data, blk.type, orientation.normal),
                     -1.0, 1.0) for i, blk in enumerate(cells)]
    return np.concatenate(parts) if parts else np.zeros(0)


@dataclass
class QualityReport:
    """The result of :func:`check_quality`.

    count
        Cells checked. ``n_inverted``: cells with q <= 0 (inverted or degenerate);
        ``n_below``: the other failing cells (below the threshold and made worse, see the module
        docstring). ``min_before`` / ``min_after``: the smallest q (None when unknown / no cells).
    worst
        Up to ``n_worst`` cells of smallest q after: ``{"cell": index in the concatenation of
        the mesh's cell blocks, "type", "quality", "quality_before", "centroid": [x, y, z] after,
        "failed": bool}``.
    """

    count: int
    n_inverted: int
    n_below: int
    threshold: float
    relative: float
    min_before: float | None
    min_after: float | None
    worst: list[dict] = field(default_factory=list)

    @property
    def n_failed(self) -> int:
        return self.n_inverted + self.n_below

    @property
    def ok(self) -> bool:
        return self.n_failed == 0

    def to_dict(self) -> dict:
        return {"cells": self.count, "inverted": self.n_inverted, "below_threshold": self.n_below,
                "threshold": self.threshold, "relative": self.relative, "min_before": self.min_before,
                "min_after": self.min_after, "ok": self.ok, "worst": self.worst}

    def summary(self) -> str:
        """One line for people: counts and min quality before/after."""
        before = "" if self.min_before is None else f"{self.min_before:.3g} before, "
        after = "n/a" if self.min_after is None else f"{self.min_after:.3g}"
        return (f"cell quality (scaled Jacobian): min {before}{after} after; {self.count} cells, "
                f"{self.n_inverted} inverted, {self.n_below} below {self.threshold:g}")

    def describe_worst(self, n: int = 5) -> str:
        """The worst failing cells, one per line: id, type, quality and where."""
        lines = []
        for w in [w for w in self.worst if w["failed"]][:n]:
            c = ", ".join(f"{v:.6g}" for v in w["centroid"])
            before = "" if w["quality_before"] is None else f" (before {w['quality_before']:.3g})"
            lines.append(f"  cell {w['cell']} ({w['type']}): quality {w['quality']:.3g}{before} at ({c})")
        return "\n".join(lines)


def check_quality(mesh: Mesh, points_after: np.ndarray | None = None, threshold: float = DEFAULT_THRESHOLD,
                  points_before: np.ndarray | None = None, *, relative: float = DEFAULT_RELATIVE,
                  n_worst: int = 10) -> QualityReport:
    """Check the cells of ``mesh`` at ``points_after`` (default: its own points).

    ``points_before`` (default: ``mesh.points`` when ``points_after`` is given, else nothing)
    gives the reference quality and orientation; without it a cell fails when q <= 0 or
    q < threshold. A mesh without interior cells (surface only) gives an empty report that passes.
    """
    if points_after is None:
        after, before = mesh.points, points_before
    else:
        after = np.asarray(points_after, dtype=np.float64)
        before = mesh.points if points_before is None else np.asarray(points_before, dtype=np.float64)
    if after.shape != mesh.points.shape:
        raise ValueError(f"points {after.shape} do not match the mesh {mesh.points.shape}")
    cells = [b for b in mesh.cells if len(b)]
    ref = after if before is None else before
    _check_types(cells, mesh.dim)
    # one pass over the reference points gives both the orientation and the quality before
    normal = cell_orientation(ref, cells, 2).normal if mesh.dim == 2 else None
    raws = [_raw_quality(ref, b.data, b.type, normal) for b in cells]
    signs = np.ones(len(cells)) if mesh.dim == 2 else _majority_signs(raws)
    q_ref = (np.concatenate([np.clip(sg * r, -1.0, 1.0) for sg, r in zip(signs, raws, strict=True)])
             if raws else np.zeros(0))
    del raws
    q = q_ref if before is None else cell_quality(after, cells, mesh.dim,
                                                   orientation=Orientation(signs, normal))
    qb = None if before is None else q_ref
    if len(q) == 0:
        return QualityReport(0, 0, 0, float(threshold), float(relative), None, None, [])
    inverted = q <= 0
    below = ~inverted & (q < threshold)
    if qb is not None:
        below &= q < relative * qb
    failed = inverted | below
    worst = np.argsort(q, kind="stable")[:n_worst]
    starts = np.cumsum([0] + [len(b) for b in cells])
    blk = np.searchsorted(starts, worst, side="right") - 1
    rows = []
    for w, k in zip(worst.tolist(), blk.tolist(), strict=True):
        ids = cells[k].data[w - starts[k]]
        rows.append({"cell": int(w), "type": cells[k].type, "quality": float(q[w]),
                     "quality_before": None if qb is None else float(qb[w]),
                     "centroid": after[ids].mean(axis=0).tolist(), "failed": bool(failed[w])})
    return QualityReport(len(q), int(inverted.sum()), int(below.sum()), float(threshold), float(relative),
                         None if qb is None else float(qb.min()), float(q.min()), rows)
