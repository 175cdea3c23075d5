"""The compiled kernels of the volume warp (:mod:`ffdcli.volume.warp`) other than the block walk
(:mod:`ffdcli.volume._warp_blocks`): one target's own walk of the tree for its reference weight, the
exact sums over every source and their transpose, the node moments and the push-down of the
transpose's node sums.

Their NumPy reference is :func:`ffdcli.volume.warp.idw_reference` (the exact sum), which the tests
compare the warp with; :func:`ffdcli.volume.warp.warp` and :func:`ffdcli.volume.warp.warp_vjp` are
the Python entry points. See :mod:`ffdcli.volume.warp` for the model (votes, groups, tolerance)."""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

#: Targets per parallel work item (inside a chunk).
_BLOCK = 128
#: Traversal stack size: the tree depth is at most log2(sources) + 1 < 64.
_STACK = 160

# ----------------------------------------------------------------------------------------------
# Kernels
#
# Votes per source (NV = 15 columns): [0:3] b (translation channel, weight w), [3:6] c = -M x_i and
# [6:15] M row-major (rotation channel, weight w g). Node moments (60 columns): [0:15] sum A v,
# [15 + 15 k + p] sum A (x_i - c_C)_k v_p.

NV = 15
NM = 60


@njit(cache=True, inline="always")
def _terms(q, ha, hb, ab, fast):
    """(L/r)^a and alpha^b (L/r)^b from q = (L/r)^2."""
    if fast:
        s = math.sqrt(q)
        qa = q * s
        return qa, ab * qa * q
    return q ** ha, ab * q ** hb


@njit(cache=True, inline="always")
def _fade(r2, rho2):
    """Rotation fade g = 1 / (1 + (r / rho)^4) (1 when rho2 <= 0: no fade)."""
    if rho2 <= 0.0:
        return 1.0
    q = r2 / rho2
    return 1.0 / (1.0 + q * q)


@njit(cache=True)
def _traverse(x0, x1, x2, node_lo, node_hi, node_left, node_right, node_c, node_r, node_a, src_x, src_a, l2,
              ha, hb, pa, pb, ab, fast, eps2, tol, fixed_node, src_soa, stack_n, stack_d, dummy):
    """One target's weight W from its own walk of the tree, nearest groups first, a group aggregated
    when its remainder bound is at most ``tol`` x the weight summed so far (the reference weight of
    :func:`weight_reference_kernel`). The surface subtree is walked before the fixed one (nodes
    ``k >= fixed_node``). ``src_soa`` (4, Ms): the sources' x, y, z and area as rows; with a = 3,
    b = 5 the leaves are summed by the vectorised :func:`_leaf_weight`.
    """
    W = 0.0
    inv_len = 1.0 / math.sqrt(l2)
    d0 = x0 - node_c[0, 0]
    d1 = x1 - node_c[0, 1]
    d2 = x2 - node_c[0, 2]
    stack_n[0] = 0
    stack_d[0] = d0 * d0 + d1 * d1 + d2 * d2
    sp = 1
    while sp > 0:
        sp -= 1
        k = stack_n[sp]
        dist2 = stack_d[sp]
        r = node_r[k]
        accept = False
        fa = 0.0
        fb = 0.0
        if r * r < dist2 and fast:
            # a = 3, b = 5: one square root; the bound without the (1 - t) factors (u >= 1) turns most
            # groups down before the division (t = r sqrt(q) / L, about r / D)
            q = l2 / (dist2 + eps2)
            sq = math.sqrt(q)
            fa = q * sq
            fb = ab * fa * q
            if r == 0.0:
                accept = True
            else:
                t = r * sq * inv_len
                tt = node_a[k] * t * t
                tw = tol * W
                if tt * (6.0 * fa + 15.0 * fb) <= tw and t < 1.0:
                    u = 1.0 / (1.0 - t)
                    u2 = u * u
                    accept = tt * u2 * u2 * u * (6.0 * fa + 15.0 * fb * u2) <= tw
        elif r * r < dist2:
            fa, fb = _terms(l2 / (dist2 + eps2), ha, hb, ab, fast)
            if r == 0.0:
                accept = True
            else:
                t = r / math.sqrt(dist2)
                u = 1.0 / (1.0 - t)
                # bound of the second-order Taylor remainder of the weights over the group
                err = node_a[k] * 0.5 * t * t * (pa * (pa + 1.0) * fa * u ** (pa + 2.0)
                                                 + pb * (pb + 1.0) * fb * u ** (pb + 2.0))
                accept = err <= tol * W
        if accept:
            W += node_a[k] * (fa + fb)
        elif node_left[k] < 0:
            if fast:
                W += _leaf_weight(x0, x1, x2, node_lo[k], node_hi[k], src_soa, l2, ab, eps2)
            else:
                for j in range(node_lo[k], node_hi[k]):
                    W += _leaf_source(x0, x1, x2, j, 1, 1.0, 0.0, 0.0, 0.0, src_x, src_a, dummy, l2, ha, hb,
                                      ab, fast, eps2, 0.0, False, dummy, dummy[0])
        else:
            lc = node_left[k]
            rc = node_right[k]
            a0 = x0 - node_c[lc, 0]
            a1 = x1 - node_c[lc, 1]
            a2 = x2 - node_c[lc, 2]
            dl = a0 * a0 + a1 * a1 + a2 * a2
            a0 = x0 - node_c[rc, 0]
            a1 = x1 - node_c[rc, 1]
            a2 = x2 - node_c[rc, 2]
            dr = a0 * a0 + a1 * a1 + a2 * a2
            if dl <= dr or rc == fixed_node:       # nearer child (the surface) on top: popped first
                stack_n[sp], stack_d[sp] = rc, dr
                stack_n[sp + 1], stack_d[sp + 1] = lc, dl
            else:
                stack_n[sp], stack_d[sp] = lc, dl
                stack_n[sp + 1], stack_d[sp + 1] = rc, dr
            sp += 2
    return W


@njit(cache=True, inline="always")
def _leaf_source(x0, x1, x2, j, mode, wfinal, g0, g1, g2, src_x, src_a, src_bm, l2, ha, hb, ab,
                 fast, eps2, rho2, rot, acc_src, res):
    """One source summed directly (same modes as :func:`_traverse`); returns its weight."""
    e0 = x0 - src_x[j, 0]
    e1 = x1 - src_x[j, 1]
    e2 = x2 - src_x[j, 2]
    r2 = e0 * e0 + e1 * e1 + e2 * e2
    ta, tb = _terms(l2 / (r2 + eps2), ha, hb, ab, fast)
    w = src_a[j] * (ta + tb)
    if mode == 0:
        for i in range(3):
            res[i] += w * src_bm[j, i]
        if rot:
            wr = w * _fade(r2, rho2)
            for i in range(3, NV):
                res[i] += wr * src_bm[j, i]
    elif mode == 2:
        c = w / wfinal
        acc_src[j, 0] += c * g0
        acc_src[j, 1] += c * g1
        acc_src[j, 2] += c * g2
        if rot:
            cr = c * _fade(r2, rho2)
            acc_src[j, 3] += cr * g0
            acc_src[j, 4] += cr * g1
            acc_src[j, 5] += cr * g2
            _outer_add(acc_src, j, 6, cr, g0, g1, g2, x0, x1, x2)
    return w


@njit(cache=True, fastmath={"reassoc", "contract", "nsz"})
def _leaf_weight(x0, x1, x2, lo, hi, soa, l2, ab, eps2):
    """The weight of the sources ``lo:hi`` of a leaf (a = 3, b = 5; rows x, y, z, area of soa)."""
    w_s = 0.0
    for j in range(lo, hi):
        e0 = x0 - soa[0, j]
        e1 = x1 - soa[1, j]
        e2 = x2 - soa[2, j]
        q = l2 / (e0 * e0 + e1 * e1 + e2 * e2 + eps2)
        qa = q * math.sqrt(q)
        w_s += soa[3, j] * (qa + ab * qa * q)
    return w_s


@njit(cache=True, inline="always")
def _outer_add(acc, k, off, c, g0, g1, g2, y0, y1, y2):
    """acc[k, off + 3 p + q] += c g_p y_q."""
    acc[k, off] += c * g0 * y0
    acc[k, off + 1] += c * g0 * y1
    acc[k, off + 2] += c * g0 * y2
    acc[k, off + 3] += c * g1 * y0
    acc[k, off + 4] += c * g1 * y1
    acc[k, off + 5] += c * g1 * y2
    acc[k, off + 6] += c * g2 * y0
    acc[k, off + 7] += c * g2 * y1
    acc[k, off + 8] += c * g2 * y2


@njit(cache=True)
def _exact_one(x0, x1, x2, mode, wfinal, g0, g1, g2, src_x, src_a, src_bm, l2, ha, hb, ab, fast,
               eps2, rho2, rot, acc_src, res):
    """The direct sum over every source for one target (same modes as :func:`_traverse`)."""
    nv = NV if rot else 3
    if mode == 0:
        for j in range(nv):
            res[j] = 0.0
    W = 0.0
    for j in range(src_x.shape[0]):
        W += _leaf_source(x0, x1, x2, j, mode, wfinal, g0, g1, g2, src_x, src_a, src_bm, l2, ha, hb,
                          ab, fast, eps2, rho2, rot, acc_src, res)
    return W


@njit(cache=True, inline="always")
def _finish(res, W, x0, x1, x2, rot, out, i):
    if W > 0:
        v0, v1, v2 = res[0], res[1], res[2]
        if rot:
            v0 += res[3] + res[6] * x0 + res[7] * x1 + res[8] * x2
            v1 += res[4] + res[9] * x0 + res[10] * x1 + res[11] * x2
            v2 += res[5] + res[12] * x0 + res[13] * x1 + res[14] * x2
        out[i, 0] = v0 / W
        out[i, 1] = v1 / W
        out[i, 2] = v2 / W
    else:
        out[i, 0] = out[i, 1] = out[i, 2] = 0.0


@njit(parallel=True, cache=True)
def exact_kernel(tx, out, src_x, src_a, src_bm, l2, ha, hb, ab, fast, eps2, rho2, rot):
    """The direct sum over every source for targets tx (n, 3): displacements into out (n, 3)."""
    n = tx.shape[0]
    dummy = np.zeros((1, NM))
    for b in prange((n + _BLOCK - 1) // _BLOCK):
        res = np.empty(NV)
        for i in range(b * _BLOCK, min(n, (b + 1) * _BLOCK)):
            x0, x1, x2 = tx[i, 0], tx[i, 1], tx[i, 2]
            W = _exact_one(x0, x1, x2, 0, 1.0, 0.0, 0.0, 0.0, src_x, src_a, src_bm, l2, ha, hb, ab, fast,
                           eps2, rho2, rot, dummy, res)
            _finish(res, W, x0, x1, x2, rot, out, i)


@njit(parallel=True, cache=True)
def exact_vjp_kernel(tx, g, acc_src, src_x, src_a, l2, ha, hb, ab, fast, eps2, rho2):
    """The transpose of :func:`exact_kernel` for the cotangents g (n, 3): per thread t into acc_src[t];
    thread t takes every T-th block of targets."""
    n = tx.shape[0]
    nthreads = acc_src.shape[0]
    nblocks = (n + _BLOCK - 1) // _BLOCK
    dummy = np.zeros((1, NM))
    for t in prange(nthreads):
        res = np.empty(NV)
        asrc = acc_src[t]
        for b in range(t, nblocks, nthreads):
            for i in range(b * _BLOCK, min(n, (b + 1) * _BLOCK)):
                g0, g1, g2 = g[i, 0], g[i, 1], g[i, 2]
                if g0 == 0.0 and g1 == 0.0 and g2 == 0.0:
                    continue
                x0, x1, x2 = tx[i, 0], tx[i, 1], tx[i, 2]
                W = _exact_one(x0, x1, x2, 1, 1.0, 0.0, 0.0, 0.0, src_x, src_a, dummy, l2, ha, hb, ab, fast,
                               eps2, rho2, True, asrc, res)
                if W > 0:
                    _exact_one(x0, x1, x2, 2, W, g0, g1, g2, src_x, src_a, dummy, l2, ha, hb, ab, fast, eps2,
                               rho2, True, asrc, res)


@njit(parallel=True, cache=True)
def weight_reference_kernel(tx, out, node_lo, node_hi, node_left, node_right, node_c, node_r, node_a, src_x,
                            src_a, l2, ha, hb, pa, pb, ab, fast, eps2, tol, fixed_node, src_soa):
    """Each target's weight W from its own walk at the tolerance ``tol`` (coarse): the reference of
    the block walk's decisions (:mod:`ffdcli.volume._warp_blocks`). A function of the target alone."""
    n = tx.shape[0]
    dummy = np.zeros((1, NM))
    for b in prange((n + _BLOCK - 1) // _BLOCK):
        stack_n = np.empty(_STACK, np.int64)
        stack_d = np.empty(_STACK)
        for i in range(b * _BLOCK, min(n, (b + 1) * _BLOCK)):
            out[i] = _traverse(tx[i, 0], tx[i, 1], tx[i, 2], node_lo, node_hi, node_left, node_right, node_c,
                               node_r, node_a, src_x, src_a, l2, ha, hb, pa, pb, ab, fast, eps2, tol, fixed_node,
                               src_soa, stack_n, stack_d, dummy)


@njit(cache=True)
def node_moments(src_bm, src_x, src_a, node_c, lo, hi, rot):
    """Per node, over its sources (A = area, v = the NV votes, delta = x_i - centroid):

    [0:NV] sum A v; [NV + NV k + p] sum A delta_k v_p.
    """
    nn = lo.shape[0]
    nv = NV if rot else 3
    out = np.zeros((nn, NM))
    for k in range(nn):
        for j in range(lo[k], hi[k]):
            a = src_a[j]
            for i in range(nv):
                out[k, i] += a * src_bm[j, i]
            for c in range(3):
                ad = a * (src_x[j, c] - node_c[k, c])
                for p in range(nv):
                    out[k, NV + NV * c + p] += ad * src_bm[j, p]
    return out


@njit(cache=True)
def push_down(acc_node, left, right):
    """Add every node's accumulator into its children's, parents first (ids grow downwards)."""
    for k in range(acc_node.shape[0]):
        if left[k] >= 0:
            for i in range(acc_node.shape[1]):
                acc_node[left[k], i] += acc_node[k, i]
                acc_node[right[k], i] += acc_node[k, i]
