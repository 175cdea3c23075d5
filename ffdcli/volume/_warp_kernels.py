"""The compiled kernels of the volume warp (:mod:`ffdcli.volume.warp`): the tree traversal, the leaf and
group sums of the forward map and of its exact transpose, the node moments.

Their NumPy reference is :func:`ffdcli.volume.warp.idw_reference` (the exact sum), which the tests
compare the warp with; :func:`ffdcli.volume.warp.warp` and :func:`ffdcli.volume.warp.warp_vjp` are
the Python entry points. See :mod:`ffdcli.volume.warp` for the model (votes, groups, tolerance).
"""

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
def _traverse(x0, x1, x2, mode, wfinal, g0, g1, g2, node_lo, node_hi, node_left, node_right,
              node_c, node_r, node_a, node_bm, src_x, src_a, src_bm, l2, ha, hb, pa, pb, ab,
              fast, eps2, tol, rho2, rot, fixed_node, src_soa, stack_n, stack_d, acc_node, acc_src,
              res):
    """Walk the tree for one target. Returns the total weight W.

    mode 0: res[:15] = the numerator sums (b channel, c and M channels) of the forward map.
    mode 1: weight only.
    mode 2: adjoint: add the target's share of g into acc_node (per node, see :func:`warp_vjp`)
    and acc_src (per source), scaled by 1 / wfinal.
    The decisions use only geometry and the running weight, identically in every mode: the map
    from the votes to the displacement is fixed by the undeformed mesh.
    ``src_soa`` (4 + NV, Ms): the sources' x, y, z, area and the NV votes as rows (mode 0, (4, Ms)
    for modes 1 and 2). With a = 3, b = 5 the leaves of modes 0 and 1 (and of the fixed sources in
    every mode) are summed by the vectorised :func:`_leaf_forward` and :func:`_leaf_weight`.
    Nodes ``k >= fixed_node`` hold fixed sources only (zero votes): they add to W and nothing
    else, and the surface subtree is walked before them (its near weights make the far-field
    groups acceptable at once).
    """
    nv = NV if rot else 3
    if mode == 0:
        for j in range(nv):
            res[j] = 0.0
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
            # a = 3, b = 5: one square root and at most two divisions per group (t = r sqrt(q) / L);
            # the bound without the (1 - t) factors (u >= 1) turns most groups down cheaply
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
                if tt * (6.0 * fa + 15.0 * fb) <= tw:
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
                if fast:
                    u5 = u * u * u * u * u
                    err = node_a[k] * t * t * u5 * (6.0 * fa + 15.0 * fb * u * u)
                else:
                    err = node_a[k] * 0.5 * t * t * (pa * (pa + 1.0) * fa * u ** (pa + 2.0)
                                                     + pb * (pb + 1.0) * fb * u ** (pb + 2.0))
                accept = err <= tol * W
        md = 1 if k >= fixed_node else mode
        if accept:
            phi = fa + fb
            W += node_a[k] * phi
            if md != 1:
                psi = (pa * fa + pb * fb) / (dist2 + eps2)      # -phi'(D) / D
                u0 = x0 - node_c[k, 0]
                u1 = x1 - node_c[k, 1]
                u2 = x2 - node_c[k, 2]
                phr = phi
                psr = psi
                if rot and rho2 > 0.0:
                    # g(D) = 1 / (1 + q^2), q = D^2 / rho^2: -g'(D) / D = 4 q g^2 / rho^2
                    q = dist2 / rho2
                    gf = 1.0 / (1.0 + q * q)
                    phr = phi * gf
                    psr = gf * (psi + 4.0 * phi * q * gf / rho2)
            if md == 0:
                _group_forward(res, node_bm[k], phi, psi, phr, psr, u0, u1, u2, rot)
            elif md == 2:
                cf = phi / wfinal
                cs = psi / wfinal
                acc_node[k, 0] += cf * g0
                acc_node[k, 1] += cf * g1
                acc_node[k, 2] += cf * g2
                _outer_add(acc_node, k, 3, cs, g0, g1, g2, u0, u1, u2)
                if rot:
                    crf = phr / wfinal
                    crs = psr / wfinal
                    acc_node[k, 12] += crf * g0
                    acc_node[k, 13] += crf * g1
                    acc_node[k, 14] += crf * g2
                    _outer_add(acc_node, k, 15, crs, g0, g1, g2, u0, u1, u2)
                    _outer_add(acc_node, k, 24, crf, g0, g1, g2, x0, x1, x2)
                    _outer_add(acc_node, k, 33, crs * u0, g0, g1, g2, x0, x1, x2)
                    _outer_add(acc_node, k, 42, crs * u1, g0, g1, g2, x0, x1, x2)
                    _outer_add(acc_node, k, 51, crs * u2, g0, g1, g2, x0, x1, x2)
        elif node_left[k] < 0:
            if md == 0 and fast:
                W += _leaf_forward(x0, x1, x2, node_lo[k], node_hi[k], src_soa, l2, ab, eps2, rho2,
                                   rot, res)
                continue
            if md == 1 and fast:
                W += _leaf_weight(x0, x1, x2, node_lo[k], node_hi[k], src_soa, l2, ab, eps2)
                continue
            for j in range(node_lo[k], node_hi[k]):
                W += _leaf_source(x0, x1, x2, j, md, wfinal, g0, g1, g2, src_x, src_a, src_bm, l2,
                                  ha, hb, ab, fast, eps2, rho2, rot, acc_src, res)
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
def _group_forward(res, m, phi, psi, phr, psr, u0, u1, u2, rot):
    """An accepted group's monopole and dipole terms added to res (mode 0); ``m`` its NM moments."""
    for p in range(3):
        res[p] += phi * m[p] + psi * (u0 * m[15 + p] + u1 * m[30 + p] + u2 * m[45 + p])
    if rot:
        for p in range(3, NV):
            res[p] += phr * m[p] + psr * (u0 * m[15 + p] + u1 * m[30 + p] + u2 * m[45 + p])


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


@njit(cache=True, fastmath={"reassoc", "contract", "nsz"})
def _leaf_forward(x0, x1, x2, lo, hi, soa, l2, ab, eps2, rho2, rot, res):
    """The sources ``lo:hi`` of a leaf summed directly into res (mode 0, a = 3, b = 5); returns
    their weight. The same sums as :func:`_leaf_source`, in scalar accumulators over the rows of
    ``soa`` (x, y, z, area, NV votes) so that the loop vectorises (sums reassociated)."""
    irho2 = 1.0 / rho2 if rho2 > 0.0 else 0.0
    w_s = 0.0
    b0 = b1 = b2 = 0.0
    if not rot:
        for j in range(lo, hi):
            e0 = x0 - soa[0, j]
            e1 = x1 - soa[1, j]
            e2 = x2 - soa[2, j]
            q = l2 / (e0 * e0 + e1 * e1 + e2 * e2 + eps2)
            qa = q * math.sqrt(q)
            w = soa[3, j] * (qa + ab * qa * q)
            w_s += w
            b0 += w * soa[4, j]
            b1 += w * soa[5, j]
            b2 += w * soa[6, j]
        res[0] += b0
        res[1] += b1
        res[2] += b2
        return w_s
    c0 = c1 = c2 = 0.0
    m0 = m1 = m2 = m3 = m4 = m5 = m6 = m7 = m8 = 0.0
    for j in range(lo, hi):
        e0 = x0 - soa[0, j]
        e1 = x1 - soa[1, j]
        e2 = x2 - soa[2, j]
        r2 = e0 * e0 + e1 * e1 + e2 * e2
        q = l2 / (r2 + eps2)
        qa = q * math.sqrt(q)
        w = soa[3, j] * (qa + ab * qa * q)
        f = r2 * irho2
        wr = w / (1.0 + f * f)
        w_s += w
        b0 += w * soa[4, j]
        b1 += w * soa[5, j]
        b2 += w * soa[6, j]
        c0 += wr * soa[7, j]
        c1 += wr * soa[8, j]
        c2 += wr * soa[9, j]
        m0 += wr * soa[10, j]
        m1 += wr * soa[11, j]
        m2 += wr * soa[12, j]
        m3 += wr * soa[13, j]
        m4 += wr * soa[14, j]
        m5 += wr * soa[15, j]
        m6 += wr * soa[16, j]
        m7 += wr * soa[17, j]
        m8 += wr * soa[18, j]
    res[0] += b0
    res[1] += b1
    res[2] += b2
    res[3] += c0
    res[4] += c1
    res[5] += c2
    res[6] += m0
    res[7] += m1
    res[8] += m2
    res[9] += m3
    res[10] += m4
    res[11] += m5
    res[12] += m6
    res[13] += m7
    res[14] += m8
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
def _warp_kernel(tx, blocks, out, exact, node_lo, node_hi, node_left, node_right, node_c, node_r,
                 node_a, node_bm, src_x, src_a, src_bm, l2, ha, hb, pa, pb, ab, fast, eps2, tol,
                 rho2, rot, fixed_node, src_soa):
    n = tx.shape[0]
    dummy = np.zeros((1, NM))
    for bi in prange(blocks.shape[0]):
        b = blocks[bi]
        stack_n = np.empty(_STACK, np.int64)
        stack_d = np.empty(_STACK)
        res = np.empty(NV)
        for i in range(b * _BLOCK, min(n, (b + 1) * _BLOCK)):
            x0, x1, x2 = tx[i, 0], tx[i, 1], tx[i, 2]
            if exact:
                W = _exact_one(x0, x1, x2, 0, 1.0, 0.0, 0.0, 0.0, src_x, src_a, src_bm, l2, ha, hb,
                               ab, fast, eps2, rho2, rot, dummy, res)
            else:
                W = _traverse(x0, x1, x2, 0, 1.0, 0.0, 0.0, 0.0, node_lo, node_hi, node_left,
                              node_right, node_c, node_r, node_a, node_bm, src_x, src_a, src_bm, l2,
                              ha, hb, pa, pb, ab, fast, eps2, tol, rho2, rot, fixed_node, src_soa,
                              stack_n, stack_d, dummy, dummy, res)
            _finish(res, W, x0, x1, x2, rot, out, i)


@njit(parallel=True, cache=True)
def _vjp_kernel(tx, g, acc_node, acc_src, exact, node_lo, node_hi, node_left, node_right, node_c,
                node_r, node_a, node_bm, src_x, src_a, src_bm, l2, ha, hb, pa, pb, ab, fast, eps2,
                tol, rho2, fixed_node, src_soa):
    """Per-thread accumulators acc_node[t], acc_src[t]; thread t takes every T-th block."""
    n = tx.shape[0]
    nthreads = acc_node.shape[0]
    nblocks = (n + _BLOCK - 1) // _BLOCK
    for t in prange(nthreads):
        stack_n = np.empty(_STACK, np.int64)
        stack_d = np.empty(_STACK)
        res = np.empty(NV)
        an = acc_node[t]
        asrc = acc_src[t]
        for b in range(t, nblocks, nthreads):
            for i in range(b * _BLOCK, min(n, (b + 1) * _BLOCK)):
                g0, g1, g2 = g[i, 0], g[i, 1], g[i, 2]
                if g0 == 0.0 and g1 == 0.0 and g2 == 0.0:
                    continue
                x0, x1, x2 = tx[i, 0], tx[i, 1], tx[i, 2]
                if exact:
                    W = _exact_one(x0, x1, x2, 1, 1.0, 0.0, 0.0, 0.0, src_x, src_a, src_bm, l2, ha,
                                   hb, ab, fast, eps2, rho2, True, asrc, res)
                    if W > 0:
                        _exact_one(x0, x1, x2, 2, W, g0, g1, g2, src_x, src_a, src_bm, l2, ha, hb,
                                   ab, fast, eps2, rho2, True, asrc, res)
                else:
                    W = _traverse(x0, x1, x2, 1, 1.0, 0.0, 0.0, 0.0, node_lo, node_hi, node_left,
                                  node_right, node_c, node_r, node_a, node_bm, src_x, src_a, src_bm,
                                  l2, ha, hb, pa, pb, ab, fast, eps2, tol, rho2, True, fixed_node,
                                  src_soa, stack_n, stack_d, an, asrc, res)
                    if W > 0:
                        _traverse(x0, x1, x2, 2, W, g0, g1, g2, node_lo, node_hi, node_left,
                                  node_right, node_c, node_r, node_a, node_bm, src_x, src_a, src_bm,
                                  l2, ha, hb, pa, pb, ab, fast, eps2, tol, rho2, True, fixed_node,
                                  src_soa, stack_n, stack_d, an, asrc, res)


@njit(cache=True)
def _node_moments(src_bm, src_x, src_a, node_c, lo, hi, rot):
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
def _push_down(acc_node, left, right):
    """Add every node's accumulator into its children's, parents first (ids grow downwards)."""
    for k in range(acc_node.shape[0]):
        if left[k] >= 0:
            for i in range(acc_node.shape[1]):
                acc_node[left[k], i] += acc_node[k, i]
                acc_node[right[k], i] += acc_node[k, i]
