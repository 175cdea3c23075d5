"""Signed sizes of cells, the fixtures' test of inversion (NumPy; no gmsh).

ffd's own gate (:func:`ffdcli.quality.gate.cell_quality`) measures shape; these measure the sign
and size a generator must get right: tetrahedra and hexahedra in VTK order, quads in the x-y plane.
"""

from __future__ import annotations

import numpy as np


def tet_volumes(points: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """Signed volumes (n,) of VTK-ordered tetrahedra ``tets`` (n, 4) of ``points`` (N, 3).

    Positive when node 3 is on the side of the right-hand normal of nodes 0, 1, 2 (the VTK and SU2
    orientation).
    """
    p = points[tets]
    return np.einsum("ij,ij->i", np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), p[:, 3] - p[:, 0]) / 6.0


def hex_volumes(points: np.ndarray, hexes: np.ndarray) -> np.ndarray:
    """Smallest signed volume of the 8 corner tetrahedra of each VTK hexahedron, (n,).

    Corner ``c`` spans its three edge neighbours in right-handed order; all eight are positive for a
    valid (convex, correctly ordered) hexahedron, so the minimum is the test of inversion.
    """
    p = np.asarray(points, dtype=np.float64)[hexes]
    # corner -> its three neighbours along the bottom/top loop and up, in right-handed order
    nb = np.array([[1, 3, 4], [2, 0, 5], [3, 1, 6], [0, 2, 7],
                   [7, 5, 0], [4, 6, 1], [5, 7, 2], [6, 4, 3]])
    c = np.arange(8)
    e = p[:, nb] - p[:, c, None]                                      # (n, 8, 3, 3)
    vol = np.einsum("nci,nci->nc", np.cross(e[:, :, 0], e[:, :, 1]), e[:, :, 2]) / 6.0
    return vol.min(axis=1)

def quad_areas(points: np.ndarray, quads: np.ndarray) -> np.ndarray:
    """Signed areas in the x-y plane of the two triangles of each quad, (n, 2); both > 0 for a valid
    counter-clockwise quad (the minimum is the test of inversion)."""
    p = points[:, :2][quads]

    def tri(a, b, c):
        return 0.5 * ((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0]))

    t = [tri(p[:, 0], p[:, 1], p[:, 2]), tri(p[:, 0], p[:, 2], p[:, 3]),
         tri(p[:, 0], p[:, 1], p[:, 3]), tri(p[:, 1], p[:, 2], p[:, 3])]
    return np.stack([np.minimum(t[0], t[1]), np.minimum(t[2], t[3])], axis=1)
