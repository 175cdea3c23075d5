"""``ffd grad`` and ``ffd jacobian``: derivatives of the mesh with respect to the design variables."""

from __future__ import annotations

import click

from ffdcli.cli import cli, common_options
from ffdcli.cli.params import FiniteFloat


@cli.command("grad")
@click.argument("design_file", metavar="DESIGN.yaml", type=click.Path())
@click.option("--sens", required=True, type=click.Path(), metavar="FILE",
              help="dJ/dX at mesh nodes: SU2 surface_sens.csv / volume_sens.csv, or rows x y z dJ/dx dJ/dy dJ/dz.")
@click.option("-o", "--output", type=click.Path(), metavar="GRAD.json",
              help="Write {variable: dJ/dv} here (JSON) as well as printing it.")
@click.option("--set", "overrides", multiple=True, metavar="KEY=VALUE", help="As for ffd deform.")
@click.option("--cache-dir", type=click.Path(file_okay=False), metavar="DIR", help="Where the box cache lives.")
@click.option("--tolerance", type=FiniteFloat(min=0.0), metavar="DIST",
              help="How far (mesh units) the file's coordinates may stand from the mesh nodes "
                   "(default 1e-6 of the mesh diagonal); farther, the file is refused.")
@common_options
def grad_cmd(design_file, sens, output, overrides, cache_dir, tolerance, console):
    """dJ/d(design variable) for every design variable of DESIGN.yaml, by the chain rule.

    \b
    The sensitivity file gives dJ/dX at the nodes of the deformed mesh (as ffd deform writes it).
    Surface nodes: dJ/dv = (dX/dv)^T dJ/dX with dX/dv = B dP/dv in closed form. When the file also
    covers volume nodes and the design uses volume.method: idw, their sensitivity is pulled back
    through the volume-mesh motion (its exact transpose). Units: per degree for angles, per unit
    for factors, per mesh length for offsets and shape values.

    \b
    Variable names: c<change index>.<kind>[<position>], e.g. c0.twist[7], c1.span, c2.twist.tip.

    \b
    Example:
      ffd grad design.yaml --sens surface_sens.csv -o grad.json
    """
    from ffdcli.api.commands import run_grad

    report = run_grad(design_file, sens, overrides, output=output, cache_dir=cache_dir, tol=tolerance,
                      progress=console.progress, comm=console.comm)
    console.result(report.summary, report.text)


@cli.command("jacobian")
@click.argument("design_file", metavar="DESIGN.yaml", type=click.Path())
@click.option("-o", "--output", required=True, type=click.Path(), metavar="JAC.npz",
              help="Where to write the Jacobian factors (NumPy .npz).")
@click.option("--dense", is_flag=True, help="Also store the dense dX/dv (3 S x n_vars; large for big meshes).")
@click.option("--set", "overrides", multiple=True, metavar="KEY=VALUE", help="As for ffd deform.")
@common_options
def jacobian_cmd(design_file, output, dense, overrides, console):
    """Write dX/dv of the surface points for every design variable, for users who chain it themselves.

    \b
    The file (NumPy .npz) holds the exact factors dX/dv = B @ D:
      names        (n_vars,) design-variable names      point_ids  (S,) 0-based mesh node ids
      B_data, B_indices, B_indptr, B_shape   the sparse (S, n_ctrl) basis matrix (CSR)
      D            (n_ctrl*3, n_vars) dP/dv, rows point-major (x, y, z of control point 0, ...)
      values       (n_vars,) the design's values       points  (S, 3) the deformed surface
    so that (B @ D.reshape(n_ctrl, 3*n_vars)).reshape(S*3, n_vars) is dX/dv, rows point-major.
    With --dense, J (S*3, n_vars) too.

    \b
    Example:
      ffd jacobian design.yaml -o jac.npz
    """
    from ffdcli.api.commands import run_jacobian

    report = run_jacobian(design_file, output, overrides, dense=dense, progress=console.progress,
                          comm=console.comm)
    console.result(report.summary, report.text)
