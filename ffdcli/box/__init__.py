"""The automatic box: a lattice fitted to the wing (box), one read from a file (imported), the frame
the changes act in, the cache.
"""

from ffdcli.box.box import (  # the face: the names `ffdcli.box` offered before the packages
    MAX_REBUILDS,
    Box,
    assemble_box,
    fit_box,
    le_basis_rows,
    reference_weights,
    section_weights,
)

__all__ = [
    "MAX_REBUILDS",
    "Box",
    "assemble_box",
    "fit_box",
    "le_basis_rows",
    "reference_weights",
    "section_weights",
]
