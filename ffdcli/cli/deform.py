"""``ffd deform DESIGN.yaml``: apply the design's changes and write the deformed mesh."""

from __future__ import annotations

import click

from ffdcli.cli import cli, common_options


@cli.command("deform")
@click.argument("design_file", metavar="DESIGN.yaml", type=click.Path())
@click.option("--set", "overrides", multiple=True, metavar="KEY=VALUE",
              help="Override one value of the design file, e.g. --set changes.0.twist.tip=12 "
                   "(repeatable; the key path uses list positions).")
@click.option("--output", "-o", type=click.Path(), metavar="FILE",
              help="Write the deformed mesh here instead of the file's output.mesh; the lattice and the "
                   "picture are named after it (out/t5.su2 -> out/t5_lattice.vtk, out/t5.png) unless "
                   "--lattice is given.")
@click.option("--lattice", "lattice_out", type=click.Path(), metavar="FILE.vtk",
              help="Write the lattice here (a .vtk name) instead of the file's output.lattice.")
@click.option("--surface-file", "surface_file", type=click.Path(), metavar="FILE",
              help="Also write the deformed surface nodes as SU2's surface-positions file (DV_KIND= "
                   "SURFACE_FILE, DV_FILENAME= FILE), for SU2_DEF's own volume deformation. See docs/su2.md.")
@click.option("--plot", "plot", is_flag=True,
              help="Also write a PNG picture (original black, deformed red) at output.plot, else beside the "
                   "mesh, and for a 3D wing <picture>_3d.png, the 3D view (needs pyvista: the [viz] extra). "
                   "Without --plot no picture is drawn, whatever output.plot says.")
@click.option("--force", is_flag=True, help="Write the mesh even if the quality check fails.")
@click.option("--cache-dir", type=click.Path(file_okay=False), metavar="DIR",
              help="Where the caches live (default: beside the mesh).")
@click.option("--no-cache", is_flag=True,
              help="Neither read nor write the caches (the box's and the volume warp's).")
@common_options
def deform_cmd(design_file, overrides, output, lattice_out, surface_file, plot, force, cache_dir, no_cache,
               console):
    """Apply the changes of DESIGN.yaml to its mesh and write the deformed mesh and lattice.

    \b
    The box (lattice and embedding) is loaded from its cache, or built and cached. The changes
    (twist, span, sweep, dihedral, chord, shape, flap, slat) are applied in file order to the lattice; the wing
    surface follows exactly (X = X0 + B (P' - P0)), the rest of the mesh by inverse-distance
    warping (volume.method: idw) or not at all (none). Every cell and node is checked (the gate of
    `ffd check`, same words): if the design inverts a cell, makes one markedly worse (below 0.05,
    under half its quality and under 0.01 or the input's worst) or drops a node's orthogonality below 20
    degrees by more than 10, nothing is written and the exit status is 3; a cell already inverted or
    degenerate in the input mesh is exit 2 (--force writes anyway in both cases).

    \b
    Examples:
      ffd deform configs/rect_twist_linear.yaml
      ffd deform design.yaml --set changes.0.twist.tip=12 -o out/tip12.su2 --json
      ffd deform design.yaml --surface-file out/wing_surface.dat   # for SU2_DEF (DV_KIND= SURFACE_FILE)
      for t in 5 10 15; do ffd deform design.yaml --set changes.0.twist.tip=$t -o out/t$t.su2; done
    """
    from ffdcli.app.deform import deform_file
    from ffdcli.quality.gate import Remedies

    # the gate states its rule; the command line says which flag overrides it
    remedies = Remedies(list_cells=" (ffd check MESH lists such cells)",
                        deform_anyway=", or give --force to deform it anyway",
                        write_anyway=" (--force writes it anyway)", forced=" (--force)")
    report = deform_file(design_file, overrides, output=output, lattice=lattice_out, surface_file=surface_file,
                         plot=plot, force=force, cache_dir=cache_dir, use_cache=not no_cache, progress=console.progress,
                         comm=console.comm, constraints_table=_constraints_report, warn=console.warn,
                         remedies=remedies)
    console.result(report.summary, report.text)


def _constraints_report(*args, **kwargs):
    """:func:`ffdcli.api.constraints_report`, imported only for a design that has ``constraints:`` (the
    API's modules cost a third of a second of every ``ffd deform``'s start)."""
    from ffdcli.api import constraints_report

    return constraints_report(*args, **kwargs)
