"""``ffd init MESH``: write a commented starter design file for a mesh."""

from __future__ import annotations

from pathlib import Path

import click

from ffdcli.cli import cli, common_options


@cli.command("init")
@click.argument("mesh", type=click.Path())
@click.option("--surface", "surfaces", multiple=True, metavar="NAME",
              help="Marker of the wing (repeat for several). Default: the only marker, or the one "
                   "that does not look like a domain boundary.")
@click.option("-o", "--output", type=click.Path(dir_okay=False), metavar="DESIGN.yaml",
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
    from ffdcli.app.starter import default_design_path, starter_design
    from ffdcli.errors import InputError
    from ffdcli.io.atomic import atomic_write, check_writable

    out = Path(output) if output else default_design_path(mesh)
    if out.suffix.lower() not in (".yaml", ".yml"):
        raise InputError("a design file is YAML: give it a .yaml name", path=out)
    check_writable(out, inputs=(mesh,))
    if out.exists() and not force:
        raise InputError("the design file exists; pass --force to replace it, or -o another name",
                         path=out)
    text = starter_design(mesh, list(surfaces) or None, design_path=out, progress=console.progress)
    with atomic_write(out, "w") as fh:
        fh.write(text)
    (out.parent / "out").mkdir(exist_ok=True)        # where its outputs go (output: out/...)
    console.result({"design": str(out), "mesh": str(mesh)},
                   f"ffd init: wrote {out}\n  next: uncomment a change in it, then `ffd plot {out}` "
                   f"and `ffd deform {out}`")
