"""What is in a mesh: markers (element and point counts), bounds, the box's dimension, the detected
wing surface, axes and root side. ``ffd inspect`` prints it; a script gets the same value.

>>> info = inspect_mesh("wing.su2")
>>> info.axes.span, info.surface
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ffdcli.app.prepare import is_surface_mesh, space_dim
from ffdcli.errors import InputError
from ffdcli.geometry.axes import Axes, detect_axes
from ffdcli.geometry.surface import default_surface, extract_surface
from ffdcli.io.formats import read_mesh
from ffdcli.mesh import Mesh
from ffdcli.mesh.idsets import unique_ids
from ffdcli.parameterization.components import root_contact
from ffdcli.volume.extruded import one_cell_thick


@dataclass(frozen=True)
class MarkerInfo:
    """One marker: its element count, its distinct point count and elements per cell type."""

    elements: int
    points: int
    types: dict[str, int]


@dataclass(frozen=True)
class MeshInfo:
    """What :func:`inspect_mesh` found in a mesh.

    dim
        The box's dimension (3 for a wing, also for a 3D surface mesh; 2 for a planar mesh).
    surface_mesh
        A 3D mesh of surface cells only (nothing to warp, no cells to gate).
    cells
        {cell type: count} of the interior cells.
    bounds
        (min (3,), max (3,)) of the points, None for no points.
    surface, axes
        The wing marker(s) (given, or found by the default rule) and the axes detected on them;
        None when there is no wing surface to detect (then ``note`` says why).
    warnings
        Things the user should know (a one-cell-thick extruded airfoil).
    """

    path: Path | None
    format: str
    dim: int
    surface_mesh: bool
    points: int
    n_cells: int
    cells: dict[str, int]
    markers: dict[str, MarkerInfo]
    bounds: tuple[np.ndarray, np.ndarray] | None
    surface: list[str] | None
    axes: Axes | None
    note: str = ""
    warnings: tuple[str, ...] = field(default_factory=tuple)
    root_on: tuple[str, int] | None = None      # (body marker, shared nodes) when the root meets a body

    def summary(self) -> dict:
        """The ``ffd inspect --json`` object."""
        return {"file": str(self.path), "format": self.format, "dim": self.dim,
                "surface_mesh": self.surface_mesh, "warnings": list(self.warnings),
                "points": self.points, "cells": dict(self.cells),
                "markers": {k: {"elements": v.elements, "points": v.points} for k, v in self.markers.items()},
                "bounds": None if self.bounds is None else {"min": self.bounds[0].tolist(),
                                                            "max": self.bounds[1].tolist()},
                "axes": self.axes.as_dict() if self.axes else None,
                "root": self.axes.root if self.axes else None, "surface": self.surface,
                "root_on": self.root_on[0] if self.root_on else None}

    def text(self) -> str:
        """The ``ffd inspect`` report, one line per item."""
        kind = f"{self.dim}D surface mesh (no volume cells)" if self.surface_mesh else f"{self.dim}D"
        lines = [f"{self.path}: {self.format.upper()}, {kind}, {self.points} points, {self.n_cells} cells"]
        if self.cells:
            lines.append("  cells:   " + ", ".join(f"{n} {t}" for t, n in self.cells.items()))
        lines.append(f"  markers ({len(self.markers)}):" if self.markers else "  markers: none")
        width = max((len(k) for k in self.markers), default=0)
        for name, v in self.markers.items():
            kinds = ", ".join(f"{n} {t}" for t, n in v.types.items()) or "no elements"
            lines.append(f"    {name:<{width}}  {v.elements:>9} elements ({kinds}), {v.points:>9} points")
        if self.bounds is not None:
            lines.append("  bounds:  " + "  ".join(f"{a} {lo_:.6g} .. {hi_:.6g}" for a, lo_, hi_ in
                                                  zip("xyz", *self.bounds, strict=True)))
        if self.surface is not None:
            lines.append(f"  surface: {', '.join(self.surface)}")
        axes = self.axes
        if axes is not None:
            ax = axes.as_dict()
            guess = " (a guess: extents are close; set box.sections to be sure)" if axes.guessed else ""
            if self.dim == 2:
                lines.append(f"  axes:    chord {ax['chord']}, thickness {ax['thickness']} "
                             f"(sections: {axes.sections}){guess}")
            else:
                lines.append(f"  axes:    chord {ax['chord']}, thickness {ax['thickness']}, span {ax['span']} "
                             f"(sections: {axes.sections}); root at {ax['span']} {axes.root}{guess}")
            if self.root_on is not None:
                lines.append(f"  root:    on the body {self.root_on[0]!r} ({self.root_on[1]} shared nodes): they and "
                             "the body do not move; the lattice sections at the junction stay fixed")
        elif self.note:
            lines.append(f"  surface: not detected: {self.note}")
        lines += [f"  warning: {w}" for w in self.warnings]
        return "\n".join(lines)

    def report(self) -> tuple[dict, str]:
        """(:meth:`summary`, :meth:`text`)."""
        return self.summary(), self.text()


def inspect_mesh(mesh: Mesh | str | Path, surfaces=(), progress=None) -> MeshInfo:
    """Inspect a mesh (a :class:`Mesh` or a file, read with ``progress``).

    ``surfaces``: the wing marker(s); unknown names are an :class:`InputError`. Without them the
    default rule of :func:`ffdcli.geometry.surface.default_surface` picks the wing, and when it cannot, the
    axes are left out and ``note`` says why (not an error: inspecting is how a user finds out).
    """
    if not isinstance(mesh, Mesh):
        mesh = read_mesh(mesh, progress=progress)
    cells: dict[str, int] = {}
    for b in mesh.cells:
        cells[b.type] = cells.get(b.type, 0) + len(b)
    if mesh.polyhedra is not None:         # polyhedral cells by shape, as checkMesh's table
        cells.update({k: v for k, v in mesh.polyhedra.shape_counts().items() if v})
    markers = {}
    for name, blocks in mesh.markers.items():
        ids = [b.data.ravel() for b in blocks]
        markers[name] = MarkerInfo(elements=sum(len(b) for b in blocks),
                                   points=len(unique_ids(*ids)) if ids else 0,
                                   types={b.type: len(b) for b in blocks})
    bounds = (mesh.points.min(axis=0), mesh.points.max(axis=0)) if mesh.n_points else None

    note = ""
    if surfaces:
        names = list(surfaces)
        surf = extract_surface(mesh, names)           # unknown names: InputError (exit 2)
    else:
        try:
            names = default_surface(mesh)
            surf = extract_surface(mesh, names)
        except InputError as e:
            names, surf, note = None, None, e.message + (f" ({e.hint})" if e.hint else "")
    axes = None
    dim = space_dim(mesh) if mesh.n_points else mesh.dim      # the box's dimension (ffd box uses it)
    surface_only = bool(mesh.n_points) and dim == 3 and (not mesh.n_cells or is_surface_mesh(mesh))
    warnings = []
    if surf is not None and surf.n_points:
        axes = detect_axes(surf.points, dim, path=mesh.path, faces=surf.faces)
        extrusion = one_cell_thick(mesh, names)
        if extrusion is not None:
            warnings.append(extrusion.message())
    contact = None
    if axes is not None and dim == 3:
        found = root_contact(mesh, surf.ids, axes.span, skip=names)
        contact = None if found is None else (found[0], len(found[1]))
    return MeshInfo(path=mesh.path, format=mesh.format, dim=dim, surface_mesh=surface_only,
                    points=mesh.n_points, n_cells=mesh.n_cells, cells=cells, markers=markers, bounds=bounds,
                    surface=names, axes=axes, note=note, warnings=tuple(warnings), root_on=contact)
