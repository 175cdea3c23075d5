"""What the wing surface hands the volume warp: its displacement B @ (P - P0) and a frame matrix per
point (the FFD map's deformation gradient F, or the rotation of the surface frame), per component.

The forward maps of the derivative chain's surface and frame stages (:mod:`ffdcli.chain.surface`,
:mod:`ffdcli.chain.frames`, which hold their products).
"""

from __future__ import annotations

import numpy as np

from ffdcli.box.box import Box
from ffdcli.lattice.lattice import derivatives
from ffdcli.volume.frames import rotations_from_deformation_gradient, surface_frame_gradient


def component_displacement(comp, P: np.ndarray) -> np.ndarray:
    """(S_c, 3) displacement of one component's surface points: B @ (P - P0)."""
    box = comp.box
    dP = box.core_control_points(P) - box.core_control_points(comp.P0)
    return box.mesh_vectors(comp.prep.embedding.displace(dP))


def component_frames(comp, P: np.ndarray, carry: str = "gradient") -> np.ndarray:
    """(S_c, 3, 3) local frame matrices of one component's surface points (identity outside its lattice).

    ``carry="gradient"``: the deformation gradient ``F = J(P) J(P0)^-1`` of the FFD map at the point
    (mesh axes; 2D: identity across the plane): the volume near the wall then moves as the FFD moves
    space there, to first order, so the cells at a sharp trailing edge or at a tip, where faces of
    different normals meet, all see one smooth map. ``carry="rotation"``: the polar rotation of the
    surface frame (:func:`ffdcli.volume.frames.surface_frame_gradient`), IDWarp's form."""
    box = comp.box
    S = len(comp.prep.embedding.inside)
    R = np.broadcast_to(np.eye(3), (S, 3, 3)).copy()
    if np.array_equal(P, comp.P0):
        return R
    ins, F, n0 = frame_gradient_inputs(comp, P)
    if not len(ins):
        return R
    if carry == "gradient":
        R[ins] = full3(box, F)
        return R
    Fs = surface_frame_gradient(F, n0)
    if box.dim == 2:
        R[ins] = rotations_from_deformation_gradient(full3(box, Fs), axis=box.axes.span)
    else:
        R[ins] = rotations_from_deformation_gradient(Fs)
    return R


def frame_gradient_inputs(comp, P: np.ndarray):
    """(inside point indices, F in core coordinates (k, d, d), unit normals n0 (k, d)) of a component."""
    box, emb = comp.box, comp.prep.embedding
    n_all = comp.prep.surface.normals[:, box.plane_axes]
    nn = np.linalg.norm(n_all, axis=1)
    ins = np.flatnonzero(emb.inside & (nn > 0))
    if not len(ins):
        return ins, None, None
    J0 = derivatives(box.lattice(comp.P0), emb.params[ins])
    J1 = derivatives(box.lattice(P), emb.params[ins])
    F = J1 @ np.linalg.inv(J0)
    return ins, F, n_all[ins] / nn[ins, None]


def full3(box: Box, Fc: np.ndarray) -> np.ndarray:
    """(k, 3, 3) mesh-axis matrices from core-coordinate ones (2D: identity across the plane)."""
    if box.dim == 3:
        return Fc
    a, b = box.plane_axes
    F3 = np.broadcast_to(np.eye(3), (len(Fc), 3, 3)).copy()
    F3[:, a, a], F3[:, a, b], F3[:, b, a], F3[:, b, b] = Fc[:, 0, 0], Fc[:, 0, 1], Fc[:, 1, 0], Fc[:, 1, 1]
    return F3
