"""Orthogonality of the dual grid: SU2's node orthogonality and the edges it is computed on.

**Orthogonality** (:func:`node_orthogonality`, one value per node, degrees): what SU2 reports as
"Orthogonality" for its vertex-centred finite volumes. Each edge i-j has a dual face (the median
dual: triangles through the edge midpoint, the centroids of the two cell faces at the edge and the
cell centroid, summed over the cells around the edge); the edge's angle is ``90 - angle(dual-face
normal, x_j - x_i)``, and the node's value is the area-weighted mean over its edges. 90 is ideal;
SU2's own guidance is that values below about 20 degrees are poor. It sees what the scaled
Jacobian misses: a sheared stack of thin boundary-layer cells keeps q but loses orthogonality.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit, prange

from ffdcli.mesh import CellBlock
from ffdcli.quality.metrics import CHUNK, Orientation, cell_orientation, check_types

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
    check_types(cells, dim)
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
        check_types(cells, dim)
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

