"""The polyhedral cell model: one model for OpenFOAM polyMeshes and CGNS NGON_n/NFACE_n sections.

A polyhedral mesh is a list of faces (polygons of any number of nodes) and, for each face, the cell
on each side: its ``owner`` and its ``neighbour`` (-1 for a boundary face). A cell is the set of
faces that name it. The face's node order gives its normal (right-hand rule), which points out of
the owner and into the neighbour. This is OpenFOAM's ``polyMesh`` (``faces``, ``owner``,
``neighbour``) without its rule that internal faces come first, so CGNS NGON_n/NFACE_n sections
(faces in any order, cells as signed face lists) fit too.

Storage is flat: the nodes of every face in one array ``face_nodes`` (K,) and the start of each face
in ``face_offsets`` (F + 1,), as OpenFOAM's ``faceCompactList`` and CGNS's ``ElementStartOffset``.

The geometry follows OpenFOAM's ``primitiveMeshTools`` exactly, so that the figures computed on it
(volumes, non-orthogonality, skewness in :mod:`ffdcli.quality.polyhedral`) are checkMesh's:

- a face's centre and area vector: the triangles (node i, node i+1, mean of the face's nodes), their
  area-weighted centroids and summed area vectors (a triangle: its centroid and half the cross
  product);
- a cell's volume: the sum of the pyramids (face, estimated centre), where the estimated centre is
  the mean of the cell's face centres; the pyramid of a face is the sum of the tetrahedra (estimated
  centre, face centre, node i, node i+1), so this is the decomposition of the cell into tetrahedra
  about the face and cell centres; the cell centre is the volume-weighted mean of the pyramid centres.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

#: OpenFOAM's small numbers (double precision): VSMALL and its square root.
VSMALL = 1.0e-300
ROOTVSMALL = 1.0e-150
#: Faces per chunk of the vectorised geometry (bounds the temporaries at a few hundred MB).
CHUNK = 1 << 18


@dataclass(frozen=True, eq=False)
class Polyhedra:
    """Polyhedral cells as faces with an owner and a neighbour cell.

    face_nodes
        (K,) int64, the 0-based point ids of every face, face after face.
    face_offsets
        (F + 1,) int64, face ``f`` is ``face_nodes[face_offsets[f]:face_offsets[f + 1]]``.
    owner
        (F,) int64, the cell the face's normal points out of.
    neighbour
        (F,) int64, the cell on the other side, -1 for a boundary face.
    n_cells
        The number of cells (every cell id in ``owner``/``neighbour`` is below it).
    """

    face_nodes: np.ndarray
    face_offsets: np.ndarray
    owner: np.ndarray
    neighbour: np.ndarray
    n_cells: int

    @property
    def n_faces(self) -> int:
        return len(self.owner)

    @property
    def face_sizes(self) -> np.ndarray:
        """(F,) nodes per face."""
        return np.diff(self.face_offsets)

    @property
    def internal(self) -> np.ndarray:
        """(F,) bool, faces between two cells."""
        return self.neighbour >= 0

    def face(self, f: int) -> np.ndarray:
        """The point ids of face ``f``."""
        return self.face_nodes[self.face_offsets[f]:self.face_offsets[f + 1]]

    def faces_per_cell(self) -> np.ndarray:
        """(C,) the number of faces of each cell."""
        n = np.bincount(self.owner, minlength=self.n_cells)
        return n + np.bincount(self.neighbour[self.neighbour >= 0], minlength=self.n_cells)

    def cell_faces(self) -> tuple[np.ndarray, np.ndarray]:
        """The cells as sets of faces: ``(offsets (C + 1,), faces)``, cell ``c``'s faces being
        ``faces[offsets[c]:offsets[c + 1]]`` (ascending face ids)."""
        inner = np.flatnonzero(self.neighbour >= 0)
        cells = np.concatenate([self.owner, self.neighbour[inner]])
        faces = np.concatenate([np.arange(self.n_faces, dtype=np.int64), inner])
        order = np.lexsort((faces, cells))
        offsets = np.zeros(self.n_cells + 1, dtype=np.int64)
        np.cumsum(np.bincount(cells, minlength=self.n_cells), out=offsets[1:])
        return offsets, faces[order]

    def shape_counts(self) -> dict[str, int]:
        """Cells by shape, told by their faces as checkMesh's table does for the usual shapes:
        hexahedra (6 quadrilaterals), prisms (2 triangles, 3 quadrilaterals), pyramids (1
        quadrilateral, 4 triangles), tetrahedra (4 triangles), polyhedra (anything else)."""
        size = self.face_sizes
        counts = {}
        for k in (3, 4):
            on = size == k
            c = np.bincount(self.owner[on], minlength=self.n_cells)
            inner = on & (self.neighbour >= 0)
            counts[k] = c + np.bincount(self.neighbour[inner], minlength=self.n_cells)
        total = self.faces_per_cell()
        tri, quad = counts[3], counts[4]
        kinds = {"hexahedra": (quad == 6) & (total == 6), "prisms": (tri == 2) & (quad == 3) & (total == 5),
                 "pyramids": (tri == 4) & (quad == 1) & (total == 5), "tetrahedra": (tri == 4) & (total == 4)}
        out = {k: int(v.sum()) for k, v in kinds.items()}
        out["polyhedra"] = self.n_cells - sum(out.values())
        return out

    def boundary_faces(self, faces: np.ndarray) -> dict[str, np.ndarray]:
        """The faces ``faces`` (ids) as cell arrays by type, for markers: ``{"triangle": (k, 3),
        "quad": (m, 4)}``; a polygon of more nodes is split into a fan of triangles about its first
        node (same orientation), so every node of the face is on the marker."""
        faces = np.asarray(faces, dtype=np.int64)
        size = self.face_sizes[faces]
        start = self.face_offsets[faces]
        out = {}
        for k, name in ((3, "triangle"), (4, "quad")):
            sel = start[size == k]
            if len(sel):
                out[name] = self.face_nodes[sel[:, None] + np.arange(k)]
        big = size > 4
        if big.any():
            s, n = start[big], size[big]
            reps = n - 2
            first = np.repeat(s, reps)
            j = np.arange(int(reps.sum())) - np.repeat(np.cumsum(reps) - reps, reps)
            fan = np.column_stack([self.face_nodes[first], self.face_nodes[first + j + 1],
                                   self.face_nodes[first + j + 2]])
            out["triangle"] = fan if "triangle" not in out else np.vstack([out["triangle"], fan])
        return out


def problem(poly: Polyhedra, n_points: int) -> tuple[str, str, int] | None:
    """The first inconsistency of ``poly`` against ``n_points`` points, or None.

    Returns ``(array, message, index)``: the array at fault (``faces``, ``owner``, ``neighbour``),
    what is wrong and the index of the first bad entry (face or cell), for the reader's message.
    """
    size = np.diff(poly.face_offsets)
    if len(poly.owner) != len(size) or len(poly.neighbour) != len(size):
        return ("owner", f"{len(poly.owner)} owners and {len(poly.neighbour)} neighbours for {len(size)} faces", 0)
    bad = np.flatnonzero(size < 3)
    if len(bad):
        return ("faces", f"face {bad[0]} has {size[bad[0]]} points, a face needs at least 3", int(bad[0]))
    nodes = poly.face_nodes
    if len(nodes) and (nodes.min() < 0 or nodes.max() >= n_points):
        at = int(np.flatnonzero((nodes < 0) | (nodes >= n_points))[0])
        f = int(np.searchsorted(poly.face_offsets, at, side="right") - 1)
        return ("faces", f"face {f} refers to point {nodes[at]}; the mesh has {n_points} points "
                f"(0 to {n_points - 1})", f)
    for name, arr, low in (("owner", poly.owner, 0), ("neighbour", poly.neighbour, -1)):
        out = np.flatnonzero((arr < low) | (arr >= poly.n_cells))
        if len(out):
            return (name, f"face {out[0]} names cell {arr[out[0]]}; there are {poly.n_cells} cells", int(out[0]))
    same = np.flatnonzero(poly.owner == poly.neighbour)
    if len(same):
        return ("neighbour", f"face {same[0]} has cell {poly.owner[same[0]]} on both sides", int(same[0]))
    few = np.flatnonzero(poly.faces_per_cell() < 4)
    if len(few):
        return ("owner", f"cell {few[0]} has {poly.faces_per_cell()[few[0]]} faces, a cell needs at least 4",
                int(few[0]))
    return None


# ----------------------------------------------------------------------------------------------
# Geometry (OpenFOAM's primitiveMeshTools, vectorised by chunks of faces)
# ----------------------------------------------------------------------------------------------

def next_in_face(offsets: np.ndarray) -> np.ndarray:
    """(K,) for each position of the flat node array, the position of the next node of its face
    (the last node's next is the face's first)."""
    k = int(offsets[-1] - offsets[0])
    nxt = np.arange(1, k + 1, dtype=np.int64)
    ends = offsets[1:] - offsets[0]
    nonempty = ends > offsets[:-1] - offsets[0]
    nxt[ends[nonempty] - 1] = (offsets[:-1] - offsets[0])[nonempty]
    return nxt


def face_centres_areas(points: np.ndarray, poly: Polyhedra, *, compiled: bool = True
                       ) -> tuple[np.ndarray, np.ndarray]:
    """Face centres (F, 3) and area vectors (F, 3) of ``poly`` at ``points`` (N, 3), as
    ``primitiveMeshTools::makeFaceCentresAndAreas``: one compiled pass over the faces, or
    (``compiled=False``) its vectorised NumPy reference by chunks of faces (equal to rounding)."""
    nf = poly.n_faces
    if compiled:
        return _face_kernel(np.ascontiguousarray(points, dtype=np.float64), poly.face_nodes, poly.face_offsets)
    centres = np.empty((nf, 3))
    areas = np.empty((nf, 3))
    for a in range(0, nf, CHUNK):
        b = min(nf, a + CHUNK)
        off = poly.face_offsets[a:b + 1]
        centres[a:b], areas[a:b] = _face_chunk(points, poly.face_nodes[off[0]:off[-1]], off - off[0])
    return centres, areas


@njit(cache=True, nogil=True)
def _face_kernel(points, nodes, offsets):  # pragma: no cover - compiled
    nf = offsets.shape[0] - 1
    centres = np.empty((nf, 3))
    areas = np.empty((nf, 3))
    for f in range(nf):
        a, b = offsets[f], offsets[f + 1]
        k = b - a
        if k == 3:
            p0, p1, p2 = points[nodes[a]], points[nodes[a + 1]], points[nodes[a + 2]]
            for d in range(3):
                centres[f, d] = (p0[d] + p1[d] + p2[d]) / 3.0
            u0, u1, u2 = p1[0] - p0[0], p1[1] - p0[1], p1[2] - p0[2]
            v0, v1, v2 = p2[0] - p0[0], p2[1] - p0[1], p2[2] - p0[2]
            areas[f, 0] = 0.5 * (u1 * v2 - u2 * v1)
            areas[f, 1] = 0.5 * (u2 * v0 - u0 * v2)
            areas[f, 2] = 0.5 * (u0 * v1 - u1 * v0)
            continue
        m0 = m1 = m2 = 0.0
        for i in range(a, b):
            m0 += points[nodes[i], 0]
            m1 += points[nodes[i], 1]
            m2 += points[nodes[i], 2]
        m0 /= k
        m1 /= k
        m2 /= k
        sn0 = sn1 = sn2 = 0.0
        sa = 0.0
        sc0 = sc1 = sc2 = 0.0
        for i in range(a, b):
            j = i + 1 if i + 1 < b else a
            x0, x1, x2 = points[nodes[i], 0], points[nodes[i], 1], points[nodes[i], 2]
            y0, y1, y2 = points[nodes[j], 0], points[nodes[j], 1], points[nodes[j], 2]
            e0, e1, e2 = y0 - x0, y1 - x1, y2 - x2
            c0, c1, c2 = m0 - x0, m1 - x1, m2 - x2
            n0 = e1 * c2 - e2 * c1
            n1 = e2 * c0 - e0 * c2
            n2 = e0 * c1 - e1 * c0
            mag = np.sqrt(n0 * n0 + n1 * n1 + n2 * n2)
            sn0 += n0
            sn1 += n1
            sn2 += n2
            sa += mag
            sc0 += mag * (x0 + y0 + m0)
            sc1 += mag * (x1 + y1 + m1)
            sc2 += mag * (x2 + y2 + m2)
        if sa < ROOTVSMALL:
            centres[f, 0], centres[f, 1], centres[f, 2] = m0, m1, m2
            areas[f, 0] = areas[f, 1] = areas[f, 2] = 0.0
        else:
            centres[f, 0], centres[f, 1], centres[f, 2] = sc0 / (3.0 * sa), sc1 / (3.0 * sa), sc2 / (3.0 * sa)
            areas[f, 0], areas[f, 1], areas[f, 2] = 0.5 * sn0, 0.5 * sn1, 0.5 * sn2
    return centres, areas


def _face_chunk(points: np.ndarray, nodes: np.ndarray, off: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    p = points[nodes]                                   # (k, 3)
    size = np.diff(off)
    starts = off[:-1]
    mean = np.add.reduceat(p, starts, axis=0) / size[:, None]
    q = p[next_in_face(off)]
    m = np.repeat(mean, size, axis=0)
    n = np.cross(q - p, m - p)
    mag = np.sqrt(np.einsum("ij,ij->i", n, n))
    sum_n = np.add.reduceat(n, starts, axis=0)
    sum_a = np.add.reduceat(mag, starts)
    sum_ac = np.add.reduceat(mag[:, None] * (p + q + m), starts, axis=0)
    tiny = sum_a < ROOTVSMALL
    with np.errstate(invalid="ignore", divide="ignore"):
        centre = np.where(tiny[:, None], mean, sum_ac / (3.0 * np.where(tiny, 1.0, sum_a))[:, None])
    area = np.where(tiny[:, None], 0.0, 0.5 * sum_n)
    tri = size == 3
    if tri.any():                                       # triangles directly (as OpenFOAM, no round-off)
        s = starts[tri]
        p0, p1, p2 = p[s], p[s + 1], p[s + 2]
        centre[tri] = (p0 + p1 + p2) / 3.0
        area[tri] = 0.5 * np.cross(p1 - p0, p2 - p0)
    return centre, area


def cell_centres_volumes(poly: Polyhedra, fc: np.ndarray, fa: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Cell centres (C, 3) and volumes (C,) from the face centres and areas, as
    ``primitiveMeshTools::makeCellCentresAndVols`` (pyramids about the mean of the face centres)."""
    own, nei = poly.owner, poly.neighbour
    inner = nei >= 0
    nc = poly.n_cells
    count = np.maximum(poly.faces_per_cell(), 1)
    est = np.column_stack([np.bincount(own, fc[:, d], nc) + np.bincount(nei[inner], fc[inner, d], nc)
                           for d in range(3)]) / count[:, None]
    pyr_own = np.einsum("ij,ij->i", fa, fc - est[own])
    pyr_nei = np.einsum("ij,ij->i", fa[inner], est[nei[inner]] - fc[inner])
    vol = np.bincount(own, pyr_own, nc) + np.bincount(nei[inner], pyr_nei, nc)
    pc_own = 0.75 * fc + 0.25 * est[own]
    pc_nei = 0.75 * fc[inner] + 0.25 * est[nei[inner]]
    ctr = np.column_stack([np.bincount(own, pyr_own * pc_own[:, d], nc)
                           + np.bincount(nei[inner], pyr_nei * pc_nei[:, d], nc) for d in range(3)])
    ok = np.abs(vol) > VSMALL
    with np.errstate(invalid="ignore", divide="ignore"):
        ctr = np.where(ok[:, None], ctr / np.where(ok, vol, 1.0)[:, None], est)
    return ctr, vol / 3.0


def pyramid_volumes(poly: Polyhedra, fc: np.ndarray, fa: np.ndarray, cc: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray]:
    """The volumes of the face pyramids with apex at the owner's and the neighbour's centre, (F,)
    each (NaN on the neighbour side of boundary faces): positive when the face points out of the
    owner and into the neighbour (``primitiveMeshTools::facePyramidVolume``)."""
    own = np.einsum("ij,ij->i", fa, fc - cc[poly.owner]) / 3.0
    nei = np.full(poly.n_faces, np.nan)
    inner = poly.neighbour >= 0
    nei[inner] = np.einsum("ij,ij->i", fa[inner], cc[poly.neighbour[inner]] - fc[inner]) / 3.0
    return own, nei


# ----------------------------------------------------------------------------------------------
# Counted records: [n, v1 .. vn, n, v1 .. vn, ...] (OpenFOAM's ASCII faces, CGNS 3 NGON_n)
# ----------------------------------------------------------------------------------------------

def counted_offsets(tokens: np.ndarray, n_records: int) -> np.ndarray:
    """Start of each record in a flat array of counted records ``[n, v1..vn, n, ...]``: (R + 1,)
    positions, the last one where the records end. ValueError when the array holds fewer records,
    a count is negative, or values are left over (the message says at which record)."""
    tokens = np.ascontiguousarray(tokens, dtype=np.int64)
    starts, stop, bad = _counted_kernel(tokens, n_records)
    if bad >= 0:
        raise ValueError(f"record {bad}: {'negative count' if bad < n_records and stop >= 0 else 'ends early'}")
    if stop != len(tokens):
        raise ValueError(f"{len(tokens) - stop} values after the last of {n_records} records")
    return starts


def counted_offsets_reference(tokens: np.ndarray, n_records: int) -> np.ndarray:
    """Plain-Python reference of :func:`counted_offsets` (for the tests)."""
    out, pos = [], 0
    for r in range(n_records):
        if pos >= len(tokens) or tokens[pos] < 0 or pos + 1 + tokens[pos] > len(tokens):
            raise ValueError(f"record {r}")
        out.append(pos)
        pos += 1 + int(tokens[pos])
    if pos != len(tokens):
        raise ValueError("values left over")
    out.append(pos)
    return np.asarray(out, dtype=np.int64)


@njit(cache=True, nogil=True)
def _counted_kernel(tokens, n_records):  # pragma: no cover - compiled
    starts = np.empty(n_records + 1, np.int64)
    pos = 0
    n = tokens.shape[0]
    for r in range(n_records):
        if pos >= n or tokens[pos] < 0 or pos + 1 + tokens[pos] > n:
            return starts, pos, r
        starts[r] = pos
        pos += 1 + tokens[pos]
    starts[n_records] = pos
    return starts, pos, -1


def split_counted(tokens: np.ndarray, n_records: int) -> tuple[np.ndarray, np.ndarray]:
    """The flat values and offsets (R + 1,) of ``n_records`` counted records ``[n, v1..vn, ...]``
    in one compiled pass (:func:`counted_offsets` then :func:`from_counted` is its reference);
    ValueError as :func:`counted_offsets`."""
    tokens = np.ascontiguousarray(tokens, dtype=np.int64)
    values, offsets, stop, bad = _split_kernel(tokens, n_records)
    if bad >= 0:
        raise ValueError(f"record {bad}: {'negative count' if stop >= 0 and bad < n_records else 'ends early'}")
    if stop != len(tokens):
        raise ValueError(f"{len(tokens) - stop} values after the last of {n_records} records")
    return values, offsets


@njit(cache=True, nogil=True)
def _split_kernel(tokens, n_records):  # pragma: no cover - compiled
    n = tokens.shape[0]
    values = np.empty(max(n - n_records, 0), np.int64)
    offsets = np.zeros(n_records + 1, np.int64)
    pos = 0
    k = 0
    for r in range(n_records):
        if pos >= n or tokens[pos] < 0 or pos + 1 + tokens[pos] > n:
            return values[:0], offsets, pos, r
        size = tokens[pos]
        for j in range(size):
            values[k + j] = tokens[pos + 1 + j]
        k += size
        offsets[r + 1] = k
        pos += 1 + size
    return values[:k], offsets, pos, -1


def from_counted(tokens: np.ndarray, starts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The flat nodes and offsets (R + 1,) of counted records whose starts are ``starts``."""
    sizes = tokens[starts[:-1]]
    offsets = np.zeros(len(sizes) + 1, dtype=np.int64)
    np.cumsum(sizes, out=offsets[1:])
    keep = np.ones(len(tokens), dtype=bool)
    keep[starts[:-1]] = False
    return tokens[keep], offsets


# ----------------------------------------------------------------------------------------------
# From cell blocks (tetrahedra, pyramids, prisms, hexahedra in VTK order)
# ----------------------------------------------------------------------------------------------

#: The faces of each VTK cell type, node order giving the outward normal (right-hand rule).
CELL_FACES = {
    "tetra": ((0, 2, 1), (0, 1, 3), (1, 2, 3), (0, 3, 2)),
    "pyramid": ((0, 3, 2, 1), (0, 1, 4), (1, 2, 4), (2, 3, 4), (3, 0, 4)),
    "wedge": ((0, 2, 1), (3, 4, 5), (0, 1, 4, 3), (1, 2, 5, 4), (2, 0, 3, 5)),
    "hexahedron": ((0, 3, 2, 1), (4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6), (3, 0, 4, 7)),
}


def face_keys(faces: np.ndarray) -> np.ndarray:
    """(n, 4) a face's nodes sorted, padded with -1 (triangles): equal for the same face."""
    keys = np.full((len(faces), 4), -1, dtype=np.int64)
    keys[:, :faces.shape[1]] = np.sort(faces, axis=1)
    return keys


def polyhedra_from_cells(blocks) -> tuple[Polyhedra, np.ndarray]:
    """The :class:`Polyhedra` of cell blocks (``.type``, ``.data`` in VTK order, volume types only),
    in OpenFOAM's order: internal faces first, by owner then neighbour (owner < neighbour, the face
    pointing out of the owner), then the boundary faces by owner. Returns it and the boundary faces'
    keys (:func:`face_keys`, (B, 4)) to match them to markers. Cells are numbered block after block."""
    tris, quads, cell0 = [], [], 0
    for b in blocks:
        data = np.asarray(b.data, dtype=np.int64)
        ids = cell0 + np.arange(len(data), dtype=np.int64)
        for f in CELL_FACES[b.type]:
            (tris if len(f) == 3 else quads).append((data[:, f], ids))
        cell0 += len(data)
    faces = [np.vstack([f for f, _ in group]) if group else np.zeros((0, k), np.int64)
             for group, k in ((tris, 3), (quads, 4))]
    cells = [np.concatenate([c for _, c in group]) if group else np.zeros(0, np.int64) for group in (tris, quads)]
    nodes4 = np.full((len(faces[0]) + len(faces[1]), 4), -1, dtype=np.int64)
    nodes4[:len(faces[0]), :3] = faces[0]
    nodes4[len(faces[0]):] = faces[1]
    cell = np.concatenate(cells)
    keys = np.vstack([face_keys(faces[0]), face_keys(faces[1])])
    order = np.lexsort(keys.T[::-1])
    keys, nodes4, cell = keys[order], nodes4[order], cell[order]
    first = np.ones(len(keys), dtype=bool)
    first[1:] = (keys[1:] != keys[:-1]).any(axis=1)
    start = np.flatnonzero(first)
    count = np.diff(np.append(start, len(keys)))
    if (count > 2).any():
        raise ValueError(f"a face is shared by {count.max()} cells")
    pair = start[count == 2]
    a, b = cell[pair], cell[pair + 1]
    f_nodes = nodes4[pair].copy()
    swap = a > b                                  # owner the lower cell; its face points out of it
    f_nodes[swap] = nodes4[pair + 1][swap]
    own, nei = np.minimum(a, b), np.maximum(a, b)
    io = np.lexsort((nei, own))
    single = start[count == 1]
    bo = np.argsort(cell[single], kind="stable")
    all_nodes = np.vstack([f_nodes[io], nodes4[single][bo]])
    owner = np.concatenate([own[io], cell[single][bo]])
    neighbour = np.concatenate([nei[io], np.full(len(single), -1, dtype=np.int64)])
    size = np.where(all_nodes[:, 3] < 0, 3, 4)
    offsets = np.zeros(len(size) + 1, dtype=np.int64)
    np.cumsum(size, out=offsets[1:])
    flat = all_nodes[all_nodes >= 0]
    return Polyhedra(flat, offsets, owner, neighbour, cell0), keys[single][bo]


def concat_polyhedra(parts: list[Polyhedra]) -> Polyhedra:
    """One :class:`Polyhedra` of several (their point ids already global), cells numbered part
    after part."""
    if len(parts) == 1:
        return parts[0]
    nodes, offsets, owner, nei, base_k, base_c = [], [np.zeros(1, dtype=np.int64)], [], [], 0, 0
    for p in parts:
        nodes.append(p.face_nodes)
        offsets.append(p.face_offsets[1:] + base_k)
        owner.append(p.owner + base_c)
        nei.append(np.where(p.neighbour >= 0, p.neighbour + base_c, -1))
        base_k += int(p.face_offsets[-1])
        base_c += p.n_cells
    return Polyhedra(np.concatenate(nodes), np.concatenate(offsets), np.concatenate(owner), np.concatenate(nei),
                     base_c)


def reverse_faces(nodes: np.ndarray, offsets: np.ndarray, flip: np.ndarray) -> np.ndarray:
    """A copy of the flat face nodes with the faces of mask ``flip`` (F,) in reverse order (their
    normals turned round)."""
    out = nodes.copy()
    size = np.diff(offsets)
    faces = np.flatnonzero(flip)
    if not len(faces):
        return out
    n = size[faces]
    start = np.repeat(offsets[faces], n)
    pos = np.arange(int(n.sum())) - np.repeat(np.cumsum(n) - n, n)
    end = np.repeat(offsets[faces] + n - 1, n)
    out[start + pos] = nodes[end - pos]
    return out
