"""Thin boundary-layer prisms under a tetrahedral wing mesh, in NumPy (a fixture; no gmsh).

:func:`add_prism_layers` pushes the tetrahedral mesh's wing nodes off the wall along the vertex
normals by the layer height (in the symmetry plane the normal is projected into the plane) and fills
the gap between the wall (the original wing nodes) and the pushed nodes with ``layers`` wedges per
wall triangle; the symmetry marker gets the quads the layers cut in the plane. The height is limited
locally to 0.3 of the shortest tetrahedron edge at the node and halved where a cell would not be
valid, so no cell inverts. Used by :func:`ffdcli.testing.gmsh_wings.wing_volume_mesh`.
"""

from __future__ import annotations

import numpy as np

from ffdcli.mesh import CellBlock, Mesh
from ffdcli.mesh.idsets import unique_ids
from ffdcli.quality.metrics import cell_quality


def add_prism_layers(points: np.ndarray, tets: np.ndarray, markers: dict[str, np.ndarray], *,
                     span_axis: int, root: float, layers: int, first: float, growth: float) -> Mesh:
    """Insert ``layers`` wedge layers between the wing wall and the tetrahedra (module docstring).

    ``markers`` hold triangles oriented out of the fluid (``wing``, ``symmetry``, ``farfield``).
    Returns the Mesh (tetra + wedge blocks; symmetry gets triangle + quad blocks).
    """
    wing = markers["wing"]
    wall = unique_ids(wing)
    n0 = len(points)
    p = points[wing]
    fn = -np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])           # into the fluid, |.| = 2 area
    on_sym = np.zeros(n0, dtype=bool)
    on_sym[unique_ids(markers["symmetry"])] = True
    vn = _wall_normals(n0, wing, fn / np.linalg.norm(fn, axis=1)[:, None], on_sym, span_axis)
    # local limit: 0.3 of the shortest tetrahedron edge at each wall node
    shortest = np.full(n0, np.inf)
    for a, b in ((0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)):
        ln = np.linalg.norm(points[tets[:, a]] - points[tets[:, b]], axis=1)
        np.minimum.at(shortest, tets[:, a], ln)
        np.minimum.at(shortest, tets[:, b], ln)
    heights = first * np.cumsum(growth ** np.arange(layers))           # top of each layer (layers,)
    scale = np.minimum(1.0, 0.3 * shortest[wall] / heights[-1])        # (W,)
    # node ids: layer 0 (the wall) .. layers-1 are new; the top is the original node, pushed off
    nw = len(wall)
    ids = np.full((layers + 1, n0), -1, dtype=np.int64)
    ids[layers, wall] = wall
    ids[:layers, wall] = n0 + np.arange(layers)[:, None] * nw + np.arange(nw)[None, :]
    # wedges: bottom triangle with its normal into the fluid (towards the top), VTK order
    tri = wing[:, [0, 2, 1]]
    wedges = np.concatenate([np.concatenate([ids[k][tri], ids[k + 1][tri]], axis=1) for k in range(layers)])
    base = points[wall]
    offs = np.concatenate([[0.0], heights[:-1]])                     # bottom of layers 0..layers-1
    sym_wall = on_sym[wall]
    pos = np.full(n0, -1)
    pos[wall] = np.arange(nw)
    for _ in range(8):      # halve the layers locally where a cell would not be valid
        pts = np.concatenate([points, np.empty((layers * nw, 3))])
        for k in range(layers):
            pts[ids[k, wall]] = base + (offs[k] * scale)[:, None] * vn[wall]
        pts[wall] = base + (heights[-1] * scale)[:, None] * vn[wall]
        pts[np.flatnonzero(on_sym), span_axis] = root                 # exactly in the plane
        for k in range(layers):
            pts[ids[k, wall[sym_wall]], span_axis] = root
        bad_nodes = [c[_quality(pts, c, t) <= 0].ravel() for c, t in ((tets, "tetra"), (wedges, "wedge"))]
        bad = unique_ids(*bad_nodes)
        bad = bad[bad < n0]
        bad = bad[pos[bad] >= 0]
        if len(bad) == 0 and all(len(b) == 0 for b in bad_nodes):
            break
        if len(bad) == 0:        # a bad cell without a wall node of its own: shrink its wedges' walls
            wn = unique_ids(*bad_nodes)
            bad = wall[np.isin(ids[:, wall], wn).any(axis=0)]
        scale[pos[bad]] *= 0.5
    # symmetry quads: wing-triangle edges with both nodes in the plane
    edges = np.concatenate([wing[:, [0, 1]], wing[:, [1, 2]], wing[:, [2, 0]]])
    owner = np.tile(np.arange(len(wing)), 3)
    root_edge = on_sym[edges[:, 0]] & on_sym[edges[:, 1]]
    e, own = edges[root_edge], owner[root_edge]
    quads, qcells = [], []
    for k in range(layers):
        quads.append(np.stack([ids[k][e[:, 0]], ids[k][e[:, 1]], ids[k + 1][e[:, 1]], ids[k + 1][e[:, 0]]], axis=1))
        qcells.append(k * len(wing) + own)
    quads = np.concatenate(quads)
    qcells = np.concatenate(qcells)
    qp = pts[quads]
    qn = np.cross(qp[:, 2] - qp[:, 0], qp[:, 3] - qp[:, 1])
    out = np.einsum("ij,ij->i", qn, qp.mean(axis=1) - pts[wedges[qcells]].mean(axis=1)) > 0
    quads = np.where(out[:, None], quads, quads[:, ::-1])
    new_wing = ids[0][wing]
    mk = {"wing": [CellBlock("triangle", new_wing)],
          "symmetry": [CellBlock("triangle", markers["symmetry"]), CellBlock("quad", quads)],
          "farfield": [CellBlock("triangle", markers["farfield"])]}
    return Mesh(points=pts, dim=3, cells=[CellBlock("tetra", tets), CellBlock("wedge", wedges)], markers=mk)


def _quality(points, cells, ctype):
    return cell_quality(points, [CellBlock(ctype, cells)]) if len(cells) else np.zeros(0)


def _wall_normals(n0: int, wing: np.ndarray, fu: np.ndarray, on_sym: np.ndarray, span_axis: int,
                  iterations: int = 60) -> np.ndarray:
    """Vertex directions that see every adjacent face from its fluid side: start from the sum of the
    unit face normals, then pull each node's direction towards the adjacent face it sees worst (at a
    sharp trailing edge the result tends to the bisector). Nodes in the symmetry plane stay in it."""
    node = wing.ravel()                                              # (3F,) pairs node -> face
    face = np.repeat(np.arange(len(wing)), 3)
    vn = np.zeros((n0, 3))
    np.add.at(vn, node, fu[face])

    def norm(v):
        v[on_sym, span_axis] = 0.0
        ln = np.linalg.norm(v, axis=1)
        v[ln > 0] /= ln[ln > 0][:, None]
        return v

    vn = norm(vn)
    for it in range(iterations):
        dots = np.einsum("ij,ij->i", vn[node], fu[face])
        worst = np.full(n0, np.inf)
        np.minimum.at(worst, node, dots)
        pick = dots <= worst[node]
        step = np.zeros((n0, 3))
        np.add.at(step, node[pick], fu[face[pick]])
        vn = norm(vn + 0.3 * 0.9 ** it * step)
    return vn
