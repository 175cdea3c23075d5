"""The frame a lattice's design changes act in: directions, reference points, weights.

:class:`LatticeFrame` is made by the box (:meth:`ffdcli.box.box.Box.frame`) and read by every change
of :mod:`ffdcli.parameterization.changes`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ffdcli.errors import InputError


@dataclass(frozen=True, eq=False)
class LatticeFrame:
    """What the changes need to know about a lattice besides its points.

    chord_dir, thickness_dir, span_dir
        (3,) unit vectors: chord from leading to trailing edge, thickness "up", span root -> tip.
        Chord and thickness must be orthogonal (they are normalised here).
    ref_weights
        (m, n, l): section ``j``'s trailing-edge reference point is
        ``p_j = sum_ik ref_weights[j, i, k] * P[i, j, k]`` (linear in ``P``).
    le_rows
        (2, n*m*l) or None (2D): ``le_rows @ P.reshape(-1, 3)`` are the surface's leading-edge
        points at the root (row 0) and the tip (row 1); they define the sweep and dihedral angles.
    dim
        2 or 3.
    le_weights
        (m, n, l) or None: section ``j``'s leading-edge point on its chord line is
        ``sum_ik le_weights[j, i, k] * P[i, j, k]``; None: the midpoint of ``P[0, j, 0]`` and
        ``P[0, j, l-1]``. With the trailing-edge points it gives the points at a chord fraction
        (:meth:`chord_points`, the twist axis).
    """

    chord_dir: np.ndarray
    thickness_dir: np.ndarray
    span_dir: np.ndarray
    ref_weights: np.ndarray
    le_rows: np.ndarray | None = None
    dim: int = 3
    le_weights: np.ndarray | None = None

    def __post_init__(self):
        for name in ("chord_dir", "thickness_dir", "span_dir"):
            v = np.asarray(getattr(self, name), dtype=float).reshape(3)
            norm = np.linalg.norm(v)
            if not norm > 0:
                raise ValueError(f"LatticeFrame.{name} must be a non-zero vector")
            object.__setattr__(self, name, v / norm)
        if abs(self.chord_dir @ self.thickness_dir) > 1e-9:
            raise ValueError("LatticeFrame: chord_dir and thickness_dir must be orthogonal")
        object.__setattr__(self, "ref_weights", np.asarray(self.ref_weights, dtype=float))
        if self.ref_weights.ndim != 3:
            raise ValueError("LatticeFrame.ref_weights must have shape (m, n, l)")
        if self.le_rows is not None:
            object.__setattr__(self, "le_rows", np.asarray(self.le_rows, dtype=float))
        if self.le_weights is None:
            m, n, l = self.ref_weights.shape
            w = np.zeros((m, n, l))
            w[:, 0, 0] += 0.5
            w[:, 0, l - 1] += 0.5
            object.__setattr__(self, "le_weights", w)
        object.__setattr__(self, "le_weights", np.asarray(self.le_weights, dtype=float))
        if self.le_weights.shape != self.ref_weights.shape:
            raise ValueError("LatticeFrame.le_weights must have the shape of ref_weights (m, n, l)")
        if self.dim not in (2, 3):
            raise ValueError(f"LatticeFrame.dim must be 2 or 3, got {self.dim}")

    @classmethod
    def from_lattice(cls, shape: Sequence[int], chord_dir, thickness_dir, span_dir,
                     dim: int = 3) -> LatticeFrame:
        """A frame read off the lattice alone (no surface): for tests and user-given lattices.

        The trailing-edge point of section ``j`` is the midpoint of ``P[n-1, j, 0]`` and
        ``P[n-1, j, l-1]``; the leading-edge points are the midpoints of ``P[0, j, 0]`` and
        ``P[0, j, l-1]`` at ``j = 0`` (root) and ``j = m-1`` (tip).
        """
        n, m, l = (int(s) for s in shape)
        w = np.zeros((m, n, l))
        w[:, n - 1, 0] += 0.5
        w[:, n - 1, l - 1] += 0.5
        le = None
        if dim == 3:
            rows = np.zeros((2, n, m, l))
            for r, j in ((0, 0), (1, m - 1)):
                rows[r, 0, j, 0] += 0.5
                rows[r, 0, j, l - 1] += 0.5
            le = rows.reshape(2, -1)
        return cls(chord_dir, thickness_dir, span_dir, w, le, dim)

    def ref_points(self, P: np.ndarray) -> np.ndarray:
        """(..., m, 3) trailing-edge reference points of the sections of ``P`` (..., n, m, l, 3)."""
        return np.einsum("jik,...ijkd->...jd", self.ref_weights, P)

    def chord_points(self, P: np.ndarray, fraction: float = 1.0) -> np.ndarray:
        """(..., m, 3) the point at chord ``fraction`` of each section's chord line (0 leading edge,
        1 trailing edge: :meth:`ref_points`); linear in ``P``, so also the map of a ``dP``."""
        te = self.ref_points(P)
        if fraction == 1.0:
            return te
        le = np.einsum("jik,...ijkd->...jd", self.le_weights, P)
        return te + (1.0 - fraction) * (le - te)

    def le_points(self, P: np.ndarray) -> np.ndarray:
        """(..., 2, 3) ``le_rows @ P``: the leading-edge points of the surface at the root and the tip
        (linear in ``P``, so it is its own derivative: ``le_points(dP)``)."""
        if self.le_rows is None:
            raise InputError("sweep and dihedral need a 3D lattice with leading-edge points")
        flat = P.reshape(*P.shape[:-4], -1, 3)
        return np.einsum("rq,...qd->...rd", self.le_rows, flat)

    def plane(self) -> np.ndarray:
        """(3, 3) projector onto the chord-thickness plane: c c^T + t t^T."""
        c, t = self.chord_dir, self.thickness_dir
        return np.outer(c, c) + np.outer(t, t)
