"""``ffd grad`` and ``ffd jacobian``: derivatives of the mesh with respect to the design variables."""

from __future__ import annotations

import json
import time
from pathlib import Path

import click

from ffdcli.cli import cli, common_options


@cli.command("grad")
@click.argument("design_file", metavar="DESIGN.yaml", type=click.Path(dir_okay=False))
@click.option("--sens", required=True, type=click.Path(dir_okay=False), metavar="FILE",
              help="dJ/dX at mesh nodes: SU2 surface_sens.csv / volume_sens.csv, or rows x y z dJ/dx dJ/dy dJ/dz.")
@click.option("-o", "--output", type=click.Path(dir_okay=False), metavar="GRAD.json",
              help="Write {variable: dJ/dv} here (JSON) as well as printing it.")
@click.option("--set", "overrides", multiple=True, metavar="KEY=VALUE", help="As for ffd deform.")
@click.option("--cache-dir", type=click.Path(file_okay=False), metavar="DIR", help="Where the box cache lives.")
@common_options
def grad_cmd(design_file, sens, output, overrides, cache_dir, console):
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
    from ffdcli.api import DesignModel, gradient_from_file
    from ffdcli.app.pipeline import load_run
    from ffdcli.design import load_design
    from ffdcli.io.outputs import plan_outputs

    t0 = time.perf_counter()
    design = load_design(design_file, overrides=overrides)
    # never over an input (the mesh, the design, the sensitivity file); checked before the work
    plan = plan_outputs([("grad", output, False, "-o")], inputs=(design.mesh, design.path, sens))
    model = DesignModel(load_run(design, cache_dir=cache_dir, progress=console.progress, comm=console.comm),
                        comm=console.comm)
    sens_file = sens
    grad = gradient_from_file(model, sens_file, progress=console.progress)
    sens, result, volume_nodes = grad.sensitivity, grad.values, grad.volume_nodes
    summary = {
        "design": str(design_file), "sensitivity": str(sens_file),
        "gradient": result, "matched_by": sens.matched_by,
        "worst_match_distance": sens.worst_distance, "surface_nodes": grad.surface_nodes,
        "volume_nodes": volume_nodes, "through_volume": grad.through_volume,
        "seconds": round(time.perf_counter() - t0, 3),
    }
    if output:
        # once: rank 0 of an MPI run
        console.comm.root_then_bcast(plan.write, {"grad": lambda tmp: tmp.write_text(json.dumps(result, indent=1))})
        summary["output"] = str(output)
    lines = [f"ffd grad: {Path(design_file).name}, {len(sens.ids)} sensitivity rows matched by "
             f"{sens.matched_by}" + (f" (worst distance {sens.worst_distance:.2e})"
                                      if sens.worst_distance == sens.worst_distance else "")
             + (f", {volume_nodes} volume nodes through the volume motion" if summary["through_volume"] else "")]
    lines += [f"  {k:<24} {v: .10e}" for k, v in result.items()]
    if output:
        lines.append(f"  wrote {output}")
    console.result(summary, "\n".join(lines))


@cli.command("jacobian")
@click.argument("design_file", metavar="DESIGN.yaml", type=click.Path(dir_okay=False))
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False), metavar="JAC.npz",
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
    import numpy as np

    from ffdcli.api import DesignModel
    from ffdcli.app.pipeline import load_run
    from ffdcli.design import load_design
    from ffdcli.io.outputs import plan_outputs

    design = load_design(design_file, overrides=overrides)
    plan = plan_outputs([("jacobian", output, False, "-o")], inputs=(design.mesh, design.path))
    model = DesignModel(load_run(design, progress=console.progress, comm=console.comm), comm=console.comm)
    B, D = model.jacobian_factors()
    arrays = dict(names=np.array(model.names), point_ids=model.surface_ids, values=model.values,
                  B_data=B.data, B_indices=B.indices, B_indptr=B.indptr, B_shape=np.array(B.shape), D=D,
                  points=model.surface_points())
    if dense:
        from ffdcli.parameterization.derivatives import surface_jacobian

        arrays["J"] = surface_jacobian(B, D)
    def write(tmp):
        with open(tmp, "wb") as fh:
            np.savez(fh, **arrays)

    console.comm.root_then_bcast(plan.write, {"jacobian": write})        # once: rank 0 of an MPI run
    console.result({"output": str(output), "variables": len(model.names), "points": int(B.shape[0])},
                   f"ffd jacobian: {len(model.names)} variables x {B.shape[0]} surface points -> {output}")
