"""``ffd constraints``: the constraints of a design file (geometric, and the volume mesh's quality), and
their exact Jacobian."""

from __future__ import annotations

import click

from ffdcli.cli import cli, common_options


@cli.command("constraints")
@click.argument("design_file", metavar="DESIGN.yaml", type=click.Path())
@click.option("--set", "overrides", multiple=True, metavar="KEY=VALUE", help="As for ffd deform.")
@click.option("--jacobian", "jacobian_file", type=click.Path(), metavar="FILE.npz",
              help="Write the exact derivatives: arrays names (C), variables (V), values, lower, upper (C) "
                   "and jacobian (C x V).")
@click.option("--cache-dir", type=click.Path(file_okay=False), metavar="DIR", help="Where the box cache lives.")
@common_options
def constraints_cmd(design_file, overrides, jacobian_file, cache_dir, console):
    """Evaluate the constraints of DESIGN.yaml at its values: name, value, lower, upper, satisfied.

    \b
    Values are ratios to the undeformed surface (le_te: mesh units):
      constraints:
        - thickness: {chord: [0.1, 0.3, 0.5, 0.7, 0.9], span: [0.1, 0.5, 0.9], lower: 1.0}
        - thickness_to_chord: {chord: [0.3], span: [0.0, 0.5, 1.0], lower: 1.0}
        - volume: {lower: 1.0}       # a half wing is closed by its symmetry plane
        - le_te: {}                  # shape moves at the LE/TE: upper + lower = 0
        - fold_free: {lower: 0.2}    # smallest det of the lattice map / baseline (> 0: no fold)
        - mesh_quality: {lower: 0.3} # smooth min over the volume cells of quality after / before
    Items are named k<index>.<kind>[<j>] (a grid runs over chord fastest). Exit 0 whether or not
    they are satisfied (see the satisfied column, or --json).

    \b
    Examples:
      ffd constraints design.yaml
      ffd constraints design.yaml --set changes.0.chord.tip=0.8 --json
      ffd constraints design.yaml --jacobian dcdv.npz
    """
    from ffdcli.api.commands import run_constraints

    report = run_constraints(design_file, overrides, jacobian_file=jacobian_file, cache_dir=cache_dir,
                             progress=console.progress, comm=console.comm)
    console.result(report.summary, report.text)
