"""The block walk of the volume warp (:mod:`ffdcli.volume.warp`): blocks of :data:`BT` nearby targets
(Morton order) walk the source tree together, each target deciding for itself.

Each target ``x`` aggregates a tree node C (radius r, area A) when ``r < |x - c_C|`` and the node's
remainder bound (:func:`remainder_bound`) is at most ``tolw(x) = tolerance x W_ref(x)``, where
``W_ref`` is the target's own weight estimated by a coarse per-target walk (:func:`weight_reference_kernel`
of :mod:`ffdcli.volume._warp_kernels`); otherwise it opens the node (its children, or a leaf's sources
one by one). The decision is a function of the target and the node alone, and every target takes its
nodes in the one depth-first order of the tree (left child first), so a target's sums are the same,
bit for bit, whichever block it is in: a block only shares the walk. The block decides for all its
targets at once where it can prove what each would decide (its bounding sphere: the node is far enough
for the nearest target with the smallest ``tolw``, or too near for the farthest with the largest;
margins of 1e-9 cover the rounding), and asks each target otherwise.

The arithmetic of one target runs in lanes: loops over the block's targets, each statement the same
for every lane (IEEE operations, no contraction, no reassociation: a lane's value does not depend on
its place in the vector), a lane that does not take part multiplied by 0.0. The transpose
(``mode`` 2) accumulates per node and source with reassociated sums: it is exact to rounding, not bit
for bit across partitions.

The loops over the lanes repeat a few lines (the distance, ``q``, the weights) in each kernel rather
than calling a shared helper: measured, a helper inlined by numba or LLVM, one shared weight loop, or one
function for the work arrays slowed the forward walk from 4.3 to 7.7-8.6 s and the transpose from 8.3 to
19-21 s on 1M targets (LLVM stopped vectorising those loops).

Modes of :func:`walk`: 0 the forward map (W and the numerators ``res``), 1 the weight W only, 2 the
transpose of the forward map (the final W given) into per-node and per-source accumulators (see
:func:`ffdcli.volume.warp.warp_vjp` for their layout).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from ffdcli.volume._warp_kernels import NV

#: Targets per block (the lanes of one walk; at most 64: a lane mask is one uint64).
BT = 64
#: Stack entries of a walk: the tree depth is at most log2(sources) + 1 < 64.
_STACK = 160
#: Relative margins of the block's decisions over the rounding of a target's own.
_MARGIN = 1e-9
_RMARGIN = 1e-12

_FAST = {"reassoc", "contract", "nsz"}


@njit(cache=True, inline="always", error_model="numpy")
def remainder_bound(D2, r, a, l2, ha, hb, pa, pb, ab, fast, eps2):
    """Bound of the second-order Taylor remainder of a group's weights: radius ``r > 0``, area ``a``,
    squared distance ``D2 > r^2`` (see :mod:`ffdcli.volume.warp`). Decreasing in D2."""
    q = l2 / (D2 + eps2)
    t = r / math.sqrt(D2)
    u = 1.0 / (1.0 - t)
    if fast:
        fa = q * math.sqrt(q)
        fb = ab * fa * q
        u2 = u * u
        return a * t * t * u2 * u2 * u * (6.0 * fa + 15.0 * fb * u2)
    fa = q ** ha
    fb = ab * q ** hb
    return a * 0.5 * t * t * (pa * (pa + 1.0) * fa * u ** (pa + 2.0) + pb * (pb + 1.0) * fb * u ** (pb + 2.0))


@njit(cache=True, error_model="numpy")
def _decide(fl, nb, X, tolw, c0, c1, c2, r, a, l2, ha, hb, pa, pb, ab, fast, eps2, acc, D2s):
    """acc[i] = fl[i] when target i aggregates the node, else 0.0 (the per-target decision:
    ``r^2 < D2`` and, for ``r > 0``, :func:`remainder_bound` at most ``tolw[i]``)."""
    rr = r * r
    for i in range(nb):
        e0 = X[0, i] - c0
        e1 = X[1, i] - c1
        e2 = X[2, i] - c2
        D2s[i] = e0 * e0 + e1 * e1 + e2 * e2
    if r == 0.0:
        for i in range(nb):
            acc[i] = fl[i] if rr < D2s[i] else 0.0
    elif fast:
        for i in range(nb):
            D2 = D2s[i]
            ok = rr < D2
            Ds = D2 if ok else 4.0 * rr + 1.0
            q = l2 / (Ds + eps2)
            t = r / math.sqrt(Ds)
            u = 1.0 / (1.0 - t)
            fa = q * math.sqrt(q)
            fb = ab * fa * q
            u2 = u * u
            e = a * t * t * u2 * u2 * u * (6.0 * fa + 15.0 * fb * u2)
            acc[i] = fl[i] if ok and e <= tolw[i] else 0.0
    else:
        for i in range(nb):
            D2 = D2s[i]
            ok = rr < D2
            Ds = D2 if ok else 4.0 * rr + 1.0
            acc[i] = fl[i] if ok and remainder_bound(Ds, r, a, l2, ha, hb, pa, pb, ab, False, eps2) <= tolw[i] else 0.0


@njit(cache=True, error_model="numpy")
def _group_terms(fl, nb, X, c0, c1, c2, l2, ha, hb, pa, pb, ab, fast, eps2, rho2, rot, T):
    """Per lane, a group's terms: T[0] phi, T[1] psi, T[2:5] u = x - c, T[5] phi g, T[6] -(phi g)'/D
    (times the lane's flag)."""
    for i in range(nb):
        u0 = X[0, i] - c0
        u1 = X[1, i] - c1
        u2 = X[2, i] - c2
        T[2, i] = u0
        T[3, i] = u1
        T[4, i] = u2
        T[7, i] = u0 * u0 + u1 * u1 + u2 * u2
    if fast:
        for i in range(nb):
            D2 = T[7, i]
            q = l2 / (D2 + eps2)
            fa = q * math.sqrt(q)
            fb = ab * fa * q
            T[0, i] = fl[i] * (fa + fb)
            T[1, i] = fl[i] * ((pa * fa + pb * fb) / (D2 + eps2))
    else:
        for i in range(nb):
            D2 = T[7, i]
            q = l2 / (D2 + eps2)
            fa = q ** ha
            fb = ab * q ** hb
            T[0, i] = fl[i] * (fa + fb)
            T[1, i] = fl[i] * ((pa * fa + pb * fb) / (D2 + eps2))
    if rot:
        if rho2 > 0.0:
            for i in range(nb):
                qq = T[7, i] / rho2
                gf = 1.0 / (1.0 + qq * qq)
                T[5, i] = T[0, i] * gf
                T[6, i] = gf * (T[1, i] + 4.0 * T[0, i] * qq * gf / rho2)
        else:
            for i in range(nb):
                T[5, i] = T[0, i]
                T[6, i] = T[1, i]


@njit(cache=True, error_model="numpy")
def _group_forward(nb, area, m, rot, T, W, res, numerators):
    """An aggregated group added to W and (``numerators``) to res; ``m`` its moments (NM,)."""
    for i in range(nb):
        W[i] += area * T[0, i]
    if not numerators:
        return
    for p in range(3):
        m0, m1, m2, m3 = m[p], m[15 + p], m[30 + p], m[45 + p]
        for i in range(nb):
            res[p, i] += T[0, i] * m0 + T[1, i] * (T[2, i] * m1 + T[3, i] * m2 + T[4, i] * m3)
    if rot:
        for p in range(3, NV):
            m0, m1, m2, m3 = m[p], m[15 + p], m[30 + p], m[45 + p]
            for i in range(nb):
                res[p, i] += T[5, i] * m0 + T[6, i] * (T[2, i] * m1 + T[3, i] * m2 + T[4, i] * m3)


@njit(cache=True, error_model="numpy")
def _group_fast(fl, nb, X, c0, c1, c2, area, m, l2, ab, eps2, rho2, numerators, rot, W, res, T):
    """:func:`_group_terms` and :func:`_group_forward` for a = 3, b = 5: the weight and the translation
    channels in one pass over the lanes, the rotation channels' terms kept in T for one pass per
    channel (fewer arrays per loop: LLVM vectorises a loop only when it can check the arrays' overlap)."""
    irho2 = 1.0 / rho2 if rho2 > 0.0 else 0.0
    if not numerators:
        for i in range(nb):
            u0 = X[0, i] - c0
            u1 = X[1, i] - c1
            u2 = X[2, i] - c2
            q = l2 / (u0 * u0 + u1 * u1 + u2 * u2 + eps2)
            fa = q * math.sqrt(q)
            W[i] += area * (fl[i] * (fa + ab * fa * q))
        return
    b0, b1, b2, b3 = m[0], m[15], m[30], m[45]
    d0, d1, d2, d3 = m[1], m[16], m[31], m[46]
    e0, e1, e2, e3 = m[2], m[17], m[32], m[47]
    for i in range(nb):
        u0 = X[0, i] - c0
        u1 = X[1, i] - c1
        u2 = X[2, i] - c2
        D2 = u0 * u0 + u1 * u1 + u2 * u2
        q = l2 / (D2 + eps2)
        fa = q * math.sqrt(q)
        fb = ab * fa * q
        phi = fl[i] * (fa + fb)
        psi = fl[i] * ((3.0 * fa + 5.0 * fb) / (D2 + eps2))
        W[i] += area * phi
        res[0, i] += phi * b0 + psi * (u0 * b1 + u1 * b2 + u2 * b3)
        res[1, i] += phi * d0 + psi * (u0 * d1 + u1 * d2 + u2 * d3)
        res[2, i] += phi * e0 + psi * (u0 * e1 + u1 * e2 + u2 * e3)
        if rot:
            qq = D2 * irho2
            gf = 1.0 / (1.0 + qq * qq)
            T[2, i] = u0
            T[3, i] = u1
            T[4, i] = u2
            T[5, i] = phi * gf
            T[6, i] = gf * (psi + 4.0 * phi * qq * gf * irho2)
    if not rot:
        return
    for p in range(3, NV):
        f0, f1, f2, f3 = m[p], m[15 + p], m[30 + p], m[45 + p]
        r = res[p]
        for i in range(nb):
            r[i] += T[5, i] * f0 + T[6, i] * (T[2, i] * f1 + T[3, i] * f2 + T[4, i] * f3)


@njit(cache=True, error_model="numpy")
def _leaf_fast(fl, nb, X, lo, hi, src_x, src_a, bm, l2, ab, eps2, rho2, numerators, rot, W, res, T):
    """The sources lo:hi summed directly for the flagged lanes, a = 3, b = 5 (as :func:`_source_terms` and
    :func:`_source_forward`; the weight and translation channels in one pass per source)."""
    irho2 = 1.0 / rho2 if rho2 > 0.0 else 0.0
    for j in range(lo, hi):
        s0, s1, s2, aj = src_x[j, 0], src_x[j, 1], src_x[j, 2], src_a[j]
        if not numerators:
            for i in range(nb):
                e0 = X[0, i] - s0
                e1 = X[1, i] - s1
                e2 = X[2, i] - s2
                q = l2 / (e0 * e0 + e1 * e1 + e2 * e2 + eps2)
                fa = q * math.sqrt(q)
                W[i] += fl[i] * (aj * (fa + ab * fa * q))
            continue
        v0, v1, v2 = bm[j, 0], bm[j, 1], bm[j, 2]
        if not rot:
            for i in range(nb):
                e0 = X[0, i] - s0
                e1 = X[1, i] - s1
                e2 = X[2, i] - s2
                q = l2 / (e0 * e0 + e1 * e1 + e2 * e2 + eps2)
                fa = q * math.sqrt(q)
                w = fl[i] * (aj * (fa + ab * fa * q))
                W[i] += w
                res[0, i] += w * v0
                res[1, i] += w * v1
                res[2, i] += w * v2
            continue
        for i in range(nb):
            e0 = X[0, i] - s0
            e1 = X[1, i] - s1
            e2 = X[2, i] - s2
            r2 = e0 * e0 + e1 * e1 + e2 * e2
            q = l2 / (r2 + eps2)
            fa = q * math.sqrt(q)
            w = fl[i] * (aj * (fa + ab * fa * q))
            qq = r2 * irho2
            T[1, i] = w / (1.0 + qq * qq)
            W[i] += w
            res[0, i] += w * v0
            res[1, i] += w * v1
            res[2, i] += w * v2
        for p in range(3, NV):
            v = bm[j, p]
            r = res[p]
            for i in range(nb):
                r[i] += T[1, i] * v


@njit(cache=True, error_model="numpy", fastmath=_FAST)
def _group_adjoint(an, k, nb, X, G, Wf, T):
    """The transpose of an aggregated group for the lanes: into the node accumulator an[k]."""
    for i in range(nb):
        w = 1.0 / Wf[i]
        T[0, i] *= w
        T[1, i] *= w
        T[5, i] *= w
        T[6, i] *= w
    for p in range(3):
        s0 = s1 = s2 = s3 = s4 = s5 = s6 = s7 = 0.0
        for i in range(nb):
            g = G[p, i]
            s0 += T[0, i] * g
            s1 += T[1, i] * g * T[2, i]
            s2 += T[1, i] * g * T[3, i]
            s3 += T[1, i] * g * T[4, i]
            s4 += T[5, i] * g
            s5 += T[6, i] * g * T[2, i]
            s6 += T[6, i] * g * T[3, i]
            s7 += T[6, i] * g * T[4, i]
        an[k, p] += s0
        an[k, 3 + 3 * p] += s1
        an[k, 4 + 3 * p] += s2
        an[k, 5 + 3 * p] += s3
        an[k, 12 + p] += s4
        an[k, 15 + 3 * p] += s5
        an[k, 16 + 3 * p] += s6
        an[k, 17 + 3 * p] += s7
        for q in range(3):
            t0 = t1 = t2 = t3 = 0.0
            for i in range(nb):
                gx = G[p, i] * X[q, i]
                t0 += T[5, i] * gx
                t1 += T[6, i] * T[2, i] * gx
                t2 += T[6, i] * T[3, i] * gx
                t3 += T[6, i] * T[4, i] * gx
            an[k, 24 + 3 * p + q] += t0
            an[k, 33 + 3 * p + q] += t1
            an[k, 42 + 3 * p + q] += t2
            an[k, 51 + 3 * p + q] += t3


@njit(cache=True, error_model="numpy")
def _source_terms(fl, nb, X, j, src_x, src_a, l2, ha, hb, ab, fast, eps2, rho2, fade, T):
    """Per lane, source j summed directly: T[0] its weight w, T[1] w g (times the lane's flag)."""
    s0, s1, s2, aj = src_x[j, 0], src_x[j, 1], src_x[j, 2], src_a[j]
    for i in range(nb):
        e0 = X[0, i] - s0
        e1 = X[1, i] - s1
        e2 = X[2, i] - s2
        T[7, i] = e0 * e0 + e1 * e1 + e2 * e2
    if fast:
        for i in range(nb):
            q = l2 / (T[7, i] + eps2)
            fa = q * math.sqrt(q)
            T[0, i] = fl[i] * (aj * (fa + ab * fa * q))
    else:
        for i in range(nb):
            q = l2 / (T[7, i] + eps2)
            T[0, i] = fl[i] * (aj * (q ** ha + ab * q ** hb))
    if not fade:
        return
    if rho2 > 0.0:
        for i in range(nb):
            qq = T[7, i] / rho2
            T[1, i] = T[0, i] / (1.0 + qq * qq)
    else:
        for i in range(nb):
            T[1, i] = T[0, i]


@njit(cache=True, error_model="numpy")
def _source_forward(nb, j, bm, rot, T, W, res, numerators):
    for i in range(nb):
        W[i] += T[0, i]
    if not numerators:
        return
    for p in range(3):
        v = bm[j, p]
        for i in range(nb):
            res[p, i] += T[0, i] * v
    if rot:
        for p in range(3, NV):
            v = bm[j, p]
            for i in range(nb):
                res[p, i] += T[1, i] * v


@njit(cache=True, error_model="numpy", fastmath=_FAST)
def _source_adjoint(asrc, j, nb, X, G, Wf, T):
    """The transpose of source j summed directly for the lanes: into asrc[j]."""
    for p in range(3):
        s0 = s1 = 0.0
        for i in range(nb):
            g = G[p, i] / Wf[i]
            s0 += T[0, i] * g
            s1 += T[1, i] * g
        asrc[j, p] += s0
        asrc[j, 3 + p] += s1
        for q in range(3):
            t = 0.0
            for i in range(nb):
                t += T[1, i] * G[p, i] / Wf[i] * X[q, i]
            asrc[j, 6 + 3 * p + q] += t


@njit(cache=True, error_model="numpy")
def _block_decision(Db, R, r, a, tmin, tmax, l2, ha, hb, pa, pb, ab, fast, eps2):
    """What every target of a block (centre at distance ``Db`` from the node's, radius ``R``; tolerances
    ``tmin..tmax``) decides for a node of radius ``r`` and area ``a``, where the block can prove it:
    1 every target aggregates the node, 2 none does, 0 unknown (each decides)."""
    dmin = Db - R - _RMARGIN * Db
    dmax = Db + R + _RMARGIN * Db
    if dmin > 0.0 and r * r < dmin * dmin * (1.0 - _RMARGIN):
        if r == 0.0 or remainder_bound(dmin * dmin, r, a, l2, ha, hb, pa, pb, ab, fast, eps2) * (1.0 + _MARGIN) <= tmin:
            return 1
    if r * r >= dmax * dmax * (1.0 + _RMARGIN):
        return 2
    if r > 0.0 and remainder_bound(dmax * dmax, r, a, l2, ha, hb, pa, pb, ab, fast, eps2) >= tmax * (1.0 + _MARGIN):
        return 2
    return 0


@njit(cache=True, inline="always", error_model="numpy")
def _aggregate(mode, fl, an, k, nb, X, G, Wf, c0, c1, c2, a, m, l2, ha, hb, pa, pb, ab, fast, eps2, rho2, fade,
               rot, T, W, res, numerators):
    """A group (centre c, area a, moments m) aggregated by the lanes flagged in fl: forward (W, res) or
    transposed (an[k])."""
    if fast and mode != 2:
        _group_fast(fl, nb, X, c0, c1, c2, a, m, l2, ab, eps2, rho2, numerators, rot, W, res, T)
        return
    _group_terms(fl, nb, X, c0, c1, c2, l2, ha, hb, pa, pb, ab, fast, eps2, rho2, fade, T)
    if mode == 2:
        _group_adjoint(an, k, nb, X, G, Wf, T)
    else:
        _group_forward(nb, a, m, rot, T, W, res, numerators)


@njit(cache=True, error_model="numpy")
def walk(mode, X, tolw, nb, mask, G, Wf, node_lo, node_hi, node_left, node_right, node_c, node_r, node_a,
         node_bm, src_x, src_a, src_bm, l2, ha, hb, pa, pb, ab, fast, eps2, rho2, rot, fixed_node, W, res,
         an, asrc, T, fl, acc, stack_n, stack_m):
    """One block's walk (module docstring): targets ``X[:, :nb]`` (3, BT), those of ``mask`` only.

    mode 0: W (BT,) and res (NV, BT) filled; 1: W only; 2: the transpose for the cotangents ``G``
    (3, BT) with the final weights ``Wf`` into an (nodes, NM) and asrc (sources, NV).
    """
    if mode != 2:
        for i in range(nb):
            W[i] = 0.0
        for p in range(NV):
            for i in range(nb):
                res[p, i] = 0.0
    lo0 = hi0 = X[0, 0]
    lo1 = hi1 = X[1, 0]
    lo2 = hi2 = X[2, 0]
    for i in range(1, nb):
        lo0, hi0 = min(lo0, X[0, i]), max(hi0, X[0, i])
        lo1, hi1 = min(lo1, X[1, i]), max(hi1, X[1, i])
        lo2, hi2 = min(lo2, X[2, i]), max(hi2, X[2, i])
    b0, b1, b2 = 0.5 * (lo0 + hi0), 0.5 * (lo1 + hi1), 0.5 * (lo2 + hi2)
    R2 = 0.0
    for i in range(nb):
        d0, d1, d2 = X[0, i] - b0, X[1, i] - b1, X[2, i] - b2
        R2 = max(R2, d0 * d0 + d1 * d1 + d2 * d2)
    R = math.sqrt(R2) * (1.0 + _MARGIN)
    one = np.uint64(1)
    tmin, tmax = np.inf, 0.0            # over the block's targets: sound for every subset
    for i in range(nb):
        if (mask >> np.uint64(i)) & one:
            tmin = min(tmin, tolw[i])
            tmax = max(tmax, tolw[i])
    stack_n[0] = 0
    stack_m[0] = mask
    sp = 1
    while sp > 0:
        sp -= 1
        k = stack_n[sp]
        mask = stack_m[sp]
        fixed = k >= fixed_node
        if fixed and mode == 2:
            continue                    # fixed sources carry no votes: nothing to transpose
        r = node_r[k]
        a = node_a[k]
        for i in range(nb):
            fl[i] = float((mask >> np.uint64(i)) & one)
        c0, c1, c2 = node_c[k, 0], node_c[k, 1], node_c[k, 2]
        d0, d1, d2 = b0 - c0, b1 - c1, b2 - c2
        Db = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        numerators = mode == 0 and not fixed      # the votes' sums (else the weight, or the transpose)
        fade = mode == 2 or (numerators and rot)
        m = node_bm[k if numerators else 0]
        state = _block_decision(Db, R, r, a, tmin, tmax, l2, ha, hb, pa, pb, ab, fast, eps2)
        rest = mask
        if state == 1:
            _aggregate(mode, fl, an, k, nb, X, G, Wf, c0, c1, c2, a, m, l2, ha, hb, pa, pb, ab, fast, eps2, rho2,
                       fade, rot, T, W, res, numerators)
            continue
        if state == 0:
            _decide(fl, nb, X, tolw, c0, c1, c2, r, a, l2, ha, hb, pa, pb, ab, fast, eps2, acc, T[7])
            rest = np.uint64(0)
            taken = np.uint64(0)
            for i in range(nb):
                bit = one << np.uint64(i)
                taken |= bit if acc[i] != 0.0 else np.uint64(0)
                rest |= bit if acc[i] == 0.0 and fl[i] != 0.0 else np.uint64(0)
            if taken:
                _aggregate(mode, acc, an, k, nb, X, G, Wf, c0, c1, c2, a, m, l2, ha, hb, pa, pb, ab, fast, eps2,
                           rho2, fade, rot, T, W, res, numerators)
            if rest == 0:
                continue
            for i in range(nb):
                fl[i] = 0.0 if acc[i] != 0.0 else fl[i]
        if node_left[k] < 0:
            if fast and mode != 2:
                _leaf_fast(fl, nb, X, node_lo[k], node_hi[k], src_x, src_a, src_bm, l2, ab, eps2, rho2, numerators,
                           rot, W, res, T)
                continue
            for j in range(node_lo[k], node_hi[k]):
                _source_terms(fl, nb, X, j, src_x, src_a, l2, ha, hb, ab, fast, eps2, rho2, fade, T)
                if mode == 2:
                    _source_adjoint(asrc, j, nb, X, G, Wf, T)
                else:
                    _source_forward(nb, j, src_bm, rot, T, W, res, numerators)
        else:
            stack_n[sp] = node_right[k]
            stack_m[sp] = rest
            stack_n[sp + 1] = node_left[k]
            stack_m[sp + 1] = rest
            sp += 2


@njit(cache=True, error_model="numpy")
def _full_mask(nb):
    return np.uint64(0xFFFFFFFFFFFFFFFF) if nb == 64 else (np.uint64(1) << np.uint64(nb)) - np.uint64(1)


@njit(parallel=True, cache=True, error_model="numpy")
def warp_blocks(tx, tolw, order, out, node_lo, node_hi, node_left, node_right, node_c, node_r, node_a,
                node_bm, src_x, src_a, src_bm, l2, ha, hb, pa, pb, ab, fast, eps2, rho2, rot, fixed_node):
    """The forward map for targets tx (n, 3) with tolerances tolw (n,): displacements into out (n, 3).
    ``order``: the blocks (of BT targets) in the order the threads take them."""
    n = tx.shape[0]
    for oi in prange(order.shape[0]):
        s = order[oi] * BT
        nb = min(n, s + BT) - s
        X = np.empty((3, BT))
        tw = np.empty(BT)
        for i in range(BT):             # a short block: its last target repeated, out of the mask
            j = s + min(i, nb - 1)
            X[0, i], X[1, i], X[2, i] = tx[j, 0], tx[j, 1], tx[j, 2]
            tw[i] = tolw[j]
        W = np.empty(BT)
        res = np.empty((NV, BT))
        T = np.empty((8, BT))
        fl = np.empty(BT)
        acc = np.empty(BT)
        stack_n = np.empty(_STACK, np.int64)
        stack_m = np.empty(_STACK, np.uint64)
        walk(0, X, tw, BT, _full_mask(nb), X, W, node_lo, node_hi, node_left, node_right, node_c, node_r,
             node_a, node_bm, src_x, src_a, src_bm, l2, ha, hb, pa, pb, ab, fast, eps2, rho2, rot, fixed_node,
             W, res, node_bm, src_bm, T, fl, acc, stack_n, stack_m)
        for i in range(nb):
            x0, x1, x2 = X[0, i], X[1, i], X[2, i]
            v0, v1, v2 = res[0, i], res[1, i], res[2, i]
            if rot:
                v0 += res[3, i] + res[6, i] * x0 + res[7, i] * x1 + res[8, i] * x2
                v1 += res[4, i] + res[9, i] * x0 + res[10, i] * x1 + res[11, i] * x2
                v2 += res[5, i] + res[12, i] * x0 + res[13, i] * x1 + res[14, i] * x2
            if W[i] > 0:
                out[s + i, 0] = v0 / W[i]
                out[s + i, 1] = v1 / W[i]
                out[s + i, 2] = v2 / W[i]
            else:
                out[s + i, 0] = out[s + i, 1] = out[s + i, 2] = 0.0


@njit(parallel=True, cache=True, error_model="numpy")
def vjp_blocks(tx, tolw, g, acc_node, acc_src, node_lo, node_hi, node_left, node_right, node_c, node_r,
               node_a, src_x, src_a, l2, ha, hb, pa, pb, ab, fast, eps2, rho2, fixed_node):
    """The transpose for the cotangents g (n, 3): per thread t, acc_node[t] and acc_src[t]; thread t
    takes every T-th block. Targets whose g is zero are left out of their block's walks."""
    n = tx.shape[0]
    nthreads = acc_node.shape[0]
    nblocks = (n + BT - 1) // BT
    dummy_bm = np.zeros((1, 1))
    for t in prange(nthreads):
        an = acc_node[t]
        asrc = acc_src[t]
        X = np.empty((3, BT))
        G = np.empty((3, BT))
        tw = np.empty(BT)
        W = np.empty(BT)
        res = np.empty((NV, BT))
        T = np.empty((8, BT))
        fl = np.empty(BT)
        acc = np.empty(BT)
        stack_n = np.empty(_STACK, np.int64)
        stack_m = np.empty(_STACK, np.uint64)
        for b in range(t, nblocks, nthreads):
            s = b * BT
            nb = min(n, s + BT) - s
            mask = np.uint64(0)
            for i in range(BT):         # a short block: its last target repeated, out of the mask
                j = s + min(i, nb - 1)
                X[0, i], X[1, i], X[2, i] = tx[j, 0], tx[j, 1], tx[j, 2]
                G[0, i], G[1, i], G[2, i] = g[j, 0], g[j, 1], g[j, 2]
                tw[i] = tolw[j]
                if i < nb and (G[0, i] != 0.0 or G[1, i] != 0.0 or G[2, i] != 0.0):
                    mask |= np.uint64(1) << np.uint64(i)
            if mask == 0:
                continue
            walk(1, X, tw, BT, mask, G, W, node_lo, node_hi, node_left, node_right, node_c, node_r, node_a,
                 dummy_bm, src_x, src_a, dummy_bm, l2, ha, hb, pa, pb, ab, fast, eps2, rho2, False, fixed_node,
                 W, res, an, asrc, T, fl, acc, stack_n, stack_m)
            for i in range(BT):
                if W[i] <= 0.0:
                    W[i] = 1.0          # a lane left out (or of no weight): its terms are zero
            walk(2, X, tw, BT, mask, G, W, node_lo, node_hi, node_left, node_right, node_c, node_r, node_a,
                 dummy_bm, src_x, src_a, dummy_bm, l2, ha, hb, pa, pb, ab, fast, eps2, rho2, True, fixed_node,
                 W, res, an, asrc, T, fl, acc, stack_n, stack_m)
