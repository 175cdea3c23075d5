"""``ffd box MESH``: fit the automatic lattice to the wing, embed it, cache it, write it as VTK."""

from __future__ import annotations

import click

from ffdcli.cli import cli, common_options
from ffdcli.cli.params import FINITE


def int_list(ctx, param, value):
    """Click callback: ``"6,8,2"`` -> (6, 8, 2)."""
    if value is None:
        return None
    try:
        out = tuple(int(v) for v in value.replace("x", ",").split(",") if v.strip())
    except ValueError:
        raise click.BadParameter(
            f"expected integers separated by commas, like 6,8,2; got {value!r}") from None
    if not out:
        raise click.BadParameter("expected integers separated by commas, like 6,8,2")
    return out


@cli.command("box")
@click.argument("mesh", type=click.Path())
@click.option("--surface", "surfaces", multiple=True, metavar="NAME",
              help="Marker of the wing (repeat for several). Default: the only marker, or the one "
                   "named like wing/airfoil.")
@click.option("--points", callback=int_list, metavar="N,M,L",
              help="Control points chordwise, spanwise, thickness (2D: N,L). Default 6,8,2 (2D: 6,5).")
@click.option("--degree", callback=int_list, metavar="P,Q,R",
              help="B-spline degree per direction. Default min(3, points-1).")
@click.option("--sections", type=click.Choice(["xy", "xz", "yz", "yx", "zx", "zy"]),
              help="Plane of the airfoil sections, chord axis first (xy: chord x, thickness y, span z). "
                   "Default: detected (span = largest extent, thickness = smallest).")
@click.option("--root", type=click.Choice(["min", "max"]),
              help="End of the span axis where the root is. Default: the end nearer 0.")
@click.option("--margin", type=FINITE, metavar="F",
              help="Clearance around the wing as a fraction of the local chord. Default 0.02.")
@click.option("--lattice", "lattice_out", type=click.Path(), metavar="FILE",
              help="Where to write the lattice (VTK). Default: <mesh stem>_lattice.vtk beside the mesh.")
@click.option("--from", "from_file", type=click.Path(), metavar="FILE.xyz",
              help="Use this single-block Plot3D lattice (a pyGeo/DAFoam FFD file) instead of fitting one.")
@click.option("--export-plot3d", type=click.Path(), metavar="FILE.xyz",
              help="Also write the lattice as Plot3D in the layout pyGeo's DVGeometry reads.")
@click.option("--cache-dir", type=click.Path(file_okay=False), metavar="DIR",
              help="Keep the cache file here instead of beside the mesh.")
@click.option("--rebuild", is_flag=True, help="Ignore an existing cache file (and replace it).")
@common_options
def box_cmd(mesh, surfaces, points, degree, sections, root, margin, lattice_out, from_file,
            export_plot3d, cache_dir, rebuild, console):
    """Fit a B-spline lattice to the wing surface of MESH and embed the surface in it.

    \b
    MESH is a mesh (.su2, .cgns, .vtu, .vtk) or a design file (.yaml): then the mesh, surface and
    box settings come from the file, and options given here override them.

    \b
    The lattice has sections from the root to the tip of the wing, each a rectangle aligned with the
    local chord line, from just ahead of the leading edge to just behind the trailing edge and from
    below the lower to above the upper surface. Every surface point is embedded by Newton point
    inversion; where a point falls outside, the margin is grown there and the lattice rebuilt, so the
    summary should always say 0 outside. The result is cached beside the mesh for `ffd deform`.

    \b
    Examples:
      ffd box wing.su2
      ffd box wing.su2 --surface wing --points 8,10,2 --sections xz --json
      ffd box design.yaml --lattice out/lattice.vtk
    """
    from ffdcli.lattice.limits import check_lattice_size

    if points is not None:           # refused in a fraction of a second, before the heavy imports
        check_lattice_size(points, path=mesh, key="--points")

    from ffdcli.app.box import box_of

    report = box_of(mesh, surfaces=surfaces, options=dict(points=points, degree=degree, sections=sections, root=root,
                                                          margin=margin, file=from_file),
                    lattice_out=lattice_out, export_plot3d=export_plot3d, cache_dir=cache_dir, rebuild=rebuild,
                    progress=console.progress, comm=console.comm)
    for w in report.warnings:
        console.warn(w)
    for note in report.notes:
        console.detail(f"note: {note}")
    console.result(report.summary, report.text)
    report.check()
