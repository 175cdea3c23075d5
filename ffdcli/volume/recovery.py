"""Recovery before refusal: what an expert tries when the deformed volume mesh fails the gate.

When :func:`ffdcli.app.deformation.deform` finds cells that fail the quality gate (:mod:`ffdcli.quality.gate`)
with the design's own ``volume:`` settings, it tries, in this order, keeping the surface exactly
where the FFD puts it (bit for bit) every time:

1. **a longer reach**: ``alpha`` x :data:`REACH_FACTOR` (the short-range ``b`` term then rules
   :data:`REACH_FACTOR` ^ (b / (b - a)) times further out: every node follows its nearest
   surface more closely, which is what planform changes need);
2. **the surface frame's rotation only** (``carry: rotation``, when the design's carry is the
   FFD gradient): a shape change that folds the lattice across the wing has a gradient the wall
   cells should not follow;
3. **rotations not faded** (``carry: rotation``, ``rotation_reach: null``): a large twist (45
   degrees) can need the rotation carried whole a chord away from the wing;
4. **the design in increments**: the lattice goes from P0 to P' in :data:`INCREMENTS` equal steps
   and the volume is warped through every intermediate surface, with the warp rebuilt on the
   mesh of the step before (so the weights see the cells where they are, not where they were),
   with the longer reach. The frame of each step is ``F_k F_(k-1)^-1`` (a rotation: ``R_k R_(k-1)^T``).

The first attempt that passes the gate is used; if none does, the one with the fewest failing cells
is reported (and written only with ``--force``). Each attempt costs one warp and one quality check
(the increments: :data:`INCREMENTS` tree builds and warps), and only a failing design pays it.

The result is NOT a smooth function of the design (it switches between attempts), so the
derivatives (``ffd grad``, ``mesh_vjp``) are those of the default warp; the summary says which was
used. Under MPI each intermediate warp is shared among the ranks like the first one (``warp(comm=)``).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ffdcli.progress import no_progress
from ffdcli.settings import WarpSettings
from ffdcli.volume.warp import prepare_mesh_warp

#: ``alpha`` is multiplied by this for the "longer reach" attempt.
REACH_FACTOR = 4.0
#: Steps of the incremental attempt.
INCREMENTS = 4


def attempts(settings: WarpSettings) -> list[tuple[str, WarpSettings, int]]:
    """(description, settings, increments) of the recovery attempts, in order. With a rigid wall layer
    (:mod:`ffdcli.volume.layer_motion`) the warp alone comes first, then the attempts without the layer:
    a design the layer's frames fold (a deflected flap's hinge) is never refused where the warp alone
    passes."""
    if settings.wall_layer != "none":
        alone = replace(settings, wall_layer="none")
        return [("the warp alone near the wall (volume.wall_layer: none)", alone, 1)] + attempts(alone)
    longer = replace(settings, alpha=settings.alpha * REACH_FACTOR)
    out = [(f"longer reach (volume.alpha: {longer.alpha:g})", longer, 1)]
    if settings.carry != "rotation":
        # a shape change that folds the lattice across the wing: its gradient is not what the wall
        # cells should follow, the rotation of the surface frame is (it never sees the lattice's
        # thickness column)
        out.append(("the surface frame's rotation only (volume.carry: rotation)",
                    replace(settings, carry="rotation"), 1))
    if settings.rotation_reach is not None:
        # a large twist: the rotation carried whole (IDWarp's form) keeps cells near the wing rigid
        out.append(("rotations not faded (volume.carry: rotation, volume.rotation_reach: null)",
                    replace(settings, carry="rotation", rotation_reach=None), 1))
    out.append((f"{INCREMENTS} increments with volume.alpha: {longer.alpha:g}", longer, INCREMENTS))
    return out


def incremental_warp(chain, P1, settings: WarpSettings, steps: int, *, progress=None) -> np.ndarray:
    """(N, 3) mesh points (a local mesh: its rows) after warping the volume through ``steps`` intermediate surfaces.

    ``chain``: the design's :class:`ffdcli.chain.DesignChain` (its surface and frame stages, its mesh
    share). Step k moves the lattice to ``P0 + k/steps (P1 - P0)``; the warp of each step is prepared on
    the points of the step before. Surface nodes end exactly at ``X0 + B (P1 - P0)``.
    """
    progress = progress or no_progress
    share = chain.share
    mesh = share.mesh
    # every component's surface (a multi-component run moves them all, one lattice each)
    names = [n for comp in chain.components for n in comp.prep.surface.names]
    sid = chain.surface_ids
    P0s = [comp.P0 for comp in chain.components]
    P1s = chain.per_component(P1)
    frames = chain.frame_stage(settings.carry)
    pts = mesh.points.copy()
    b_prev = np.zeros((len(sid), 3))
    R_prev = None
    for k in range(1, steps + 1):
        Pk = P1s if k == steps else tuple(P0 + (k / steps) * (Q - P0) for P0, Q in zip(P0s, P1s, strict=True))
        bk = chain.surface.forward(Pk)
        Rk = frames.forward(Pk)
        dR = Rk if R_prev is None else Rk @ np.linalg.inv(R_prev)
        model, _ = prepare_mesh_warp(replace(mesh, points=pts), names, settings, progress=progress,
                                     size=share.diagonal(pts), targets=share.targets(), nodes=share.nodes())
        pts = pts + share.warp(model, bk - b_prev, dR, progress)
        pts[sid] = mesh.points[sid] + bk
        b_prev, R_prev = bk, Rk
    return pts
