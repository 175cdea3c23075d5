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
