"""Cell quality and orthogonality, and the one quality gate of ``ffd deform`` and ``ffd check``.

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

**Orthogonality** (:func:`node_orthogonality`, one value per node, degrees): what SU2 reports as
"Orthogonality" for its vertex-centred finite volumes. Each edge i-j has a dual face (the median
dual: triangles through the edge midpoint, the centroids of the two cell faces at the edge and the
cell centroid, summed over the cells around the edge); the edge's angle is ``90 - angle(dual-face
normal, x_j - x_i)``, and the node's value is the area-weighted mean over its edges. 90 is ideal;
SU2's own guidance is that values below about 20 degrees are poor. It sees what the scaled
Jacobian misses: a sheared stack of thin boundary-layer cells keeps q but loses orthogonality.

**The gate** (:func:`check_quality` gives the counts, :func:`enforce` applies them). With a mesh
before (``ffd deform``):

- *input problem, exit 2*: a cell already inverted or degenerate in the INPUT (``q_before <= 0``) is
  the mesh's problem, not the design's: :func:`enforce` raises :class:`InputError` naming the cell
  and where it is (with ``force``: only reported; such cells are not counted as failures below);
- a cell *fails* when the design inverts it: ``q_after <= 0 < q_before``;
- or when the design made it markedly worse: ``q_after < threshold`` (0.05) and ``q_after <
  relative * q_before`` (``relative`` 0.5) and ``q_after < min(collapse, min q_before)`` (``collapse``
  0.01; ``min q_before`` the input mesh's worst cell). So a mesh whose worst cell did not get worse
  is never refused on the scaled Jacobian (the solver already ran on a cell that bad), and a cell
  squeezed from 0.11 to 0.039 by a tip-chord change is counted (below 0.05) but not refused: the
  scaled Jacobian refuses cells on their way to collapse, the orthogonality rule below judges the
  shape a finite-volume solver sees;
- a node *fails* when its orthogonality falls below ``ortho_min`` (20 degrees) after losing more than
  ``ortho_loss`` (10 degrees) from the input.

- *shaped by the design* (``ffd deform`` gives the gate the design's own map, ``design_map``): a cell
  or node that would fail by the two rules above and lies near the wall is compared with what the
  design's own map makes of it (the input nodes moved by the FFD map linearised at the nearest
  surface node, :func:`ffdcli.app.pipeline.design_map`). When the volume's result keeps at least
  ``DESIGN_SLACK`` (0.9) x that cell's scaled Jacobian, or its orthogonality is at most
  ``DESIGN_SLACK_DEG`` (2 degrees) below the map's, the change of shape is the one the design asks
  for (a tip chord halved squeezes the cells on the tip's faces whatever the volume does), not a
  failure of the volume motion: it is counted and reported as *shaped by the design*, not refused.
  An inverted cell is always refused.

Without a mesh before (``ffd check``) nothing is relative: the counts are of the mesh as it is.

**One set of words.** Both commands print the same counts of the mesh AS WRITTEN under the same
words (:meth:`QualityReport.summary`): ``N inverted or degenerate`` (q <= 0) and ``N below 0.05``
(0 < q < threshold) of the cells, the minimum q, the minimum orthogonality and ``N nodes below 20
deg``; ``ffd check`` of a written mesh repeats the "after" numbers of the ``ffd deform`` that wrote
it. ``ffd deform`` adds the "before" values and what the gate refuses on: ``inverted by the design``,
``made worse`` and ``nodes that lost orthogonality``; the refusal message states the rule.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numba import njit, prange

from ffdcli.errors import InputError, QualityError
from ffdcli.mesh import CellBlock, Mesh
from ffdcli.mesh.idsets import unique_ids

#: Default threshold of the scaled Jacobian below which a cell that got worse fails the gate.
DEFAULT_THRESHOLD = 0.05
#: A cell below the threshold fails only if its quality dropped below this fraction of before.
DEFAULT_RELATIVE = 0.5
#: ... and only if it also falls below this (or below the input mesh's worst cell, if lower).
DEFAULT_COLLAPSE = 0.01
#: A node fails when its orthogonality (degrees) falls below this ...
DEFAULT_ORTHO_MIN = 20.0
#: ... after losing more than this many degrees from the input mesh.
DEFAULT_ORTHO_LOSS = 10.0
#: A failing cell is the design's own (not refused) when its quality is at least this fraction of
#: what the design's FFD map itself makes of it ...
DESIGN_SLACK = 0.9
#: ... and a failing node when its orthogonality is at most this many degrees below the map's.
DESIGN_SLACK_DEG = 2.0
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


def _raw_quality(points: np.ndarray, data: np.ndarray, ctype: str, normal: np.ndarray | None, *,
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


@njit(cache=True, parallel=True)
def _raw_quality_nb(points, data, corners, scale, plane, out):
    """Numba twin of the NumPy branch of :func:`_raw_quality` (3 edges per corner in 3D, 2 in 2D)."""
    n_corners, width = corners.shape
    for c in prange(data.shape[0]):
        best = np.inf
        for k in range(n_corners):
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
            q = det / length if length > 0 else 0.0
            if q < best:
                best = q
        out[c] = best * scale


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
        # no cells or no area at all: the axis of least extent
        normal = _plane_normal_of(total, np.ptp(pts, axis=0) if len(pts) else np.ones(3))
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


# ----------------------------------------------------------------------------------------------
# Orthogonality of the dual grid (what SU2 computes)
# ----------------------------------------------------------------------------------------------

# Faces of the 3D cells (local nodes, VTK order; the orientation of a face does not matter here).
_FACES = {
    "tetra": [(0, 1, 2), (0, 1, 3), (1, 2, 3), (0, 2, 3)],
    "hexahedron": [(0, 1, 2, 3), (4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6), (3, 0, 4, 7)],
    "wedge": [(0, 1, 2), (3, 4, 5), (0, 1, 4, 3), (1, 2, 5, 4), (2, 0, 3, 5)],
    "pyramid": [(0, 1, 2, 3), (0, 1, 4), (1, 2, 4), (2, 3, 4), (3, 0, 4)],
}
# VTK reference cells (positive orientation), used to orient the edge tables once.
_REFERENCE = {
    "tetra": [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]],
    "hexahedron": [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]],
    "wedge": [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [0, 1, 1]],
    "pyramid": [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0.5, 0.5, 1]],
    "triangle": [[0, 0, 0], [1, 0, 0], [0, 1, 0]],
    "quad": [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]],
}


def _face_table(ctype: str) -> tuple[np.ndarray, np.ndarray]:
    """(F, 4) local face nodes padded with -1, and (F,) node counts (2D: the cell is its one face)."""
    faces = _FACES.get(ctype) or [tuple(range(len(_REFERENCE[ctype])))]
    tab = np.full((len(faces), 4), -1, dtype=np.int64)
    for i, f in enumerate(faces):
        tab[i, :len(f)] = f
    return tab, np.array([len(f) for f in faces], dtype=np.int64)


def _dual_facets(p: np.ndarray, faces: np.ndarray, counts: np.ndarray, table: np.ndarray,
                 normal: np.ndarray | None) -> np.ndarray:
    """Dual-face normals of the local edges of cells ``p`` (n, k, 3): (n, E, 3), oriented a -> b.

    3D: the two triangles (edge midpoint, centroid of face f1, cell centroid) and (midpoint, cell
    centroid, centroid of face f2); 2D: the segment from the edge midpoint to the cell centroid,
    turned by 90 degrees in the mesh plane (``normal``)."""
    centre = p.mean(axis=1)[:, None, :]                                       # (n, 1, 3)
    mid = 0.5 * (p[:, table[:, 0]] + p[:, table[:, 1]])                       # (n, E, 3)
    if normal is not None:
        return np.cross(centre - mid, normal)
    fc = np.stack([p[:, faces[f, :counts[f]]].mean(axis=1) for f in range(len(faces))], axis=1)
    a, b = fc[:, table[:, 2]] - mid, fc[:, table[:, 3]] - mid
    c = centre - mid
    return 0.5 * (np.cross(a, c) + np.cross(c, b))


def _edge_table(ctype: str) -> np.ndarray:
    """(E, 4) rows (a, b, f1, f2): the local edges of a cell type and, in 3D, the two faces that
    share each edge, ordered so that the dual-face normal points from a to b in a positive cell."""
    faces, counts = _face_table(ctype)
    if ctype in ("triangle", "quad"):
        k = counts[0]
        table = np.array([[i, (i + 1) % k, 0, 0] for i in range(k)], dtype=np.int64)
        ref = np.asarray(_REFERENCE[ctype], float)[None]
        n = _dual_facets(ref, faces, counts, table, np.array([0.0, 0.0, 1.0]))[0]
        assert np.all(np.einsum("ek,ek->e", n, ref[0, table[:, 1]] - ref[0, table[:, 0]]) > 0)
        return table
    shared: dict[tuple[int, int], list[int]] = {}
    for f, nodes in enumerate(_FACES[ctype]):
        for i in range(len(nodes)):
            a, b = nodes[i], nodes[(i + 1) % len(nodes)]
            shared.setdefault((min(a, b), max(a, b)), []).append(f)
    table = np.array([[a, b, *fs] for (a, b), fs in sorted(shared.items())], dtype=np.int64)
    ref = np.asarray(_REFERENCE[ctype], float)[None]
    n = _dual_facets(ref, faces, counts, table, None)[0]
    flip = np.einsum("ek,ek->e", n, ref[0, table[:, 1]] - ref[0, table[:, 0]]) < 0
    table[flip] = table[flip][:, [0, 1, 3, 2]]
    return table


_EDGES = {t: _edge_table(t) for t in _REFERENCE}


@dataclass(frozen=True)
class EdgeTopology:
    """The edges of a mesh and, per cell block, which edge each local edge of a cell is.

    edges
        (E, 2) node pairs, lower id first.
    ids, signs
        Per block: (n, e) edge index of each local edge, and +1 where the local edge runs from the
        lower to the higher node id, -1 otherwise.
    """

    edges: np.ndarray
    ids: tuple
    signs: tuple


def edge_topology(cells: list[CellBlock], n_points: int, *, use_numba: bool = True) -> EdgeTopology:
    """Number the edges of ``cells`` (shared by the cells around them). Linear time with numba."""
    shapes = [(len(blk), len(_EDGES[blk.type])) for blk in cells]
    total = sum(a * b for a, b in shapes)
    lo, hi = np.empty(total, np.int64), np.empty(total, np.int64)
    sign_parts, start = [], 0
    for blk, (n, ne) in zip(cells, shapes, strict=True):
        t = _EDGES[blk.type]
        sign = np.empty((n, ne), np.int8)
        if use_numba:
            _edge_pairs_nb(np.ascontiguousarray(blk.data), t, lo[start:start + n * ne], hi[start:start + n * ne], sign)
        else:
            a, b = blk.data[:, t[:, 0]], blk.data[:, t[:, 1]]
            lo[start:start + n * ne] = np.minimum(a, b).ravel()
            hi[start:start + n * ne] = np.maximum(a, b).ravel()
            sign[:] = np.where(a < b, 1, -1)
        sign_parts.append(sign)
        start += n * ne
    if use_numba:
        eid, elo, ehi = _number_edges_nb(lo, hi, int(n_points))
    else:
        key, eid = np.unique(lo * np.int64(n_points) + hi, return_inverse=True)
        elo, ehi = key // n_points, key % n_points
    ids, start = [], 0
    for shape in shapes:
        size = shape[0] * shape[1]
        ids.append(eid[start:start + size].reshape(shape))
        start += size
    return EdgeTopology(np.column_stack([elo, ehi]), tuple(ids), tuple(sign_parts))


@njit(cache=True, parallel=True)
def _edge_pairs_nb(data, table, lo, hi, sign):
    """(lo, hi) node pairs of the local edges of every cell (flat, cell-major) and their direction."""
    ne = table.shape[0]
    for c in prange(data.shape[0]):
        for e in range(ne):
            a = data[c, table[e, 0]]
            b = data[c, table[e, 1]]
            lo[c * ne + e] = min(a, b)
            hi[c * ne + e] = max(a, b)
            sign[c, e] = 1 if a < b else -1


@njit(cache=True)
def _number_edges_nb(lo, hi, n_points):
    """Edge id of every (lo, hi) pair: a counting sort by ``lo``, then the distinct ``hi`` of each
    node's (short) list. Ids are in order of (lo, first appearance of hi)."""
    n = lo.size
    start = np.zeros(n_points + 1, np.int64)
    for p in range(n):
        start[lo[p] + 1] += 1
    for i in range(n_points):
        start[i + 1] += start[i]
    fill = start[:-1].copy()
    order = np.empty(n, np.int64)
    for p in range(n):
        order[fill[lo[p]]] = p
        fill[lo[p]] += 1
    eid = np.empty(n, np.int64)
    elo = np.empty(n, np.int64)
    ehi = np.empty(n, np.int64)
    m = 0
    for i in range(n_points):
        first = m
        for q in range(start[i], start[i + 1]):
            p = order[q]
            h = hi[p]
            found = -1
            for e in range(first, m):
                if ehi[e] == h:
                    found = e
                    break
            if found < 0:
                elo[m] = i
                ehi[m] = h
                found = m
                m += 1
            eid[p] = found
    return eid, elo[:m].copy(), ehi[:m].copy()


def edge_normals(points: np.ndarray, cells: list[CellBlock], topology: EdgeTopology,
                 orientation: Orientation, *, use_numba: bool = True) -> np.ndarray:
    """(E, 3) dual-face area normal of every edge (sum over the cells around it), pointing from the
    lower to the higher node id. A numba kernel (one pass over the cells); ``use_numba=False``: the
    NumPy reference, vectorised in chunks of cells."""
    n_edges = len(topology.edges)
    pts = np.ascontiguousarray(points, dtype=np.float64)
    plane = np.zeros(3) if orientation.normal is None else np.asarray(orientation.normal, dtype=np.float64)
    acc = np.zeros((n_edges, 3))
    for b, blk in enumerate(cells):
        table = _EDGES[blk.type]
        faces, counts = _face_table(blk.type)
        sign = float(orientation.signs[b])
        if use_numba:
            _edge_normals_nb(pts, blk.data, table, faces, counts, sign, orientation.normal is not None, plane,
                             topology.ids[b], topology.signs[b], acc)
            continue
        for lo in range(0, len(blk), CHUNK):
            c = blk.data[lo:lo + CHUNK]
            nrm = _dual_facets(pts[c], faces, counts, table, orientation.normal)      # (n, E, 3)
            nrm *= (sign * topology.signs[b][lo:lo + CHUNK])[:, :, None]
            ids = topology.ids[b][lo:lo + CHUNK].ravel()
            for k in range(3):
                acc[:, k] += np.bincount(ids, weights=nrm[..., k].ravel(), minlength=n_edges)
    return acc


@njit(cache=True)
def _edge_normals_nb(points, data, table, faces, counts, sign, planar, plane, ids, signs, acc):
    """Numba twin of the NumPy branch of :func:`edge_normals` for one block (adds into ``acc``)."""
    n_cells, k = data.shape
    n_faces = faces.shape[0]
    fc = np.empty((n_faces, 3))
    centre = np.empty(3)
    for c in range(n_cells):
        for d in range(3):
            t = 0.0
            for v in range(k):
                t += points[data[c, v], d]
            centre[d] = t / k
        if not planar:
            for f in range(n_faces):
                for d in range(3):
                    t = 0.0
                    for v in range(counts[f]):
                        t += points[data[c, faces[f, v]], d]
                    fc[f, d] = t / counts[f]
        for e in range(table.shape[0]):
            a = data[c, table[e, 0]]
            b = data[c, table[e, 1]]
            m0 = 0.5 * (points[a, 0] + points[b, 0])
            m1 = 0.5 * (points[a, 1] + points[b, 1])
            m2 = 0.5 * (points[a, 2] + points[b, 2])
            c0, c1, c2 = centre[0] - m0, centre[1] - m1, centre[2] - m2
            if planar:
                n0 = c1 * plane[2] - c2 * plane[1]
                n1 = c2 * plane[0] - c0 * plane[2]
                n2 = c0 * plane[1] - c1 * plane[0]
            else:
                f1 = table[e, 2]
                f2 = table[e, 3]
                a0, a1, a2 = fc[f1, 0] - m0, fc[f1, 1] - m1, fc[f1, 2] - m2
                b0, b1, b2 = fc[f2, 0] - m0, fc[f2, 1] - m1, fc[f2, 2] - m2
                # 0.5 * (a x c + c x b) = 0.5 * (a - b) x c
                d0, d1, d2 = a0 - b0, a1 - b1, a2 - b2
                n0 = 0.5 * (d1 * c2 - d2 * c1)
                n1 = 0.5 * (d2 * c0 - d0 * c2)
                n2 = 0.5 * (d0 * c1 - d1 * c0)
            s = sign * signs[c, e]
            i = ids[c, e]
            acc[i, 0] += s * n0
            acc[i, 1] += s * n1
            acc[i, 2] += s * n2


def edge_orthogonality(points: np.ndarray, cells: list[CellBlock], dim: int = 3, *,
                       orientation: Orientation | None = None, topology: EdgeTopology | None = None,
                       use_numba: bool = True) -> tuple[np.ndarray, np.ndarray, EdgeTopology]:
    """Per edge: ``90 - angle(dual-face normal, edge vector)`` in degrees, the dual-face area, and the
    topology (``topology.edges`` says which edge is which). A zero-area dual face counts as -90.
    Arguments as :func:`node_orthogonality`."""
    pts = np.asarray(points, dtype=np.float64)
    _check_types(cells, dim)
    orientation = orientation or cell_orientation(pts, cells, dim)
    topology = topology or edge_topology(cells, len(pts), use_numba=use_numba)
    nrm = edge_normals(pts, cells, topology, orientation, use_numba=use_numba)
    e = topology.edges
    vec = pts[e[:, 1]] - pts[e[:, 0]]
    area = np.linalg.norm(nrm, axis=1)
    length = np.linalg.norm(vec, axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        cos = np.einsum("ek,ek->e", nrm, vec) / (area * length)
    cos = np.where(np.isfinite(cos), np.clip(cos, -1.0, 1.0), -1.0)
    return 90.0 - np.degrees(np.arccos(cos)), area, topology


def node_orthogonality(points: np.ndarray, cells: list[CellBlock], dim: int = 3, *,
                       orientation: Orientation | None = None,
                       topology: EdgeTopology | None = None, use_numba: bool = True) -> np.ndarray:
    """SU2's orthogonality angle of every node, in degrees (NaN for a node of no cell).

    For each edge i-j, the angle between its dual-face normal (the median-dual control-volume face,
    :func:`edge_normals`) and the vector from i to j; the node's value is the area-weighted mean of
    ``90 - angle`` over its edges (90: the dual face is normal to every edge; negative: some dual
    face is turned over, as in an inverted cell). This is ``CPhysicalGeometry::
    ComputeMeshQualityStatistics`` of SU2 (the "Orthogonality" volume output), with the cosine
    clipped to [-1, 1] where SU2 can give NaN.

    Parameters
    ----------
    points
        (N, 3) coordinates.
    cells
        Interior cell blocks (VTK order).
    dim
        Topological dimension of the cells.
    orientation
        From :func:`cell_orientation` of the undeformed mesh (default: from ``points``).
    topology
        From :func:`edge_topology` (default: computed; pass it to evaluate a mesh twice).
    use_numba
        False: the NumPy reference (same values to rounding).

    Returns
    -------
    (N,) float64 degrees.
    """
    pts = np.asarray(points, dtype=np.float64)
    n = len(pts)
    if use_numba:
        _check_types(cells, dim)
        orientation = orientation or cell_orientation(pts, cells, dim)
        topology = topology or edge_topology(cells, n)
        nrm = edge_normals(pts, cells, topology, orientation)
        out = np.empty(n)
        _node_orthogonality_nb(np.ascontiguousarray(pts), topology.edges, nrm, out)
        return out
    ortho, area, topology = edge_orthogonality(pts, cells, dim, orientation=orientation, topology=topology,
                                               use_numba=False)
    e = topology.edges
    wsum = np.bincount(e[:, 0], weights=area * ortho, minlength=n) + np.bincount(e[:, 1], weights=area * ortho,
                                                                                 minlength=n)
    asum = np.bincount(e[:, 0], weights=area, minlength=n) + np.bincount(e[:, 1], weights=area, minlength=n)
    touched = np.zeros(n, dtype=bool)
    touched[e.ravel()] = True
    with np.errstate(divide="ignore", invalid="ignore"):
        out = np.where(asum > 0, wsum / np.where(asum > 0, asum, 1.0), -90.0)
    out[~touched] = np.nan
    return out


@njit(cache=True)
def _node_orthogonality_nb(points, edges, nrm, out):
    """Numba twin of the NumPy branch of :func:`node_orthogonality` (edge angles and node means)."""
    n = points.shape[0]
    wsum = np.zeros(n)
    asum = np.zeros(n)
    touched = np.zeros(n, np.bool_)
    for e in range(edges.shape[0]):
        i = edges[e, 0]
        j = edges[e, 1]
        v0 = points[j, 0] - points[i, 0]
        v1 = points[j, 1] - points[i, 1]
        v2 = points[j, 2] - points[i, 2]
        area = np.sqrt(nrm[e, 0] ** 2 + nrm[e, 1] ** 2 + nrm[e, 2] ** 2)
        length = np.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
        den = area * length
        cos = (nrm[e, 0] * v0 + nrm[e, 1] * v1 + nrm[e, 2] * v2) / den if den > 0 else -1.0
        if not np.isfinite(cos):
            cos = -1.0
        cos = min(1.0, max(-1.0, cos))
        ortho = 90.0 - np.degrees(np.arccos(cos))
        wsum[i] += area * ortho
        wsum[j] += area * ortho
        asum[i] += area
        asum[j] += area
        touched[i] = True
        touched[j] = True
    for i in range(n):
        if not touched[i]:
            out[i] = np.nan
        elif asum[i] > 0:
            out[i] = wsum[i] / asum[i]
        else:
            out[i] = -90.0


# ----------------------------------------------------------------------------------------------
# The gate
# ----------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class QualityReport:
    """The counts of :func:`check_quality` (see the module docstring for each rule).

    count, n_nodes
        Cells checked; nodes with an orthogonality (nodes of some cell).
    n_inverted, n_below
        The mesh as written (after): cells with q <= 0, and with 0 < q < ``threshold``.
    n_inverted_before, n_below_before
        The same of the input mesh (None without a mesh before).
    n_input_bad
        Cells already inverted or degenerate in the input (0 without a mesh before).
    n_new_inverted, n_worse, n_ortho_failed
        What the gate refuses on: cells the design inverted, cells made markedly worse, nodes that
        lost orthogonality (0 without a mesh before).
    min_before, min_after
        Smallest q (None when unknown / no cells).
    ortho_before, ortho_after, ortho_loss
        Smallest node orthogonality (degrees) before / after, and the largest loss of one node.
    n_ortho_low, n_ortho_low_before
        Nodes below ``ortho_min`` after / before.
    n_design_cells, n_design_nodes
        Cells and nodes that the rules above would fail but that the design's own FFD map shapes
        so (within ``DESIGN_SLACK``): reported, not refused.
    worst
        Up to ``n_worst`` cells of smallest q after: ``{"cell": index in the concatenation of the
        mesh's cell blocks, "type", "quality", "quality_before", "centroid": [x, y, z] after,
        "failed": bool}``.
    worst_nodes
        Up to ``n_worst`` nodes of largest orthogonality loss (or smallest value without a before):
        ``{"node", "before", "after", "point": [x, y, z] after, "failed"}``.
    input_bad
        Up to ``n_worst`` cells inverted or degenerate in the input: ``{"cell", "type", "quality",
        "centroid"}`` (input coordinates).
    """

    count: int
    n_inverted: int
    n_below: int
    threshold: float
    relative: float
    min_before: float | None
    min_after: float | None
    n_inverted_before: int | None = None
    n_below_before: int | None = None
    n_input_bad: int = 0
    n_new_inverted: int = 0
    n_worse: int = 0
    n_nodes: int = 0
    ortho_min: float = DEFAULT_ORTHO_MIN
    ortho_loss_max: float = DEFAULT_ORTHO_LOSS
    ortho_before: float | None = None
    ortho_after: float | None = None
    ortho_loss: float | None = None
    n_ortho_low: int = 0
    n_ortho_low_before: int | None = None
    n_ortho_failed: int = 0
    n_design_cells: int = 0
    n_design_nodes: int = 0
    collapse: float = DEFAULT_COLLAPSE
    worst: list = field(default_factory=list)
    worst_nodes: list = field(default_factory=list)
    input_bad: list = field(default_factory=list)

    @property
    def relative_check(self) -> bool:
        """True when there was a mesh before (``ffd deform``), False for ``ffd check``."""
        return self.min_before is not None or self.n_inverted_before is not None

    @property
    def collapse_floor(self) -> float | None:
        """The quality under which a cell made worse fails: min(collapse, the input's worst)."""
        return None if self.min_before is None else min(self.collapse, self.min_before)

    @property
    def n_failed(self) -> int:
        """What the gate refuses on (cells inverted by the design, made worse; nodes that lost
        orthogonality). Without a mesh before: the inverted or degenerate cells."""
        if not self.relative_check:
            return self.n_inverted
        return self.n_new_inverted + self.n_worse + self.n_ortho_failed

    @property
    def ok(self) -> bool:
        return self.n_failed == 0

    def rule(self) -> str:
        """The gate's rule in words, for messages."""
        return (f"a cell fails when the design inverts it, or when its scaled Jacobian falls below "
                f"{self.threshold:g}, below {self.relative:g} x its value before and below "
                f"{_g(self.collapse_floor)} (the lower of {self.collapse:g} and the input mesh's worst); "
                f"a node fails when its orthogonality falls below "
                f"{self.ortho_min:g} deg after losing more than {self.ortho_loss_max:g} deg; "
                f"unless the design's own FFD map shapes the cell or node so (within {DESIGN_SLACK:g} x "
                f"its quality, {DESIGN_SLACK_DEG:g} deg)")

    def to_dict(self) -> dict:
        """The report for ``--json`` (the same keys for ``deform`` and ``check``)."""
        return {"cells": self.count, "inverted": self.n_inverted, "below_threshold": self.n_below,
                "threshold": self.threshold, "relative": self.relative, "collapse": self.collapse,
                "min_before": self.min_before,
                "min_after": self.min_after, "inverted_before": self.n_inverted_before,
                "below_threshold_before": self.n_below_before, "input_degenerate": self.n_input_bad,
                "inverted_by_design": self.n_new_inverted, "made_worse": self.n_worse,
                "shaped_by_design": {"cells": self.n_design_cells, "nodes": self.n_design_nodes},
                "orthogonality": {"nodes": self.n_nodes, "min_before": self.ortho_before,
                                  "min_after": self.ortho_after, "largest_loss": self.ortho_loss,
                                  "below_min": self.n_ortho_low, "below_min_before": self.n_ortho_low_before,
                                  "failed": self.n_ortho_failed, "min": self.ortho_min,
                                  "loss": self.ortho_loss_max},
                "failed": self.n_failed, "ok": self.ok, "worst": self.worst, "worst_nodes": self.worst_nodes,
                "input_bad": self.input_bad}

    def summary(self) -> str:
        """One line for people: the same words for ``ffd deform`` and ``ffd check``."""
        rel = self.relative_check
        before = f"{_g(self.min_before)} before, " if rel else ""
        after = _g(self.min_after) + (" after" if rel else "")
        text = (f"cell quality (scaled Jacobian): min {before}{after}; {self.count} cells: "
                f"{self.n_inverted} inverted or degenerate, {self.n_below} below {self.threshold:g}")
        if rel:
            text += f" ({self.n_below_before} before); {self.n_new_inverted} inverted by the design, " \
                    f"{self.n_worse} made worse"
        if self.n_nodes:
            ob = f"{_g(self.ortho_before, '.1f')} before, " if rel else ""
            oa = _g(self.ortho_after, ".1f") + (" after" if rel else "")
            text += (f". orthogonality (SU2): min {ob}{oa} deg; {self.n_ortho_low} nodes below "
                     f"{self.ortho_min:g} deg")
            if rel:
                text += (f" ({self.n_ortho_low_before} before), largest loss {_g(self.ortho_loss, '.1f')} deg, "
                         f"{self.n_ortho_failed} nodes lost orthogonality")
        if self.n_design_cells or self.n_design_nodes:
            text += (f"; shaped by the design's own map (accepted): {self.n_design_cells} cells, "
                     f"{self.n_design_nodes} nodes")
        return text

    def describe_worst(self, n: int = 5) -> str:
        """The worst failing cells and nodes, one per line: id, type, values and where."""
        lines = []
        for w in [w for w in self.worst if w["failed"]][:n]:
            before = "" if w["quality_before"] is None else f" (before {w['quality_before']:.3g})"
            lines.append(f"  cell {w['cell']} ({w['type']}): quality {w['quality']:.3g}{before} "
                         f"at {_xyz(w['centroid'])}")
        for w in [w for w in self.worst_nodes if w["failed"]][:n]:
            lines.append(f"  node {w['node']}: orthogonality {w['after']:.1f} deg (before {w['before']:.1f}) "
                         f"at {_xyz(w['point'])}")
        return "\n".join(lines)

    def failure_message(self) -> str:
        """What failed, the rule and the worst place, in one line (for the exit-3 message)."""
        what = []
        if self.n_new_inverted:
            what.append(f"{self.n_new_inverted} cells inverted by the design")
        if self.n_worse:
            what.append(f"{self.n_worse} cells made worse")
        if self.n_ortho_failed:
            what.append(f"{self.n_ortho_failed} nodes lost orthogonality")
        worst = self.describe_worst(1).strip().splitlines()
        where = f"; worst: {worst[0].strip()}" if worst else ""
        return f"{', '.join(what) or 'no failure'} of {self.count} cells ({self.rule()}){where}"


def _g(v, spec: str = ".3g") -> str:
    return "n/a" if v is None else format(v, spec)


def _xyz(p) -> str:
    return "(" + ", ".join(f"{v:.6g}" for v in p) + ")"


def check_quality(mesh: Mesh, points_after: np.ndarray | None = None, threshold: float = DEFAULT_THRESHOLD,
                  points_before: np.ndarray | None = None, *, relative: float = DEFAULT_RELATIVE,
                  collapse: float = DEFAULT_COLLAPSE,
                  ortho_min: float = DEFAULT_ORTHO_MIN, ortho_loss: float = DEFAULT_ORTHO_LOSS,
                  orthogonality: bool = True, n_worst: int = 10,
                  reference: QualityReference | None = None, design_map=None) -> QualityReport:
    """The counts of the gate for the cells of ``mesh`` at ``points_after`` (default: its own points).

    Parameters
    ----------
    mesh
        The mesh (its cells; ``mesh.points`` is the input geometry).
    points_after
        (N, 3) coordinates to judge. Default: ``mesh.points``, and then there is no "before"
        (``ffd check``) unless ``points_before`` is given.
    threshold, relative, collapse, ortho_min, ortho_loss
        The rules of the module docstring.
    points_before
        (N, 3) the reference (default ``mesh.points`` when ``points_after`` is given).
    orthogonality
        Also compute the node orthogonality (the dual grid; about as costly as the scaled Jacobian).
    n_worst
        How many of the worst cells / nodes to list.
    reference
        :func:`quality_reference` of the reference geometry (``points_before``, or ``points_after``
        without a before), to skip recomputing it (a design loop, a recovery).
    design_map
        ``design_map(node_ids) -> (k, 3)``: where the design's own map puts those input nodes (NaN
        rows for nodes it does not judge); with it, failing cells and nodes that the map itself
        shapes so are *shaped by the design*, not failures (module docstring).

    Returns
    -------
    QualityReport. A mesh without interior cells (surface only) gives an empty report that passes.
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
    kw = {"threshold": float(threshold), "relative": float(relative), "ortho_min": float(ortho_min),
          "ortho_loss_max": float(ortho_loss), "collapse": float(collapse)}
    if not cells:
        return QualityReport(0, 0, 0, min_before=None, min_after=None, **kw)
    if reference is None or (orthogonality and reference.ortho is None):
        reference = quality_reference(mesh, ref, orthogonality=orthogonality)
    orientation, q_ref = reference.orientation, reference.q
    has_before = before is not None
    q = q_ref if not has_before else cell_quality(after, cells, mesh.dim, orientation=orientation)
    qb = q_ref if has_before else None
    starts = np.cumsum([0] + [len(b) for b in cells])

    def cell_rows(index, values, with_failed=None, coords=after):
        blk = np.searchsorted(starts, index, side="right") - 1
        rows = []
        for w, k in zip(index.tolist(), blk.tolist(), strict=True):
            ids = cells[k].data[w - starts[k]]
            row = {"cell": int(w), "type": cells[k].type, "quality": float(values[w])}
            if with_failed is not None:
                row["quality_before"] = None if qb is None else float(qb[w])
            row["centroid"] = coords[ids].mean(axis=0).tolist()
            if with_failed is not None:
                row["failed"] = bool(with_failed[w])
            rows.append(row)
        return rows

    floor = None
    if has_before:
        valid = qb > 0
        floor = collapse_floor(float(qb[valid].min()) if valid.any() else None, collapse)
    inverted, below, bad_in, new_inv, worse, failed = cell_rule(q, qb, threshold, relative, floor)
    out = {"n_inverted": int(inverted.sum()), "n_below": int(below.sum()), "min_after": float(q.min())}
    if has_before and design_map is not None and worse.any():
        by_design = shaped_by_design(after, cells, np.flatnonzero(worse), q, design_map, orientation)
        worse[by_design] = False
        failed = new_inv | worse
        out["n_design_cells"] = int(by_design.size)
    if has_before:
        valid = ~bad_in
        out.update(n_inverted_before=int(bad_in.sum()), n_below_before=int((valid & (qb < threshold)).sum()),
                   n_input_bad=int(bad_in.sum()), n_new_inverted=int(new_inv.sum()), n_worse=int(worse.sum()),
                   min_before=float(qb.min()))
        if bad_in.any():
            idx = np.flatnonzero(bad_in)
            out["input_bad"] = cell_rows(idx[np.argsort(qb[idx], kind="stable")][:n_worst], qb, coords=ref)
    else:
        out["min_before"] = None
    worst = np.argsort(q, kind="stable")[:n_worst]
    out["worst"] = cell_rows(worst, q, failed)
    if orthogonality:
        out.update(_orthogonality_counts(ref, after if has_before else None, cells, mesh.dim, reference,
                                         ortho_min, ortho_loss, n_worst, design_map))
    return QualityReport(len(q), **out, **kw)


def collapse_floor(min_valid_before: float | None, collapse: float) -> float:
    """The quality under which a cell made worse fails: the lower of ``collapse`` and the input
    mesh's worst valid cell (0 when the input has no valid cell)."""
    return min(0.0 if min_valid_before is None else float(min_valid_before), collapse)


def cell_rule(q: np.ndarray, qb: np.ndarray | None, threshold: float, relative: float, floor: float | None):
    """The gate's rule on cells (the one home, see the module docstring), for any set of cells.

    ``q``, ``qb``: (k,) scaled Jacobians after and before (``qb`` None: no mesh before); ``floor``:
    :func:`collapse_floor` of the WHOLE input mesh. Returns the (k,) masks ``(inverted, below,
    bad_in, new_inv, worse, failed)`` (the three of the before None without one)."""
    inverted = q <= 0
    below = ~inverted & (q < threshold)
    if qb is None:
        return inverted, below, None, None, None, inverted
    bad_in = qb <= 0
    valid = ~bad_in
    new_inv = inverted & valid
    worse = valid & ~inverted & (q < threshold) & (q < relative * qb) & (q < floor)
    return inverted, below, bad_in, new_inv, worse, new_inv | worse


def node_rule(o: np.ndarray, o_ref: np.ndarray, has: np.ndarray, ortho_min: float, ortho_loss: float):
    """The gate's rule on nodes (the one home): ``(loss, fail)`` of orthogonality after ``o`` and
    before ``o_ref`` (degrees), where ``has`` (nodes of some cell)."""
    loss = np.where(has, o_ref - o, 0.0)
    return loss, has & (o < ortho_min) & (loss > ortho_loss)


@dataclass(frozen=True)
class QualityReference:
    """What the gate needs of the input mesh, computed once (:func:`quality_reference`) and reused
    for every candidate geometry of a design loop or a recovery: the orientation convention, the
    scaled Jacobian of every cell, the edges and the node orthogonality (None when not wanted)."""

    orientation: Orientation
    q: np.ndarray
    topology: EdgeTopology | None = None
    ortho: np.ndarray | None = None


def quality_reference(mesh: Mesh, points: np.ndarray | None = None, *, orthogonality: bool = True
                      ) -> QualityReference:
    """The :class:`QualityReference` of ``mesh`` at ``points`` (default its own): pass it to
    :func:`check_quality` as ``reference`` with the same ``points_before``."""
    pts = mesh.points if points is None else np.asarray(points, dtype=np.float64)
    cells = [b for b in mesh.cells if len(b)]
    _check_types(cells, mesh.dim)
    # one pass over the points gives both the orientation and the quality
    normal = cell_orientation(pts, cells, 2).normal if mesh.dim == 2 else None
    raws = [_raw_quality(pts, b.data, b.type, normal) for b in cells]
    signs = np.ones(len(cells)) if mesh.dim == 2 else _majority_signs(raws)
    orientation = Orientation(signs, normal)
    q = (np.concatenate([np.clip(sg * r, -1.0, 1.0) for sg, r in zip(signs, raws, strict=True)]) if raws
         else np.zeros(0))
    topo = ortho = None
    if orthogonality and cells:
        topo = edge_topology(cells, len(pts))
        ortho = node_orthogonality(pts, cells, mesh.dim, orientation=orientation, topology=topo)
    return QualityReference(orientation, q, topo, ortho)


def shaped_by_design(after, cells, index, q, design_map, orientation) -> np.ndarray:
    """The rule *shaped by the design* on cells (the one home): the cells of ``index`` (numbered in
    the concatenation of ``cells``) whose quality ``q`` is at least ``DESIGN_SLACK`` x what the
    design's own map (``design_map``, see :func:`check_quality`) makes of them, every node mapped."""
    starts = np.cumsum([0] + [len(b) for b in cells])
    blk = np.searchsorted(starts, index, side="right") - 1
    per_block = [cells[k].data[index[blk == k] - starts[k]] for k in range(len(cells))]
    nodes = unique_ids(*per_block)
    moved = np.asarray(design_map(nodes), dtype=np.float64)
    good = np.isfinite(moved).all(axis=1)
    pts = np.array(after, dtype=np.float64)
    pts[nodes[good]] = moved[good]
    mapped = np.zeros(len(pts), dtype=bool)
    mapped[nodes[good]] = True
    q_map = np.full(len(index), np.inf)
    for k, data in enumerate(per_block):
        if len(data):
            raw = _raw_quality(pts, data, cells[k].type, orientation.normal)
            q_map[blk == k] = np.where(mapped[data].all(axis=1),
                                       np.clip(orientation.signs[k] * raw, -1.0, 1.0), np.inf)
    return index[q[index] >= DESIGN_SLACK * q_map]


def nodes_shaped_by_design(after, cells, dim, orientation, topology, fail, o, design_map) -> np.ndarray:
    """The rule *shaped by the design* on nodes (the one home): the failing nodes (mask ``fail``)
    whose orthogonality ``o`` is at most ``DESIGN_SLACK_DEG`` below what it is when the nodes of
    their cells move by the design's own map (the node itself mapped)."""
    cand = np.flatnonzero(fail)
    near = np.zeros(len(after), dtype=bool)
    near[cand] = True
    around = [b.data[near[b.data].any(axis=1)] for b in cells]
    nodes = unique_ids(*around)
    moved = np.asarray(design_map(nodes), dtype=np.float64)
    good = np.isfinite(moved).all(axis=1)
    pts = np.array(after, dtype=np.float64)
    pts[nodes[good]] = moved[good]
    o_map = node_orthogonality(pts, cells, dim, orientation=orientation, topology=topology)
    mapped = np.zeros(len(pts), dtype=bool)
    mapped[nodes[good]] = True
    return cand[mapped[cand] & (o[cand] >= o_map[cand] - DESIGN_SLACK_DEG)]


def _orthogonality_counts(ref, after, cells, dim, reference, ortho_min, ortho_loss, n_worst,
                          design_map=None) -> dict:
    """The orthogonality fields of the report (``after`` None: only the mesh ``ref`` itself)."""
    topo, o_ref, orientation = reference.topology, reference.ortho, reference.orientation
    has = np.isfinite(o_ref)
    if not has.any():
        return {}
    if after is None:
        o = o_ref
        low = has & (o < ortho_min)
        idx = np.flatnonzero(has)
        worst = idx[np.argsort(o[idx], kind="stable")][:n_worst]
        rows = [{"node": int(i), "before": None, "after": float(o[i]), "point": ref[i].tolist(), "failed": False}
                for i in worst.tolist()]
        return {"n_nodes": int(has.sum()), "ortho_after": float(np.min(o[has])), "n_ortho_low": int(low.sum()),
                "worst_nodes": rows}
    o = node_orthogonality(after, cells, dim, orientation=orientation, topology=topo)
    loss, fail = node_rule(o, o_ref, has, ortho_min, ortho_loss)
    n_design = 0
    if design_map is not None and fail.any():
        by_design = nodes_shaped_by_design(after, cells, dim, orientation, topo, fail, o, design_map)
        fail[by_design] = False
        n_design = int(by_design.size)
    idx = np.flatnonzero(has)
    worst = idx[np.lexsort((o[idx], ~fail[idx]))][:n_worst]          # failing first, then lowest after
    rows = [{"node": int(i), "before": float(o_ref[i]), "after": float(o[i]), "point": after[i].tolist(),
             "failed": bool(fail[i])} for i in worst.tolist()]
    return {"n_nodes": int(has.sum()), "ortho_before": float(np.min(o_ref[has])), "ortho_after": float(np.min(o[has])),
            "ortho_loss": float(loss.max()), "n_ortho_low": int((has & (o < ortho_min)).sum()),
            "n_ortho_low_before": int((has & (o_ref < ortho_min)).sum()), "n_ortho_failed": int(fail.sum()),
            "n_design_nodes": n_design, "worst_nodes": rows}


def enforce(report: QualityReport | None, *, mesh_path=None, design_path=None, force: bool = False,
            recovery: list | None = None) -> list[str]:
    """Apply the gate to a report of ``ffd deform``: raise, or return warnings for ``--force``.

    ``recovery``: the attempts of :mod:`ffdcli.volume.recovery` (``Deformation.recovery``); the refusal
    then says what was tried and what to try next.

    Raises :class:`~ffdcli.errors.InputError` (exit 2) when the input mesh already has inverted or
    degenerate cells, naming the first and where it is; :class:`~ffdcli.errors.QualityError` (exit 3)
    when the design fails the gate, with the counts, the rule and the worst place. With ``force``
    neither is raised and the warnings say what would have been.
    """

    if report is None:
        return []
    warnings = []
    if report.n_input_bad:
        w = report.input_bad[0]
        more = f" (and {report.n_input_bad - 1} more)" if report.n_input_bad > 1 else ""
        msg = (f"cell {w['cell']} ({w['type']}) at {_xyz(w['centroid'])} is already "
               f"{'inverted' if w['quality'] < 0 else 'degenerate'} in the input mesh (scaled Jacobian "
               f"{w['quality']:.3g}){more}: a problem of the mesh, not of the design; repair or regenerate "
               f"the mesh (ffd check MESH lists such cells)")
        if not force:
            raise InputError(msg + ", or give --force to deform it anyway", path=mesh_path)
        warnings.append(msg)
    if not report.ok:
        msg = f"the deformed mesh fails the quality gate: {report.failure_message()}"
        if recovery:
            tried = ", ".join(f"{a['attempt']} ({'?' if a['failed'] is None else a['failed']} failing)"
                              for a in recovery)
            msg += (f"; tried: {tried}; try next: the change in smaller steps (several runs), "
                    "volume.rotation_reach: null, or a finer surface mesh where the worst cell is")
        if not force:
            raise QualityError(msg + "; nothing was written (--force writes it anyway)", path=design_path,
                               report=report.to_dict())
        warnings.append(msg + "; written anyway (--force)")
    return warnings


# ----------------------------------------------------------------------------------------------
# The gate on partitions (MPI): each rank its share of the cells and nodes, the counts reduced
# ----------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class PartReference(QualityReference):
    """:class:`QualityReference` of one rank's :class:`~ffdcli.parallel.partition.MeshPart`: the orientation
    of the WHOLE mesh (agreed between the ranks), ``q`` of the cells this rank counts (blocks
    concatenated), the topology and node orthogonality of the part (valid at its owned nodes),
    and the input's worst cells over every rank (the gate's collapse floor needs them)."""

    q_min: float | None = None          # min q of the whole input mesh
    q_min_valid: float | None = None    # min q > 0 of the whole input mesh (None: no valid cell)


def _counted_blocks(part) -> list[CellBlock]:
    return [CellBlock(t, b.data[c]) for t, b, c in zip(part.types, part.cells, part.counted, strict=True)]


def part_reference(part, comm, points=None, *, orthogonality: bool = True) -> PartReference:
    """The :class:`PartReference` of a part at ``points`` (local rows; default its own): a
    collective (every rank calls it). The orientation is that of :func:`cell_orientation` of the
    whole mesh: each block's sign from the counts of every rank, the 2D plane normal from the sum
    over every rank's cells."""
    pts = part.points if points is None else np.asarray(points, dtype=np.float64)
    counted = _counted_blocks(part)
    _check_types(counted, part.dim)
    normal = None
    if part.dim == 2:
        total = np.zeros(3)
        for blk in counted:
            d = blk.data
            for lo in range(0, len(d), CHUNK):
                c = d[lo:lo + CHUNK]
                total += np.cross(pts[c[:, 1]] - pts[c[:, 0]], pts[c[:, 2]] - pts[c[:, 0]]).sum(axis=0)
        total = comm.allreduce_sum(total)
        own = pts[part.owned]
        box = np.concatenate([own.min(axis=0), -own.max(axis=0)]) if len(own) else np.full(6, np.inf)
        box = np.array([min(v) for v in zip(*comm.allgather(box), strict=True)])
        ext = -box[3:] - box[:3] if np.all(np.isfinite(box)) else np.ones(3)
        normal = _plane_normal_of(total, ext)
    raws = comm.run(lambda: [_raw_quality(pts, b.data, b.type, normal) for b in counted])
    if part.dim == 2:
        signs = np.ones(len(counted))
    else:
        tally = np.array([[np.count_nonzero(r < 0), np.count_nonzero(r > 0)] for r in raws], dtype=np.float64)
        tally = comm.allreduce_sum(tally.reshape(-1, 2)) if len(raws) else tally
        signs = np.array([-1.0 if neg > pos else 1.0 for neg, pos in tally])
    orientation = Orientation(signs, normal)
    q = (np.concatenate([np.clip(sg * r, -1.0, 1.0) for sg, r in zip(signs, raws, strict=True)]) if raws
         else np.zeros(0))
    mins = comm.allgather((float(q.min()) if len(q) else None,
                           float(q[q > 0].min()) if np.any(q > 0) else None))
    q_min = min((a for a, _ in mins if a is not None), default=None)
    q_valid = min((b for _, b in mins if b is not None), default=None)
    topo = ortho = None
    if orthogonality:
        def dual():
            t = edge_topology(list(part.cells), len(pts))
            return t, node_orthogonality(pts, list(part.cells), part.dim, orientation=orientation, topology=t)

        topo, ortho = comm.run(dual)
    return PartReference(orientation, q, topo, ortho, q_min=q_min, q_min_valid=q_valid)


def _plane_normal_of(total: np.ndarray, ext: np.ndarray) -> np.ndarray:
    """The 2D mesh-plane normal of :func:`cell_orientation` from the summed cell normals ``total``
    (or, with no area at all, the axis of least extent ``ext``)."""
    nrm = np.linalg.norm(total)
    normal = total / nrm if nrm > 0 else np.eye(3)[int(np.argmin(ext))]
    k = int(np.argmax(np.abs(normal)))
    if abs(normal[k]) >= 1 - 1e-12:                        # a mesh in a coordinate plane
        normal = np.sign(normal[k]) * np.eye(3)[k]
    return normal


def check_quality_part(part, comm, points_after=None, points_before=None, threshold: float = DEFAULT_THRESHOLD,
                       *, relative: float = DEFAULT_RELATIVE, collapse: float = DEFAULT_COLLAPSE,
                       ortho_min: float = DEFAULT_ORTHO_MIN, ortho_loss: float = DEFAULT_ORTHO_LOSS,
                       orthogonality: bool = True, n_worst: int = 10,
                       reference: PartReference | None = None, design_map=None) -> QualityReport:
    """:func:`check_quality` shared between MPI ranks: a collective; every rank returns the same
    :class:`QualityReport`, equal to the serial one of the whole mesh.

    Each rank judges the cells it counts and the nodes it owns of its
    :class:`~ffdcli.parallel.partition.MeshPart` (the cells around its nodes give their orthogonality); the
    counts, minima and worst places are gathered (a few numbers and ``n_worst`` rows a rank).

    Parameters
    ----------
    part
        This rank's part (:func:`ffdcli.parallel.partition.part_of`, or read by rank).
    comm
        :mod:`ffdcli.parallel.comm` communicator.
    points_after, points_before
        (n, 3) coordinates of the part's local nodes (``part.ids``); as in :func:`check_quality`
        (``points_after`` None: the part's own points, and no before unless given).
    reference
        :func:`part_reference` of the reference geometry, to reuse.
    design_map
        As in :func:`check_quality`, of GLOBAL node ids.
    """
    if points_after is None:
        after, before = part.points, points_before
    else:
        after = np.asarray(points_after, dtype=np.float64)
        before = part.points if points_before is None else np.asarray(points_before, dtype=np.float64)
    if after.shape != part.points.shape:
        raise ValueError(f"points {after.shape} do not match the part {part.points.shape}")
    ref = after if before is None else before
    kw = {"threshold": float(threshold), "relative": float(relative), "ortho_min": float(ortho_min),
          "ortho_loss_max": float(ortho_loss), "collapse": float(collapse)}
    if part.n_cells == 0:
        return QualityReport(0, 0, 0, min_before=None, min_after=None, **kw)
    if reference is None or (orthogonality and reference.ortho is None):
        reference = part_reference(part, comm, ref, orthogonality=orthogonality)
    # the rank's own figures, agreed on (an error on one rank ends every rank), then gathered
    local_map = None if design_map is None else (lambda local: design_map(part.ids[local]))
    mine = comm.run(_part_figures, part, after, before, ref, reference, threshold, relative, collapse,
                    ortho_min, ortho_loss, orthogonality, n_worst, local_map)
    return _merge_parts(comm.allgather(mine), before is not None, orthogonality, reference, n_worst, kw)


def _part_figures(part, after, before, ref, reference, threshold, relative, collapse, ortho_min, ortho_loss,
                  orthogonality, n_worst, design_map=None) -> dict:
    """One rank's counts, minima and worst rows of :func:`check_quality_part` (no communication)."""
    counted = _counted_blocks(part)
    has_before = before is not None
    q_ref = reference.q
    q = q_ref if not has_before else cell_quality(after, counted, part.dim, orientation=reference.orientation)
    qb = q_ref if has_before else None
    gid = np.concatenate([c[m] for c, m in zip(part.cell_ids, part.counted, strict=True)])
    kind = np.concatenate([np.full(len(b), k, dtype=np.int64) for k, b in enumerate(counted)])
    rows_of = np.concatenate([np.flatnonzero(m) for m in part.counted])
    floor = collapse_floor(reference.q_min_valid, collapse) if has_before else None
    inverted, below, bad_in, new_inv, worse, failed = cell_rule(q, qb, threshold, relative, floor)
    n_design = 0
    if has_before and design_map is not None and worse.any():
        by_design = shaped_by_design(after, counted, np.flatnonzero(worse), q, design_map, reference.orientation)
        worse[by_design] = False
        failed = new_inv | worse
        n_design = int(by_design.size)

    def cell_rows(index, values, with_failed=None, coords=after):
        rows = []
        for w in index.tolist():
            k = int(kind[w])
            nodes = part.cells[k].data[rows_of[w]]
            row = {"cell": int(gid[w]), "type": part.types[k], "quality": float(values[w])}
            if with_failed is not None:
                row["quality_before"] = None if qb is None else float(qb[w])
            row["centroid"] = coords[nodes].mean(axis=0).tolist()
            if with_failed is not None:
                row["failed"] = bool(with_failed[w])
            rows.append(row)
        return rows

    mine = {"count": len(q), "n_inverted": int(inverted.sum()), "n_below": int(below.sum()),
            "min_after": float(q.min()) if len(q) else None}
    if has_before:
        valid = ~bad_in
        mine.update(n_inverted_before=int(bad_in.sum()), n_below_before=int((valid & (qb < threshold)).sum()),
                    n_input_bad=int(bad_in.sum()), n_new_inverted=int(new_inv.sum()), n_worse=int(worse.sum()),
                    n_design_cells=n_design)
        idx = np.flatnonzero(bad_in)
        idx = idx[np.lexsort((gid[idx], qb[idx]))][:n_worst]
        mine["input_bad"] = cell_rows(idx, qb, coords=ref)
    worst = np.lexsort((gid, q))[:n_worst]
    mine["worst"] = cell_rows(worst, q, failed)
    if orthogonality and reference.ortho is not None:
        mine["ortho"] = _part_orthogonality(part, ref, after if has_before else None, reference, ortho_min,
                                            ortho_loss, n_worst, design_map)
    return mine


def _part_orthogonality(part, ref, after, reference, ortho_min, ortho_loss, n_worst, design_map=None) -> dict:
    """This rank's orthogonality figures of its owned nodes (see :func:`_orthogonality_counts`)."""
    own = part.owned
    o_ref = reference.ortho
    has = np.isfinite(o_ref) & own
    gids = part.ids
    out = {"n_nodes": int(has.sum())}
    idx = np.flatnonzero(has)
    if after is None:
        o = o_ref
        out.update(ortho_after=float(o[has].min()) if has.any() else None,
                   n_ortho_low=int((has & (o < ortho_min)).sum()))
        worst = idx[np.lexsort((gids[idx], o[idx]))][:n_worst]
        out["worst_nodes"] = [((float(o[i]), int(gids[i])), {"node": int(gids[i]), "before": None,
                               "after": float(o[i]), "point": ref[i].tolist(), "failed": False})
                              for i in worst.tolist()]
        return out
    o = node_orthogonality(after, list(part.cells), part.dim, orientation=reference.orientation,
                           topology=reference.topology)
    loss, fail = node_rule(o, o_ref, has, ortho_min, ortho_loss)
    n_design = 0
    if design_map is not None and fail.any():
        by_design = nodes_shaped_by_design(after, list(part.cells), part.dim, reference.orientation,
                                           reference.topology, fail, o, design_map)
        fail[by_design] = False
        n_design = int(by_design.size)
    out.update(ortho_before=float(o_ref[has].min()) if has.any() else None,
               ortho_after=float(o[has].min()) if has.any() else None,
               ortho_loss=float(loss[own].max()) if own.any() else None,
               n_ortho_low=int((has & (o < ortho_min)).sum()),
               n_ortho_low_before=int((has & (o_ref < ortho_min)).sum()),
               n_ortho_failed=int(fail.sum()), n_design_nodes=n_design)
    worst = idx[np.lexsort((gids[idx], o[idx], ~fail[idx]))][:n_worst]
    out["worst_nodes"] = [((bool(~fail[i]), float(o[i]), int(gids[i])),
                           {"node": int(gids[i]), "before": float(o_ref[i]), "after": float(o[i]),
                            "point": after[i].tolist(), "failed": bool(fail[i])}) for i in worst.tolist()]
    return out


def _merge_parts(parts: list[dict], has_before: bool, orthogonality: bool, reference, n_worst: int,
                 kw: dict) -> QualityReport:
    """The :class:`QualityReport` of the whole mesh from every rank's figures (same on every rank)."""

    def total(key):
        return sum(p[key] for p in parts)

    def least(values):
        values = [v for v in values if v is not None]
        return min(values) if values else None

    out = {"n_inverted": total("n_inverted"), "n_below": total("n_below"),
           "min_after": least(p["min_after"] for p in parts)}
    rows = sorted((r for p in parts for r in p["worst"]), key=lambda r: (r["quality"], r["cell"]))
    out["worst"] = rows[:n_worst]
    if has_before:
        for key in ("n_inverted_before", "n_below_before", "n_input_bad", "n_new_inverted", "n_worse",
                    "n_design_cells"):
            out[key] = total(key)
        out["min_before"] = reference.q_min
        bad = sorted((r for p in parts for r in p["input_bad"]), key=lambda r: (r["quality"], r["cell"]))
        if bad:
            out["input_bad"] = bad[:n_worst]
    else:
        out["min_before"] = None
    ortho = [p["ortho"] for p in parts if "ortho" in p]
    if orthogonality and ortho and sum(o["n_nodes"] for o in ortho):
        out["n_nodes"] = sum(o["n_nodes"] for o in ortho)
        out["ortho_after"] = least(o["ortho_after"] for o in ortho)
        out["n_ortho_low"] = sum(o["n_ortho_low"] for o in ortho)
        if has_before:
            out["ortho_before"] = least(o["ortho_before"] for o in ortho)
            out["ortho_loss"] = max(o["ortho_loss"] for o in ortho if o["ortho_loss"] is not None)
            out["n_ortho_low_before"] = sum(o["n_ortho_low_before"] for o in ortho)
            out["n_ortho_failed"] = sum(o["n_ortho_failed"] for o in ortho)
            out["n_design_nodes"] = sum(o["n_design_nodes"] for o in ortho)
        nodes = sorted((w for o in ortho for w in o["worst_nodes"]), key=lambda w: w[0])
        out["worst_nodes"] = [row for _, row in nodes[:n_worst]]
    return QualityReport(sum(p["count"] for p in parts), **out, **kw)
