"""``ffd check MESH``: the cell-quality check of ``ffd deform`` on any mesh."""

from __future__ import annotations

import click

from ffdcli.cli import cli, common_options
from ffdcli.cli.params import FINITE


@cli.command("check")
@click.argument("mesh", type=click.Path())
@click.option("--threshold", type=FINITE, default=None, metavar="Q",
              help="Also fail when a cell's scaled Jacobian is below Q (default: only inverted or "
                   "degenerate cells fail; cells below 0.05 are counted).")
@click.option("--worst", "n_worst", type=click.IntRange(0, None), default=5, show_default=True,
              help="How many of the worst cells to list.")
@common_options
def check_cmd(mesh, threshold, n_worst, console):
    """Cell quality of MESH: scaled Jacobian of every cell and SU2's orthogonality of every node.

    \b
    Prints, in the words of `ffd deform`'s summary: the number of cells, the minimum scaled
    Jacobian (1 ideal, <= 0 inverted or degenerate), the cells inverted or degenerate and those
    below 0.05, the minimum orthogonality (degrees; SU2's dual-grid measure, 90 ideal) and the nodes
    below 20 degrees, and where the worst are. `ffd check` of a mesh written by `ffd deform` repeats
    the "after" numbers of that deform. Exit status 3 when a cell is inverted or degenerate (or
    below --threshold when given), 0 otherwise.

    \b
    Examples:
      ffd check out/wing_twist.su2
      ffd check mesh.su2 --threshold 0.01 --worst 10 --json
    """
    from ffdcli.app.check import check_mesh
    from ffdcli.errors import InputError

    if threshold is not None and not (-1.0 <= threshold <= 1.0):
        raise InputError(f"expected a scaled Jacobian in [-1, 1], got {threshold}", key="--threshold")
    got = check_mesh(mesh, threshold=threshold, n_worst=n_worst, progress=console.progress, comm=console.comm)
    console.result(got.summary, got.text)
