"""The source tree of the volume warp: Morton order of the targets, the k-d tree of the sources.

The warp's sources (surface nodes and fixed-marker nodes) are held in a k-d tree: median splits
on the widest coordinate, leaves of up to :data:`LEAF_SIZE` sources, the surface sources and the
fixed sources in separate subtrees under the root (:func:`build_forest`). Every node keeps a
``[lo, hi)`` range of the sources in tree order and its children (-1 for a leaf; children have
larger ids than their parent); :func:`node_geometry` gives its area, area-weighted centroid
``c_C`` and radius ``r`` (largest distance of a source from ``c_C``). The moments of the motion
and the traversal that aggregates far groups are :mod:`ffdcli.volume.warp`'s (they depend on the motion).
Everything here depends on the undeformed geometry only.

Targets are sorted along a Z-order (Morton) curve so that neighbours in memory walk the same tree
nodes (:func:`ffdcli.mesh.morton.morton_order`).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

#: Sources per tree leaf.
LEAF_SIZE = 16


def build_forest(pos: np.ndarray, n_first: int):
    """One tree over pos whose root splits [0, n_first) (surface) from the rest (fixed markers).

    Median splits over a far-field sphere and a wing together would put far-field and wing nodes
    in the same groups for a dozen levels (groups of radius ~ the farfield radius, which no wing
    target can aggregate); a subtree per kind keeps every group compact.
    """
    m = len(pos)
    if n_first in (0, m):
        return _build_tree(pos, LEAF_SIZE)
    parts = [_build_tree(np.ascontiguousarray(pos[:n_first]), LEAF_SIZE),
             _build_tree(np.ascontiguousarray(pos[n_first:]), LEAF_SIZE)]
    perm = [np.zeros(0, np.int64)]
    lo, hi, left, right = [np.array([0])], [np.array([m])], [np.array([1])], [np.array([0])]
    node_off, src_off = 1, 0
    for p, plo, phi, pl, pr in parts:
        perm.append(p + src_off)
        lo.append(plo + src_off)
        hi.append(phi + src_off)
        left.append(np.where(pl >= 0, pl + node_off, -1))
        right.append(np.where(pr >= 0, pr + node_off, -1))
        src_off += len(p)
        node_off += len(plo)
    right[0][0] = 1 + len(parts[0][1])
    return tuple(np.concatenate(x).astype(np.int64) for x in (perm, lo, hi, left, right))


@njit(cache=True)
def _build_tree(pos, leaf_size):
    """k-d tree over pos (M, 3): permutation and per-node [lo, hi) ranges and children."""
    m = pos.shape[0]
    cap = 2 * m + 1
    lo = np.empty(cap, np.int64)
    hi = np.empty(cap, np.int64)
    left = np.full(cap, -1, np.int64)
    right = np.full(cap, -1, np.int64)
    perm = np.arange(m)
    stack = np.empty(200, np.int64)
    lo[0] = 0
    hi[0] = m
    nn = 1
    stack[0] = 0
    sp = 1
    while sp > 0:
        sp -= 1
        k = stack[sp]
        a, b = lo[k], hi[k]
        if b - a <= leaf_size:
            continue
        best, axis = -1.0, 0
        for c in range(3):
            vmin, vmax = np.inf, -np.inf
            for j in range(a, b):
                v = pos[perm[j], c]
                vmin = min(vmin, v)
                vmax = max(vmax, v)
            if vmax - vmin > best:
                best, axis = vmax - vmin, c
        seg = perm[a:b].copy()
        keys = np.empty(b - a)
        for j in range(b - a):
            keys[j] = pos[seg[j], axis]
        o = np.argsort(keys, kind="mergesort")
        for j in range(b - a):
            perm[a + j] = seg[o[j]]
        mid = (a + b) // 2
        lo[nn], hi[nn] = a, mid
        lo[nn + 1], hi[nn + 1] = mid, b
        left[k], right[k] = nn, nn + 1
        stack[sp] = nn
        stack[sp + 1] = nn + 1
        sp += 2
        nn += 2
    return perm, lo[:nn].copy(), hi[:nn].copy(), left[:nn].copy(), right[:nn].copy()


@njit(cache=True)
def node_geometry(pos, area, lo, hi):
    """Per node: area-weighted centroid (nn, 3), radius (nn,) about it and total area (nn,).

    A node of zero area takes the plain mean of its sources as its centre."""
    nn = lo.shape[0]
    center = np.zeros((nn, 3))
    radius = np.zeros(nn)
    narea = np.zeros(nn)
    for k in range(nn):
        s = 0.0
        c0 = c1 = c2 = 0.0
        for j in range(lo[k], hi[k]):
            s += area[j]
            c0 += area[j] * pos[j, 0]
            c1 += area[j] * pos[j, 1]
            c2 += area[j] * pos[j, 2]
        if s > 0:
            c0, c1, c2 = c0 / s, c1 / s, c2 / s
        else:
            cnt = hi[k] - lo[k]
            c0 = c1 = c2 = 0.0
            for j in range(lo[k], hi[k]):
                c0 += pos[j, 0] / cnt
                c1 += pos[j, 1] / cnt
                c2 += pos[j, 2] / cnt
        r2 = 0.0
        for j in range(lo[k], hi[k]):
            d = (pos[j, 0] - c0) ** 2 + (pos[j, 1] - c1) ** 2 + (pos[j, 2] - c2) ** 2
            r2 = max(r2, d)
        center[k, 0], center[k, 1], center[k, 2] = c0, c1, c2
        # a hair larger than the largest distance so rounding never makes it too small
        radius[k] = math.sqrt(r2) * (1.0 + 1e-12)
        narea[k] = s
    return center, radius, narea
