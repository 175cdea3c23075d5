"""The design changes: twist, span, sweep, dihedral, chord, shape, flap and slat as maps of lattice sections.

One module per concept: :mod:`.base` (the :class:`Change` protocol, homogeneous coordinates, section
laws), :mod:`.twist`, :mod:`.chord`, :mod:`.span`, :mod:`.sweep_dihedral` (the shears), :mod:`.shape`,
:mod:`.control_surfaces` (flap and slat; where they sit in the lattice: :mod:`.devices`) and
:mod:`.pipeline` (a list of changes, built from the design file). Each kind registers itself in
:data:`CHANGES` at the end of its module (:mod:`ffdcli.registry`: ``kind``, ``schema()``,
``from_spec(spec, ctx)``); this package face imports every kind module, so that they are all registered.

A lattice ``P`` has shape ``(n, m, l, 3)``: ``i`` chordwise (0 = leading-edge side), ``j`` spanwise
(0 = root section), ``k`` thickness (0 = lower side), in mesh coordinates. A 2D lattice has
``m = 1``. The directions and reference points the changes need are held by a :class:`LatticeFrame`.

Each change is a frozen dataclass with

``apply(P, frame) -> P'``
    the change itself, as affine maps in homogeneous coordinates (4 x 4 ``T(p) R T(-p)`` per
    section for twist and chord, one 4 x 4 scale or shear for span, sweep and dihedral) plus
    translations for sweep/dihedral offsets and shape;
``variables() -> [(name, value), ...]``
    its design variables, named relative to the change as written in the design file
    (``twist[7]`` for a list, ``twist.tip`` for ``{tip: }``, ``span`` for a scalar);
``with_values(values) -> change``
    the same change with new values of its variables;
``jacobian_own(P, frame) -> (k, n, m, l, 3)``, ``jvp(P, frame, dvalues) -> dP'``
    the derivative of ``apply`` with respect to its own variables (per degree for angles);
``jvp_P(P, frame, dP) -> dP'``
    the derivative with respect to the input lattice (the trailing-edge points and the sweep and
    dihedral angles depend on ``P``); ``dP`` may carry leading batch axes ``(..., n, m, l, 3)``;
``bounds(P, frame) -> (k, 2)``
    the natural bounds of its variables as an open interval (lower, upper) per variable: chord and
    span factors > 0, a sweep or dihedral angle that keeps the leading-edge line within
    +-``MAX_SHEAR_ANGLE`` of the span axis; twist, offsets and shape moves are unbounded.

All derivatives are analytic. :func:`apply_changes`, :func:`design_variables` and
:func:`set_design_variables` work on a whole pipeline (a list of changes applied in order).
"""

from ffdcli.box.frame import LatticeFrame
from ffdcli.parameterization.changes.base import (
    CHANGES,
    DEG,
    MAX_SHEAR_ANGLE,
    Change,
    SectionLaw,
    SectionMap,
    SpecContext,
    about,
    apply_homogeneous,
    homogeneous,
    not_in_2d,
    rotation,
    rotation_derivative,
    translation,
)
from ffdcli.parameterization.changes.chord import Chord
from ffdcli.parameterization.changes.control_surfaces import ControlSurface, Flap, Slat
from ffdcli.parameterization.changes.pipeline import (
    apply_changes,
    changes_from_spec,
    design_bounds,
    design_units,
    design_variables,
    set_design_variables,
)
from ffdcli.parameterization.changes.shape import Shape
from ffdcli.parameterization.changes.span import Span
from ffdcli.parameterization.changes.sweep_dihedral import Dihedral, Shear, Sweep
from ffdcli.parameterization.changes.twist import Twist

__all__ = [
    "CHANGES", "DEG", "MAX_SHEAR_ANGLE", "Change", "Chord", "ControlSurface", "Dihedral", "Flap",
    "LatticeFrame", "SectionLaw", "SectionMap", "Shape", "Shear", "Slat", "Span", "SpecContext", "Sweep",
    "Twist", "about", "apply_changes", "apply_homogeneous", "changes_from_spec", "design_bounds",
    "design_units", "design_variables", "homogeneous", "not_in_2d", "rotation", "rotation_derivative",
    "set_design_variables", "translation",
]
