"""The near-wall layer of a 3-D RANS wing (32 prism layers from a 1e-6 chord first cell, its root on a
symmetry plane) moves with its wall: every first cell keeps its height (1 +- 0.005) and its angle to the
wall (within 0.5 degrees) under sweeps, span-wise twists and chord changes that tilt the root's wall out
of square with the plane, and under deflected slats and flaps (a kink of the wall at the hinge line)."""

import numpy as np
import pytest

from ffdcli.quality.wall_layer import wall_node_rows
from ffdcli.volume.warp import WarpSettings, prepare_mesh_warp, warp

pytest.importorskip("gmsh")


@pytest.fixture(scope="module")
def wing():
    from ffdcli.testing.gmsh_wings import CASES, smaller, wing_volume_mesh

    m = wing_volume_mesh(smaller(CASES["rect_z_rans32"], 4.0))
    model, _ = prepare_mesh_warp(m, "wing", WarpSettings(tolerance=0))
    assert model.layer is not None
    return m, model


def _rot(theta):
    c, s = np.cos(theta), np.sin(theta)
    R = np.zeros(np.shape(theta) + (3, 3))
    R[..., 0, 0], R[..., 0, 1], R[..., 1, 0], R[..., 1, 1], R[..., 2, 2] = c, -s, s, c, 1.0
    dR = np.zeros_like(R)
    dR[..., 0, 0], dR[..., 0, 1], dR[..., 1, 0], dR[..., 1, 1] = -s, -c, c, -s
    return R, dR


def _map(p, kind, size):
    """(moved points, F) of a smooth or hinged map of the wing's points ``p`` (S, 3): span along z from
    the root plane, chord along x."""
    z0, span = p[:, 2].min(), np.ptp(p[:, 2])
    x0, chord = p[:, 0].min(), np.ptp(p[:, 0])
    eta = (p[:, 2] - z0) / span
    F = np.broadcast_to(np.eye(3), (len(p), 3, 3)).copy()
    q = p.copy()
    if kind == "sweep":
        t = np.tan(np.radians(size))
        q[:, 0] += t * (p[:, 2] - z0)
        F[:, 0, 2] = t
    elif kind == "twist":                          # grows along the span: tilts the root's wall
        c = np.array([x0 + 0.25 * chord, 0.0, 0.0])
        R, dR = _rot(np.radians(size) * eta)
        r = p - c
        r[:, 2] = 0.0
        q = c + np.einsum("nij,nj->ni", R, r)
        q[:, 2] = p[:, 2]
        F = R + np.einsum("nij,nj->ni", dR, r)[:, :, None] * (np.radians(size) / span) * np.eye(3)[2][None, None, :]
    elif kind == "chord":
        f = 1.0 + size * eta
        q[:, 0] = x0 + (p[:, 0] - x0) * f
        F[:, 0, 0] = f
        F[:, 0, 2] = (p[:, 0] - x0) * size / span
    elif kind == "bump":      # a thickness change of size chords, smooth along the span (-0.05 folds this wing's
        # trailing edge: its half thickness at 0.9 chord is 0.016)
        w = np.sin(np.pi * (p[:, 0] - x0) / chord) * np.sin(np.pi * eta / 2 + 0.3)
        q[:, 1] += size * chord * w * np.sign(p[:, 1] + 1e-12)
        F[:, 1, 0] = size * np.pi * np.cos(np.pi * (p[:, 0] - x0) / chord) * np.sin(np.pi * eta / 2 + 0.3) \
            * np.sign(p[:, 1] + 1e-12)
    else:                                           # a slat or a flap: the part ahead of / behind a hinge turns
        xh = x0 + (0.15 if kind == "slat" else 0.75) * chord
        part = p[:, 0] < xh if kind == "slat" else p[:, 0] > xh
        R, _ = _rot(np.radians(size if kind == "slat" else -size))
        h = np.array([xh, 0.0, 0.0])
        q[part] = h + (p[part] - h) @ R.T
        F[part] = R
    return q, F


@pytest.mark.parametrize("kind,size", [("sweep", 10.0), ("sweep", -10.0), ("twist", 20.0), ("twist", -20.0),
                                       ("chord", -0.5), ("bump", 0.05), ("bump", -0.03), ("slat", 15.0),
                                       ("flap", 10.0), ("flap", 25.0)])
def test_every_first_cell_keeps_its_height_and_angle(wing, kind, size):
    m, model = wing
    ids = model.surface_ids
    q, F = _map(m.points[ids], kind, size)
    after = m.points + warp(model, q - m.points[ids], F)
    rows = wall_node_rows(m, "wing", after, m.points)
    ratio = rows[:, 3] / rows[:, 1]
    change = np.abs(rows[:, 5] - rows[:, 4])
    assert len(rows) > 0.7 * len(ids)          # all but the sharp trailing edge and the tip's rim
    assert np.abs(ratio - 1).max() < 0.005, (ratio.min(), ratio.max())
    assert change.max() < 0.5, change.max()
