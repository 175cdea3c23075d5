"""``ffd fit DESIGN.yaml --target AIRFOIL.dat``: shape values that morph the airfoil into a target."""

from __future__ import annotations

from pathlib import Path

import click

from ffdcli.cli import cli, common_options


@cli.command("fit")
@click.argument("design_file", metavar="DESIGN.yaml", type=click.Path(dir_okay=False))
@click.option("--target", required=True, type=click.Path(dir_okay=False), metavar="AIRFOIL.dat",
              help="Target airfoil, Selig or Lednicer format (detected).")
@click.option("-o", "--output", type=click.Path(dir_okay=False), metavar="FITTED.yaml",
              help="Write the design file with the fitted shape (default: <design>_fitted.yaml).")
@click.option("--set", "overrides", multiple=True, metavar="KEY=VALUE",
              help="Override a value of the design file, e.g. --set box.points=[12,5].")
@click.option("--rows", type=click.Choice(["all", "edge"]), default="all", show_default=True,
              help="all: move every thickness row of the lattice (shape: {rows: ...}); edge: only the "
                   "upper and lower rows (shape: {upper, lower}), as in the paper, a much looser fit.")
@common_options
def fit_cmd(design_file, target, output, overrides, rows, console):
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

    out = Path(output) if output else Path(design_file).with_name(Path(design_file).stem + "_fitted.yaml")
    rep = fit_design(design_file, target, out, overrides=overrides, rows=rows, progress=console.progress)
    b, a = rep["before"], rep["after"]
    console.result(rep, "\n".join([
        f"ffd fit: {Path(design_file).name} -> {Path(target).name} ({rep['name']}), lattice "
        f"{' x '.join(map(str, rep['lattice']))}, {rep['points']} surface points",
        f"  before    max {b['max']:.5f}, rms {b['rms']:.5f} chords",
        f"  after     max {a['max']:.5f}, rms {a['rms']:.5f} chords",
        f"  wrote     {rep['output']}",
    ]))
