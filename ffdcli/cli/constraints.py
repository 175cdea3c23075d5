"""``ffd constraints``: the constraints of a design file (geometric, and the volume mesh's quality), and
their exact Jacobian."""

from __future__ import annotations

import click

from ffdcli.cli import cli, common_options
from ffdcli.cli.console import bound_text


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
    import numpy as np

    from ffdcli.api import DesignModel
    from ffdcli.app.run import load_run
    from ffdcli.design import load_design
    from ffdcli.io.outputs import plan_outputs

    design = load_design(design_file, overrides=overrides)
    plan = plan_outputs([("jacobian", jacobian_file, False, "--jacobian")], inputs=(design.mesh, design.path))
    model = DesignModel(load_run(design, cache_dir=cache_dir, progress=console.progress, comm=console.comm),
                        comm=console.comm)
    if jacobian_file:
        arrays = model.constraint_jacobian_arrays()

        def write(tmp):
            with open(tmp, "wb") as fh:
                np.savez(fh, **arrays)

        console.comm.root_then_bcast(plan.write, {"jacobian": write})        # once: rank 0 of an MPI run
    rows = model.constraints_table()
    width = max([len(r["name"]) for r in rows] + [10])
    lines = [f"{'constraint':<{width}}  {'value':>12}  {'lower':>10}  {'upper':>10}  satisfied"]
    lines += [f"{r['name']:<{width}}  {r['value']:>12.8g}  {bound_text(r['lower']):>10}  {bound_text(r['upper']):>10}  "
              f"{'yes' if r['satisfied'] else 'NO'}" for r in rows]
    if not rows:
        lines.append("(the design file has no constraints:)")
    if jacobian_file:
        lines.append(f"jacobian ({len(rows)} x {model.n_vars}) written to {jacobian_file}")
    summary = {"constraints": rows, "variables": model.variables_table()}
    if jacobian_file:
        summary["jacobian"] = str(jacobian_file)
    console.result(summary, "\n".join(lines))
