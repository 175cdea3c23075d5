"""The warp's plain NumPy direct sum (the formula of :mod:`ffdcli.volume.warp`'s docstring), the
reference the tests check the compiled kernels against."""

from __future__ import annotations

import numpy as np

from ffdcli.settings import WarpSettings


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
