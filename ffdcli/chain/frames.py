"""lattices -> frames: the frame matrix each surface point hands the volume warp (``volume.carry``).

``x`` a tuple of every component's control points; ``y`` (S, 3, 3) per surface point (rows as the
run's surface): with ``carry="gradient"`` the FFD map's deformation gradient ``F = J(P') J(P0)^-1``,
with ``carry="rotation"`` the polar rotation of the surface frame (:mod:`ffdcli.volume.frames`);
the identity outside a lattice, and exactly the identity for a component at its baseline
(:func:`ffdcli.volume.surface_motion.component_frames`, the forward map).

The parametric Jacobian ``J(P)`` at a point is linear in the control points, ``J[:, :, a] = dB_a P``
with ``dB_a`` the basis functions' derivatives along parameter ``a`` (:func:`derivative_basis`), and
the frame is a function of ``J`` point by point. So the products are, per point, a small matrix
``A`` (9 x d^2: the frame's derivative with respect to ``J``, built by pushing the d^2 unit
directions through :func:`ffdcli.volume.frames.surface_frame_gradient_jvp` and the polar rotation's
derivative) between ``dB`` and its transpose: ``dFrame = A vec(dB dP)``, ``gP = dB^T A^T g``.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ffdcli.chain.cache import Memo, Once, digest
from ffdcli.chain.stage import Stage
from ffdcli.lattice.lattice import derivatives
from ffdcli.lattice.spline import basis_derivs
from ffdcli.volume.frames import (
    planar_rotation_derivative,
    polar_rotation_derivative,
    rotations_from_deformation_gradient,
    surface_frame_gradient,
    surface_frame_gradient_jvp,
)
from ffdcli.volume.surface_motion import component_frames, frame_gradient_inputs, full3

CARRIES = ("gradient", "rotation")


def derivative_basis(lattice, params: np.ndarray) -> list[sp.csr_matrix]:
    """``[dB_a]``, one (k, n_ctrl) CSR per parameter axis ``a``: ``dB_a @ P.reshape(n_ctrl, gdim)`` is
    ``derivatives(lattice(P), params)[:, :, a]`` for every control net ``P`` of the lattice's shape."""
    params = np.asarray(params, dtype=np.float64)
    k, pdim = params.shape
    shape = lattice.shape
    tables = []
    for a in range(pdim):
        first, ders = basis_derivs(lattice.knots[a], lattice.degree[a], params[:, a], nder=1)
        tables.append((first, ders[0], ders[1]))
    out = []
    strides = np.cumprod((1,) + tuple(shape[::-1]))[:-1][::-1]        # C order of the control net
    for a in range(pdim):
        cols = np.zeros((k, 1), dtype=np.int64)
        vals = np.ones((k, 1))
        for axis, (first, val, der) in enumerate(tables):
            w = der if axis == a else val
            idx = first[:, None] + np.arange(w.shape[1])[None, :]
            cols = (cols[:, :, None] + strides[axis] * idx[:, None, :]).reshape(k, -1)
            vals = (vals[:, :, None] * w[:, None, :]).reshape(k, -1)
        rows = np.repeat(np.arange(k), cols.shape[1])
        out.append(sp.csr_matrix((vals.ravel(), (rows, cols.ravel())), shape=(k, int(np.prod(shape)))))
    return out


class _Fixed:
    """What a component's frames need of its baseline: the points inside (with a normal), their
    parameters' derivative bases, ``J(P0)^-1``."""

    def __init__(self, comp):
        box, emb = comp.box, comp.prep.embedding
        self.ins, _, self.n0 = frame_gradient_inputs(comp, comp.P0)
        if len(self.ins):
            params = emb.params[self.ins]
            self.J0inv = np.linalg.inv(derivatives(box.lattice(comp.P0), params))
            self.dB = derivative_basis(box.lattice(comp.P0), params)
        self.d = 3 if box.dim == 3 else 2


class FrameStage(Stage):
    """lattices -> frames for one ``carry`` (module docstring).

    Parameters
    ----------
    components : sequence of Component
    rows : sequence of (S_c,) int arrays
        Each component's surface points' rows in the run's surface.
    n_surface : int
        S, the run's surface points.
    carry : str
        ``"gradient"`` or ``"rotation"``.
    """

    def __init__(self, components, rows, n_surface: int, carry: str):
        if carry not in CARRIES:
            raise ValueError(f"carry must be one of {CARRIES}, got {carry!r}")
        self.components = tuple(components)
        self.rows = tuple(rows)
        self.n_surface = int(n_surface)
        self.carry = carry
        self._fixed = [Once() for _ in self.components]
        self._local = [Memo() for _ in self.components]

    def fixed(self, c: int) -> _Fixed:
        return self._fixed[c].get(lambda: _Fixed(self.components[c]))

    def forward(self, x) -> np.ndarray:
        if len(self.components) == 1:
            return component_frames(self.components[0], x[0], self.carry)
        out = np.broadcast_to(np.eye(3), (self.n_surface, 3, 3)).copy()
        for comp, rows, P in zip(self.components, self.rows, x, strict=True):
            out[rows] = component_frames(comp, P, self.carry)
        return out

    def local(self, c: int, P: np.ndarray) -> np.ndarray:
        """(k, 9, d*d): each inside point's derivative of its frame (row-major 3 x 3) with respect to
        its parametric Jacobian ``J`` (row-major d x d), at control points ``P`` of component ``c``."""
        return self._local[c].get(digest(P), lambda: self._local_map(c, P))

    def _local_map(self, c: int, P: np.ndarray) -> np.ndarray:
        comp, fx = self.components[c], self.fixed(c)
        box, d, k = comp.box, fx.d, len(fx.ins)
        span = box.axes.span
        F = derivatives(box.lattice(P), comp.prep.embedding.params[fx.ins]) @ fx.J0inv
        if self.carry == "rotation":
            Fs = surface_frame_gradient(F, fx.n0)
            if d == 3:
                R = rotations_from_deformation_gradient(Fs)
            else:
                Fs3 = full3(box, Fs)
        A = np.zeros((k, 9, d * d))
        for e in range(d * d):
            dJ = np.zeros((k, d, d))
            dJ[:, e // d, e % d] = 1.0
            dF = dJ @ fx.J0inv
            if self.carry == "gradient":
                out = full3(box, dF)
                if d == 2:
                    out[:, span, span] = 0.0
            else:
                dFs = surface_frame_gradient_jvp(F, fx.n0, dF)
                if d == 3:
                    out = polar_rotation_derivative(Fs, R, dFs)
                else:
                    dFs3 = full3(box, dFs)
                    dFs3[:, span, span] = 0.0
                    out = planar_rotation_derivative(Fs3, dFs3, span)
            A[:, :, e] = out.reshape(k, 9)
        return A

    def _rows(self, c: int) -> np.ndarray:
        return self.rows[c] if len(self.components) > 1 else np.arange(self.n_surface)

    def jvp(self, x, dx) -> np.ndarray:
        out = np.zeros((self.n_surface, 3, 3))
        for c, (comp, P, dP) in enumerate(zip(self.components, x, dx, strict=True)):
            fx = self.fixed(c)
            if not len(fx.ins):
                continue
            core = comp.box.core_control_points(np.asarray(dP, dtype=float)).reshape(-1, fx.d)
            dJ = np.stack([B @ core for B in fx.dB], axis=-1)             # (k, d, d): [:, :, a] = dB_a dP
            out[self._rows(c)[fx.ins]] = np.einsum("kfe,ke->kf", self.local(c, P),
                                                    dJ.reshape(len(fx.ins), -1)).reshape(-1, 3, 3)
        return out

    def vjp(self, x, gy) -> tuple[np.ndarray, ...]:
        g = np.asarray(gy, dtype=float)
        out = []
        for c, (comp, P) in enumerate(zip(self.components, x, strict=True)):
            fx, box = self.fixed(c), comp.box
            gP = np.zeros(comp.P0.shape)
            if len(fx.ins):
                gk = g[self._rows(c)[fx.ins]].reshape(len(fx.ins), 9)
                gJ = np.einsum("kfe,kf->ke", self.local(c, P), gk).reshape(-1, fx.d, fx.d)
                core = sum(B.T @ gJ[:, :, a] for a, B in enumerate(fx.dB))    # (n_ctrl, d)
                if box.dim == 3:
                    gP = core.reshape(comp.P0.shape)
                else:
                    n, m, l, _ = comp.P0.shape
                    gP[:, 0, :, :][..., box.plane_axes] = core.reshape(n, l, 2)
            out.append(gP)
        return tuple(out)
