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
0.5; null: no fade, IDWarp's form, which reproduces any rigid motion exactly). The fixed sources
hold the far field still: without them a far node would move with the average surface motion.

Settings (``volume:`` in the design file, :class:`WarpSettings`): ``a`` = 3, ``b`` = 5,
``alpha`` = 1 and ``ldef`` = L. Only the ratio of the two terms depends on L (the common factor
cancels), so L sets where the short-range ``b`` term takes over: closer than ``alpha^(b/(b-a)) L``
(L itself with the defaults: the whole wing's neighbourhood follows its nearest surface, the way
IDWarp is run for planform changes with ``LdefFact`` 50-100; IDWarp's own default, alpha 0.25 here,
let a far surface's average motion shear the cells behind a moving tip of swept wings). Default L:
the surface's bounding-box diagonal. Area weights: vertex areas (:func:`vertex_areas`).
**Marker rules**: :mod:`ffdcli.volume.roles`. **The source tree**: :mod:`ffdcli.volume.tree`.

**Tree approximation.** The exact sum costs O(N_targets x N_sources). Sources are held in a k-d
tree (median splits on the widest coordinate, leaves of up to 16 sources; the surface sources and
the fixed sources in separate subtrees under the root). For each tree node C the warp keeps the
area, the area-weighted centroid ``c_C``, the radius ``r`` (largest distance of a source from
``c_C``) and the moments ``sum A_i v_i`` and ``sum A_i (x_i - c_C) v_i^T`` of the votes
``v_i = (b_i, -M_i x_i, M_i)``. A group at distance ``D = |x - c_C| > r`` contributes its monopole
and dipole terms: ``phi(D) sum A_i v_i + psi(D) sum A_i ((x - c_C).(x_i - c_C)) v_i`` to the
numerator and ``A_C phi(D)`` to W (the dipole of the weights is zero about the centroid), with
``phi(D) = (L/D)^a + (alpha L/D)^b`` and ``psi = -phi'(D)/D`` for the translation votes, and
``phi g``, ``-(phi g)'/D`` for the rotation votes. A target aggregates a group when the bound of
the second-order remainder of its weights

    A_C (t^2 / 2) [a (a+1) (L/D)^a (1-t)^-(a+2) + b (b+1) (alpha L/D)^b (1-t)^-(b+2)],  t = r/D

is at most ``tolerance * W_ref / 4`` (:data:`REFERENCE_SHARE`), and otherwise opens it (its
children, or a leaf's sources one by one). ``W_ref`` is the target's own weight, estimated by a
coarse walk of its own (nearest groups first, the surface subtree before the fixed one, tolerance
:data:`REFERENCE_TOLERANCE` against the weight summed so far; kept with the model: it depends on the
geometry only); 2 bounds the spread of translation votes relative to the largest displacement.
Every decision is a function of the target and the node alone, and every target takes its nodes in
the tree's one depth-first order, so a target's value does not depend on which other targets are
warped with it (an MPI rank's part, a row range, a chunk: bit for bit the whole run's). That is what
lets nearby targets share the walk: blocks of 64 targets in Morton order walk the tree together
(:mod:`ffdcli.volume._warp_blocks`), decide for all at once where the block's bounding sphere proves
what each target would decide, and sum each group or leaf for all their targets in vectorised loops
(``python -m benchmarks.versus``: 1.7-1.8x faster than one walk per target). The decisions depend
on the undeformed geometry only, never on the motion: the approximate warp is one fixed linear map of (b, M), so
:func:`warp_vjp` (its exact transpose) is the exact derivative, and ``ffd grad`` / ``mesh_vjp``
match central differences of the written mesh at the default tolerance. This is a per-group
criterion, not a bound on the total: the error measured against the exact sum is about
``tolerance x max |b|`` (``benchmarks/bench_warp.py``); the tests check
``<= tolerance x max |b|`` on small meshes.

Kernels: :mod:`ffdcli.volume._warp_blocks` (the block walk), :mod:`ffdcli.volume._warp_kernels` (the
reference walk, exact sums, moments); NumPy reference :mod:`ffdcli.volume.idw_reference`.

**The wall layer.** A mesh with thin cells stacked on its wall (a RANS mesh) moves them rigidly with
their wall (:mod:`ffdcli.volume.wall_layer`, :mod:`ffdcli.volume.layer_motion`; ``volume.wall_layer``):
not linear (it turns with the deformed wall's normals): :func:`warp_vjp` and the forward derivative take ``at=(b, F)``.
The nodes that follow their wall wholly (blend weight 1: most of a RANS mesh's volume near the wall) are
not warped at all (:func:`~ffdcli.volume.layer_motion.warped_rows`), nor their reference weights walked.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numba
import numpy as np

from ffdcli.geometry.surface import mean_chord, vertex_areas
from ffdcli.mesh import CellBlock, diagonal
from ffdcli.mesh.idsets import setdiff_ids, unique_ids
from ffdcli.mesh.morton import morton_order
from ffdcli.progress import chunks, no_progress
from ffdcli.settings import METHODS, WarpSettings  # noqa: F401  (WarpSettings: re-exported)
from ffdcli.volume._warp_blocks import BT, vjp_blocks, warp_blocks
from ffdcli.volume._warp_kernels import (
    NM,
    NV,
    exact_kernel,
    exact_vjp_kernel,
    node_moments,
    push_down,
    weight_reference_kernel,
)
from ffdcli.volume.frames import rotations_from_deformation_gradient  # noqa: F401  (re-exported)
from ffdcli.volume.idw_reference import idw_reference  # noqa: F401  (re-exported)
from ffdcli.volume.layer_motion import blend_layer, layer_transpose, warped_rows
from ffdcli.volume.roles import (  # noqa: F401  (re-exported: the public names of the warp)
    PLANE_TOLERANCE,
    MarkerRoles,
    SlidingPlane,
    marker_roles,
    sliding_projectors,
)
from ffdcli.volume.tree import LEAF_SIZE, build_forest, node_geometry  # noqa: F401
from ffdcli.volume.wall_layer import WallLayer, saved_or_detected

#: The tolerance (on the scale of ``tolerance / 2``) of the coarse per-target walk whose weight is each
#: target's reference in the block walk's decisions (:meth:`WarpModel.tolerances`).
REFERENCE_TOLERANCE = 0.3
#: The share of the reference weight a node's remainder bound is held to. A target's final weight is
#: larger than the weight it has summed when a one-walk-per-target criterion decides (and the coarse
#: walk's estimate may be a few % high): with the whole reference the largest error on the 1M-node
#: extruded wing (60 x 300 nodes against the exact sum) was 1.14e-3 of the largest move, with half of
#: it 7.4e-4 (0.7: 9.4e-4), at 15 % more time.
REFERENCE_SHARE = 0.5

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
    #: each target's reference weight (:meth:`tolerances`), walked on first use ("walked"; NaN: not yet)
    weight_refs: dict = field(default_factory=dict, repr=False)
    #: the near-wall layer that moves rigidly with its wall (:mod:`ffdcli.volume.layer_motion`), or None
    layer: WallLayer | None = field(default=None, repr=False)

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

    def tolerances(self, lo: int, hi: int, rows: np.ndarray | None = None) -> np.ndarray:
        """(hi - lo,) ``tolerance / 2 x REFERENCE_SHARE x W_ref`` of the targets ``lo:hi`` (``rows``: of
        those rows of it only, relative to ``lo``): what a tree node's remainder bound is held to by each
        target (:mod:`ffdcli.volume._warp_blocks`). ``W_ref``: the target's weight from its own walk at the
        coarse tolerance :data:`REFERENCE_TOLERANCE` (geometry only), walked for the targets asked for
        and kept (a target's walk is its own: the same bits whichever targets are asked for with it)."""
        idx = np.arange(lo, hi) if rows is None else lo + np.asarray(rows, dtype=np.int64)
        walked = self.weight_refs.setdefault("walked", np.full(self.n_targets, np.nan))   # NaN: not yet
        todo = idx[np.isnan(walked[idx])]
        if len(todo):
            l2, ha, hb, pa, pb, ab, fast, eps2, tol, rho2 = self.params()
            soa = np.ascontiguousarray(np.vstack([self.src_pos.T, self.src_area[None, :]]))
            w = np.empty(len(todo))
            weight_reference_kernel(self.target_pos[todo], w, self.node_lo, self.node_hi, self.node_left,
                                    self.node_right, self.node_center, self.node_radius, self.node_area,
                                    self.src_pos, self.src_area, l2, ha, hb, pa, pb, ab, fast, eps2,
                                    REFERENCE_TOLERANCE, self.fixed_node, soa)
            walked[todo] = w
        return self.params()[8] * REFERENCE_SHARE * walked[idx]

    def reference_weights(self, every: bool = True) -> np.ndarray:
        """(Nt,) every target's reference weight (:meth:`tolerances`), walked now where not yet; ``every``
        False: as walked so far (NaN where not: the targets the wall layer moves wholly are never warped)."""
        if every:
            self.tolerances(0, self.n_targets)
        return self.weight_refs.setdefault("walked", np.full(self.n_targets, np.nan))

    def set_reference_weights(self, weights: np.ndarray) -> None:
        """Use ``weights`` (Nt,) as :meth:`reference_weights` of this mesh and settings gave them
        (read back by :mod:`ffdcli.volume.cache`; NaN: not walked, walked when asked for)."""
        w = np.array(weights, dtype=np.float64)
        if w.shape != (self.n_targets,):
            raise ValueError(f"reference weights must be ({self.n_targets},), got {w.shape}")
        self.weight_refs["walked"] = w

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
    a = _source_areas(pts, areas, faces, src_ids)
    chord = mean_chord(pts[surface_ids], a[:len(surface_ids)], size)

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


def _source_areas(pts: np.ndarray, areas, faces, src_ids: np.ndarray) -> np.ndarray:
    """(k,) area weights of the sources ``src_ids``: ``areas`` (N,) given, or from the boundary
    ``faces`` (:func:`vertex_areas`); a source of zero area (a node on no face) gets the median."""
    n = len(pts)
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
    return a


def prepare_mesh_warp(mesh, surface, settings: WarpSettings | None = None, *, progress=None, size: float | None = None,
                      targets=None, nodes=None, saved_layer=None) -> tuple[WarpModel, MarkerRoles]:
    """:func:`marker_roles` then :func:`prepare_warp` for an :class:`ffdcli.mesh.Mesh`.

    ``surface`` is the marker name or names of the deforming surface. The warp's surface nodes
    (``model.surface_ids``) are the sorted unique nodes of those markers: :func:`warp` takes their
    displacement in that order. ``size``: the bounding-box diagonal of the whole mesh when ``mesh``
    is one MPI rank's local mesh (:func:`ffdcli.parallel.distributed.diagonal`); default that of its points.
    ``targets``: as in :func:`prepare_warp`; ``nodes``, ``saved_layer``: :func:`~.wall_layer.saved_or_detected`'s."""
    settings = settings or WarpSettings()
    roles = marker_roles(mesh.points, mesh.markers, surface, mesh.dim, settings, path=mesh.path, size=size)
    model = prepare_warp(mesh.points, roles.surface_ids, roles.fixed_ids, roles.sliding, settings,
                         faces=roles.faces, progress=progress, targets=targets)
    if settings.wall_layer == "rigid" and settings.method != "none":
        names = [surface] if isinstance(surface, str) else list(surface)
        model.layer = saved_or_detected(mesh.points, mesh.cells, mesh.marker_faces(names), model.surface_ids,
                                        model.target_ids, roles.sliding, nodes, saved_layer)
    return model, roles


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


def _blocks(n: int, size: int = BT) -> np.ndarray:
    """The blocks of ``size`` targets of a chunk, interleaved so that both threads get near-wall and far targets."""
    nb = (n + size - 1) // size
    stride = 7 if nb % 7 else 11
    return (np.arange(nb, dtype=np.int64) * stride) % nb if nb % stride else np.arange(nb)


def warp(model: WarpModel, surface_displacement: np.ndarray, surface_rotation: np.ndarray | None = None,
         *, exact: bool = False, progress=None, rows: tuple[int, int] | None = None, comm=None,
         at: np.ndarray | None = None) -> np.ndarray:
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
    at
        With a wall layer (``model.layer``, :mod:`ffdcli.volume.layer_motion`; nonlinear): ``(b, F)``, the
        translations (Ns, 3) and frames (Ns, 3, 3) at which to linearise it, ``surface_displacement``
        and ``surface_rotation - I`` then being a direction: the forward derivative (``DesignModel.mesh_jvp``).

    Returns
    -------
    (N, 3) displacement: surface nodes get ``surface_displacement`` exactly, fixed nodes zero,
    sliding nodes the IDW displacement projected on their plane, every other node the IDW value.
    The tree's decisions depend on the undeformed mesh only, so this is a fixed linear map of
    (b, M = R - I) whose transpose is :func:`warp_vjp`.
    """
    if comm is not None and comm.size > 1 and rows is None:
        part = comm.run(warp, model, surface_displacement, surface_rotation, exact=exact, progress=progress,
                        rows=comm.share(model.n_targets), at=at)
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
    node_bm = node_moments(bm, model.src_pos, model.src_area, model.node_center, model.node_lo,
                            model.node_hi, use_rot)
    l2, ha, hb, pa, pb, ab, fast, eps2, _, rho2 = model.params()
    # the targets that follow their wall wholly are not warped (their warp would be multiplied by 0)
    free = warped_rows(model.layer, t_lo, t_hi)
    pos = model.target_pos[t_lo:t_hi] if free is None else model.target_pos[t_lo + free]
    d = np.empty((len(pos), 3))
    tolw = None if exact else model.tolerances(t_lo, t_hi, free)
    with progress("volume mesh", len(pos)) as bar:
        for lo, hi in chunks(len(pos), model.settings.chunk):
            if exact:
                exact_kernel(pos[lo:hi], d[lo:hi], model.src_pos, model.src_area, bm, l2, ha, hb, ab, fast, eps2,
                              rho2, use_rot)
            else:
                warp_blocks(pos[lo:hi], tolw[lo:hi], _blocks(hi - lo), d[lo:hi], model.node_lo, model.node_hi,
                            model.node_left, model.node_right, model.node_center, model.node_radius,
                            model.node_area, node_bm, model.src_pos, model.src_area, bm, l2, ha, hb, pa, pb,
                            ab, fast, eps2, rho2, use_rot, model.fixed_node)
            bar.update(hi - lo)
    if free is not None:
        warped, d = d, np.zeros((t_hi - t_lo, 3))
        d[free] = warped
    d = blend_layer(model.layer, d, b, surface_rotation, t_lo, t_hi, at=at)
    if len(model.slide_rows):
        mine = (model.slide_rows >= t_lo) & (model.slide_rows < t_hi)
        sr = model.slide_rows[mine] - t_lo
        d[sr] = np.einsum("nij,nj->ni", model.slide_proj[mine], d[sr])
    if rows is not None:
        return d
    out[model.target_ids] = d
    out[model.surface_ids] = b
    return out


def warp_vjp(model: WarpModel, g: np.ndarray, *, exact: bool = False, progress=None, comm=None,
             at: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
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
    through dR/d(design) (:mod:`ffdcli.volume.frames`). With a wall layer (``model.layer``) the warp is
    not linear in the frames: ``at`` (Ns, 3, 3) is required, the frames of the :func:`warp` differentiated.
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
    if model.layer is not None and len(model.layer.rows):
        if at is None:
            raise ValueError("warp_vjp: this model moves its wall layer rigidly (nonlinear in the frames): "
                             "pass at=(b, F), the translations and frames the warp was given")
        layer_b, layer_M = layer_transpose(model.layer, gt, at)
        g_b += layer_b
        g_M += layer_M
    l2, ha, hb, pa, pb, ab, fast, eps2, _, rho2 = model.params()
    nthreads = numba.get_num_threads()
    nn, ms = len(model.node_lo), len(model.src_index)
    acc_node = np.zeros((nthreads, nn, NM))
    acc_src = np.zeros((nthreads, ms, NV))
    t_lo, t_hi = (0, model.n_targets) if comm is None else comm.share(model.n_targets)

    def accumulate():
        tolw = None if exact else model.tolerances(t_lo, t_hi)
        with progress("volume mesh (transpose)", t_hi - t_lo) as bar:
            for lo, hi in chunks(t_hi - t_lo, model.settings.chunk):
                tx, gc = model.target_pos[lo + t_lo:hi + t_lo], np.ascontiguousarray(gt[lo + t_lo:hi + t_lo])
                if exact:
                    exact_vjp_kernel(tx, gc, acc_src, model.src_pos, model.src_area, l2, ha, hb, ab, fast,
                                      eps2, rho2)
                else:
                    vjp_blocks(tx, tolw[lo:hi], gc, acc_node, acc_src, model.node_lo, model.node_hi,
                               model.node_left, model.node_right, model.node_center, model.node_radius,
                               model.node_area, model.src_pos, model.src_area, l2, ha, hb, pa, pb, ab, fast,
                               eps2, rho2, model.fixed_node)
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
    push_down(an, model.node_left, model.node_right)
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
    g_M[sid] += gx[moving] - gc[moving][:, :, None] * x[moving][:, None, :]
    return g_b, g_M
