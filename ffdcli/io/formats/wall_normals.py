"""SU2's vertex normals of wall nodes, pointing into the fluid: what turns a continuous adjoint's scalar
surface sensitivity S (``Surface_Sensitivity`` of SU2's ``surface_adjoint.csv``) into dJ/dX = -S n̂.

SU2_DOT projects that file as ``SetProjection_FD`` in ``SU2_DEF/src/drivers/CDiscAdjDeformationDriver.cpp``
does: dJ/dε = Σ_wall −S (n̂ · dx/dε), n̂ the unit vertex normal into the fluid. Its vertex normal is the
sum of the dual-face normals of the wall elements around the node:

* 2D: each wall edge oriented so that the fluid (the cell that owns the edge) lies to its left; the
  edge's normal is its left normal of the edge's length; a node's normal is the sum of the halves of
  its two edges' normals;
* 3D: each wall face's area vector, oriented toward its cell; a node gets the face's vector divided by
  the face's node count (the median-dual share, exact for triangles).

Checked against SU2_DOT to 1e-15 relative on SU2's NACA0012 case (docs/optimize.md).
"""

from __future__ import annotations

import numpy as np

from ffdcli.errors import InputError

#: The faces of each cell type (VTK node order): wall elements are matched to these.
CELL_FACES = {
    "triangle": ((0, 1), (1, 2), (2, 0)),
    "quad": ((0, 1), (1, 2), (2, 3), (3, 0)),
    "tetra": ((0, 1, 2), (0, 1, 3), (1, 2, 3), (0, 2, 3)),
    "pyramid": ((0, 1, 2, 3), (0, 1, 4), (1, 2, 4), (2, 3, 4), (3, 0, 4)),
    "wedge": ((0, 1, 2), (3, 4, 5), (0, 1, 4, 3), (1, 2, 5, 4), (2, 0, 3, 5)),
    "hexahedron": ((0, 1, 2, 3), (4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6), (3, 0, 4, 7)),
}


def _keys(faces: np.ndarray, width: int) -> np.ndarray:
    """One comparable key per face: its sorted node ids padded with -1 to ``width``, as a void scalar."""
    k = np.full((len(faces), width), -1, dtype=np.int64)
    k[:, :faces.shape[1]] = np.sort(faces, axis=1)
    return np.ascontiguousarray(k).view(np.dtype((np.void, 8 * width))).ravel()


def _owner_centroids(mesh, points: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(F, 3) the centroid of the interior cell that owns each wall face ``faces`` (F, k)."""
    width = 4
    want = _keys(faces, width)
    order = np.argsort(want)
    found = np.zeros(len(faces), dtype=bool)
    out = np.zeros((len(faces), 3))
    for block in mesh.cells:
        table = CELL_FACES.get(block.type)
        if table is None:
            continue
        centroid = points[block.data].mean(axis=1)
        for face in table:
            keys = _keys(block.data[:, list(face)], width)
            pos = np.searchsorted(want[order], keys)
            pos = np.minimum(pos, len(want) - 1)
            hit = want[order][pos] == keys
            rows = order[pos[hit]]
            out[rows] = centroid[hit]
            found[rows] = True
    if not found.all():
        raise InputError(f"{int((~found).sum())} wall faces belong to no interior cell of the mesh; the "
                         "surface sensitivity needs the volume mesh to orient the wall normals", path=mesh.path)
    return out


def wall_vertex_normals(mesh, points: np.ndarray, markers) -> tuple[np.ndarray, np.ndarray]:
    """(ids (K,), unit normals (K, 3)) of the nodes of ``markers``, SU2's vertex normals into the fluid.

    Parameters
    ----------
    mesh : ffdcli.mesh.Mesh
        The mesh with its interior cells (to know which side is the fluid).
    points : ndarray, shape (N, 3)
        The node coordinates of the design (the deformed mesh).
    markers : list of str
        The wall markers.
    """
    blocks = [b for name in markers for b in mesh.markers[name] if b.type != "vertex"]
    acc = np.zeros((mesh.n_points, 3))
    for block in blocks:
        f = block.data
        owner = _owner_centroids(mesh, points, f)
        p = points[f]                                             # (F, k, 3)
        if f.shape[1] == 2:                                       # a 2D edge: left normal, length |e|
            e = p[:, 1] - p[:, 0]
            n = np.stack([-e[:, 1], e[:, 0], np.zeros(len(e))], axis=1)
        elif f.shape[1] == 4:                                     # a quad's area vector: half the diagonals' cross
            n = 0.5 * np.cross(p[:, 2] - p[:, 0], p[:, 3] - p[:, 1])
        else:                                                     # a triangle's area vector
            n = 0.5 * np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
        side = np.einsum("ij,ij->i", owner - p.mean(axis=1), n)
        n = np.where(side[:, None] < 0, -n, n)                    # toward the owning cell: into the fluid
        share = n / f.shape[1]
        for c in range(f.shape[1]):
            np.add.at(acc, f[:, c], share)
    ids = np.unique(np.concatenate([b.data.ravel() for b in blocks])) if blocks else np.zeros(0, np.int64)
    nrm = acc[ids]
    length = np.linalg.norm(nrm, axis=1)
    length[length == 0] = 1.0
    return ids, nrm / length[:, None]


def surface_sensitivity_gradient(mesh, points: np.ndarray, ids: np.ndarray, S: np.ndarray) -> np.ndarray:
    """dJ/dX (K, 3) = −S n̂ at wall nodes ``ids`` (K,) from SU2's scalar surface sensitivity ``S`` (K,).

    The wall is every marker all of whose nodes are among ``ids`` (the file's rows); n̂ is
    :func:`wall_vertex_normals` on ``points`` (the design's coordinates)."""
    have = np.zeros(mesh.n_points, dtype=bool)
    have[ids] = True
    markers = [name for name, blocks in mesh.markers.items()
               if blocks and all(have[b.data].all() for b in blocks if b.type != "vertex")
               and any(b.type != "vertex" for b in blocks)]
    if not markers:
        raise InputError("the surface sensitivity's rows cover no whole marker of the mesh; it needs the wall "
                         "marker(s) the solver monitored", path=mesh.path)
    wall, normals = wall_vertex_normals(mesh, points, markers)
    pos = np.searchsorted(wall, ids)
    pos = np.minimum(pos, len(wall) - 1)
    on = wall[pos] == ids
    out = np.zeros((len(ids), 3))
    out[on] = -S[on, None] * normals[pos[on]]
    return out
