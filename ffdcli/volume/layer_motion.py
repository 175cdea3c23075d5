"""The near-wall layer moves rigidly with its wall: the motion, blended into the warp's, and its exact
derivatives (forward and transpose).

A node of the layer (:mod:`ffdcli.volume.wall_layer`: weights ``psi_k`` of its nearest wall nodes,
blend weight ``s``) moves by

    d = (1 - s) d_warp + s sum_k psi_k [b_k + (G_k - I)(x - x_k)],

``b_k`` the wall node's translation and ``G_k`` its *surface frame*: ``G = F (I - n n^T) + n' n^T`` for
the frame ``F`` the warp is given (:func:`ffdcli.volume.frames.surface_frame_gradient`; ``n'`` the
deformed unit normal ``cof(F) n / |cof(F) n|``). ``G`` is the rotation of the wall's local frame
(the polar factor of G, which maps ``n`` to ``n'``) times the wall's own stretch along itself: it
never stretches along the normal. An off-wall edge ``h n + tau`` (``tau`` along the wall) goes to
``h n' + F tau``: its height over the deformed wall is ``h`` exactly (y+ kept) and it leans from the
new normal only as much as the wall's own stretch tilts its tangential part (a 0.3 degree edge, a 5 %
stretch: 0.015 degree). With ``volume.carry: rotation`` the frames are rotations and ``G = F``; with
``carry: gradient`` (the default) the warp beyond the layer keeps the FFD map's whole gradient. A wall
node on a sharp edge (zero normal in the layer) carries ``F`` itself: the wedge behind a sharp trailing
edge is one smooth map, as with ``carry: gradient``.

The motion is linear in (b, G) with the weights fixed on the undeformed mesh (a sparse matrix ``P``:
``sum_k psi_k [b_k - (G_k - I) x_k] + (sum_k psi_k (G_k - I)) x``), and ``G`` is a function of ``F``
node by node: its derivative in a direction ``(db, dF)`` at frames ``F`` is
``(1 - s) d_warp(db, dF) + s P [db + dG(F; dF) (x - x_k)]`` (:func:`blend_layer` with ``at``), the
transpose :func:`layer_transpose`. A frame equal to the identity gives ``G = I`` exactly, so a design
without changes writes the input back bit for bit.
"""

from __future__ import annotations

import numpy as np

from ffdcli.volume.frames import surface_frame_gradient, surface_frame_gradient_jvp
from ffdcli.volume.wall_layer import WallLayer

_EYE = np.eye(3)


def _frames(frames, ns: int) -> np.ndarray:
    if frames is None:
        return np.broadcast_to(_EYE, (ns, 3, 3))
    F = np.asarray(frames, dtype=np.float64)
    if F.shape != (ns, 3, 3):
        raise ValueError(f"surface frames must be ({ns}, 3, 3), got {F.shape}")
    return F


def _with_normal(normals: np.ndarray) -> np.ndarray:
    return np.einsum("ij,ij->i", normals, normals) > 0


def _planes(planes, ns: int) -> np.ndarray:
    return np.zeros((ns, 3)) if planes is None else planes


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


def _frame(F, n, p):
    """(G, R) (k, 3, 3) of nodes with unit normals n (k, 3) and plane normals p (k, 3; zero: no plane)."""
    Fs = surface_frame_gradient(F, n)
    n1 = np.einsum("kij,kj->ki", Fs, n)
    pn = n1 - p * np.einsum("ki,ki->k", p, n1)[:, None]
    n2 = pn / np.linalg.norm(pn, axis=1)[:, None]
    return Fs + (n2 - n1)[:, :, None] * n[:, None, :], _turn(n, n2)


def _frame_jvp(F, n, p, dF):
    """(dG, dR) of :func:`_frame` in the direction dF."""
    Fs = surface_frame_gradient(F, n)
    dFs = surface_frame_gradient_jvp(F, n, dF)
    n1 = np.einsum("kij,kj->ki", Fs, n)
    dn1 = np.einsum("kij,kj->ki", dFs, n)
    pn = n1 - p * np.einsum("ki,ki->k", p, n1)[:, None]
    dpn = dn1 - p * np.einsum("ki,ki->k", p, dn1)[:, None]
    q = np.linalg.norm(pn, axis=1)[:, None]
    n2 = pn / q
    dn2 = (dpn - n2 * np.einsum("ki,ki->k", n2, dpn)[:, None]) / q
    return dFs + (dn2 - dn1)[:, :, None] * n[:, None, :], _turn_jvp(n, n2, dn2)


def wall_frames(F: np.ndarray, normals: np.ndarray, planes: np.ndarray | None = None, *,
                turns: bool = False):
    """(Ns, 3, 3) each wall node's surface frame ``G`` (module docstring) for frames ``F`` (Ns, 3, 3) and
    unit ``normals`` (Ns, 3; a zero row: ``G = F``). ``G = I`` exactly where ``F`` is the identity.
    ``turns``: also return ``R`` (Ns, 3, 3), the least rotation taking ``n`` to ``G n`` (``F`` where
    there is no normal, ``I`` where ``F`` is).

    ``planes`` (Ns, 3): the unit normal ``p`` of the plane a wall node slides in (zero: none; the
    node's ``n`` then lies in the plane, :func:`ffdcli.volume.wall_layer.in_plane`). Its off-wall nodes
    slide in that plane too, while the one-sided deformed normal ``n'`` may leave it (a twist or a
    sweep that grows along the span tilts the root's wall). With the mirror image the plane stands for,
    the wall's normal at the root is the unit ``P n' / |P n'|`` (``P = I - p p^T``; for a map that keeps
    the plane, ``P cof(F) n`` has the direction of ``P cof(F) n_1`` for any one-sided normal ``n_1``
    whose projection is ``n``), and ``G`` maps ``n`` to it: the root's first cell keeps its height along
    the mirrored wall's normal, and its edge its angle to it."""
    G = np.array(F, dtype=np.float64, copy=True)
    R = G.copy()
    m = np.flatnonzero(_with_normal(normals) & np.any(G != _EYE, axis=(1, 2)))
    if len(m):
        G[m], R[m] = _frame(G[m], normals[m], _planes(planes, len(G))[m])
    return (G, R) if turns else G


def wall_frames_jvp(F: np.ndarray, normals: np.ndarray, dF: np.ndarray, planes: np.ndarray | None = None, *,
                    turns: bool = False):
    """(Ns, 3, 3) ``dG`` (and ``dR`` with ``turns``): the derivative of :func:`wall_frames` at ``F`` in the
    direction ``dF``."""
    dG = np.array(dF, dtype=np.float64, copy=True)
    dR = dG.copy()
    m = np.flatnonzero(_with_normal(normals))
    if len(m):
        dG[m], dR[m] = _frame_jvp(F[m], normals[m], _planes(planes, len(dG))[m], dF[m])
    return (dG, dR) if turns else dG


def wall_frames_vjp(F: np.ndarray, normals: np.ndarray, gG: np.ndarray, planes: np.ndarray | None = None,
                    gR: np.ndarray | None = None) -> np.ndarray:
    """(Ns, 3, 3) ``gF``: the transpose of :func:`wall_frames_jvp` applied to ``gG`` (Ns, 3, 3) and ``gR``
    (the turns' cotangent; None: zero) (each node's 9 x 9 Jacobians from nine forward products)."""
    out = np.array(gG, dtype=np.float64, copy=True)
    if gR is not None:
        out += gR
    m = np.flatnonzero(_with_normal(normals))
    k = len(m)
    if not k:
        return out
    basis = np.eye(9).reshape(9, 3, 3)
    Fm = np.broadcast_to(F[m][None], (9, k, 3, 3)).reshape(-1, 3, 3)
    nm = np.broadcast_to(normals[m][None], (9, k, 3)).reshape(-1, 3)
    pm = np.broadcast_to(_planes(planes, len(out))[m][None], (9, k, 3)).reshape(-1, 3)
    dF = np.broadcast_to(basis[:, None], (9, k, 3, 3)).reshape(-1, 3, 3)
    JG, JR = _frame_jvp(Fm, nm, pm, dF)           # J[a, node, :] = vec dG(E_a)
    out[m] = np.einsum("ank,nk->na", JG.reshape(9, k, 9), gG[m].reshape(k, 9)).reshape(k, 3, 3)
    if gR is not None:
        out[m] += np.einsum("ank,nk->na", JR.reshape(9, k, 9), gR[m].reshape(k, 9)).reshape(k, 3, 3)
    return out


def _rigid(layer: WallLayer, b: np.ndarray, M: np.ndarray, sel: np.ndarray | None = None) -> np.ndarray:
    """(n, 3) ``sum_k psi_k [b_k + M_k (x - x_k)]`` of the layer's rows ``sel`` (default all)."""
    P = layer.partition if sel is None else layer.partition[sel]
    x = layer.position if sel is None else layer.position[sel]
    c = b - np.einsum("nij,nj->ni", M, layer.wall_position)
    Mx = (P @ M.reshape(-1, 9)).reshape(-1, 3, 3)
    return P @ c + np.einsum("nij,nj->ni", Mx, x)


def blend_layer(layer: WallLayer | None, d: np.ndarray, b: np.ndarray, frames, lo: int, hi: int, *, at=None
                ) -> np.ndarray:
    """Blend the layer's rigid motion into the warp's displacements ``d`` (hi - lo, 3) of the target
    rows ``lo:hi`` (in place; returned). ``b`` (Ns, 3) the surface translations, ``frames`` (Ns, 3, 3) or
    None (identity) the frames given to the warp. ``at``: the frames (Ns, 3, 3) at which the layer is
    linearised (then ``frames - I`` is a direction ``dF`` and ``b`` a ``db``: the forward derivative)."""
    if layer is None or not len(layer.rows):
        return d
    sel = np.flatnonzero((layer.rows >= lo) & (layer.rows < hi))
    if not len(sel):
        return d
    ns = len(layer.normals)
    F = _frames(frames, ns)
    if at is None:
        G, R = wall_frames(F, layer.normals, layer.planes, turns=True)
        M, T = G - _EYE, R - G                      # T: the turn's difference from the frame
    else:
        M, dR = wall_frames_jvp(_frames(at, ns), layer.normals, F - _EYE, layer.planes, turns=True)
        T = dR - M
    rows, s = layer.rows[sel] - lo, layer.weight[sel][:, None]
    rigid = _rigid(layer, np.asarray(b, dtype=np.float64), M, sel)
    if layer.stacked is not None:                   # a stack's lean turns with its wall, unstretched
        rigid += layer.stacked[sel][:, None] * _rigid(layer, np.zeros((ns, 3)), T, sel)
    d[rows] = (1.0 - s) * d[rows] + s * rigid
    return d


def layer_transpose(layer: WallLayer, gt: np.ndarray, at) -> tuple[np.ndarray, np.ndarray]:
    """The transpose of :func:`blend_layer`'s derivative at frames ``at`` (Ns, 3, 3; None: identity).

    ``gt`` (Nt, 3): dJ/d(displacement) of every target (after the sliding projections' transpose); it is
    scaled in place by ``1 - s`` on the layer's rows (what goes on to the warp's transpose). Returns
    the layer's own ``(dJ/db (Ns, 3), dJ/dF (Ns, 3, 3))``."""
    ns = len(layer.normals)
    rows, s = layer.rows, layer.weight[:, None]
    gs = s * gt[rows]
    gt[rows] *= 1.0 - s
    PT = layer.partition.T.tocsr()
    g_b = PT @ gs
    g_M = _rigid_transpose(layer, PT, gs, g_b)
    if layer.stacked is None:
        return g_b, wall_frames_vjp(_frames(at, ns), layer.normals, g_M, layer.planes)
    g_T = _rigid_transpose(layer, PT, layer.stacked[:, None] * gs)
    return g_b, wall_frames_vjp(_frames(at, ns), layer.normals, g_M - g_T, layer.planes, g_T)


def _rigid_transpose(layer: WallLayer, PT, g: np.ndarray, g_b: np.ndarray | None = None) -> np.ndarray:
    """(Ns, 3, 3) the transpose of :func:`_rigid` in ``M`` applied to ``g`` (n, 3); ``g_b``: ``PT @ g``."""
    ns = PT.shape[0]
    g_b = PT @ g if g_b is None else g_b
    g_M = (PT @ (g[:, :, None] * layer.position[:, None, :]).reshape(-1, 9)).reshape(ns, 3, 3)
    g_M -= g_b[:, :, None] * layer.wall_position[:, None, :]
    return g_M
