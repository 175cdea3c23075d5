"""Cell and node quality of a mesh and the gate that refuses a design that spoils it.

:mod:`~ffdcli.quality.metrics` (the scaled Jacobian of every cell), :mod:`~ffdcli.quality.orthogonality`
(SU2's node orthogonality), :mod:`~ffdcli.quality.reference` (what the gate needs of the input mesh),
:mod:`~ffdcli.quality.rules` (the rules on cells and nodes) and :mod:`~ffdcli.quality.gate` (the
report, the gate on the parts of a mesh, a whole mesh its one-part case, and :func:`enforce`).
"""

from ffdcli.quality.gate import QualityReport, Remedies, check_quality, check_quality_part, enforce
from ffdcli.quality.metrics import CHUNK, Orientation, cell_orientation, cell_quality
from ffdcli.quality.orthogonality import (
    EdgeTopology,
    edge_normals,
    edge_orthogonality,
    edge_topology,
    node_orthogonality,
)
from ffdcli.quality.reference import PartReference, QualityReference, part_reference, quality_reference
from ffdcli.quality.rules import (
    DEFAULT_COLLAPSE,
    DEFAULT_ORTHO_LOSS,
    DEFAULT_ORTHO_MIN,
    DEFAULT_RELATIVE,
    DEFAULT_THRESHOLD,
    DESIGN_SLACK,
    DESIGN_SLACK_DEG,
    cell_rule,
    collapse_floor,
    node_rule,
    nodes_shaped_by_design,
    shaped_by_design,
)

__all__ = [
    "CHUNK",
    "DEFAULT_COLLAPSE",
    "DEFAULT_ORTHO_LOSS",
    "DEFAULT_ORTHO_MIN",
    "DEFAULT_RELATIVE",
    "DEFAULT_THRESHOLD",
    "DESIGN_SLACK",
    "DESIGN_SLACK_DEG",
    "EdgeTopology",
    "Orientation",
    "PartReference",
    "QualityReference",
    "QualityReport",
    "Remedies",
    "cell_orientation",
    "cell_quality",
    "cell_rule",
    "check_quality",
    "check_quality_part",
    "collapse_floor",
    "edge_normals",
    "edge_orthogonality",
    "edge_topology",
    "enforce",
    "node_orthogonality",
    "node_rule",
    "nodes_shaped_by_design",
    "part_reference",
    "quality_reference",
    "shaped_by_design",
]
