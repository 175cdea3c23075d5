"""The near-wall layer of a mesh, found from the mesh itself: which nodes move rigidly with their wall.

A RANS mesh stacks thin cells on its walls (first cell 1e-6 to 1e-5 chord, aspect ratios of 1e3 to
1e4). Each wall node ``k`` of the deforming surface has one *off-wall edge*: the edge of a cell on
the wall from ``k`` to a node off the wall that is best aligned with the wall normal ``n_k`` (the
quad or prism stacked on the wall; in a tetrahedral mesh the most normal edge).
Its projection on the normal is the first-cell height ``h_k`` (:func:`off_wall_edges`).

The mesh *has* a boundary layer when its first cells are thin against the wall's own spacing
``s_k`` (the shortest wall edge at ``k``): the median aspect ratio ``s_k / h_k`` is at
least :data:`MIN_ASPECT` (50). An Euler mesh (aspect about 1) has none and its volume moves as
before. The layer's thickness ``delta_k`` at a wall node is its stack's height
(:mod:`ffdcli.volume.wall_stacks`: the stacked quads or prisms, as long as they are thinner than wide:
a prism layer's thickness, or where a structured mesh's cells become isotropic), but no more than
:data:`STACK_SPACINGS` (1) wall spacing ``s_k``; where a node is, the
thickness is the blend ``delta = sum_k psi_k delta_k`` of its wall nodes' (the weights below).
A node at distance ``d`` from its nearest wall
node has the weight

    s(d) = 1 for d <= delta;  1 - 3 t^2 + 2 t^3,  t = (d - delta) / (BLEND x delta)  up to
    delta (1 + BLEND);  0 beyond,

with which it follows the wall rigidly (:mod:`ffdcli.volume.layer_motion`); the rest of its motion is
the warp's. ``BLEND`` (4): the warp's thickness-wise stretch ``f`` of the first cells (0.4 to 1.6 for
shape moves of 5 % chord) is taken up over the blend, which stays monotone for ``BLEND > (1 - f) / f``.

Which wall: the node's ``K + 1`` nearest wall nodes (``K`` = :data:`NEIGHBOURS`: 4 in 2D, 8 in 3D) give
the Franke-Little weights ``psi_k = ((R - d_k)_+ / (R d_k))^3``, ``R`` the distance to the last of them,
normalised (:attr:`WallLayer.partition`): a node on an off-wall edge 1e-6 above its wall node and a
wall spacing of 1e-2 gives that node all but 1e-18 of the weight (its first cell is that node's
alone), while between wall nodes, and in the wedge behind a sharp trailing edge, the weights vary
continuously (a node leaving the ``K`` nearest has weight 0 as it leaves): no jump between stacks.
A wall node on a sharp edge (faces turning by more than 60 degrees: :func:`sharp_nodes`) has no
normal; it carries the FFD map's gradient itself (:mod:`ffdcli.volume.layer_motion`).

Everything here depends on the undeformed mesh only (a fixed assignment: the layer motion is then
differentiable exactly, its derivative taken at the frames of the design).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.sparse import csr_matrix
from scipy.spatial import cKDTree

from ffdcli.geometry.surface import face_vectors, vertex_normals
from ffdcli.mesh import CellBlock
from ffdcli.parallel.distributed import RankNodes, extent
from ffdcli.volume.wall_stacks import stack_heights

#: The median first-cell aspect ratio (shortest wall spacing / first-cell height) from which a mesh has
#: a boundary layer that moves with its wall: a RANS mesh's first cell (1e-6 to 1e-5 chord) against a
#: wall spacing of 1e-3 to 1e-2 chord is 100 to 1e4; an Euler mesh's about 1, a coarse mesh with a
#: first cell of 5e-3 chord (y+ in the hundreds) about 10.
MIN_ASPECT = 50.0
#: The layer is at most this many wall spacings thick at a wall node (its stack of thin cells may be
#: taller: a structured mesh's cells stay thinner than wide 0.1 chord from the RAE2822's wall, 6 spacings).
#: A wall turned by theta over one spacing s (a deflected hinge) folds the stacks set on it along its
#: normals at s / theta from it (5.7 s at 10 degrees): the layer and its blend stay inside that.
STACK_SPACINGS = 1.0
#: The blend from the rigid layer into the warp's motion, in layer thicknesses.
BLEND = 4.0
#: A wall node is on a sharp edge (a sharp trailing edge, a flat tip's rim) when the faces around it
#: turn by more than 60 degrees: |sum of their vector areas| < cos(30 deg) x the sum of their areas.
SHARP_COS = float(np.cos(np.radians(30.0)))
#: A wall node is on a sliding plane within this fraction of the wall's size (the warp's own tolerance).
PLANE_TOL = 1e-9
#: ... and when its wall meets the plane at more than this many degrees (a wing's root: about 90).
PLANE_MIN_ANGLE = 30.0
#: The wall nodes whose rigid motions a layer node blends (2D, 3D).
NEIGHBOURS = {2: 4, 3: 8}


@dataclass(frozen=True)
class WallLayer:
    """The nodes that follow their wall point rigidly, and how much (from :func:`detect_wall_layer`).

    rows
        (n,) rows of the warp's targets (``WarpModel.target_ids``) in the layer or its blend.
    partition
        (n, Ns) sparse: each one's weights of the wall nodes (rows sum to 1).
    position
        (n, 3) the nodes' undeformed positions, relative to ``origin``.
    wall_position
        (Ns, 3) the wall nodes' positions relative to ``origin``.
    weight
        (n,) ``s`` in (0, 1]: 1 in the layer, falling to 0 over the blend.
    normals
        (Ns, 3) unit wall normals of the surface nodes (zero where a node is on no face or on a sharp edge).
    planes
        (Ns, 3) the unit normal of the plane a wall node slides in (a wing's root on a symmetry plane),
        zero for the others.
    faces
        the wall's faces as :class:`~ffdcli.mesh.CellBlock` s of rows of ``wall_position``: the deformed
        wall's own normals (:func:`layer_normals`).
    stacked
        (n,) how much each node is on one wall node's stack alone, in [0, 1]: ``(K sum_k psi_k^2 - 1) /
        (K - 1)`` (1: one wall node has all the weight, as the first cells' nodes have; 0: ``K`` share
        it evenly). That share of its offset from the wall turns with the wall's rotation unstretched
        (the stack's lean kept); the rest follows the wall's frame (:mod:`ffdcli.volume.layer_motion`).
    thickness
        the median of the stacks' heights (mesh units; the blend ends at ``delta (1 + BLEND)`` of each node's).
    """

    rows: np.ndarray
    partition: csr_matrix
    position: np.ndarray
    wall_position: np.ndarray
    weight: np.ndarray
    normals: np.ndarray
    thickness: float
    planes: np.ndarray | None = None
    stacked: np.ndarray | None = None
    faces: tuple = ()


@dataclass(frozen=True)
class OffWallEdges:
    """Each wall node's off-wall edge (:func:`off_wall_edges`).

    node
        (Ns,) the node at the edge's far end (-1 where the wall node is in no volume cell).
    height
        (Ns,) first-cell height ``(x_node - x_wall) . n`` (positive; 0 where ``node`` is -1).
    angle
        (Ns,) angle (degrees) between the edge and the wall normal.
    spacing
        (Ns,) the shortest wall edge at the node (0 where it is on none).
    """

    node: np.ndarray
    height: np.ndarray
    angle: np.ndarray
    spacing: np.ndarray


def wall_normals(points: np.ndarray, faces: list[CellBlock], wall_ids: np.ndarray) -> np.ndarray:
    """(Ns, 3) area-weighted unit normals of the wall nodes ``wall_ids`` from the wall ``faces``
    (global node ids; lines of a 2D mesh give in-plane normals)."""
    return vertex_normals(points, [b for b in faces if b.type != "vertex"])[wall_ids]


def _cell_pairs(cells: list[CellBlock], on_wall: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Every (wall node, off-wall node) pair sharing a cell touching the wall: (a, b) int64 arrays."""
    a_all, b_all = [], []
    for blk in cells:
        data = blk.data
        if not len(data):
            continue
        touch = on_wall[data].any(axis=1)
        d = data[touch]
        w = on_wall[d]
        k = d.shape[1]
        for i in range(k):           # column pairs of one cell type: at most 8 x 7
            for j in range(k):
                if i == j:
                    continue
                m = w[:, i] & ~w[:, j]
                a_all.append(d[m, i])
                b_all.append(d[m, j])
    if not a_all:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    return np.concatenate(a_all), np.concatenate(b_all)


def _wall_spacing(points: np.ndarray, faces: list[CellBlock], wall_ids: np.ndarray) -> np.ndarray:
    """(Ns,) the shortest wall face edge at each wall node (0 on none): a first cell is thin when it
    is thin against the wall's spacing in every direction along it."""
    n = len(points)
    short = np.full(n, np.inf)
    for b in faces:
        if b.type == "vertex" or not len(b.data):
            continue
        k = b.data.shape[1]
        for i in range(k if k > 2 else 1):
            p, q = b.data[:, i], b.data[:, (i + 1) % k]
            ln = np.linalg.norm(points[q] - points[p], axis=1)
            np.minimum.at(short, p, ln)
            np.minimum.at(short, q, ln)
    sel = short[wall_ids]
    return np.where(np.isfinite(sel), sel, 0.0)


def off_wall_edges(points: np.ndarray, cells: list[CellBlock], faces: list[CellBlock], wall_ids: np.ndarray,
                   normals: np.ndarray | None = None, edge_nodes: np.ndarray | None = None) -> OffWallEdges:
    """Each wall node's off-wall edge: among the nodes off the wall sharing a cell with it, the one
    whose direction is closest to the wall normal (the stacked quad's or prism's; ``edge_nodes``
    (Ns,): take these instead, e.g. the undeformed mesh's choice to measure a deformed one).

    Parameters
    ----------
    points
        (N, 3) mesh points.
    cells
        The volume cells (global ids).
    faces
        The wall's boundary faces (global ids).
    wall_ids
        (Ns,) sorted wall node ids.
    normals
        (Ns, 3) unit normals (default: :func:`wall_normals` of ``points``).
    """
    pts = np.asarray(points, dtype=np.float64)
    wall_ids = np.asarray(wall_ids, dtype=np.int64)
    ns = len(wall_ids)
    nrm = wall_normals(pts, faces, wall_ids) if normals is None else normals
    if edge_nodes is None:
        on_wall = np.zeros(len(pts), bool)
        on_wall[wall_ids] = True
        a, b = _cell_pairs(cells, on_wall)
        node = np.full(ns, -1, np.int64)
        if len(a):
            ka = np.searchsorted(wall_ids, a)
            e = pts[b] - pts[a]
            ln = np.linalg.norm(e, axis=1)
            cos = np.abs(np.einsum("ij,ij->i", e, nrm[ka])) / np.where(ln > 0, ln, 1.0)
            order = np.lexsort((-cos, ka))          # per wall node, the most normal first
            first = np.r_[True, ka[order][1:] != ka[order][:-1]]
            node[ka[order][first]] = b[order][first]
    else:
        node = np.asarray(edge_nodes, dtype=np.int64)
    ok = node >= 0
    e = np.zeros((ns, 3))
    e[ok] = pts[node[ok]] - pts[wall_ids[ok]]
    ln = np.linalg.norm(e, axis=1)
    dot = np.einsum("ij,ij->i", e, nrm)
    height = np.abs(dot)
    cosang = np.clip(height / np.where(ln > 0, ln, 1.0), 0.0, 1.0)
    angle = np.where(ok, np.degrees(np.arccos(cosang)), 0.0)
    return OffWallEdges(node, np.where(ok, height, 0.0), angle, _wall_spacing(pts, faces, wall_ids))


def wall_planes(wall: np.ndarray, normals: np.ndarray, sliding=()) -> np.ndarray:
    """(Ns, 3) the unit normal of the sliding plane each wall node lies in (zero for the others).

    ``wall`` (Ns, 3) the wall nodes' positions, ``normals`` (Ns, 3) their wall normals, ``sliding`` the
    warp's :class:`~ffdcli.volume.roles.SlidingPlane` s (or ``(ids, normal, point)``). A wall node is on a
    plane when it lies in it (to :data:`PLANE_TOL` of the wall's size) and its wall meets the plane at
    more than :data:`PLANE_MIN_ANGLE` (a wing's root on a symmetry plane; a wall lying in the plane is
    not one)."""
    planes = np.zeros((len(wall), 3))
    if not len(wall):
        return planes
    size = float(np.linalg.norm(np.ptp(wall, axis=0)))
    for plane in sliding:
        normal = np.asarray(plane[1], dtype=np.float64)
        on = np.abs((wall - np.asarray(plane[2], dtype=np.float64)) @ normal) <= PLANE_TOL * size
        on &= np.abs(normals @ normal) < np.sin(np.radians(90.0 - PLANE_MIN_ANGLE)) * np.linalg.norm(normals, axis=1)
        planes[on] = normal
    return planes


def in_plane(normals: np.ndarray, planes: np.ndarray) -> np.ndarray:
    """(Ns, 3) the wall normals of the nodes on a plane (``planes``, :func:`wall_planes`) projected into
    it and made unit again; the others as they are.

    A symmetry plane mirrors the wall: a root node's faces are half of its faces, the mirror image the
    other half, and the normal of the whole (the wall and its image) lies in the plane. The one-sided
    normal of a triangulated leading edge leans out of the plane by several degrees (7 on the generated
    wings), and a twist or a sweep that grows along the span tilts it further; the mirrored wall's
    normal does not lean, and it is the direction a mesh generator stacks the root's layers in (in the
    plane)."""
    on = np.einsum("ij,ij->i", planes, planes) > 0
    if not on.any():
        return normals
    out = np.array(normals, dtype=np.float64, copy=True)
    v = out[on] - planes[on] * np.einsum("ij,ij->i", out[on], planes[on])[:, None]
    ln = np.linalg.norm(v, axis=1)
    out[on] = np.where(ln[:, None] > 0, v / np.where(ln > 0, ln, 1.0)[:, None], 0.0)
    return out


def sharp_nodes(points: np.ndarray, faces: list[CellBlock], wall_ids: np.ndarray) -> np.ndarray:
    """(k,) the wall nodes (rows of ``wall_ids``) on a sharp edge (:data:`SHARP_COS`)."""
    n = len(points)
    blocks = [b for b in faces if b.type != "vertex" and len(b.data)]
    if not blocks:
        return np.zeros(0, np.int64)
    vec = face_vectors(points, blocks)
    idx = np.concatenate([b.data.ravel() for b in blocks])
    rep = np.concatenate([np.repeat(np.arange(len(b.data)), b.data.shape[1]) for b in blocks])
    off = np.cumsum([0] + [len(b.data) for b in blocks])[:-1]
    rep = rep + np.repeat(off, [b.data.size for b in blocks])
    v = vec[rep]
    tot = np.column_stack([np.bincount(idx, v[:, c], n) for c in range(3)])[wall_ids]
    area = np.bincount(idx, np.linalg.norm(v, axis=1), n)[wall_ids]
    return np.flatnonzero((area > 0) & (np.linalg.norm(tot, axis=1) < SHARP_COS * area))


def detect_wall_layer(points: np.ndarray, cells: list[CellBlock], faces: list[CellBlock], wall_ids: np.ndarray,
                      target_ids: np.ndarray, sliding=(), nodes: RankNodes | None = None) -> WallLayer | None:
    """The wall layer of a mesh (module docstring), or None when its first cells are not thin.

    ``faces``: the deforming surface's faces (global ids); ``wall_ids`` (Ns,): its sorted nodes (the
    warp's surface nodes); ``target_ids`` (Nt,): the warp's targets, in its order; ``sliding``: the warp's
    :class:`~ffdcli.volume.roles.SlidingPlane` s (the wall nodes in one slide with it).

    ``nodes``: of one MPI rank's local mesh (a collective: :class:`~ffdcli.parallel.distributed.RankNodes`;
    the local mesh holds every wall node and face, but only the cells around the nodes it owns): each
    wall node's off-wall edge is the owner's, the stacks are walked step by step by the owners of their
    tops (:func:`ffdcli.volume.wall_stacks.stack_heights`), the flatness is the whole mesh's. Every wall
    figure is then the serial one bit for bit, and each target's weights are computed from them alone:
    the rows of the serial layer."""
    pts = np.asarray(points, dtype=np.float64)
    wall_ids = np.asarray(wall_ids, dtype=np.int64)
    target_ids = np.asarray(target_ids, dtype=np.int64)
    has_cells = bool(cells) if nodes is None else any(nodes.comm.allgather(bool(cells)))
    if not len(wall_ids) or not has_cells:
        return None
    if nodes is None and not len(target_ids):
        return None
    wall = pts[wall_ids]
    nrm = wall_normals(pts, faces, wall_ids)
    planes = wall_planes(wall, nrm, sliding)
    nrm = in_plane(nrm, planes)                 # a root's layer stacks in its symmetry plane
    edges = off_wall_edges(pts, cells, faces, wall_ids, nrm)
    if nodes is not None:
        edges = _owners_edges(edges, wall_ids, nodes)
    ok = (edges.height > 0) & (edges.spacing > 0)
    if not ok.any():
        return None
    aspect = edges.spacing[ok] / edges.height[ok]
    if np.median(aspect) < MIN_ASPECT:
        return None
    cap = STACK_SPACINGS * edges.spacing
    thick = np.maximum(np.minimum(stack_heights(pts, cells, wall_ids, nrm, edges.spacing, edges.node, nodes, cap),
                                  cap), edges.height)
    if nodes is None:                             # (the extremes along contiguous rows: the same, faster)
        span = np.ptp(np.ascontiguousarray(pts.T), axis=1)
    else:                                         # every node once: the owned rows of every rank
        lo, hi = extent(pts[nodes.owned], nodes.comm)
        span = hi - lo
    flat = span.min() <= 1e-12 * max(float(span.max()), 1e-300)
    if not len(target_ids):                       # a rank without targets: nothing of its own moves
        return None
    reach = float(thick.max()) * (1.0 + BLEND)
    tree = cKDTree(wall)
    k = min(NEIGHBOURS[2 if flat else 3], len(wall_ids) - 1)
    x = pts[target_ids]
    # one search: the k + 1 nearest wall nodes of every target, the nearest's distance its reach
    dist, near = tree.query(x, k=k + 1) if k >= 1 else (tree.query(x)[0][:, None], None)
    rows = nodes_within(tree, x, dist[:, 0], reach)
    part, psi2 = _partition(dist[rows], None if near is None else near[rows], k, len(wall_ids))
    delta = part @ thick                        # the layer's thickness where each node is (continuous)
    t = np.clip((dist[rows, 0] - delta) / (BLEND * delta), 0.0, 1.0)
    weight = 1.0 - t * t * (3.0 - 2.0 * t)
    keep = weight > 0
    rows, weight, part, psi2 = rows[keep], weight[keep], part[keep], psi2[keep]
    stacked = np.clip((k * psi2 - 1.0) / (k - 1.0), 0.0, 1.0) if k > 1 else np.ones(len(rows))
    return _assemble(pts, faces, wall_ids, target_ids, sliding, rows.astype(np.int64), part, weight, stacked,
                     float(np.median(thick)), (nrm, planes))


def _assemble(pts, faces, wall_ids, target_ids, sliding, rows, part, weight, stacked, thickness,
              normals=None) -> WallLayer:
    """The layer of the nodes ``rows`` (with their weights, found by :func:`detect_wall_layer` or read
    back by :func:`layer_from_arrays`) and the wall's geometry, which is cheap to compute again
    (``normals``: the wall's normals in their planes and the planes, when the caller has them)."""
    wall = pts[wall_ids]
    if normals is None:
        nrm = wall_normals(pts, faces, wall_ids)
        planes = wall_planes(wall, nrm, sliding)
        nrm = in_plane(nrm, planes)
    else:
        nrm, planes = normals[0].copy(), normals[1]
    nrm[sharp_nodes(pts, faces, wall_ids)] = 0.0
    origin = wall.mean(axis=0) if len(wall) else np.zeros(3)
    local = tuple(CellBlock(b.type, np.searchsorted(wall_ids, b.data)) for b in faces
                  if b.type != "vertex" and len(b.data))
    unit = layer_normals(wall - origin, local, planes)         # the same sums the deformed wall's go through
    unit[_no_normal(nrm)] = 0.0
    return WallLayer(rows, part, pts[target_ids[rows]] - origin, wall - origin, weight, unit, thickness,
                     planes, stacked, local)


def layer_arrays(layer: WallLayer) -> dict[str, np.ndarray]:
    """What :func:`detect_wall_layer` found of ``layer`` that takes time to find (the nodes, their wall
    weights, blend weights and stack shares, the thickness), as named arrays for a cache file
    (:mod:`ffdcli.volume.cache`); :func:`layer_from_arrays` builds the layer back from them."""
    part = layer.partition.tocsr()
    return {"layer_rows": layer.rows, "layer_indptr": part.indptr.astype(np.int64),
            "layer_indices": part.indices.astype(np.int64), "layer_psi": part.data, "layer_weight": layer.weight,
            "layer_stacked": layer.stacked, "layer_thickness": np.array(layer.thickness)}


def layer_from_arrays(points: np.ndarray, faces: list[CellBlock], wall_ids: np.ndarray, target_ids: np.ndarray,
                      arrays: dict, sliding=()) -> WallLayer | None:
    """The layer :func:`detect_wall_layer` finds on this mesh, from :func:`layer_arrays` of it (read back
    from a cache file whose key is this mesh's, surface's and settings'); None when the arrays are
    absent or do not fit (then the layer is found again). The same arrays bit for bit: the wall's
    geometry is computed by the same functions."""
    names = ("layer_rows", "layer_indptr", "layer_indices", "layer_psi", "layer_weight", "layer_stacked",
             "layer_thickness")
    if not all(n in arrays for n in names):
        return None
    rows, ptr, idx, psi, weight, stacked, thick = (arrays[n] for n in names)
    n, ns, nt = len(rows), len(wall_ids), len(target_ids)
    ints = all(a.dtype == np.int64 for a in (rows, ptr, idx))
    floats = all(a.dtype == np.float64 for a in (psi, weight, stacked, thick))
    if not (ints and floats and rows.ndim == 1 and thick.shape == () and ptr.shape == (n + 1,)
            and weight.shape == (n,) and stacked.shape == (n,) and idx.shape == psi.shape == (ptr[-1] if n else 0,)
            and ptr[0] == 0 and np.all(np.diff(ptr) >= 0) and (not n or (rows.min() >= 0 and rows.max() < nt))
            and (not len(idx) or (idx.min() >= 0 and idx.max() < ns))):
        return None
    pts = np.asarray(points, dtype=np.float64)
    part = csr_matrix((psi, idx, ptr), shape=(n, ns))
    return _assemble(pts, faces, np.asarray(wall_ids, dtype=np.int64), np.asarray(target_ids, dtype=np.int64),
                     sliding, rows, part, weight, stacked, float(thick))


def saved_or_detected(points: np.ndarray, cells: list[CellBlock], faces: list[CellBlock], wall_ids: np.ndarray,
                      target_ids: np.ndarray, sliding=(), nodes: RankNodes | None = None, saved=None
                      ) -> WallLayer | None:
    """:func:`detect_wall_layer`, unless ``saved`` (a function of ``target_ids`` giving the arrays an
    earlier run kept, :func:`layer_arrays`, or an empty dict; :mod:`ffdcli.volume.cache`) gives arrays
    that fit: then the layer built from them (:func:`layer_from_arrays`). Serial runs only (``nodes`` None)."""
    kept = saved(target_ids) if saved is not None and nodes is None else {}
    layer = layer_from_arrays(points, faces, wall_ids, target_ids, kept, sliding) if kept else None
    return layer if layer is not None else detect_wall_layer(points, cells, faces, wall_ids, target_ids, sliding,
                                                             nodes)


def _owners_edges(edges: OffWallEdges, wall_ids: np.ndarray, nodes: RankNodes) -> OffWallEdges:
    """The off-wall edges of one rank's local mesh as the owners of the wall nodes found them (the owner
    holds every cell around its node: the serial edge), gathered (a collective); ``node`` in global ids."""
    k = np.flatnonzero(nodes.owned[wall_ids])
    far = edges.node[k]
    gid = np.where(far >= 0, nodes.ids[np.maximum(far, 0)], -1)
    got = nodes.comm.allgather((k, gid, edges.height[k], edges.angle[k]))
    node = np.full(len(wall_ids), -1, np.int64)
    height, angle = np.zeros(len(wall_ids)), np.zeros(len(wall_ids))
    for kk, g, h, a in got:
        node[kk], height[kk], angle[kk] = g, h, a
    return OffWallEdges(node, height, angle, edges.spacing)


def _no_normal(normals: np.ndarray) -> np.ndarray:
    """(Ns,) True where a wall node has no normal (zero row: a sharp edge, a node on no face)."""
    return np.einsum("ij,ij->i", normals, normals) == 0


def layer_normals(position: np.ndarray, faces, planes: np.ndarray | None = None) -> np.ndarray:
    """(Ns, 3) the unit normals of a wall whose nodes are at ``position`` (Ns, 3) (the sums of its
    ``faces``' vector areas, :func:`ffdcli.geometry.surface.face_vectors`; blocks of rows of
    ``position``), a node on a plane (``planes``) with the mirror image's (:func:`in_plane`). On a kink
    (a deflected hinge) it is the mean of the two sides', as a mesh generator extrudes there."""
    summed = np.zeros((len(position), 3))
    for b in faces:
        v = face_vectors(position, [b])
        for c in range(3):
            summed[:, c] += np.bincount(b.data.ravel(), np.repeat(v[:, c], b.data.shape[1]), len(position))
    ln = np.linalg.norm(summed, axis=1)
    unit = np.where(ln[:, None] > 0, summed / np.where(ln > 0, ln, 1.0)[:, None], 0.0)
    return unit if planes is None else in_plane(unit, planes)


def nodes_within(tree: cKDTree, x: np.ndarray, nearest: np.ndarray, reach: float) -> np.ndarray:
    """The rows of ``x`` (n, 3) whose nearest wall node (at ``nearest`` (n,)) is within ``reach``, as the
    tree's own bounded search decides (it compares squared distances): the few at ``reach`` to
    rounding asked to it."""
    inside = nearest < reach
    edge = np.flatnonzero(np.abs(nearest - reach) <= 1e-9 * reach)
    if len(edge):
        inside[edge] = np.isfinite(tree.query(x[edge], distance_upper_bound=reach)[0])
    return np.flatnonzero(inside)


def _partition(d: np.ndarray, j: np.ndarray | None, k: int, ns: int) -> tuple[csr_matrix, np.ndarray]:
    """(n, ns) the normalised Franke-Little weights of each point's ``k`` nearest wall nodes (module
    docstring), from the distances ``d`` (n, k + 1) and the indices ``j`` (n, k + 1) of its ``k + 1``
    nearest, and (n,) the sums of their squares."""
    n = len(d)
    if k < 1:
        return csr_matrix((np.ones(n), (np.arange(n), np.zeros(n, np.int64))), shape=(n, ns)), np.ones(n)
    R = d[:, -1:]
    d, j = d[:, :-1], j[:, :-1]
    with np.errstate(divide="ignore", invalid="ignore"):
        psi = (np.maximum(R - d, 0.0) / (R * np.maximum(d, 1e-300))) ** 3
    bad = ~np.isfinite(psi).all(axis=1) | (psi.sum(axis=1) <= 0)
    psi[bad] = 0.0
    psi[bad, 0] = 1.0                   # on a wall node, or every neighbour as far: the nearest
    psi /= psi.sum(axis=1, keepdims=True)
    ptr = np.arange(0, n * k + 1, k)
    return csr_matrix((psi.ravel(), j.ravel(), ptr), shape=(n, ns)), np.einsum("ij,ij->i", psi, psi)
