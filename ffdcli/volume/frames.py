"""The local rotation of the wing surface under the FFD map, for the volume-mesh warp.

The FFD map's deformation gradient at a surface point is ``F = J(P') J(P0)^-1`` (J: the lattice's
parametric Jacobian at the point's (u, v, w)). Its action on the *tangent plane* of the surface is
what moves the wing; its action across the surface (the thickness column of the lattice) is not
seen by the wing at all, and a shape change that moves the lattice rows unevenly can fold it (a
NACA0012 -> S1223 fit gives polar rotations of 144 degrees at the trailing edge while the surface
itself turns by a few degrees). So the rotation handed to the warp is that of the surface frame:

    F_s = F (I - n0 n0^T) + n1 n0^T,    n1 = cof(F) n0 / |cof(F) n0|,

F on the tangent plane, the unit normal n0 mapped to the deformed unit normal n1 (which depends only
on F's tangential part: cof(F)(t1 x t2) = F t1 x F t2; in 2D n1 = rot90(F t) / |F t|), and the
rotation is the polar factor of F_s. Its derivative in a direction dF is

    dF_s = dF (I - n0 n0^T) + dn1 n0^T,   dn1 = (I - n1 n1^T) dw / |w|,

with w = F t1 x F t2 (dw = dF t1 x F t2 + F t1 x dF t2), or w = rot90(F t) in 2D.

This module is the one home of the rotation math (array functions, stacks of matrices):
:func:`surface_frame_gradient` and its derivative, the polar rotation
(:func:`rotations_from_deformation_gradient`, 3D by SVD, 2D in closed form) and its derivative
(:func:`polar_rotation_derivative`: ``dR = R Omega``, Omega skew solving
``Omega U + U Omega = R^T dF - dF^T R`` with ``U = R^T F``, i.e. ``(tr(U) I - U) omega =
axial(R^T dF - dF^T R)``; :func:`planar_rotation_derivative` for the 2D angle).
"""

from __future__ import annotations

import numpy as np


def _tangents(n0: np.ndarray):
    """Orthonormal t1, t2 (S, 3) with t1 x t2 = n0 (unit normals (S, 3))."""
    a = np.where(np.abs(n0[:, [0]]) < 0.9, np.array([[1.0, 0, 0]]), np.array([[0, 1.0, 0]]))
    t1 = np.cross(a, n0)
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    t2 = np.cross(n0, t1)
    return t1, t2


def _rot90(v: np.ndarray) -> np.ndarray:
    return np.stack([-v[..., 1], v[..., 0]], axis=-1)


def surface_frame_gradient(F: np.ndarray, n0: np.ndarray) -> np.ndarray:
    """F_s (S, d, d) for deformation gradients F (S, d, d) and unit normals n0 (S, d), d = 2 or 3."""
    F = np.asarray(F, dtype=np.float64)
    n0 = np.asarray(n0, dtype=np.float64)
    n1, _ = _deformed_normal(F, n0)
    Pn = np.eye(F.shape[-1]) - n0[:, :, None] * n0[:, None, :]
    return F @ Pn + n1[:, :, None] * n0[:, None, :]


def _deformed_normal(F, n0):
    if F.shape[-1] == 3:
        t1, t2 = _tangents(n0)
        w = np.cross(np.einsum("sij,sj->si", F, t1), np.einsum("sij,sj->si", F, t2))
    else:
        t = -_rot90(n0)                    # rot90(t) = n0
        w = _rot90(np.einsum("sij,sj->si", F, t))
    norm = np.linalg.norm(w, axis=1, keepdims=True)
    return w / np.where(norm > 0, norm, 1.0), norm


def surface_frame_gradient_jvp(F: np.ndarray, n0: np.ndarray, dF: np.ndarray) -> np.ndarray:
    """dF_s (S, d, d): derivative of :func:`surface_frame_gradient` in direction dF."""
    n1, norm = _deformed_normal(F, n0)
    if F.shape[-1] == 3:
        t1, t2 = _tangents(n0)
        Ft1, Ft2 = np.einsum("sij,sj->si", F, t1), np.einsum("sij,sj->si", F, t2)
        dw = np.cross(np.einsum("sij,sj->si", dF, t1), Ft2) + np.cross(Ft1, np.einsum("sij,sj->si", dF, t2))
    else:
        t = -_rot90(n0)
        dw = _rot90(np.einsum("sij,sj->si", dF, t))
    dn1 = (dw - n1 * np.einsum("si,si->s", n1, dw)[:, None]) / np.where(norm > 0, norm, 1.0)
    Pn = np.eye(F.shape[-1]) - n0[:, :, None] * n0[:, None, :]
    return dF @ Pn + dn1[:, :, None] * n0[:, None, :]


# ----------------------------------------------------------------------------------------------
# Polar decomposition and its derivative


def rotations_from_deformation_gradient(F: np.ndarray, *, axis: int | None = None) -> np.ndarray:
    """The rotation R of the polar decomposition F = R U, for a stack of (Ns, 3, 3) matrices.

    3D: R = W V^T from the SVD F = W S V^T, with the sign of the last singular direction flipped
    where det(W V^T) < 0, so R is always a proper rotation (the one nearest F). 2D meshes: pass
    ``axis``, the out-of-plane axis (e.g. 2 for an x-y mesh); the in-plane block gets the closed
    form R = rotation by atan2(F_ji - F_ij, F_ii + F_jj) and that axis's row and column are the
    identity's.
    """
    F = np.asarray(F, dtype=np.float64)
    if F.ndim != 3 or F.shape[1:] != (3, 3):
        raise ValueError(f"F must be (N, 3, 3), got {F.shape}")
    if axis is not None:
        i, j = [k for k in range(3) if k != axis]
        ang = np.arctan2(F[:, j, i] - F[:, i, j], F[:, i, i] + F[:, j, j])
        R = np.broadcast_to(np.eye(3), F.shape).copy()
        c, s = np.cos(ang), np.sin(ang)
        R[:, i, i] = c
        R[:, j, j] = c
        R[:, j, i] = s
        R[:, i, j] = -s
        return R
    if len(F) == 0:
        return F.copy()
    W, _, Vt = np.linalg.svd(F)
    R = W @ Vt
    neg = np.linalg.det(R) < 0
    if np.any(neg):
        W[neg, :, 2] *= -1
        R[neg] = W[neg] @ Vt[neg]
    return R


def _axial(W: np.ndarray) -> np.ndarray:
    """Axial vectors (..., 3) of skew matrices (..., 3, 3): W = [w]x."""
    return np.stack([W[..., 2, 1], W[..., 0, 2], W[..., 1, 0]], axis=-1)


def _skew(w: np.ndarray) -> np.ndarray:
    z = np.zeros(w.shape[:-1])
    return np.stack([np.stack([z, -w[..., 2], w[..., 1]], -1),
                     np.stack([w[..., 2], z, -w[..., 0]], -1),
                     np.stack([-w[..., 1], w[..., 0], z], -1)], axis=-2)


def polar_rotation_derivative(F: np.ndarray, R: np.ndarray, dF: np.ndarray) -> np.ndarray:
    """dR (..., 3, 3) of the polar rotation R of F (..., 3, 3) in direction dF (3D)."""
    U = np.swapaxes(R, -1, -2) @ F
    U = 0.5 * (U + np.swapaxes(U, -1, -2))
    A = np.swapaxes(R, -1, -2) @ dF
    rhs = _axial(A - np.swapaxes(A, -1, -2))
    K = np.trace(U, axis1=-2, axis2=-1)[..., None, None] * np.eye(3) - U
    omega = np.linalg.solve(K, rhs[..., None])[..., 0]
    return R @ _skew(omega)


def planar_rotation_derivative(F: np.ndarray, dF: np.ndarray, axis: int) -> np.ndarray:
    """dR (..., 3, 3) of :func:`rotations_from_deformation_gradient` with ``axis`` (2D)."""
    i, j = [k for k in range(3) if k != axis]
    a = F[..., j, i] - F[..., i, j]
    c = F[..., i, i] + F[..., j, j]
    da = dF[..., j, i] - dF[..., i, j]
    dc = dF[..., i, i] + dF[..., j, j]
    dphi = (da * c - a * dc) / (a * a + c * c)
    phi = np.arctan2(a, c)
    out = np.zeros(F.shape)
    s, co = np.sin(phi), np.cos(phi)
    out[..., i, i] = -s * dphi
    out[..., j, j] = -s * dphi
    out[..., j, i] = co * dphi
    out[..., i, j] = -co * dphi
    return out
