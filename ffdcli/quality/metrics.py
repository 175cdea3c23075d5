"""Cell quality: the scaled Jacobian of every cell and the orientation convention of a mesh.

**Scaled Jacobian** (:func:`cell_quality`, one value per cell). The smallest, over the cell's
corners, of the corner's Jacobian determinant divided by the lengths of the corner's edges::

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
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit, prange

from ffdcli.jit import inlined
from ffdcli.mesh import CellBlock

#: Cells evaluated per vectorised step (bounds the temporary arrays to ~100 MB).
CHUNK = 200_000
#: 2-D cells whose nodes lie farther than this (relative to the mesh's extent) from one plane are a
#: surface in space (a wing's skin, a closed box's faces), not an airfoil mesh: they have no volume
#: and no "inverted" (:func:`in_one_plane`).
PLANAR_TOL = 1e-6

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


def raw_quality(points: np.ndarray, data: np.ndarray, ctype: str, normal: np.ndarray | None, *,
                 use_numba: bool = True) -> np.ndarray:
    """Scaled Jacobian of cells of one type in VTK order, unflipped and unclipped: a parallel numba
    kernel, or (``use_numba=False``) its NumPy reference, vectorised in chunks."""
    corners = _CORNERS[ctype]
    if use_numba:
        out = np.empty(len(data))
        plane = np.zeros(3) if normal is None else np.asarray(normal, dtype=np.float64)
        _raw_quality_nb(np.ascontiguousarray(points, dtype=np.float64), np.ascontiguousarray(data), corners,
                        float(_SCALE[ctype]), plane, out)
        return out
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


@inlined
def corner_det_length(points, data, c, corners, k, width, plane):
    """``(det, length)`` of corner ``k`` of cell ``c``: the determinant of its edges ``[e1, e2, e3]``
    (2D: ``(e1 x e2) . plane``) and the product of their lengths; the scaled Jacobian is ``scale * det /
    length``. The one home of the corner of :func:`_raw_quality_nb` and of the constraint's
    :func:`ffdcli.constraints.mesh_quality.corner_values` (no division: the callers keep their own
    rounding)."""
    p = data[c, corners[k, 0]]
    a = data[c, corners[k, 1]]
    b = data[c, corners[k, 2]]
    e10 = points[a, 0] - points[p, 0]
    e11 = points[a, 1] - points[p, 1]
    e12 = points[a, 2] - points[p, 2]
    e20 = points[b, 0] - points[p, 0]
    e21 = points[b, 1] - points[p, 1]
    e22 = points[b, 2] - points[p, 2]
    x0 = e11 * e22 - e12 * e21
    x1 = e12 * e20 - e10 * e22
    x2 = e10 * e21 - e11 * e20
    length = np.sqrt(e10 * e10 + e11 * e11 + e12 * e12) * np.sqrt(e20 * e20 + e21 * e21 + e22 * e22)
    if width == 4:
        d = data[c, corners[k, 3]]
        e30 = points[d, 0] - points[p, 0]
        e31 = points[d, 1] - points[p, 1]
        e32 = points[d, 2] - points[p, 2]
        det = x0 * e30 + x1 * e31 + x2 * e32
        length *= np.sqrt(e30 * e30 + e31 * e31 + e32 * e32)
    else:
        det = x0 * plane[0] + x1 * plane[1] + x2 * plane[2]
    return det, length


@njit(cache=True, parallel=True)
def _raw_quality_nb(points, data, corners, scale, plane, out):
    """Numba twin of the NumPy branch of :func:`raw_quality` (3 edges per corner in 3D, 2 in 2D)."""
    n_corners, width = corners.shape
    for c in prange(data.shape[0]):
        best = np.inf
        for k in range(n_corners):
            det, length = corner_det_length(points, data, c, corners, k, width, plane)
            q = det / length if length > 0 else 0.0
            if q < best:
                best = q
        out[c] = best * scale


def corner_table(ctype: str) -> tuple[np.ndarray, float]:
    """The corners of a cell type, ``(k, 4)`` rows (corner node, edge ends a, b, c) in 3D or ``(k, 3)``
    (node, a, b) in 2D, local node numbers in VTK order, and the factor ``c`` that scales the ideal
    cell to 1 (see the module docstring)."""
    return _CORNERS[ctype], float(_SCALE[ctype])


def check_types(cells: list[CellBlock], dim: int):
    """ValueError unless every block is a cell type with a quality measure, of dimension ``dim``."""
    for blk in cells:
        if blk.type not in _CORNERS:
            raise ValueError(f"no quality measure for {blk.type} cells")
        if _DIM[blk.type] != dim:
            raise ValueError(f"{blk.type} cells in a {dim}D mesh")


def cell_orientation(points: np.ndarray, cells: list[CellBlock], dim: int = 3) -> Orientation:
    """The sign convention of each block (and the 2D plane normal), from undeformed points."""
    pts = np.asarray(points, dtype=np.float64)
    check_types(cells, dim)
    normal = None
    if dim == 2:
        total = np.zeros(3)
        for blk in cells:
            d = blk.data
            for lo in range(0, len(d), CHUNK):
                c = d[lo:lo + CHUNK]
                total += np.cross(pts[c[:, 1]] - pts[c[:, 0]], pts[c[:, 2]] - pts[c[:, 0]]).sum(axis=0)
        # no cells or no area at all: the axis of least extent
        normal = plane_normal(total, np.ptp(pts, axis=0) if len(pts) else np.ones(3))
        return Orientation(np.ones(len(cells)), normal)
    return Orientation(majority_signs([raw_quality(pts, b.data, b.type, None) for b in cells]), None)


def majority_signs(raws: list[np.ndarray]) -> np.ndarray:
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
    check_types(cells, dim)
    orientation = orientation or cell_orientation(pts, cells, dim)
    parts = [np.clip(orientation.signs[i] * raw_quality(pts, blk.data, blk.type, orientation.normal),
                     -1.0, 1.0) for i, blk in enumerate(cells)]
    return np.concatenate(parts) if parts else np.zeros(0)


def plane_distance(points: np.ndarray, cells: list[CellBlock], normal: np.ndarray, origin: np.ndarray) -> float:
    """The largest distance of the cells' nodes from the plane through ``origin`` (3,) with unit
    ``normal`` (3,) (0 without cells)."""
    out = 0.0
    for blk in cells:
        d = blk.data
        for lo in range(0, len(d), CHUNK):
            nodes = np.unique(d[lo:lo + CHUNK])
            if len(nodes):
                out = max(out, float(np.abs((points[nodes] - origin) @ normal).max()))
    return out


def in_one_plane(points: np.ndarray, cells: list[CellBlock], normal: np.ndarray) -> bool:
    """True when 2-D ``cells`` lie in one plane (normal ``normal``, through their nodes' mean) to
    :data:`PLANAR_TOL` of their extent: an airfoil mesh, judged as flat cells. False: a surface in
    space, which has no volume cells to judge."""
    used = [b for b in cells if len(b)]
    if not used:
        return True
    nodes = np.unique(np.concatenate([b.data.reshape(-1) for b in used]))
    pts = np.asarray(points, dtype=np.float64)[nodes]
    size = float(np.linalg.norm(np.ptp(pts, axis=0)))
    return plane_distance(points, used, normal, pts.mean(axis=0)) <= PLANAR_TOL * max(size, np.finfo(float).tiny)


def plane_normal(total: np.ndarray, ext: np.ndarray) -> np.ndarray:
    """The 2D mesh-plane normal of :func:`cell_orientation` from the summed cell normals ``total``
    (or, with no area at all, the axis of least extent ``ext``)."""
    nrm = np.linalg.norm(total)
    normal = total / nrm if nrm > 0 else np.eye(3)[int(np.argmin(ext))]
    k = int(np.argmax(np.abs(normal)))
    if abs(normal[k]) >= 1 - 1e-12:                        # a mesh in a coordinate plane
        normal = np.sign(normal[k]) * np.eye(3)[k]
    return normal
