"""``ffd inspect MESH``: what is in a mesh (markers, counts, bounds, detected axes, root side)."""

from __future__ import annotations

import click

from ffdcli.cli import cli, common_options


@cli.command("inspect")
@click.argument("mesh", type=click.Path(dir_okay=False))
@click.option("--surface", "surfaces", multiple=True, metavar="NAME",
              help="Marker(s) of the wing used to detect the axes (default: guessed, see below).")
@common_options
def inspect_cmd(mesh, surfaces, console):
    """Markers (element and point counts), bounds, dimension, detected axes and root side.

    The axes are detected from the wing surface: span = largest extent, thickness = smallest.
    Without --surface the wing is the only marker, or the only one whose name does not look like
    a domain boundary (far, farfield, sym, symmetry, inlet, outlet, inflow, outflow, freestream,
    box); when that is ambiguous the axes are not shown and the markers are listed.
    """
    summary, text = inspect_mesh(mesh, surfaces, progress=console.progress)
    console.result(summary, text)


def inspect_mesh(path, surfaces=(), progress=None) -> tuple[dict, str]:
    """The ``--json`` summary and the text report of a mesh file."""
    import numpy as np

    from ffdcli.axes import detect_axes
    from ffdcli.errors import InputError
    from ffdcli.extruded import one_cell_thick
    from ffdcli.formats import read_mesh
    from ffdcli.pipeline import is_surface_mesh, space_dim
    from ffdcli.surface import default_surface, extract_surface

    mesh = read_mesh(path, progress=progress)
    cells: dict[str, int] = {}
    for b in mesh.cells:
        cells[b.type] = cells.get(b.type, 0) + len(b)
    markers = {}
    for name, blocks in mesh.markers.items():
        ids = [b.data.ravel() for b in blocks]
        npts = len(np.unique(np.concatenate(ids))) if ids else 0
        markers[name] = {"elements": sum(len(b) for b in blocks), "points": npts,
                         "types": {b.type: len(b) for b in blocks}}
    if mesh.n_points:
        lo, hi = mesh.points.min(axis=0), mesh.points.max(axis=0)
        bounds = {"min": lo.tolist(), "max": hi.tolist()}
    else:
        bounds = None

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

    summary = {"file": str(mesh.path), "format": mesh.format, "dim": dim, "surface_mesh": surface_only,
               "warnings": warnings,
               "points": mesh.n_points, "cells": cells,
               "markers": {k: {"elements": v["elements"], "points": v["points"]}
                           for k, v in markers.items()},
               "bounds": bounds, "axes": axes.as_dict() if axes else None,
               "root": axes.root if axes else None, "surface": names}

    kind = f"{dim}D surface mesh (no volume cells)" if surface_only else f"{dim}D"
    lines = [f"{mesh.path}: {mesh.format.upper()}, {kind}, {mesh.n_points} points, "
             f"{mesh.n_cells} cells"]
    if cells:
        lines.append("  cells:   " + ", ".join(f"{n} {t}" for t, n in cells.items()))
    lines.append(f"  markers ({len(markers)}):" if markers else "  markers: none")
    width = max((len(k) for k in markers), default=0)
    for name, v in markers.items():
        kinds = ", ".join(f"{n} {t}" for t, n in v["types"].items()) or "no elements"
        lines.append(f"    {name:<{width}}  {v['elements']:>9} elements ({kinds}), {v['points']:>9} points")
    if bounds:
        lines.append("  bounds:  " + "  ".join(f"{a} {lo_:.6g} .. {hi_:.6g}" for a, lo_, hi_ in
                                              zip("xyz", bounds["min"], bounds["max"], strict=True)))
    if names is not None:
        lines.append(f"  surface: {', '.join(names)}")
    if axes is not None:
        ax = axes.as_dict()
        guess = " (a guess: extents are close; set box.sections to be sure)" if axes.guessed else ""
        if dim == 2:
            lines.append(f"  axes:    chord {ax['chord']}, thickness {ax['thickness']} "
                         f"(sections: {axes.sections}){guess}")
        else:
            lines.append(f"  axes:    chord {ax['chord']}, thickness {ax['thickness']}, span {ax['span']} "
                         f"(sections: {axes.sections}); root at {ax['span']} {axes.root}{guess}")
    elif note:
        lines.append(f"  surface: not detected: {note}")
    lines += [f"  warning: {w}" for w in warnings]
    return summary, "\n".join(lines)
