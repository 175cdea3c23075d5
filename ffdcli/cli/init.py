"""``ffd init MESH``: write a commented starter design file for a mesh."""

from __future__ import annotations

import click

from ffdcli.cli import cli, common_options


@cli.command("init")
@click.argument("mesh", type=click.Path())
@click.option("--surface", "surfaces", multiple=True, metavar="NAME",
              help="Marker of the wing (repeat for several). Default: the only marker, or the one "
                   "that does not look like a domain boundary.")
@click.option("-o", "--output", type=click.Path(), metavar="DESIGN.yaml",
              help="Where to write the design file. Default: <mesh stem>.yaml beside the mesh.")
@click.option("--force", is_flag=True, help="Replace the design file if it exists.")
@common_options
def init_cmd(mesh, surfaces, output, force, console):
    """Write a starter design file for MESH: the detected wing surface, axes, root and a lattice
    size, the default volume settings, and every change kind commented out, each line explained.

    \b
    Unedited, `ffd deform` of it writes the input mesh back unchanged (into out/, which is created
    beside the design file). Then uncomment a change:
      ffd init wing.su2 -o wing.yaml
      $EDITOR wing.yaml                  # e.g. uncomment "- twist: {tip: 5}"
      ffd plot wing.yaml                 # look at it
      ffd deform wing.yaml               # out/wing.su2
    """
    from ffdcli.app.starter import init_design

    report = init_design(mesh, list(surfaces) or None, output=output, force=force, progress=console.progress)
    console.result(report.summary, report.text)
