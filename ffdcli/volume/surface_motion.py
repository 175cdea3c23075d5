"""What the wing surface hands the volume warp: its displacement B @ (P - P0) and a frame matrix per
point (the FFD map's deformation gradient F, or the rotation of the surface frame), per component.

Used by the deform workflow (:mod:`ffdcli.app.run`); :func:`frame_jacobian` is the frames' derivative,
which the derivatives through the volume (:mod:`ffdcli.api`) chain with the warp's transpose.
"""

from __future__ import annotations

import numpy as np

from ffdcli.box.box import Box
from ffdcli.lattice.lattice import derivatives
from ffdcli.volume.frames import (
    planar_rotation_derivative,
    polar_rotation_derivative,
    rotations_from_deformation_gradient,
    surface_frame_gradient,
    surface_frame_gradient_jvp,
)


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


def frame_jacobian(components, lattices, layout, n_vars: int, n_surface: int, carry: str, single: bool
                   ) -> np.ndarray:
    """d(frame)/dv (n_vars, S, 3, 3) at the surface points of a design's components (zero outside a
    lattice): the derivative of :func:`component_frames` with ``carry`` ("gradient": F itself, linear
    in the control points; "rotation": the polar rotation of the surface frame and its derivative,
    :mod:`ffdcli.volume.frames`). ``lattices``: every component's deformed control points;
    ``layout``: :class:`ffdcli.parameterization.components.Layout` of the run's surface rows and
    variables; ``n_surface``: the run's surface points; ``single``: one component (its rows are its
    own surface points)."""
    lay = layout
    gradient = carry == "gradient"
    out = np.zeros((n_vars, n_surface, 3, 3))
    for c, (comp, P1) in enumerate(zip(components, lattices, strict=True)):
        box, emb = comp.box, comp.prep.embedding
        rows = lay.rows[c] if not single else np.arange(len(emb.inside))
        ins, F, n0 = frame_gradient_inputs(comp, P1)
        nv = lay.var_offsets[c + 1] - lay.var_offsets[c]
        if not len(ins) or not nv:
            continue
        J0inv = np.linalg.inv(derivatives(box.lattice(comp.P0), emb.params[ins]))
        D = comp.lattice_jacobian().reshape(*P1.shape, nv)
        if not gradient:
            Fs = surface_frame_gradient(F, n0)
            if box.dim == 3:
                R = rotations_from_deformation_gradient(Fs)
            else:
                Fs3 = full3(box, Fs)
        for k in range(nv):
            v = lay.var_offsets[c] + k
            dF = derivatives(box.lattice(D[..., k]), emb.params[ins]) @ J0inv
            if gradient:          # the frame is F itself: linear in the control points
                dF3 = full3(box, dF)
                if box.dim == 2:
                    dF3[:, box.axes.span, box.axes.span] = 0.0
                out[v, rows[ins]] = dF3
                continue
            dFs = surface_frame_gradient_jvp(F, n0, dF)
            if box.dim == 3:
                out[v, rows[ins]] = polar_rotation_derivative(Fs, R, dFs)
            else:
                dFs3 = full3(box, dFs)
                dFs3[:, box.axes.span, box.axes.span] = 0.0
                out[v, rows[ins]] = planar_rotation_derivative(Fs3, dFs3, box.axes.span)
    return out
