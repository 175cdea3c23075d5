"""The near-wall layer moves rigidly with its wall: the motion, blended into the warp's, and its exact
derivatives (forward and transpose).

A node of the layer (:mod:`ffdcli.volume.wall_layer`: wall point ``w``, undeformed offset
``e = x - x_w``, weight ``s``) moves by

    d = (1 - s) d_warp + s [b_w + (Q_w - I) e],

``b_w`` the wall point's translation and ``Q_w`` the rotation of the wall's local frame: the polar
rotation of the surface frame gradient ``F_s = F (I - n n^T) + n' n^T`` of the frame ``F`` the warp is
given (:mod:`ffdcli.volume.frames`; ``n'`` the deformed unit normal). ``Q n = n'``: an off-wall edge
keeps its length and its angle to the wall, so the first-cell height and the wall orthogonality are
those of the input (y+ kept). With ``volume.carry: rotation`` the frames are rotations already and
``Q = F``; with ``carry: gradient`` (the default) the warp beyond the layer keeps the FFD map's
gradient (the cells at a sharp trailing edge), and the layer drops only its stretch.

``Q`` is a nonlinear function of ``F``: the layer motion is linear in (b, Q) with the assignment
fixed on the undeformed mesh, and its derivative in a direction ``(db, dF)`` at frames ``F`` is
``(1 - s) d_warp(db, dF) + s [db_w + dQ_w(F; dF) e]`` (:func:`blend_layer` with ``at``), the transpose
of which is :func:`layer_transpose`. A frame equal to the identity (a design that does not move the
surface there) gives ``Q = I`` exactly, so a design without changes writes the input back bit for bit.
"""

from __future__ import annotations

import numpy as np

from ffdcli.volume.frames import (
    polar_rotation_derivative,
    rotations_from_deformation_gradient,
    surface_frame_gradient,
    surface_frame_gradient_jvp,
)
from ffdcli.volume.wall_layer import WallLayer

_EYE = np.eye(3)


def _frames(frames, ns: int) -> np.ndarray:
    if frames is None:
        return np.broadcast_to(_EYE, (ns, 3, 3))
    F = np.asarray(frames, dtype=np.float64)
    if F.shape != (ns, 3, 3):
        raise ValueError(f"surface frames must be ({ns}, 3, 3), got {F.shape}")
    return F


def _moving(F: np.ndarray, normals: np.ndarray, nodes: np.ndarray) -> np.ndarray:
    """The rows of ``nodes`` whose frame is not the identity and whose normal is defined."""
    Fn = F[nodes]
    return nodes[np.any(Fn != _EYE, axis=(1, 2)) & (np.einsum("ij,ij->i", normals[nodes], normals[nodes]) > 0)]


def wall_rotations(F: np.ndarray, normals: np.ndarray, nodes: np.ndarray | None = None) -> np.ndarray:
    """(Ns, 3, 3) the rotation ``Q`` of each wall node's local frame under its frame ``F`` (Ns, 3, 3),
    for unit ``normals`` (Ns, 3); computed at ``nodes`` only (default every one), identity elsewhere
    and where ``F`` is the identity."""
    ns = len(normals)
    Q = np.broadcast_to(_EYE, (ns, 3, 3)).copy()
    nodes = np.arange(ns) if nodes is None else nodes
    m = _moving(F, normals, nodes)
    if len(m):
        Q[m] = rotations_from_deformation_gradient(surface_frame_gradient(F[m], normals[m]))
    return Q


def wall_rotations_jvp(F: np.ndarray, normals: np.ndarray, dF: np.ndarray, nodes: np.ndarray | None = None
                       ) -> np.ndarray:
    """(Ns, 3, 3) ``dQ``: the derivative of :func:`wall_rotations` at ``F`` in the direction ``dF``."""
    ns = len(normals)
    out = np.zeros((ns, 3, 3))
    nodes = np.arange(ns) if nodes is None else nodes
    m = nodes[np.einsum("ij,ij->i", normals[nodes], normals[nodes]) > 0]
    if len(m):
        out[m] = _rotation_jvp(F[m], normals[m], dF[m])
    return out


def _rotation_jvp(F, n0, dF):
    Fs = surface_frame_gradient(F, n0)
    Q = rotations_from_deformation_gradient(Fs)
    return polar_rotation_derivative(Fs, Q, surface_frame_gradient_jvp(F, n0, dF))


def wall_rotations_vjp(F: np.ndarray, normals: np.ndarray, gQ: np.ndarray, nodes: np.ndarray | None = None
                       ) -> np.ndarray:
    """(Ns, 3, 3) ``gF``: the transpose of :func:`wall_rotations_jvp` applied to ``gQ`` (Ns, 3, 3)
    (each node's 9 x 9 Jacobian from nine forward products)."""
    ns = len(normals)
    out = np.zeros((ns, 3, 3))
    nodes = np.arange(ns) if nodes is None else nodes
    m = nodes[np.einsum("ij,ij->i", normals[nodes], normals[nodes]) > 0]
    if not len(m):
        return out
    k = len(m)
    basis = np.eye(9).reshape(9, 3, 3)
    Fm = np.repeat(F[m][None], 9, axis=0).reshape(-1, 3, 3)
    nm = np.repeat(normals[m][None], 9, axis=0).reshape(-1, 3)
    dF = np.repeat(basis[:, None], k, axis=1).reshape(-1, 3, 3)
    J = _rotation_jvp(Fm, nm, dF).reshape(9, k, 9)         # J[a, node, :] = vec dQ(E_a)
    out[m] = np.einsum("ank,nk->na", J, gQ[m].reshape(k, 9)).reshape(k, 3, 3)
    return out


def blend_layer(layer: WallLayer, d: np.ndarray, b: np.ndarray, frames, lo: int, hi: int, *, at=None
                ) -> np.ndarray:
    """Blend the layer's rigid motion into the warp's displacements ``d`` (hi - lo, 3) of the target
    rows ``lo:hi`` (in place; returned). ``b`` (Ns, 3) the surface translations, ``frames`` (Ns, 3, 3) or
    None (identity) the frames given to the warp. ``at``: the frames (Ns, 3, 3) at which the layer is
    linearised (then ``frames - I`` is a direction ``dF`` and ``b`` a ``db``: the forward derivative)."""
    if layer is None or not len(layer.rows):
        return d
    mine = (layer.rows >= lo) & (layer.rows < hi)
    if not mine.any():
        return d
    rows, w, e, s = layer.rows[mine] - lo, layer.wall[mine], layer.offset[mine], layer.weight[mine]
    ns = len(layer.normals)
    F = _frames(frames, ns)
    nodes = np.unique(w)
    if at is None:
        M = wall_rotations(F, layer.normals, nodes) - _EYE
    else:
        M = wall_rotations_jvp(_frames(at, ns), layer.normals, F - _EYE, nodes)
    rigid = b[w] + np.einsum("nij,nj->ni", M[w], e)
    d[rows] = (1.0 - s)[:, None] * d[rows] + s[:, None] * rigid
    return d


def layer_transpose(layer: WallLayer, gt: np.ndarray, at) -> tuple[np.ndarray, np.ndarray]:
    """The transpose of :func:`blend_layer`'s derivative at frames ``at`` (Ns, 3, 3; None: identity).

    ``gt`` (Nt, 3): dJ/d(displacement) of every target (after the sliding projections' transpose); it is
    scaled in place by ``1 - s`` on the layer's rows (what goes on to the warp's transpose). Returns
    the layer's own ``(dJ/db (Ns, 3), dJ/dF (Ns, 3, 3))``."""
    ns = len(layer.normals)
    g_b = np.zeros((ns, 3))
    g_F = np.zeros((ns, 3, 3))
    if layer is None or not len(layer.rows):
        return g_b, g_F
    rows, w, e, s = layer.rows, layer.wall, layer.offset, layer.weight
    gs = s[:, None] * gt[rows]
    gt[rows] *= (1.0 - s)[:, None]
    for c in range(3):
        g_b[:, c] = np.bincount(w, gs[:, c], ns)
    gQ = np.zeros((ns, 9))
    outer = (gs[:, :, None] * e[:, None, :]).reshape(-1, 9)
    for c in range(9):
        gQ[:, c] = np.bincount(w, outer[:, c], ns)
    nodes = np.unique(w)
    g_F = wall_rotations_vjp(_frames(at, ns), layer.normals, gQ.reshape(ns, 3, 3), nodes)
    return g_b, g_F
