"""``shape`` moves along each section's own thickness direction, after the section's twist (issue 31).

Oracle: a twisted section's shape change equals the untwisted one turned by the twist. Derivatives
(the directions depend on the input lattice) against central differences.
"""

from __future__ import annotations

import numpy as np
import pytest
from test_changes import wing_lattice
from test_derivatives import assert_matches_fd

from ffdcli.parameterization.changes import Chord, Shape, Sweep, Twist, apply_changes
from ffdcli.parameterization.changes.shape import section_normals
from ffdcli.parameterization.changes.twist import rotation

UP = np.array([0.0, 0.01, 0.02, 0.015, 0.005, 0.0])
LO = np.array([0.0, -0.01, -0.012, -0.008, -0.002, 0.0])


@pytest.mark.parametrize("axes", ["rect", "crm"])
def test_twisted_shape_is_the_untwisted_one_turned(axes):
    P, frame = wing_lattice(axes=axes)
    theta = np.linspace(0.0, 25.0, 8)
    twist, shape = Twist(theta), Shape(UP, LO)
    P1 = twist.apply(P, frame)
    turned = apply_changes(P, frame, [twist, shape]) - P1        # the shape change of the twisted lattice
    plain = shape.apply(P, frame) - P                             # of the untwisted one
    R = rotation(frame, np.radians(theta))
    np.testing.assert_allclose(turned, np.einsum("jab,ijkb->ijka", R, plain), atol=1e-14)
    # and the twisted sections' directions are the frame's turned by the twist
    np.testing.assert_allclose(section_normals(P1, frame), R @ frame.thickness_dir, atol=1e-15)


def test_untwisted_box_moves_exactly_along_the_thickness_axis():
    P, frame = wing_lattice(sweep_deg=20.0, dihedral_deg=4.0)
    D = Shape(UP, LO).apply(P, frame) - P
    assert np.array_equal(D[..., 0], np.zeros(D.shape[:3]))
    assert np.array_equal(D[..., 2], np.zeros(D.shape[:3]))


def test_a_shape_does_not_turn_its_own_direction():
    P, frame = wing_lattice()
    P1 = Twist(np.full(8, 12.0)).apply(P, frame)
    Q = Shape(UP, LO).apply(P1, frame)
    np.testing.assert_allclose(section_normals(Q, frame), section_normals(P1, frame), atol=1e-15)


@pytest.mark.parametrize("axes", ["rect", "crm"])
def test_derivatives_with_the_twist_before(axes):
    P, frame = wing_lattice(axes=axes, l=3)
    changes = [Twist(np.linspace(0, 20, 8)), Chord(np.linspace(1, 0.7, 8)), Sweep(5.0),
               Shape(UP, LO, sections=[1, 4, 6]), Shape(UP * 0.5, None), Twist(np.linspace(0, -5, 8))]
    assert_matches_fd(P, frame, changes)
