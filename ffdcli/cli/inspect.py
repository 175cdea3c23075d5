"""``ffd inspect MESH``: what is in a mesh (markers, counts, bounds, detected axes, root side)."""

from __future__ import annotations

import click

from ffdcli.cli import cli, common_options


@cli.command("inspect")
@click.argument("mesh", type=click.Path())
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
    from ffdcli.app.inspection import inspect_mesh

    info = inspect_mesh(mesh, surfaces, progress=console.progress)
    console.result(info.summary(), info.text())
