"""Constraints on the design with exact Jacobians, one module per kind (pyGeo's layout).

:mod:`~ffdcli.constraints.base` (the protocol, what a constraint reads, the evaluation of a list),
:mod:`~ffdcli.constraints.build` (from the design file's ``constraints:``) and the kinds:
:mod:`~ffdcli.constraints.thickness` (thickness, thickness_to_chord), :mod:`~ffdcli.constraints.volume`,
:mod:`~ffdcli.constraints.le_te`, :mod:`~ffdcli.constraints.fold_free`, :mod:`~ffdcli.constraints.mesh_quality`.
Each kind registers itself in :data:`CONSTRAINTS` at the end of its module; this face imports them all.
"""

from ffdcli.constraints.add_material import AddMaterial  # noqa: F401  (registers its kind)
from ffdcli.constraints.base import (
    CONSTRAINTS,
    SATISFIED_TOL,
    Constraint,
    ConstraintContext,
    ConstraintInputs,
    constraint_bounds,
    constraint_names,
    evaluate,
    item_schema,
    satisfied,
    surface_segments,
    surface_triangles,
)
from ffdcli.constraints.build import build_constraints
from ffdcli.constraints.fold_free import FOLD_SAMPLES, FoldFree
from ffdcli.constraints.le_te import LeTe
from ffdcli.constraints.mesh_quality import KS_GAP, MESH_QUALITY_GOOD, MESH_QUALITY_LOWER, MeshQuality, ks_min
from ffdcli.constraints.thickness import END_INSET, Thickness, ThicknessToChord, chord_lines, project_thickness
from ffdcli.constraints.volume import Volume, enclosed_volume

__all__ = [
    "CONSTRAINTS",
    "END_INSET",
    "FOLD_SAMPLES",
    "KS_GAP",
    "MESH_QUALITY_GOOD",
    "MESH_QUALITY_LOWER",
    "SATISFIED_TOL",
    "Constraint",
    "ConstraintContext",
    "ConstraintInputs",
    "FoldFree",
    "LeTe",
    "MeshQuality",
    "Thickness",
    "ThicknessToChord",
    "Volume",
    "build_constraints",
    "chord_lines",
    "constraint_bounds",
    "constraint_names",
    "enclosed_volume",
    "evaluate",
    "item_schema",
    "ks_min",
    "project_thickness",
    "satisfied",
    "surface_segments",
    "surface_triangles",
]
