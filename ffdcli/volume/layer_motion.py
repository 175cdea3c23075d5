"""The near-wall layer moves rigidly with its wall: the motion, blended into the warp's, and its exact
derivatives (forward and transpose).

A node of the layer (:mod:`ffdcli.volume.wall_layer`: weights ``psi_k`` of its nearest wall nodes,
blend weight ``s``, stack share ``w``) moves by

    d = (1 - s) d_warp + s sum_k psi_k [b_k + ((1 - w) G_k + w R_k - I)(x - x_k)],

``b_k`` the wall node's translation, ``G_k = F (I - n n^T) + n' n^T`` its frame: ``F`` the frame the
warp is given along the wall (the wall's own stretch), ``n'`` the unit normal of the *deformed wall*
at the node (:func:`deformed_normals`: the moved wall faces' vector areas, a root's projected into its
symmetry plane), not ``cof(F) n`` (one-sided at a hinge, unresolved across a device's transition).
``R_k`` the least rotation taking ``n`` to ``n'``. An off-wall edge ``h n + tau`` (``tau`` along the
wall) of a node on one stack (``w = 1``) goes to ``h n' + R tau``: its height over the deformed wall
is ``h`` and its angle to the normal the same (y+ and the stack's lean kept); between stacks
(``w -> 0``) it goes to ``h n' + F tau``, following the wall's stretch (an affine map kept affine).
A wall node on a sharp edge (zero normal in the layer) carries ``F`` itself: the wedge behind a sharp
trailing edge is one smooth map, as with ``carry: gradient``.

The motion is linear in (b, G, R) with the weights fixed on the undeformed mesh (a sparse matrix
``P``: ``sum_k psi_k [b_k - M_k x_k] + (sum_k psi_k M_k) x``), ``G`` linear in ``F`` and both
``G`` and ``R`` functions of ``n'``, itself a function of ``b``: the derivative in a direction
``(db, dF)`` at ``(b, F)`` is :func:`blend_layer` with ``at=(b, F)``, the transpose
:func:`layer_transpose` (``dn'`` through :func:`deformed_normals_jvp` / :func:`deformed_normals_vjp`).
A frame equal to the identity and an unmoved wall give ``G = R = I`` exactly, so a design without
changes writes the input back bit for bit.
"""

from __future__ import annotations

import numpy as np

from ffdcli.geometry.surface import face_vectors
from ffdcli.mesh import CellBlock
from ffdcli.volume.wall_layer import WallLayer, layer_normals

_EYE = np.eye(3)
#: A wall node whose deformed normal is within this of the reverse of its normal (cos > 1 - FLIPPED) has
#: turned over: no least rotation, R is G there.
FLIPPED = 1e-6


def _frames(frames, ns: int) -> np.ndarray:
    if frames is None:
        return np.broadcast_to(_EYE, (ns, 3, 3))
    F = np.asarray(frames, dtype=np.float64)
    if F.shape != (ns, 3, 3):
        raise ValueError(f"surface frames must be ({ns}, 3, 3), got {F.shape}")
    return F


def _with_normal(normals: np.ndarray) -> np.ndarray:
    return np.einsum("ij,ij->i", normals, normals) > 0


def _cross_matrix(v):
    """(k, 3, 3) [v]x of (k, 3) vectors."""
    out = np.zeros(v.shape[:-1] + (3, 3))
    out[..., 0, 1], out[..., 0, 2], out[..., 1, 2] = -v[..., 2], v[..., 1], -v[..., 0]
    out[..., 1, 0], out[..., 2, 0], out[..., 2, 1] = v[..., 2], -v[..., 1], v[..., 0]
    return out


def _turn(n, n2):
    """(k, 3, 3) the least rotation taking unit n to unit n2 (Rodrigues: c I + [v]x + v v^T / (1 + c))."""
    v = np.cross(n, n2)
    c = np.einsum("ki,ki->k", n, n2)[:, None, None]
    return c * _EYE + _cross_matrix(v) + v[:, :, None] * v[:, None, :] / (1.0 + c)


def _turn_jvp(n, n2, dn2):
    v, dv = np.cross(n, n2), np.cross(n, dn2)
    c = np.einsum("ki,ki->k", n, n2)[:, None, None]
    dc = np.einsum("ki,ki->k", n, dn2)[:, None, None]
    vv = v[:, :, None] * v[:, None, :]
    dvv = dv[:, :, None] * v[:, None, :] + v[:, :, None] * dv[:, None, :]
    return dc * _EYE + _cross_matrix(dv) + dvv / (1.0 + c) - vv * dc / (1.0 + c) ** 2


def _flipped(n, n2):
    """(k,) True where the wall has turned over (n2 nearly -n: a design that folds the wall), where the
    least rotation is not defined: there R is G."""
    return np.einsum("ki,ki->k", n, n2) < FLIPPED - 1.0


def _frame(F, n, n2):
    """(G, R) (k, 3, 3): ``F (I - n n^T) + n2 n^T`` and the least rotation taking n to n2."""
    G = F - np.einsum("kij,kj->ki", F, n)[:, :, None] * n[:, None, :] + n2[:, :, None] * n[:, None, :]
    flip = _flipped(n, n2)
    R = _turn(n, np.where(flip[:, None], n, n2))
    R[flip] = G[flip]
    return G, R


def _frame_jvp(n, n2, dF, dn2):
    """(dG, dR) of :func:`_frame` in the direction (dF, dn2)."""
    dG = dF - np.einsum("kij,kj->ki", dF, n)[:, :, None] * n[:, None, :] + dn2[:, :, None] * n[:, None, :]
    flip = _flipped(n, n2)
    dR = _turn_jvp(n, np.where(flip[:, None], n, n2), dn2)
    dR[flip] = dG[flip]
    return dG, dR


def wall_frames(F: np.ndarray, normals: np.ndarray, new_normals: np.ndarray, *, turns: bool = False):
    """(Ns, 3, 3) each wall node's frame ``G = F (I - n n^T) + n' n^T`` (module docstring) for frames ``F``
    (Ns, 3, 3), unit ``normals`` ``n`` (Ns, 3; a zero row: ``G = F``) and the deformed wall's unit
    normals ``n'`` (:func:`deformed_normals`). ``G = I`` exactly where ``F`` is the identity and ``n' = n``.
    ``turns``: also return ``R`` (Ns, 3, 3), the least rotation taking ``n`` to ``n'`` (``F`` where
    there is no normal, ``I`` where ``G`` is)."""
    G = np.array(F, dtype=np.float64, copy=True)
    R = G.copy()
    moved = np.any(G != _EYE, axis=(1, 2)) | np.any(new_normals != normals, axis=1)
    m = np.flatnonzero(_with_normal(normals) & moved)
    if len(m):
        G[m], R[m] = _frame(G[m], normals[m], new_normals[m])
    return (G, R) if turns else G


def wall_frames_jvp(normals: np.ndarray, new_normals: np.ndarray, dF: np.ndarray, dn2: np.ndarray, *,
                    turns: bool = False):
    """(Ns, 3, 3) ``dG`` (and ``dR`` with ``turns``): the derivative of :func:`wall_frames` in the direction
    ``(dF, dn')`` (it is linear in ``F``: the point enters through ``n'`` only)."""
    dG = np.array(dF, dtype=np.float64, copy=True)
    dR = dG.copy()
    m = np.flatnonzero(_with_normal(normals))
    if len(m):
        dG[m], dR[m] = _frame_jvp(normals[m], new_normals[m], dF[m], dn2[m])
    return (dG, dR) if turns else dG


def wall_frames_vjp(normals: np.ndarray, new_normals: np.ndarray, gG: np.ndarray, gR: np.ndarray | None = None
                    ) -> tuple[np.ndarray, np.ndarray]:
    """The transpose of :func:`wall_frames_jvp`: ``(gF (Ns, 3, 3), gn' (Ns, 3))`` of ``gG`` and ``gR``
    (Ns, 3, 3; None: zero)."""
    gF = np.array(gG, dtype=np.float64, copy=True)
    if gR is not None:
        gF += gR
    gn = np.zeros((len(gF), 3))
    m = np.flatnonzero(_with_normal(normals))
    if not len(m):
        return gF, gn
    n, n2 = normals[m], new_normals[m]
    gm = gG[m]
    gF[m] = gm - np.einsum("kij,kj->ki", gm, n)[:, :, None] * n[:, None, :]
    gn[m] = np.einsum("kij,kj->ki", gm, n)
    if gR is not None:
        flip = _flipped(n, n2)
        safe = np.where(flip[:, None], n, n2)
        for a in range(3):              # three forward products of the turn
            e = np.zeros_like(n2)
            e[:, a] = 1.0
            gn[m, a] += np.einsum("kij,kij->k", _turn_jvp(n, safe, e), gR[m]) * ~flip
        fl = m[flip]                    # a turned-over wall: R is G
        if len(fl):
            gF[fl] += gR[fl] - np.einsum("kij,kj->ki", gR[fl], normals[fl])[:, :, None] * normals[fl][:, None, :]
            gn[fl] += np.einsum("kij,kj->ki", gR[fl], normals[fl])
    return gF, gn


def deformed_normals(layer: WallLayer, b: np.ndarray) -> np.ndarray:
    """(Ns, 3) the unit normals of the wall moved by ``b`` (Ns, 3) (:func:`ffdcli.volume.wall_layer.layer_normals`)."""
    return layer_normals(layer.wall_position + b, layer.faces, layer.planes)


def _normal_parts(layer: WallLayer, b: np.ndarray):
    pos = layer.wall_position + b
    summed = np.zeros((len(pos), 3))
    for blk in layer.faces:
        v = face_vectors(pos, [blk])
        for c in range(3):
            summed[:, c] += np.bincount(blk.data.ravel(), np.repeat(v[:, c], blk.data.shape[1]), len(pos))
    ln = np.linalg.norm(summed, axis=1)
    u = summed / np.where(ln > 0, ln, 1.0)[:, None]
    p = np.zeros((len(pos), 3)) if layer.planes is None else layer.planes
    pu = u - p * np.einsum("ij,ij->i", p, u)[:, None]
    q = np.linalg.norm(pu, axis=1)
    return pos, u, np.where(ln > 0, ln, 1.0), p, pu / np.where(q > 0, q, 1.0)[:, None], np.where(q > 0, q, 1.0)


def _face_pairs(blk: CellBlock):
    """Each face's vector area as ``scale * (u x v)`` (lines: a turn of u): (columns of u: +, -; of v: +, -)."""
    if blk.type == "triangle":
        return (1, 0), (2, 0)
    if blk.type == "quad":
        return (2, 0), (3, 1)
    return (1, 0), None


def _line_turn(t):
    v = np.zeros_like(t)
    v[:, 0], v[:, 1] = t[:, 1], -t[:, 0]
    return v


def deformed_normals_jvp(layer: WallLayer, b: np.ndarray, db: np.ndarray) -> np.ndarray:
    """(Ns, 3) the derivative of :func:`deformed_normals` at ``b`` in the direction ``db``."""
    pos, u, ln, p, n2, q = _normal_parts(layer, b)
    dS = np.zeros_like(pos)
    for blk in layer.faces:
        (a1, a0), vv = _face_pairs(blk)
        d = blk.data
        du = db[d[:, a1]] - db[d[:, a0]]
        if vv is None:
            dv = _line_turn(du)
        else:
            uu = pos[d[:, a1]] - pos[d[:, a0]]
            w = pos[d[:, vv[0]]] - pos[d[:, vv[1]]]
            dw = db[d[:, vv[0]]] - db[d[:, vv[1]]]
            dv = 0.5 * (np.cross(du, w) + np.cross(uu, dw))
        for c in range(3):
            dS[:, c] += np.bincount(d.ravel(), np.repeat(dv[:, c], d.shape[1]), len(pos))
    du = (dS - u * np.einsum("ij,ij->i", u, dS)[:, None]) / ln[:, None]
    dpu = du - p * np.einsum("ij,ij->i", p, du)[:, None]
    return (dpu - n2 * np.einsum("ij,ij->i", n2, dpu)[:, None]) / q[:, None]


def deformed_normals_vjp(layer: WallLayer, b: np.ndarray, g: np.ndarray) -> np.ndarray:
    """(Ns, 3) the transpose of :func:`deformed_normals_jvp` applied to ``g`` (Ns, 3)."""
    pos, u, ln, p, n2, q = _normal_parts(layer, b)
    g = (g - n2 * np.einsum("ij,ij->i", n2, g)[:, None]) / q[:, None]
    g = g - p * np.einsum("ij,ij->i", p, g)[:, None]
    gS = (g - u * np.einsum("ij,ij->i", u, g)[:, None]) / ln[:, None]
    out = np.zeros_like(pos)
    for blk in layer.faces:
        (a1, a0), vv = _face_pairs(blk)
        d = blk.data
        gf = gS[d].sum(axis=1)                          # (F, 3): each face's cotangent
        if vv is None:
            gu = -_line_turn(gf)                        # the turn's transpose is minus itself
            gw = None
        else:
            uu = pos[d[:, a1]] - pos[d[:, a0]]
            w = pos[d[:, vv[0]]] - pos[d[:, vv[1]]]
            gu = 0.5 * np.cross(w, gf)
            gw = 0.5 * np.cross(gf, uu)
        pairs = [(a1, gu), (a0, -gu)] + ([] if gw is None else [(vv[0], gw), (vv[1], -gw)])
        for col, val in pairs:
            for c in range(3):
                out[:, c] += np.bincount(d[:, col], val[:, c], len(pos))
    return out


def _rigid(layer: WallLayer, b: np.ndarray, M: np.ndarray, sel: np.ndarray | None = None,
           T: np.ndarray | None = None) -> np.ndarray:
    """(n, 3) ``sum_k psi_k [b_k + M_k (x - x_k)]`` of the layer's rows ``sel`` (default all); with ``T``
    (Ns, 3, 3) plus ``w sum_k psi_k T_k (x - x_k)``, ``w`` the rows' ``stacked`` share (one product with
    the partition for both)."""
    P = layer.partition if sel is None else layer.partition[sel]
    x = layer.position if sel is None else layer.position[sel]
    parts = [b - np.einsum("nij,nj->ni", M, layer.wall_position), M.reshape(-1, 9)]
    if T is not None:
        parts += [-np.einsum("nij,nj->ni", T, layer.wall_position), T.reshape(-1, 9)]
    got = P @ np.hstack(parts)
    out = got[:, :3] + np.einsum("nij,nj->ni", got[:, 3:12].reshape(-1, 3, 3), x)
    if T is not None:
        w = layer.stacked if sel is None else layer.stacked[sel]
        out += w[:, None] * (got[:, 12:15] + np.einsum("nij,nj->ni", got[:, 15:].reshape(-1, 3, 3), x))
    return out


def _point(at, b, ns: int):
    """(b0, F0) of ``at``: the surface translations and frames the layer is linearised at."""
    if at is None:
        return np.zeros((ns, 3)), _frames(None, ns)
    if isinstance(at, tuple) and at[0] is not None and np.shape(at[0]) == (ns, 3):
        return np.asarray(at[0], dtype=np.float64), _frames(at[1], ns)
    raise ValueError("the wall layer's derivative needs at=(surface translations, frames) of the point: "
                     "its normals are the deformed wall's")


def warped_rows(layer: WallLayer | None, lo: int, hi: int) -> np.ndarray | None:
    """(k,) the target rows ``lo:hi`` (relative to ``lo``) whose warp displacement :func:`blend_layer` keeps
    some of: all but the layer's rows of weight 1 (the warp's there is multiplied by ``1 - s = 0``: it
    need not be computed); None when that is all of them."""
    if layer is None or not len(layer.rows):
        return None
    whole = layer.rows[(layer.weight == 1.0) & (layer.rows >= lo) & (layer.rows < hi)] - lo
    if not len(whole):
        return None
    keep = np.ones(hi - lo, bool)
    keep[whole] = False
    return np.flatnonzero(keep)


def blend_layer(layer: WallLayer | None, d: np.ndarray, b: np.ndarray, frames, lo: int, hi: int, *, at=None
                ) -> np.ndarray:
    """Blend the layer's rigid motion into the warp's displacements ``d`` (hi - lo, 3) of the target
    rows ``lo:hi`` (in place; returned). ``b`` (Ns, 3) the surface translations, ``frames`` (Ns, 3, 3) or
    None (identity) the frames given to the warp. ``at``: ``(b0, F0)`` at which the layer is linearised
    (then ``frames - I`` is a direction ``dF`` and ``b`` a ``db``: the forward derivative)."""
    if layer is None or not len(layer.rows):
        return d
    sel = np.flatnonzero((layer.rows >= lo) & (layer.rows < hi))
    if not len(sel):
        return d
    ns = len(layer.normals)
    F = _frames(frames, ns)
    b = np.asarray(b, dtype=np.float64)
    if at is None:
        G, R = wall_frames(F, layer.normals, deformed_normals(layer, b), turns=True)
        M, T = G - _EYE, R - G                      # T: the turn's difference from the frame
    else:
        b0, _ = _point(at, b, ns)
        n2 = deformed_normals(layer, b0)
        M, dR = wall_frames_jvp(layer.normals, n2, F - _EYE, deformed_normals_jvp(layer, b0, b), turns=True)
        T = dR - M
    every = len(sel) == len(layer.rows)              # serially: every row, no copies of the weights
    rows, s = layer.rows[sel] - lo, layer.weight[sel][:, None]
    # a stack's lean turns with its wall, unstretched (the stacked share of T)
    rigid = _rigid(layer, b, M, None if every else sel, None if layer.stacked is None else T)
    d[rows] = (1.0 - s) * d[rows] + s * rigid
    return d


def layer_transpose(layer: WallLayer, gt: np.ndarray, at) -> tuple[np.ndarray, np.ndarray]:
    """The transpose of :func:`blend_layer`'s derivative at ``at`` = ``(b0, F0)`` (None: the undeformed wall).

    ``gt`` (Nt, 3): dJ/d(displacement) of every target (after the sliding projections' transpose); it is
    scaled in place by ``1 - s`` on the layer's rows (what goes on to the warp's transpose). Returns
    the layer's own ``(dJ/db (Ns, 3), dJ/dF (Ns, 3, 3))``."""
    ns = len(layer.normals)
    b0, _ = _point(at, None, ns)
    rows, s = layer.rows, layer.weight[:, None]
    gs = s * gt[rows]
    gt[rows] *= 1.0 - s
    PT = layer.partition.T.tocsr()
    g_b = PT @ gs
    g_M = _rigid_transpose(layer, PT, gs, g_b)
    n2 = deformed_normals(layer, b0)
    if layer.stacked is None:
        g_F, g_n = wall_frames_vjp(layer.normals, n2, g_M)
    else:
        g_T = _rigid_transpose(layer, PT, layer.stacked[:, None] * gs)
        g_F, g_n = wall_frames_vjp(layer.normals, n2, g_M - g_T, g_T)
    return g_b + deformed_normals_vjp(layer, b0, g_n), g_F


def _rigid_transpose(layer: WallLayer, PT, g: np.ndarray, g_b: np.ndarray | None = None) -> np.ndarray:
    """(Ns, 3, 3) the transpose of :func:`_rigid` in ``M`` applied to ``g`` (n, 3); ``g_b``: ``PT @ g``."""
    ns = PT.shape[0]
    g_b = PT @ g if g_b is None else g_b
    g_M = (PT @ (g[:, :, None] * layer.position[:, None, :]).reshape(-1, 9)).reshape(ns, 3, 3)
    g_M -= g_b[:, :, None] * layer.wall_position[:, None, :]
    return g_M
