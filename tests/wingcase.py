"""Small wing meshes and design files built in the tests (no bundled file needed)."""

from __future__ import annotations

from pathlib import Path

import yaml

from ffdcli.io.formats import write_mesh
from ffdcli.testing.wings import Planform, extruded_wing_mesh, surface_mesh


def write_surface_wing(tmp: Path, name: str = "wing.su2", **planform) -> Path:
    """A surface-only wing (marker ``wing``) written as SU2; returns its path."""
    mesh = surface_mesh(Planform(**planform), n_chord=31, n_span=13)
    path = tmp / name
    write_mesh(mesh, path)
    return path


def write_volume_wing(tmp: Path, name: str = "vwing.su2", **planform) -> Path:
    """A small hexahedral volume mesh around a wing (markers wing/farfield/symmetry/side)."""
    mesh = extruded_wing_mesh(Planform(**planform), n_around=41, n_radial=9, n_span=6)
    path = tmp / name
    write_mesh(mesh, path)
    return path


def write_design(tmp: Path, mesh: Path, changes: list, *, name: str = "design.yaml", points=(6, 8, 2),
                 volume: dict | None = None, sections: str | None = None, extra: dict | None = None) -> Path:
    data = {"mesh": mesh.name, "surface": "wing", "box": {"points": list(points)}, "changes": changes,
            "output": {"mesh": f"out_{Path(name).stem}{mesh.suffix}",
                       "lattice": f"out_{Path(name).stem}_lattice.vtk"}}
    if sections:
        data["box"]["sections"] = sections
    if volume is not None:
        data["volume"] = volume
    if extra:
        data.update(extra)
    path = tmp / name
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path
