"""``ffd plot DESIGN.yaml``: a PNG of the original (black) and deformed (red) wing with its lattice."""

from __future__ import annotations

import click

from ffdcli.cli import cli, common_options


@cli.command("plot")
@click.argument("design_file", metavar="DESIGN.yaml", type=click.Path())
@click.option("-o", "--output", type=click.Path(), metavar="FILE.png",
              help="Where to write the picture (default: output.plot, else beside output.mesh).")
@click.option("--set", "overrides", multiple=True, metavar="KEY=VALUE", help="As for ffd deform.")
@click.option("--3d/--no-3d", "view3d", default=True, show_default=True,
              help="Also write <FILE>_3d.png, a 3D view rendered off-screen with pyvista (3D designs; "
                   "skipped with a note when pyvista or an OpenGL backend is missing).")
@click.option("--target", type=click.Path(), metavar="AIRFOIL.dat",
              help="2D: also draw this airfoil (Selig/Lednicer .dat) on the mesh airfoil's chord line, "
                   "e.g. the target of `ffd fit`.")
@common_options
def plot_cmd(design_file, output, overrides, view3d, target, console):
    """Draw the design: planform, front view and root/mid/tip sections (2D: the airfoil), original
    surface in black, deformed in red, lattice points and edges. Headless (matplotlib Agg).

    \b
    The pictures: a planform (chord streamwise to the right, root at the bottom) and a front view
    as outlines (leading/trailing edge, root, tip, sections at the lattice stations), black over
    red; the change itself (thickness-wise displacement along the chord at root, mid and tip, in %
    of the local chord, so a 1 % change is plain); the root/mid/tip sections labelled by lattice
    section j and span fraction eta. When the quality gate would refuse the design (ffd deform would
    write nothing), the picture's title and a warning say so.

    \b
    Examples:
      ffd plot configs/rect_twist_linear.yaml -o out/twist.png
      ffd plot out/s1223.yaml --target samples/s1223.dat -o out/fit.png
    """
    from ffdcli.app.plot import plot_file

    report = plot_file(design_file, overrides, output=output, view3d=view3d, target=target, progress=console.progress)
    for w in report.warnings:
        console.warn(w)
    console.result(report.summary, report.text)
