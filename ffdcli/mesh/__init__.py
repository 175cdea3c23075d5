"""The mesh as ffd holds it: points, interior cells and markers (model), id sets, the Morton order."""

from ffdcli.mesh.model import (  # the face: the names `ffdcli.mesh` offered before the packages
    CELL_DIM,
    CELL_NODES,
    VTK_ID,
    VTK_TYPE,
    CellBlock,
    Mesh,
    check_markers,
    diagonal,
)

__all__ = [
    "CELL_DIM",
    "CELL_NODES",
    "VTK_ID",
    "VTK_TYPE",
    "CellBlock",
    "Mesh",
    "check_markers",
    "diagonal",
]
