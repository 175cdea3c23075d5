"""The volume mesh follows the surface: inverse-distance weighting carrying local frames (IDWarp style).

Every mesh node that is not on the deforming surface or on a fixed marker moves by a weighted
blend of the boundary motion, in the manner of IDWarp (Secco et al., AIAA J. 59(4), 2021). The
*sources* are the surface nodes (moving) and the nodes of the fixed markers (not moving). Source
``i`` at ``x_i`` with area weight ``A_i`` has a translation ``b_i`` and a frame matrix ``F_i``
(``M_i = F_i - I``; zero for fixed sources). A target node at ``x`` moves by::

    d(x) = sum_i w_i(x) [b_i + g(r_i) M_i (x - x_i)] / sum_i w_i(x)
    w_i(x) = A_i [ (L/r_i)^a + (alpha L/r_i)^b ],   r_i = |x - x_i|
    g(r) = 1 / (1 + (r / rho)^4)

The frame term carries each surface node's neighbourhood along. Which frame is the caller's
(``volume.carry``, :meth:`ffdcli.app.pipeline.DesignRun.surface_frames`): the FFD map's deformation
gradient at the node (the default: the cells at the wall deform as the FFD deforms space there,
also where faces of different normals meet at a sharp edge), or the rotation of the surface's
frame (IDWarp's form: cells near a twisted wing rotate with it). This module only sees the
matrices: the warp is linear in (b, M) whatever they are. Because the weights are normalised, a
rigid translation moves every node rigidly, and so does a rigid rotation near the surface. The
*fade* ``g`` keeps the frame term from carrying nodes far from the surface along with it:
``|g(r) M (x - x_i)| <= 0.57 rho |M|`` whatever the distance, so a node outboard of a twisted tip
or behind a root whose frame turns moves no further than the surface motion near it explains.
``rho = rotation_reach x`` the mean chord (:attr:`WarpModel.rotation_length`; ``rotation_reach``
0.3; null: no fade, IDWarp's form, which reproduces any rigid motion exactly). The fixed sources
hold the far field still: without them a far node would move with the average surface motion.

Settings (``volume:`` in the design file, :class:`WarpSettings`): ``a`` = 3, ``b`` = 5,
``alpha`` = 1 and ``ldef`` = L. Only the ratio of the two terms depends on L (the common factor
cancels), so L sets where the short-range ``b`` term takes over: closer than ``alpha^(b/(b-a)) L``
(L itself with the defaults: the whole wing's neighbourhood follows its nearest surface, the way
IDWarp is run for planform changes with ``LdefFact`` 50-100; IDWarp's own default, the equivalent
of alpha 0.25 here, hands over at 3 % of L and lets a far surface's average motion shear the cells
behind a tip that moves, which inverted cells of swept wings). Default L: the diagonal of the
bounding box of the surface nodes.
Area weights are vertex areas: each boundary face (a line in 2D) gives an equal share of its area
(length) to each of its nodes (:func:`vertex_areas`).

**Marker rules**: :mod:`ffdcli.volume.roles` (which markers are fixed, which slide; docs/design-choices.md
copies its list). **The source tree**: :mod:`ffdcli.volume.tree`.

**Tree approximation.** The exact sum costs O(N_targets x N_sources). Sources are held in a k-d
tree (median splits on the widest coordinate, leaves of up to 16 sources; the surface sources and
the fixed sources in separate subtrees under the root). For each tree node C the warp keeps the
area, the area-weighted centroid ``c_C``, the radius ``r`` (largest distance of a source from
``c_C``) and the moments ``sum A_i v_i`` and ``sum A_i (x_i - c_C) v_i^T`` of the votes
``v_i = (b_i, -M_i x_i, M_i)``. A group at distance ``D = |x - c_C| > r`` contributes its monopole
and dipole terms: ``phi(D) sum A_i v_i + psi(D) sum A_i ((x - c_C).(x_i - c_C)) v_i`` to the
numerator and ``A_C phi(D)`` to W (the dipole of the weights is zero about the centroid), with
``phi(D) = (L/D)^a + (alpha L/D)^b`` and ``psi = -phi'(D)/D`` for the translation votes, and
``phi g``, ``-(phi g)'/D`` for the rotation votes. Each target walks the surface subtree nearest
groups first, then the fixed subtree (its groups carry no votes, so they add to W only, and the
weight already summed near the wall lets most far-field groups be taken whole), and aggregates a
group when the bound of the second-order remainder of its weights

    A_C (t^2 / 2) [a (a+1) (L/D)^a (1-t)^-(a+2) + b (b+1) (alpha L/D)^b (1-t)^-(b+2)],  t = r/D

is at most ``tolerance * W / 2``, W the weight the target has summed so far (2 bounds the spread
of translation votes relative to the largest displacement). The decisions depend on the undeformed
geometry only, never on the motion: the approximate warp is one fixed linear map of (b, M), so
:func:`warp_vjp` (its exact transpose) is the exact derivative, and ``ffd grad`` / ``mesh_vjp``
match central differences of the written mesh at the default tolerance. This is a per-group
criterion, not a bound on the total: the error measured against the exact sum is about
``tolerance x max |b|`` (``benchmarks/bench_warp.py``); the tests check
``<= tolerance x max |b|`` on small meshes.


Numba kernels (``prange`` over blocks of targets, explicit stack traversal) have NumPy references
(:func:`idw_reference`) used by the tests. With a = 3, b = 5 the leaves and the accepted groups of
the forward map are summed by small kernels that vectorise (sources as rows of one array, scalar
accumulators, sums reassociated): the same terms, rounded in another order.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np
from numba import njit, prange

from ffdcli.geometry.surface import vertex_areas
from ffdcli.mesh import CellBlock, diagonal
from ffdcli.mesh.idsets import setdiff_ids, unique_ids
from ffdcli.mesh.morton import morton_order
from ffdcli.progress import chunks, no_progress
from ffdcli.settings import METHODS, WarpSettings  # noqa: F401  (WarpSettings: re-exported)
from ffdcli.volume.frames import rotations_from_deformation_gradient  # noqa: F401  (re-exported)
from ffdcli.volume.roles import (  # noqa: F401  (re-exported: the public names of the warp)
    PLANE_TOLERANCE,
    MarkerRoles,
    SlidingPlane,
    marker_roles,
    sliding_projectors,
)
from ffdcli.volume.tree import LEAF_SIZE, build_forest, node_geometry  # noqa: F401

#: Targets per parallel work item (inside a chunk).
_BLOCK = 128
#: Traversal stack size: the tree depth is at most log2(sources) + 1 < 64.
_STACK = 160

# ----------------------------------------------------------------------------------------------
# The model


@dataclass
class WarpModel:
    """Everything :func:`warp` needs, precomputed from the undeformed mesh by :func:`prepare_warp`.

    Coordinates are stored relative to ``origin`` (the centre of the surface's bounding box),
    which keeps the rotation moments well conditioned. Sources are in tree order: ``src_index``
    maps them to the concatenation [surface nodes, fixed nodes] (values < ``n_surface`` move).
    """

    n_points: int
    settings: WarpSettings
    surface_ids: np.ndarray
    surface_pos: np.ndarray         # (Ns, 3) relative to origin
    fixed_ids: np.ndarray
    target_ids: np.ndarray          # every other node, in tree-friendly (Morton) order
    target_pos: np.ndarray          # (Nt, 3) relative to origin
    slide_rows: np.ndarray          # rows of target_ids that slide
    slide_proj: np.ndarray          # (K, 3, 3) symmetric projectors
    origin: np.ndarray
    ldef: float
    chord: float                    # mean chord estimate of the surface (see rotation_length)
    src_pos: np.ndarray             # (Ms, 3) relative to origin, tree order
    src_area: np.ndarray
    src_index: np.ndarray
    node_lo: np.ndarray
    node_hi: np.ndarray
    node_left: np.ndarray           # -1 for leaves; children have larger ids than parents
    node_right: np.ndarray
    node_center: np.ndarray         # area-weighted centroid
    node_radius: np.ndarray         # max distance of the node's sources from the centroid
    node_area: np.ndarray

    @property
    def n_surface(self) -> int:
        return len(self.surface_ids)

    @property
    def n_targets(self) -> int:
        return len(self.target_ids)

    @property
    def fixed_node(self) -> int:
        """First tree node of the fixed sources' subtree (every later node is in it; the node
        count when there are no fixed sources). Sources in tree order: the surface ones first."""
        nn, ms = len(self.node_lo), len(self.src_index)
        if self.n_surface == 0:
            return 0
        if self.n_surface >= ms:
            return nn
        return int(self.node_right[0])

    def params(self) -> tuple:
        s = self.settings
        fast = s.a == 3.0 and s.b == 5.0
        eps2 = (1e-12 * self.ldef) ** 2
        return (self.ldef ** 2, 0.5 * s.a, 0.5 * s.b, s.a, s.b, s.alpha ** s.b, fast, eps2,
                0.5 * float(s.tolerance), self.rotation_length ** 2 if self.rotation_length else 0.0)

    @property
    def rotation_length(self) -> float | None:
        """rho of the rotation fade: ``rotation_reach`` x the mean chord (None: no fade).

        The mean chord is estimated from the surface alone: its area over twice the diagonal of
        its bounding box (a wing's wetted area is about 2 x span x mean chord, its diagonal about
        the span); for a 2D mesh half the length of the airfoil's outline."""
        rr = self.settings.rotation_reach
        return None if rr is None else float(rr) * self.chord


def prepare_warp(points: np.ndarray, surface_ids, fixed_ids=(), sliding=(),
                 settings: WarpSettings | None = None, *, areas: np.ndarray | None = None,
                 faces: list[CellBlock] | None = None, progress=None, targets=None) -> WarpModel:
    """Precompute the sources, their area weights, L and the tree, from the undeformed mesh.

    Parameters
    ----------
    points
        (N, 3) undeformed mesh points.
    surface_ids
        Node ids of the deforming surface (their displacement is given to :func:`warp`).
    fixed_ids
        Node ids that never move (sources of zero motion). Ids also in ``surface_ids`` are
        surface nodes.
    sliding
        :class:`SlidingPlane` s, or ``(ids, normal, point)`` tuples: nodes that move only in a
        plane. Ids that are surface or fixed nodes keep those roles.
    settings
        :class:`WarpSettings`. ``method="none"`` builds no tree.
    areas, faces
        Area weight per mesh node, (N,); or the boundary faces of the surface and fixed markers
        (lines in 2D) to compute them with :func:`vertex_areas`. A source of zero area (a node on
        no face) gets the median area of the sources.
    targets
        Node ids whose displacement is wanted (one MPI rank's part of its local mesh, owned nodes
        and halo); the other nodes that are neither surface nor fixed are then not warped (zero
        displacement, as fixed nodes, but no source). Default: every node. Each warped node's value
        is the same either way (it depends on the sources only).
    """
    settings = settings or WarpSettings()
    progress = progress or no_progress
    pts = np.asarray(points, dtype=np.float64)
    n = len(pts)
    surface_ids = unique_ids(np.asarray(surface_ids, dtype=np.int64))
    fixed_ids = setdiff_ids(np.asarray(fixed_ids, dtype=np.int64), surface_ids)
    for name, ids in (("surface", surface_ids), ("fixed", fixed_ids)):
        if ids.size and (ids[0] < 0 or ids[-1] >= n):
            raise ValueError(f"{name} node ids out of range 0..{n - 1}")
    is_target = np.ones(n, dtype=bool)
    is_target[surface_ids] = False
    is_target[fixed_ids] = False
    if targets is not None:
        wanted = np.zeros(n, dtype=bool)
        wanted[np.asarray(targets, dtype=np.int64)] = True
        is_target &= wanted
    target_ids = np.flatnonzero(is_target)

    lo, hi = ((pts[surface_ids].min(axis=0), pts[surface_ids].max(axis=0)) if surface_ids.size
              else (pts.min(axis=0), pts.max(axis=0)) if n else (np.zeros(3), np.zeros(3)))
    origin = 0.5 * (lo + hi)
    size = float(np.linalg.norm(hi - lo))
    if size <= 0:
        size = max(diagonal(pts), 1.0)
    ldef = float(settings.ldef) if settings.ldef is not None else size
    chord = size
    surface_pos = pts[surface_ids] - origin

    # sliding projectors, per target row
    slide_rows, slide_proj = sliding_projectors(sliding, is_target, n)
    rows_of = np.full(n, -1, dtype=np.int64)

    empty_tree = dict(src_pos=np.zeros((0, 3)), src_area=np.zeros(0), src_index=np.zeros(0, np.int64),
                      node_lo=np.zeros(0, np.int64), node_hi=np.zeros(0, np.int64),
                      node_left=np.zeros(0, np.int64), node_right=np.zeros(0, np.int64),
                      node_center=np.zeros((0, 3)), node_radius=np.zeros(0), node_area=np.zeros(0))
    if settings.method == "none":
        return WarpModel(n, settings, surface_ids, surface_pos, fixed_ids, target_ids, np.zeros((0, 3)),
                         np.zeros(0, np.int64), np.zeros((0, 3, 3)), origin, ldef, chord, **empty_tree)

    # sources and their areas
    src_ids = np.concatenate([surface_ids, fixed_ids])
    if areas is None:
        if faces is None:
            raise ValueError("prepare_warp needs the area weights: pass areas= or faces=")
        areas = vertex_areas(pts, faces, n)
    areas = np.asarray(areas, dtype=np.float64)
    if areas.shape != (n,):
        raise ValueError(f"areas must have one value per mesh node ({n}), got {areas.shape}")
    a = areas[src_ids].copy()
    if np.any(~np.isfinite(a)) or np.any(a < 0):
        raise ValueError("area weights must be finite and >= 0")
    if a.size and np.any(a == 0):
        pos = a[a > 0]
        a[a == 0] = np.median(pos) if pos.size else 1.0
    ns = len(surface_ids)
    if ns:
        flat = np.ptp(pts[surface_ids], axis=0).min() <= 1e-12 * size    # a 2D mesh: areas are lengths
        total = float(a[:ns].sum())
        chord = total / 2 if flat else total / (2 * size)
        if not (chord > 0 and math.isfinite(chord)):
            chord = size

    # targets in Morton order: neighbours in memory walk the same tree nodes
    tpos = pts[target_ids] - origin
    order = morton_order(tpos)
    target_ids = target_ids[order]
    tpos = np.ascontiguousarray(tpos[order])
    rows_of[target_ids] = np.arange(len(target_ids))
    if len(slide_rows):
        # slide_rows were given as mesh ids: translate to rows of the reordered targets
        slide_rows = rows_of[slide_rows]

    spos = np.ascontiguousarray(pts[src_ids] - origin)
    with progress("warp tree", 1) as bar:
        if len(spos):
            perm, nlo, nhi, nleft, nright = build_forest(spos, len(surface_ids))
            spos_t = np.ascontiguousarray(spos[perm])
            a_t = a[perm]
            center, radius, narea = node_geometry(spos_t, a_t, nlo, nhi)
        else:
            return WarpModel(n, settings, surface_ids, surface_pos, fixed_ids, target_ids, tpos,
                             slide_rows, slide_proj, origin, ldef, chord, **empty_tree)
        bar.update(1)
    return WarpModel(n, settings, surface_ids, surface_pos, fixed_ids, target_ids, tpos, slide_rows,
                     slide_proj, origin, ldef, chord, spos_t, a_t, perm.astype(np.int64), nlo, nhi, nleft, nright,
                     center, radius, narea)


def prepare_mesh_warp(mesh, surface, settings: WarpSettings | None = None, *, progress=None,
                      size: float | None = None, targets=None) -> tuple[WarpModel, MarkerRoles]:
    """:func:`marker_roles` then :func:`prepare_warp` for an :class:`ffdcli.mesh.Mesh`.

    ``surface`` is the marker name or names of the deforming surface. The warp's surface nodes
    (``model.surface_ids``) are the sorted unique nodes of those markers: :func:`warp` takes their
    displacement in that order. ``size``: the bounding-box diagonal of the whole mesh when ``mesh``
    is one MPI rank's local mesh (:func:`ffdcli.parallel.distributed.diagonal`); default that of its points.
    ``targets``: as in :func:`prepare_warp`.
    """
    settings = settings or WarpSettings()
    roles = marker_roles(mesh.points, mesh.markers, surface, mesh.dim, settings, path=mesh.path, size=size)
    model = prepare_warp(mesh.points, roles.surface_ids, roles.fixed_ids, roles.sliding, settings,
                         faces=roles.faces, progress=progress, targets=targets)
    return model, roles


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


# ----------------------------------------------------------------------------------------------
# Public evaluation


def _source_motion(model: WarpModel, disp, rot):
    """Per source in tree order: the NV votes (b, -M x_i, M), and whether M is used."""
    ns = model.n_surface
    b = np.asarray(disp, dtype=np.float64)
    if b.shape != (ns, 3):
        raise ValueError(f"surface displacement must be ({ns}, 3), got {b.shape}")
    ms = len(model.src_index)
    bm = np.zeros((ms, NV))
    moving = model.src_index < ns
    sid = model.src_index[moving]
    bm[moving, :3] = b[sid]
    use_rot = rot is not None
    if use_rot:
        R = np.asarray(rot, dtype=np.float64)
        if R.shape != (ns, 3, 3):
            raise ValueError(f"surface rotation must be ({ns}, 3, 3), got {R.shape}")
        M = R[sid] - np.eye(3)
        bm[moving, 3:6] = -np.einsum("nij,nj->ni", M, model.src_pos[moving])
        bm[moving, 6:] = M.reshape(-1, 9)
    return bm, use_rot


def _blocks(n: int) -> np.ndarray:
    """Work items of a chunk, interleaved so that both threads get near-wall and far targets."""
    nb = (n + _BLOCK - 1) // _BLOCK
    stride = 7 if nb % 7 else 11
    return (np.arange(nb, dtype=np.int64) * stride) % nb if nb % stride else np.arange(nb)


def warp(model: WarpModel, surface_displacement: np.ndarray, surface_rotation: np.ndarray | None = None,
         *, exact: bool = False, progress=None, rows: tuple[int, int] | None = None, comm=None) -> np.ndarray:
    """Displacement (N, 3) of every mesh node given the motion of the surface nodes.

    Parameters
    ----------
    model
        From :func:`prepare_warp`.
    surface_displacement
        (Ns, 3) translation ``b`` of each surface node, in the order of ``model.surface_ids``.
    surface_rotation
        (Ns, 3, 3) frame matrix ``F`` of each surface node (``M = F - I``: the FFD map's gradient
        or the rotation of the surface frame, see :meth:`ffdcli.app.pipeline.DesignRun.surface_frames`),
        or None for translation only (M = 0).
    exact
        Evaluate the direct O(N x Ns) sum instead of the tree (tests, error reports).
    progress
        Progress factory (:mod:`ffdcli.progress`).
    rows
        ``(lo, hi)``: compute only the volume nodes ``model.target_ids[lo:hi]`` (one MPI rank's
        share, :func:`ffdcli.parallel.comm.share`) and return their (hi - lo, 3) displacements; each
        node's value is the same as in the whole run.
    comm
        :mod:`ffdcli.parallel.comm` communicator (a collective): each rank warps its block of the volume
        nodes (``rows``) and the blocks are gathered; every rank returns the whole result, equal bit
        for bit to the serial one.

    Returns
    -------
    (N, 3) displacement: surface nodes get ``surface_displacement`` exactly, fixed nodes zero,
    sliding nodes the IDW displacement projected on their plane, every other node the IDW value.
    The tree's decisions depend on the undeformed mesh only, so this is a fixed linear map of
    (b, M = R - I) whose transpose is :func:`warp_vjp`.
    """
    if comm is not None and comm.size > 1 and rows is None:
        part = comm.run(warp, model, surface_displacement, surface_rotation, exact=exact, progress=progress,
                        rows=comm.share(model.n_targets))
        out = np.zeros((model.n_points, 3))
        out[model.target_ids] = comm.allgather_rows(part)
        out[model.surface_ids] = np.asarray(surface_displacement, dtype=np.float64)
        return out
    progress = progress or no_progress
    b = np.asarray(surface_displacement, dtype=np.float64)
    out = np.zeros((model.n_points, 3))
    if b.shape != (model.n_surface, 3):
        raise ValueError(f"surface displacement must be ({model.n_surface}, 3), got {b.shape}")
    t_lo, t_hi = (0, model.n_targets) if rows is None else (int(rows[0]), int(rows[1]))
    if not 0 <= t_lo <= t_hi <= model.n_targets:
        raise ValueError(f"rows {rows} out of range 0..{model.n_targets}")
    if model.settings.method == "none" or model.n_targets == 0 or len(model.src_index) == 0:
        if rows is not None:
            return np.zeros((t_hi - t_lo, 3))
        out[model.surface_ids] = b
        return out
    bm, use_rot = _source_motion(model, b, surface_rotation)
    node_bm = _node_moments(bm, model.src_pos, model.src_area, model.node_center, model.node_lo,
                            model.node_hi, use_rot)
    l2, ha, hb, pa, pb, ab, fast, eps2, tol, rho2 = model.params()
    soa = np.ascontiguousarray(np.vstack([model.src_pos.T, model.src_area[None, :], bm.T]))
    d = np.empty((t_hi - t_lo, 3))
    with progress("volume mesh", t_hi - t_lo) as bar:
        for lo, hi in chunks(t_hi - t_lo, model.settings.chunk):
            _warp_kernel(model.target_pos[t_lo + lo:t_lo + hi], _blocks(hi - lo), d[lo:hi], exact,
                         model.node_lo, model.node_hi, model.node_left, model.node_right,
                         model.node_center, model.node_radius, model.node_area, node_bm,
                         model.src_pos, model.src_area, bm, l2, ha, hb, pa, pb, ab, fast, eps2, tol,
                         rho2, use_rot, model.fixed_node, soa)
            bar.update(hi - lo)
    if len(model.slide_rows):
        mine = (model.slide_rows >= t_lo) & (model.slide_rows < t_hi)
        sr = model.slide_rows[mine] - t_lo
        d[sr] = np.einsum("nij,nj->ni", model.slide_proj[mine], d[sr])
    if rows is not None:
        return d
    out[model.target_ids] = d
    out[model.surface_ids] = b
    return out


def warp_vjp(model: WarpModel, g: np.ndarray, *, exact: bool = False,
             progress=None, comm=None) -> tuple[np.ndarray, np.ndarray]:
    """Transpose of :func:`warp`: ``g`` (N, 3) = dJ/d(displacement) -> (dJ/db (Ns, 3), dJ/dM (Ns, 3, 3)).

    :func:`warp` is a fixed linear map of (b, M = R - I) (its tree decisions are made on the
    undeformed mesh); this is its exact transpose, tree and all:
    ``sum(g * warp(model, v, I + V)) == sum(g_b * v) + sum(g_M * V)`` to rounding, so it is also
    the exact derivative of :func:`warp` at every (b, R). The pass-through of surface nodes, the
    zero of fixed nodes and the sliding projections are included. ``exact`` must match the
    :func:`warp` call being differentiated.
    ``comm`` (:mod:`ffdcli.parallel.comm`, a collective): each rank sums over its share of the volume
    nodes and the sums are added over the ranks; every rank passes the whole ``g`` and gets the
    whole result (equal to the serial one to rounding: the sums are added in another order).

    With rotations that follow the design (R from the FFD's deformation gradient), chain ``g_M``
    through dR/d(design) (:mod:`ffdcli.volume.frames`).
    """
    progress = progress or no_progress
    g = np.asarray(g, dtype=np.float64)
    if g.shape != (model.n_points, 3):
        raise ValueError(f"g must be ({model.n_points}, 3), got {g.shape}")
    ns = model.n_surface
    g_b = g[model.surface_ids].copy()
    g_M = np.zeros((ns, 3, 3))
    if model.settings.method == "none" or model.n_targets == 0 or len(model.src_index) == 0:
        return g_b, g_M
    gt = g[model.target_ids]
    if len(model.slide_rows):
        gt[model.slide_rows] = np.einsum("nij,nj->ni", model.slide_proj, gt[model.slide_rows])
    l2, ha, hb, pa, pb, ab, fast, eps2, tol, rho2 = model.params()
    nthreads = numba.get_num_threads()
    nn, ms = len(model.node_lo), len(model.src_index)
    acc_node = np.zeros((nthreads, nn, NM))
    acc_src = np.zeros((nthreads, ms, NV))
    dummy_bm = np.zeros((1, NM))
    soa = np.ascontiguousarray(np.vstack([model.src_pos.T, model.src_area[None, :]]))
    t_lo, t_hi = (0, model.n_targets) if comm is None else comm.share(model.n_targets)

    def accumulate():
        with progress("volume mesh (transpose)", t_hi - t_lo) as bar:
            for lo, hi in chunks(t_hi - t_lo, model.settings.chunk):
                lo, hi = lo + t_lo, hi + t_lo
                _vjp_kernel(model.target_pos[lo:hi], np.ascontiguousarray(gt[lo:hi]), acc_node,
                            acc_src, exact, model.node_lo, model.node_hi, model.node_left,
                            model.node_right, model.node_center, model.node_radius, model.node_area,
                            dummy_bm, model.src_pos, model.src_area, dummy_bm, l2, ha, hb, pa, pb, ab,
                            fast, eps2, tol, rho2, model.fixed_node, soa)
                bar.update(hi - lo)

    if comm is None:
        accumulate()
    else:
        comm.run(accumulate)
        acc_node = comm.allreduce_sum(acc_node.sum(axis=0, keepdims=True))
        acc_src = comm.allreduce_sum(acc_src.sum(axis=0, keepdims=True))
    # Node accumulators, per node C over the targets that aggregated it (u = x - c_C; phi, psi of
    # the b channel, phi_r, psi_r of the rotation channels):
    # [0:3] sum phi/W g; [3 + 3p + k] sum psi/W g_p u_k; [12:15] sum phi_r/W g;
    # [15 + 3p + k] sum psi_r/W g_p u_k; [24 + 3p + q] sum phi_r/W g_p x_q;
    # [33 + 9k + 3p + q] sum psi_r/W u_k g_p x_q. Source i of C gets A_i (G_f + G_s (x_i - c_C))
    # per channel: fold the -c_C parts into G_f so that the sums can be pushed down the tree.
    an = acc_node.sum(axis=0)
    asrc = acc_src.sum(axis=0)
    c = model.node_center
    for f, s in ((0, 3), (12, 15)):
        an[:, f:f + 3] -= np.einsum("npk,nk->np", an[:, s:s + 9].reshape(-1, 3, 3), c)
    an[:, 24:33] -= np.einsum("nk,nkpq->npq", c, an[:, 33:60].reshape(-1, 3, 3, 3)).reshape(-1, 9)
    _push_down(an, model.node_left, model.node_right)
    leaves = np.flatnonzero(model.node_left < 0)
    leaves = leaves[np.argsort(model.node_lo[leaves])]      # leaf ranges partition the sources
    leaf = an[np.repeat(leaves, model.node_hi[leaves] - model.node_lo[leaves])]
    x = model.src_pos
    a = model.src_area[:, None]
    gb = asrc[:, 0:3] + a * (leaf[:, 0:3] + np.einsum("npk,nk->np", leaf[:, 3:12].reshape(-1, 3, 3), x))
    gc = asrc[:, 3:6] + a * (leaf[:, 12:15] + np.einsum("npk,nk->np", leaf[:, 15:24].reshape(-1, 3, 3), x))
    gx = asrc[:, 6:15].reshape(-1, 3, 3) + a[:, :, None] * (
        leaf[:, 24:33].reshape(-1, 3, 3) + np.einsum("nk,nkpq->npq", x, leaf[:, 33:60].reshape(-1, 3, 3, 3)))
    moving = model.src_index < ns
    sid = model.src_index[moving]
    g_b[sid] += gb[moving]
    # c = -M x_i: its gradient reaches M as -g_c x_i^T
    g_M[sid] = gx[moving] - gc[moving][:, :, None] * x[moving][:, None, :]
    return g_b, g_M


def idw_reference(points_src: np.ndarray, areas: np.ndarray, disp: np.ndarray, rot: np.ndarray | None,
                  targets: np.ndarray, settings: WarpSettings, ldef: float,
                  rotation_length: float | None = None) -> np.ndarray:
    """Plain NumPy direct sum (the formula of the module docstring) for checking the kernels.

    ``rotation_length``: rho of the rotation fade (None: no fade)."""
    s = settings
    e = targets[:, None, :] - points_src[None, :, :]
    r2raw = np.einsum("tsk,tsk->ts", e, e)
    r2 = r2raw + (1e-12 * ldef) ** 2
    q = ldef ** 2 / r2
    w = areas[None, :] * (q ** (s.a / 2) + s.alpha ** s.b * q ** (s.b / 2))
    v = np.broadcast_to(disp[None, :, :], e.shape).copy()
    if rot is not None:
        gf = 1.0 if rotation_length is None else 1.0 / (1.0 + (r2raw / rotation_length ** 2) ** 2)
        v += np.broadcast_to(gf, w.shape)[:, :, None] * np.einsum("sij,tsj->tsi", rot - np.eye(3), e)
    return np.einsum("ts,tsi->ti", w, v) / w.sum(axis=1)[:, None]
