"""``ffd fit DESIGN.yaml --target AIRFOIL.dat``: shape values that morph the airfoil into a target."""

from __future__ import annotations

import click

from ffdcli.cli import cli, common_options


@cli.command("fit")
@click.argument("design_file", metavar="DESIGN.yaml", type=click.Path())
@click.option("--target", required=True, type=click.Path(), metavar="AIRFOIL.dat",
              help="Target airfoil, Selig or Lednicer format (detected).")
@click.option("-o", "--output", type=click.Path(), metavar="FITTED.yaml",
              help="Write the design file with the fitted shape (default: <design>_fitted.yaml).")
@click.option("--force", is_flag=True, help="Replace the output design file if it exists.")
@click.option("--set", "overrides", multiple=True, metavar="KEY=VALUE",
              help="Override a value of the design file, e.g. --set box.points=[12,5].")
@click.option("--rows", type=click.Choice(["all", "edge"]), default="all", show_default=True,
              help="all: move every thickness row of the lattice (shape: {rows: ...}); edge: only the "
                   "upper and lower rows (shape: {upper, lower}), as in the paper, a much looser fit.")
@common_options
def fit_cmd(design_file, target, output, force, overrides, rows, console):
    """Find the `shape` values of a 2D design (thickness-wise moves of the lattice rows) that make its
    airfoil best match TARGET, by regularised linear least squares, and write them as a design file.

    \b
    The target is placed on the mesh airfoil's chord line (same leading and trailing edge); the
    deviation is measured across the chord at each surface point and reported in chord units,
    before and after. `ffd deform FITTED.yaml` then writes the morphed airfoil mesh.

    \b
    Example:
      ffd fit configs/naca0012_s1223.yaml --target samples/s1223.dat -o out/s1223.yaml
      ffd deform out/s1223.yaml
    """
    from ffdcli.app.fit import fit_design

    report = fit_design(design_file, target, output, overrides=overrides, rows=rows, force=force,
                        default_output=True, progress=console.progress)
    console.result(report.summary, report.text)
