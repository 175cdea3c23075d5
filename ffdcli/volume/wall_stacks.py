"""How thick the stacked layers on a wall are: each wall node's stack of thin cells, walked from the mesh.

From a wall node's off-wall edge (:func:`ffdcli.volume.wall_layer.off_wall_edges`) the stack goes on,
one node at a time, to the node sharing a cell with the stack's top that is farthest along the wall
normal's direction (the next quad's or prism's), for as long as that edge stays within
:data:`STACK_COS` of the normal and shorter than the wall's own spacing at the node (the cells still
thinner than wide). The stack's height is the top node's height over the wall node: the prism layer's
thickness on a tetrahedral mesh with prisms, the height at which a structured mesh's cells become as
tall as wide. Serially each stack is walked on its own by a compiled kernel
(:mod:`ffdcli.volume._stack_walk`); under MPI all stacks advance together, one vectorised step per layer.
"""

from __future__ import annotations

import numpy as np

from ffdcli.mesh import CellBlock
from ffdcli.parallel.distributed import RankNodes
from ffdcli.volume._stack_walk import node_cells, walk_stacks

#: A stack goes on along edges within 37 degrees of the wall normal (cos 0.8).
STACK_COS = 0.8
#: At most this many layers are walked.
MAX_LAYERS = 400
#: A stack walked serially stops once its top is this much (relatively) higher than the caller's cap
#: (:func:`stack_heights`): far above the rounding of a height, which the kernel and NumPy may sum
#: in other orders.
CAP_MARGIN = 1e-6


def _node_cells(cells: list[CellBlock], n: int):
    """(cells padded to 8 nodes with -1 (C, 8), the cells of each node as CSR: cell ids, pointers (n + 1,))."""
    blocks = [np.pad(b.data, ((0, 0), (0, 8 - b.data.shape[1])), constant_values=-1) for b in cells if len(b.data)]
    pad = np.concatenate(blocks) if blocks else np.zeros((0, 8), np.int64)
    flat = pad.ravel()
    valid = flat >= 0
    cell_of = np.repeat(np.arange(len(pad)), 8)[valid]
    node = flat[valid]
    order = np.argsort(node, kind="stable")
    ptr = np.r_[0, np.cumsum(np.bincount(node, minlength=n))]
    return pad, cell_of[order], ptr


def _padded(cells: list[CellBlock]) -> np.ndarray:
    """(C, 8) the cells' nodes padded with -1."""
    blocks = [b.data for b in cells if len(b.data)]
    pad = np.full((sum(len(d) for d in blocks), 8), -1, dtype=np.int64)
    start = 0
    for d in blocks:                    # one copy per cell block
        pad[start:start + len(d), :d.shape[1]] = d
        start += len(d)
    return pad


def _gather(nodes: RankNodes | None, *arrays: np.ndarray) -> tuple[np.ndarray, ...]:
    """Every rank's ``arrays`` (rows of one step, each row found by one rank), concatenated; serially themselves."""
    if nodes is None:
        return arrays
    got = nodes.comm.allgather(arrays)
    return tuple(np.concatenate([g[j] for g in got]) for j in range(len(arrays)))


def stack_heights(points: np.ndarray, cells: list[CellBlock], wall_ids: np.ndarray, normals: np.ndarray,
                  spacing: np.ndarray, first: np.ndarray, nodes: RankNodes | None = None,
                  cap: np.ndarray | None = None) -> np.ndarray:
    """(Ns,) each wall node's stack height (module docstring).

    ``normals`` (Ns, 3) unit wall normals pointing anywhere (the stack goes the way its first edge goes);
    ``spacing`` (Ns,) the shortest wall edge at each node; ``first`` (Ns,) the off-wall edge's far node
    (-1: none). ``cap`` (Ns,): the caller takes ``min(height, cap)``, so a stack may stop once it is
    higher than ``cap`` (each step of a stack raises its top: ``min(height, cap)`` is the same, bit for
    bit, while the walk stops short, :data:`CAP_MARGIN`); serially only.

    ``nodes``: of one MPI rank's local mesh (a collective; ``first`` then holds global ids, and
    ``wall_ids`` every wall node, as on every rank): each step of a stack is taken by the rank owning
    its top node, which holds every cell around it, by the serial arithmetic, and the steps are
    gathered (one gather per layer), so every rank returns the serial heights bit for bit."""
    pts = np.asarray(points, dtype=np.float64)
    ns = len(wall_ids)
    on_wall = np.zeros(len(pts), bool)
    on_wall[wall_ids] = True
    rows = (lambda g: g) if nodes is None else nodes.rows
    base = pts[wall_ids]
    height = np.zeros(ns)
    alive = first >= 0
    up = normals.copy()
    # the normal the stack's way and the first edge's height, by the rank holding the wall node's cells
    k0 = np.flatnonzero(alive if nodes is None else alive & nodes.owned[wall_ids])
    e0 = pts[rows(first[k0])] - base[k0]
    sign = np.sign(np.einsum("ij,ij->i", e0, up[k0]))
    sign = np.where(sign == 0, 1.0, sign)
    h0 = np.einsum("ij,ij->i", e0, up[k0] * sign[:, None])
    k0, sign, h0 = _gather(nodes, k0, sign, h0)
    up[k0] *= sign[:, None]
    height[k0] = h0
    front = first.copy()
    if nodes is None:                   # serially: each stack walked on its own by a compiled kernel
        pad = _padded(cells)
        cell_of, ptr = node_cells(pad, len(pts))
        stop = np.full(ns, np.inf) if cap is None else (1.0 + CAP_MARGIN) * np.asarray(cap, np.float64)
        top = walk_stacks(pts, pad, cell_of, ptr, on_wall, np.ascontiguousarray(up), np.asarray(spacing, np.float64),
                          np.asarray(first, np.int64), MAX_LAYERS, STACK_COS, np.asarray(wall_ids, np.int64), stop)
        moved = np.flatnonzero(top != first)
        height[moved] = np.einsum("ij,ij->i", pts[top[moved]] - base[moved], up[moved])
        return height
    pad, cell_of, ptr = _node_cells(cells, len(pts))
    for _ in range(MAX_LAYERS):
        k = np.flatnonzero(alive)
        if not len(k):
            break
        here = k if nodes is None else k[nodes.owns(front[k])]
        go_k, go_c = _step(pts, pad, cell_of, ptr, on_wall, up, spacing, here, rows(front[here]))
        h = np.einsum("ij,ij->i", pts[go_c] - base[go_k], up[go_k])
        go_k, go_c, h = _gather(nodes, go_k, go_c if nodes is None else nodes.ids[go_c], h)
        alive[k] = False
        alive[go_k] = True
        front[go_k] = go_c
        height[go_k] = h
    return height


def _step(pts, pad, cell_of, ptr, on_wall, up, spacing, k: np.ndarray, f: np.ndarray):
    """One layer of the stacks ``k`` whose tops are the rows ``f``: the stacks that go on and their new tops
    (rows), the node of the tops' cells farthest along the normal while thinner than wide (module docstring)."""
    counts = ptr[f + 1] - ptr[f]
    total = int(counts.sum())
    start = np.repeat(ptr[f] - np.r_[0, np.cumsum(counts)[:-1]], counts)
    cand = pad[cell_of[start + np.arange(total)]]              # (m, 8) nodes of the front's cells
    kk = np.repeat(np.repeat(k, counts), 8)
    ff = np.repeat(np.repeat(f, counts), 8)
    cc = cand.ravel()
    ok = cc >= 0
    kk, ff, cc = kk[ok], ff[ok], cc[ok]
    ok = ~on_wall[cc]
    kk, ff, cc = kk[ok], ff[ok], cc[ok]
    e = pts[cc] - pts[ff]
    ln = np.linalg.norm(e, axis=1)
    cos = np.einsum("ij,ij->i", e, up[kk]) / np.where(ln > 0, ln, 1.0)
    ok = cos > STACK_COS
    kk, cc, cos, ln = kk[ok], cc[ok], cos[ok], ln[ok]
    order = np.lexsort((-cos, kk))
    firsts = np.r_[True, kk[order][1:] != kk[order][:-1]] if len(order) else np.zeros(0, bool)
    pick_k, pick_c, pick_ln = kk[order][firsts], cc[order][firsts], ln[order][firsts]
    thin = pick_ln < spacing[pick_k]
    return pick_k[thin], pick_c[thin]
