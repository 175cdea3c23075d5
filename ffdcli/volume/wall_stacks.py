"""How thick the stacked layers on a wall are: each wall node's stack of thin cells, walked from the mesh.

From a wall node's off-wall edge (:func:`ffdcli.volume.wall_layer.off_wall_edges`) the stack goes on,
one node at a time, to the node sharing a cell with the stack's top that is farthest along the wall
normal's direction (the next quad's or prism's; the first of equals), for as long as that edge stays within
:data:`STACK_COS` of the normal and shorter than the wall's own spacing at the node (the cells still
thinner than wide). The stack's height is the top node's height over the wall node: the prism layer's
thickness on a tetrahedral mesh with prisms, the height at which a structured mesh's cells become as
tall as wide. Each stack is walked by a compiled kernel (:mod:`ffdcli.volume._stack_walk`).
"""

from __future__ import annotations

import numpy as np

from ffdcli.mesh import CellBlock
from ffdcli.volume._stack_walk import node_cells, walk_stacks

#: A stack goes on along edges within 37 degrees of the wall normal (cos 0.8).
STACK_COS = 0.8
#: At most this many layers are walked.
MAX_LAYERS = 400


def _padded(cells: list[CellBlock]) -> np.ndarray:
    """(C, 8) the cells' nodes padded with -1."""
    blocks = [b.data for b in cells if len(b.data)]
    pad = np.full((sum(len(d) for d in blocks), 8), -1, dtype=np.int64)
    start = 0
    for d in blocks:                    # one copy per cell block
        pad[start:start + len(d), :d.shape[1]] = d
        start += len(d)
    return pad


def stack_heights(points: np.ndarray, cells: list[CellBlock], wall_ids: np.ndarray, normals: np.ndarray,
                  spacing: np.ndarray, first: np.ndarray) -> np.ndarray:
    """(Ns,) each wall node's stack height (module docstring).

    ``normals`` (Ns, 3) unit wall normals pointing anywhere (the stack goes the way its first edge goes);
    ``spacing`` (Ns,) the shortest wall edge at each node; ``first`` (Ns,) the off-wall edge's far node
    (-1: none)."""
    pts = np.asarray(points, dtype=np.float64)
    on_wall = np.zeros(len(pts), bool)
    on_wall[wall_ids] = True
    base = pts[wall_ids]
    up = normals.copy()
    sign = np.sign(np.einsum("ij,ij->i", pts[np.maximum(first, 0)] - base, up))
    up *= np.where(sign == 0, 1.0, sign)[:, None]          # the normal the stack's way
    pad = _padded(cells)
    cell_of, ptr = node_cells(pad, len(pts))
    return walk_stacks(pts, pad, cell_of, ptr, on_wall, np.ascontiguousarray(base), np.ascontiguousarray(up),
                       np.asarray(spacing, dtype=np.float64), np.asarray(first, dtype=np.int64), MAX_LAYERS,
                       STACK_COS)
