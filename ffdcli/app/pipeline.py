"""One design end to end, under the names the commands and scripts have always imported.

The stages have their own modules: :mod:`ffdcli.app.prepare` (mesh -> surface -> box, cached),
:mod:`ffdcli.app.run` (:class:`DesignRun`, :func:`load_run`), :mod:`ffdcli.app.deformation` (changes ->
surface -> volume -> gate), :mod:`ffdcli.app.write` (the outputs together).
"""

from ffdcli.app.deformation import DESIGN_ZONE, Deformation, deform, design_map, volume_method
from ffdcli.app.prepare import (
                                PreparedBox,
                                check_sections_plane,
                                is_surface_mesh,
                                prepare_box,
                                read_lattice_block,
                                resolve_surface,
                                space_dim,
)
from ffdcli.app.run import DesignRun, load_run
from ffdcli.app.write import deform_writers, write_outputs
from ffdcli.volume.surface_motion import component_displacement, component_frames, frame_gradient_inputs, full3

__all__ = ["DESIGN_ZONE", "Deformation", "DesignRun", "PreparedBox", "check_sections_plane", "component_displacement",
           "component_frames", "deform", "deform_writers", "design_map", "frame_gradient_inputs", "full3",
           "is_surface_mesh", "load_run", "prepare_box", "read_lattice_block", "resolve_surface", "space_dim",
           "volume_method", "write_outputs"]
