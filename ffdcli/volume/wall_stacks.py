"""How thick the stacked layers on a wall are: each wall node's stack of thin cells, walked from the mesh.

From a wall node's off-wall edge (:func:`ffdcli.volume.wall_layer.off_wall_edges`) the stack goes on,
one node at a time, to the node sharing a cell with the stack's top that is farthest along the wall
normal's direction (the next quad's or prism's), for as long as that edge stays within
:data:`STACK_COS` of the normal and shorter than the wall's own spacing at the node (the cells still
thinner than wide). The stack's height is the top node's height over the wall node: the prism layer's
thickness on a tetrahedral mesh with prisms, the height at which a structured mesh's cells become as
tall as wide. All stacks advance together (one vectorised step per layer).
"""

from __future__ import annotations

import numpy as np

from ffdcli.mesh import CellBlock

#: A stack goes on along edges within 37 degrees of the wall normal (cos 0.8).
STACK_COS = 0.8
#: At most this many layers are walked.
MAX_LAYERS = 400


def _node_cells(cells: list[CellBlock], n: int):
    """(cells padded to 8 nodes with -1 (C, 8), the cells of each node as CSR: cell ids, pointers (n + 1,))."""
    pad = np.concatenate([np.pad(b.data, ((0, 0), (0, 8 - b.data.shape[1])), constant_values=-1)
                          for b in cells if len(b.data)])
    flat = pad.ravel()
    valid = flat >= 0
    cell_of = np.repeat(np.arange(len(pad)), 8)[valid]
    node = flat[valid]
    order = np.argsort(node, kind="stable")
    ptr = np.r_[0, np.cumsum(np.bincount(node, minlength=n))]
    return pad, cell_of[order], ptr


def stack_heights(points: np.ndarray, cells: list[CellBlock], wall_ids: np.ndarray, normals: np.ndarray,
                  spacing: np.ndarray, first: np.ndarray) -> np.ndarray:
    """(Ns,) each wall node's stack height (module docstring).

    ``normals`` (Ns, 3) unit wall normals pointing anywhere (the stack goes the way its first edge goes);
    ``spacing`` (Ns,) the shortest wall edge at each node; ``first`` (Ns,) the off-wall edge's far node
    (-1: none)."""
    pts = np.asarray(points, dtype=np.float64)
    ns = len(wall_ids)
    on_wall = np.zeros(len(pts), bool)
    on_wall[wall_ids] = True
    base = pts[wall_ids]
    height = np.zeros(ns)
    alive = first >= 0
    up = normals.copy()
    sign = np.sign(np.einsum("ij,ij->i", pts[np.maximum(first, 0)] - base, up))
    up *= np.where(sign == 0, 1.0, sign)[:, None]          # the normal the stack's way
    height[alive] = np.einsum("ij,ij->i", pts[first[alive]] - base[alive], up[alive])
    front = first.copy()
    pad, cell_of, ptr = _node_cells(cells, len(pts))
    for _ in range(MAX_LAYERS):
        k = np.flatnonzero(alive)
        if not len(k):
            break
        f = front[k]
        counts = ptr[f + 1] - ptr[f]
        total = int(counts.sum())
        start = np.repeat(ptr[f] - np.r_[0, np.cumsum(counts)[:-1]], counts)
        cand = pad[cell_of[start + np.arange(total)]]              # (m, 8) nodes of the front's cells
        kk = np.repeat(np.repeat(k, counts), 8)
        cc = cand.ravel()
        ok = cc >= 0
        kk, cc = kk[ok], cc[ok]
        ok = ~on_wall[cc]
        kk, cc = kk[ok], cc[ok]
        e = pts[cc] - pts[front[kk]]
        ln = np.linalg.norm(e, axis=1)
        cos = np.einsum("ij,ij->i", e, up[kk]) / np.where(ln > 0, ln, 1.0)
        ok = cos > STACK_COS
        kk, cc, cos, ln = kk[ok], cc[ok], cos[ok], ln[ok]
        order = np.lexsort((-cos, kk))
        firsts = np.r_[True, kk[order][1:] != kk[order][:-1]] if len(order) else np.zeros(0, bool)
        pick_k, pick_c, pick_ln = kk[order][firsts], cc[order][firsts], ln[order][firsts]
        thin = pick_ln < spacing[pick_k]
        alive[k] = False
        go_k, go_c = pick_k[thin], pick_c[thin]
        alive[go_k] = True
        front[go_k] = go_c
        height[go_k] = np.einsum("ij,ij->i", pts[go_c] - base[go_k], up[go_k])
    return height
