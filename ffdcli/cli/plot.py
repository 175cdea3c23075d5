"""``ffd plot DESIGN.yaml``: a PNG of the original (black) and deformed (red) wing with its lattice."""

from __future__ import annotations

from pathlib import Path

import click

from ffdcli.cli import cli, common_options


@cli.command("plot")
@click.argument("design_file", metavar="DESIGN.yaml", type=click.Path(dir_okay=False))
@click.option("-o", "--output", type=click.Path(dir_okay=False), metavar="FILE.png",
              help="Where to write the picture (default: output.plot, else beside output.mesh).")
@click.option("--set", "overrides", multiple=True, metavar="KEY=VALUE", help="As for ffd deform.")
@click.option("--3d/--no-3d", "view3d", default=True, show_default=True,
              help="Also write <FILE>_3d.png, a 3D view rendered off-screen with pyvista (3D designs; "
                   "skipped with a note when pyvista or an OpenGL backend is missing).")
@common_options
def plot_cmd(design_file, output, overrides, view3d, console):
    """Draw the design: planform, front view and root/mid/tip sections (2D: the airfoil), original
    surface in black, deformed in red, lattice points and edges. Headless (matplotlib Agg).

    \b
    Example:
      ffd plot configs/rect_twist_linear.yaml -o out/twist.png
    """
    from ffdcli.atomic import check_writable
    from ffdcli.design import load_design
    from ffdcli.pipeline import deform, load_run
    from ffdcli.plot import plot_design

    design = load_design(design_file, overrides=overrides)
    png = Path(output or design.output.get("plot") or Path(design.output["mesh"]).with_suffix(".png"))
    check_writable(png, inputs=(design.mesh, design.path))
    if png.suffix.lower() != ".png":
        from ffdcli.errors import InputError

        raise InputError("pictures are written as PNG: give the file a .png name", path=png)
    run = load_run(design, progress=console.progress)
    result = deform(run, progress=console.progress)
    plot_design(run, result, png)
    written = [str(png)]
    if view3d and run.box.dim == 3:
        from ffdcli.plot import plot_3d

        got = plot_3d(run, result, png.with_name(png.stem + "_3d.png"))
        if got is None:
            console.warn("no 3D view: pyvista or an off-screen OpenGL backend is missing "
                         "(pip install 'ffdcli[viz]'); the 2D views are written")
        else:
            written.append(str(got))
    console.result({"plot": str(png), "plots": written, "max_displacement": result.max_displacement},
                   "ffd plot: wrote " + ", ".join(written))
