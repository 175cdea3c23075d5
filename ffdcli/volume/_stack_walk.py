"""Compiled kernels of the stack walk (:mod:`ffdcli.volume.wall_stacks`): the cells of each node, and
every wall node's stack walked one node at a time, each stack on its own (no Python loop over
layers or nodes)."""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange


@njit(cache=True)
def node_cells(pad: np.ndarray, n: int):
    """The cells of each node of cells ``pad`` (C, 8; -1 padded) as CSR: (cell ids, pointers (n + 1,)),
    each node's cells in increasing order (a counting sort)."""
    ptr = np.zeros(n + 1, np.int64)
    for c in range(pad.shape[0]):
        for q in range(pad.shape[1]):
            v = pad[c, q]
            if v >= 0:
                ptr[v + 1] += 1
    for i in range(n):
        ptr[i + 1] += ptr[i]
    fill = ptr[:-1].copy()
    cell_of = np.empty(ptr[n], np.int64)
    for c in range(pad.shape[0]):
        for q in range(pad.shape[1]):
            v = pad[c, q]
            if v >= 0:
                cell_of[fill[v]] = c
                fill[v] += 1
    return cell_of, ptr


@njit(cache=True, parallel=True)
def walk_stacks(pts, pad, cell_of, ptr, on_wall, up, spacing, first, max_layers, stack_cos, wall, stop):
    """(Ns,) each stack's top node, from its first off-wall node ``first`` (-1: none): on to the node of
    the top's cells most aligned with ``up`` (Ns, 3) (the first of equals) while its edge is within
    ``stack_cos`` of it and shorter than ``spacing``, and the top's height over its wall node ``wall``
    (Ns,) along ``up`` is at most ``stop`` (Ns,; inf: no stop) (the heights are the caller's, as the
    vectorised walk computes them)."""
    ns = first.shape[0]
    top = first.copy()
    for k in prange(ns):               # each stack on its own
        f = first[k]
        if f < 0:
            continue
        w = wall[k]
        for _ in range(max_layers):
            h = ((pts[f, 0] - pts[w, 0]) * up[k, 0] + (pts[f, 1] - pts[w, 1]) * up[k, 1]
                 + (pts[f, 2] - pts[w, 2]) * up[k, 2])
            if h > stop[k]:
                break
            best = -1
            best_cos = stack_cos
            best_ln = 0.0
            for j in range(ptr[f], ptr[f + 1]):
                c = cell_of[j]
                for q in range(pad.shape[1]):
                    v = pad[c, q]
                    if v < 0 or on_wall[v]:
                        continue
                    e0 = pts[v, 0] - pts[f, 0]
                    e1 = pts[v, 1] - pts[f, 1]
                    e2 = pts[v, 2] - pts[f, 2]
                    dot = e0 * up[k, 0] + e1 * up[k, 1] + e2 * up[k, 2]
                    if dot <= 0.0 and best_cos >= 0.0:     # no closer to the normal than the best: skip the root
                        continue
                    ln = math.sqrt(e0 * e0 + e1 * e1 + e2 * e2)
                    cos = dot / (ln if ln > 0 else 1.0)
                    if cos > best_cos:
                        best, best_cos, best_ln = v, cos, ln
            if best < 0 or not best_ln < spacing[k]:
                break
            f = best
        top[k] = f
    return top
