"""``ffd plot DESIGN.yaml``: a PNG of the original (black) and deformed (red) wing with its lattice."""

from __future__ import annotations

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
@click.option("--target", type=click.Path(dir_okay=False), metavar="AIRFOIL.dat",
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
    from ffdcli.app.pipeline import deform, deform_writers, load_run
    from ffdcli.design import load_design
    from ffdcli.io.outputs import plan_plot

    design = load_design(design_file, overrides=overrides)
    plan = plan_plot(design, output, view3d=view3d)       # checked before the work
    coords = None
    if target is not None:
        from ffdcli.io.formats.airfoil import read_airfoil

        coords = read_airfoil(target).coords
    run = load_run(design, progress=console.progress)
    result = deform(run, progress=console.progress)
    q = result.quality
    if q is not None and not q.ok:
        console.warn(f"the quality gate would refuse this design (ffd deform writes nothing without "
                     f"--force): {q.summary()}")
    writers = {k: w for k, w in deform_writers(run, result, target=coords).items() if k in plan}
    written = plan.write(writers)
    if "plot_3d" in plan and "plot_3d" not in written and run.box.dim == 3:
        console.warn("no 3D view: pyvista or an off-screen OpenGL backend is missing "
                     "(pip install 'ffdcli[viz]'); the 2D views are written")
    png = written["plot"]
    console.result({"plot": png, "plots": list(written.values()), "max_displacement": result.max_displacement,
                    "refused": bool(q is not None and not q.ok),
                    "quality": q.to_dict() if q is not None else None},
                   "ffd plot: wrote " + ", ".join(written.values()))
