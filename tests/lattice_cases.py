"""Lattices for the tests: curved, non-affine lattices like the ones fitted around a wing.

The control points are a regular grid in (chord, span, thickness) mapped by a swept, tapered,
twisted and bent (dihedral) wing shape, so the lattice map is non-affine in every direction while
staying a one-to-one map (its Jacobian is well conditioned: the twist is 12 degrees over the span).
"""

from __future__ import annotations

import numpy as np

from ffdcli.lattice.lattice import Lattice


def wing_grid(shape, span=4.0, chord=1.0, thickness=0.3):
    """Control points (n, m, l, 3) of a swept, tapered, twisted and bent box."""
    n, m, l = shape
    s, t, r = np.meshgrid(np.linspace(0, 1, n), np.linspace(0, 1, m), np.linspace(0, 1, l), indexing="ij")
    y = span * t
    local_chord = chord * (1.0 - 0.55 * t)                  # taper
    x = (s - 0.25) * local_chord
    z = (r - 0.5) * thickness * local_chord * (1.0 + 0.3 * np.sin(np.pi * s))   # thicker mid-chord
    twist = np.radians(12.0) * t                            # wash-out, linear in span
    xr = np.cos(twist) * x + np.sin(twist) * z
    zr = -np.sin(twist) * x + np.cos(twist) * z
    xr += 0.6 * y                                           # sweep
    zr += 0.08 * y ** 2                                     # curved dihedral
    return np.stack([xr + 3.0, y - 1.0, zr + 0.5], axis=-1)


def wing_lattice(shape=(8, 6, 2), degree=(3, 3, 1)) -> Lattice:
    return Lattice(wing_grid(shape), degree)


def curved_patch(shape=(6, 5), degree=(3, 2), gdim=2) -> Lattice:
    """A bent 2D patch (n, l, gdim): an annular sector, with a wavy third coordinate when gdim is 3."""
    n, l = shape
    a, r = np.meshgrid(np.linspace(0.2, 1.3, n), np.linspace(1.0, 2.0, l), indexing="ij")
    radius = r * (1.0 + 0.1 * a)
    pts = [radius * np.cos(a), radius * np.sin(a)]
    if gdim == 3:
        pts.append(0.2 * np.sin(2 * a) * r)
    return Lattice(np.stack(pts, axis=-1), degree)
