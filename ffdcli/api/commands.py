"""The workflows of the commands that stand on a :class:`~ffdcli.api.DesignModel`: ``ffd vars``,
``ffd constraints``, ``ffd grad`` and ``ffd jacobian``. Each takes the command's inputs (a design file
and its ``--set`` overrides), does the work and returns a :class:`~ffdcli.app.report.CommandReport`;
the command line only parses, calls and prints. They live here, not in ``app/``, because the model
they use is the API's (``app`` comes before ``api`` in the layer order)."""

from __future__ import annotations

import numpy as np

from ffdcli.api.gradient import grad_design, jacobian_design
from ffdcli.api.model import DesignModel
from ffdcli.app.report import CommandReport
from ffdcli.app.run import load_run
from ffdcli.design import load_design
from ffdcli.io.outputs import plan_outputs


def bound_text(x) -> str:
    """A bound in the tables of ``ffd vars`` and ``ffd constraints``: ``-`` for none, else 6 digits."""
    return "-" if x is None else f"{x:.6g}"


def run_vars(design_file, overrides=(), *, cache_dir=None, progress=None) -> CommandReport:
    """``ffd vars``: the design variables with value, unit and bounds."""
    model = DesignModel.from_file(design_file, overrides, cache_dir=cache_dir, progress=progress)
    rows = model.variables_table()
    width = max([len(r["name"]) for r in rows] + [8])
    lines = [f"{'variable':<{width}}  {'value':>12}  {'unit':<6}  {'lower':>12}  {'upper':>12}"]
    lines += [f"{r['name']:<{width}}  {r['value']:>12.6g}  {r['unit']:<6}  {bound_text(r['lower']):>12}  "
              f"{bound_text(r['upper']):>12}" for r in rows]
    if not rows:
        lines.append("(no design variables: changes: is empty)")
    return CommandReport({"variables": rows}, "\n".join(lines))


def run_constraints(design_file, overrides=(), *, jacobian_file=None, cache_dir=None, progress=None,
                       comm=None) -> CommandReport:
    """``ffd constraints``: the constraints at the design's values and, with ``jacobian_file``, their
    exact Jacobian written as ``.npz`` (planned before the work; once, by rank 0 of an MPI run)."""
    design = load_design(design_file, overrides=overrides)
    plan = plan_outputs([("jacobian", jacobian_file, False, "--jacobian")], inputs=(design.mesh, design.path))
    model = DesignModel(load_run(design, cache_dir=cache_dir, progress=progress, comm=comm), comm=comm)
    if jacobian_file:
        arrays = model.constraint_jacobian_arrays()

        def write(tmp):
            with open(tmp, "wb") as fh:
                np.savez(fh, **arrays)

        model.comm.root_then_bcast(plan.write, {"jacobian": write})
    rows = model.constraints_table()
    width = max([len(r["name"]) for r in rows] + [10])
    lines = [f"{'constraint':<{width}}  {'value':>12}  {'lower':>10}  {'upper':>10}  satisfied"]
    lines += [f"{r['name']:<{width}}  {r['value']:>12.8g}  {bound_text(r['lower']):>10}  {bound_text(r['upper']):>10}  "
              f"{'yes' if r['satisfied'] else 'NO'}" for r in rows]
    if not rows:
        lines.append("(the design file has no constraints:)")
    summary = {"constraints": rows, "variables": model.variables_table()}
    if jacobian_file:
        lines.append(f"jacobian ({len(rows)} x {model.n_vars}) written to {jacobian_file}")
        summary["jacobian"] = str(jacobian_file)
    return CommandReport(summary, "\n".join(lines))


def run_grad(design_file, sens, overrides=(), *, output=None, cache_dir=None, tol=None, progress=None,
                    comm=None) -> CommandReport:
    """``ffd grad``: dJ/dv of every design variable from a sensitivity file (:func:`grad_design`)."""
    design = load_design(design_file, overrides=overrides)
    summary, text = grad_design(design, sens, output=output, cache_dir=cache_dir, progress=progress, comm=comm,
                                tol=tol)
    return CommandReport(summary, text)


def run_jacobian(design_file, output, overrides=(), *, dense: bool = False, progress=None,
                    comm=None) -> CommandReport:
    """``ffd jacobian``: the factors of dX/dv written as ``.npz`` (:func:`jacobian_design`)."""
    design = load_design(design_file, overrides=overrides)
    summary, text = jacobian_design(design, output, dense=dense, progress=progress, comm=comm)
    return CommandReport(summary, text)
