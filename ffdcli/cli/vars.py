"""``ffd vars``: the design variables of a design file with their values, units and bounds."""

from __future__ import annotations

import click

from ffdcli.cli import cli, common_options


@cli.command("vars")
@click.argument("design_file", metavar="DESIGN.yaml", type=click.Path())
@click.option("--set", "overrides", multiple=True, metavar="KEY=VALUE", help="As for ffd deform.")
@click.option("--cache-dir", type=click.Path(file_okay=False), metavar="DIR", help="Where the box cache lives.")
@common_options
def vars_cmd(design_file, overrides, cache_dir, console):
    """The design variables of DESIGN.yaml: name, value, unit, lower and upper bound.

    \b
    Every number in changes: is a variable, named c<change index>.<kind>[<position>] (as ffd grad
    and --jacobian name them). Units: deg (angles), factor (span and chord), length (mesh units:
    offsets and shape moves). Natural bounds are open: a span or chord factor must be > 0, a sweep
    or dihedral angle must keep the leading-edge line within 85 degrees of the span axis. The
    design file's bounds: map narrows them (closed), by name or by the start of names:
      bounds: {c0.twist: [-10, 10], c1.span: {lower: 0.8, upper: 1.2}, c3.shape.upper[2]: [null, 0.05]}
    '-' means no bound.

    \b
    Examples:
      ffd vars design.yaml
      ffd vars design.yaml --json | jq '.variables[] | select(.unit == "deg")'
    """
    from ffdcli.api.commands import run_vars

    report = run_vars(design_file, overrides, cache_dir=cache_dir, progress=console.progress)
    console.result(report.summary, report.text)
