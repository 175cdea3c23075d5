"""dJ/dv from a sensitivity file (dJ/dX at the nodes of the deformed mesh), and the workflows of
``ffd grad`` and ``ffd jacobian`` (they differentiate, so they run on the API's model)."""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ffdcli.api.model import DesignModel
from ffdcli.app.run import load_run
from ffdcli.errors import InputError
from ffdcli.io.formats.sensitivity import Sensitivity, read_sensitivity
from ffdcli.io.jsontext import to_json
from ffdcli.io.outputs import plan_outputs
from ffdcli.parallel.comm import SerialComm
from ffdcli.parameterization.derivatives import surface_jacobian


def read_sensitivity_for(model, path, *, points=None, tol: float | None = None):
    """Read a sensitivity file against the deformed mesh of ``model`` (SPEC: coordinates of the
    design being differentiated; ``tol`` as :func:`read_sensitivity`). Returns (g (N, 3) dense, Sensitivity)."""
    mesh = model.run.prep.mesh
    pts = model.mesh_points() if points is None else points
    sens = read_sensitivity(path, pts, mesh.dim, tol=tol, mesh=mesh)
    return sens.to_dense(mesh.n_points), sens


@dataclass(frozen=True)
class Gradient:
    """dJ/dv from a sensitivity file (:func:`gradient_from_file`).

    values
        {variable name: dJ/dv} in the order of the model's variables.
    sensitivity
        The file's rows as matched to the mesh (``matched_by``, ``worst_distance``).
    surface_nodes, volume_nodes
        How many rows are on the surface marker(s), and how many elsewhere in the mesh.
    through_volume
        Whether the volume rows were pulled back through the volume-mesh motion (a volume method and
        volume rows); otherwise only the surface rows count.
    """

    values: dict[str, float]
    sensitivity: Sensitivity
    surface_nodes: int
    volume_nodes: int
    through_volume: bool


def gradient_from_file(model, path, *, progress=None, tol: float | None = None) -> Gradient:
    """dJ/dv of every design variable of ``model`` by the chain rule from a sensitivity file (dJ/dX at
    the nodes of the deformed mesh). The file must cover every surface node (InputError otherwise);
    volume rows go through the volume-mesh motion's exact transpose when the design moves the volume.
    A gradient that overflows float64 (finite but huge sensitivities) is an InputError naming the file."""
    g, sens = read_sensitivity_for(model, path, tol=tol)
    sens.check_covers(model.surface_ids, path)
    on_surface = np.isin(sens.ids, model.surface_ids)
    volume_nodes = int((~on_surface).sum())
    through = bool(volume_nodes and model.uses_volume())
    with np.errstate(over="ignore", invalid="ignore"):
        grad = model.mesh_vjp(g, progress=progress) if through else model.surface_vjp(g[model.surface_ids])
    if not np.all(np.isfinite(grad)):
        raise InputError(f"the gradient overflows float64 (sensitivities up to {np.abs(g).max():.3g}); scale "
                         "the function J down", path=path)
    return Gradient(values={name: float(v) for name, v in zip(model.names, grad, strict=True)},
                    sensitivity=sens, surface_nodes=int(on_surface.sum()), volume_nodes=volume_nodes,
                    through_volume=through)


def grad_design(design, sens, *, output=None, cache_dir=None, progress=None, comm=None,
                tol: float | None = None) -> tuple[dict, str]:
    """``ffd grad``: dJ/dv of a loaded design from sensitivity file ``sens``, written to ``output``
    (JSON) when given (``tol``: :func:`read_sensitivity`'s). Returns (the ``--json`` summary, the text)."""
    t0 = time.perf_counter()
    comm = comm or SerialComm()
    # never over an input (the mesh, the design, the sensitivity file); checked before the work
    plan = plan_outputs([("grad", output, False, "-o")], inputs=(design.mesh, design.path, sens))
    model = DesignModel(load_run(design, cache_dir=cache_dir, progress=progress, comm=comm), comm=comm)
    grad = gradient_from_file(model, sens, progress=progress, tol=tol)
    rows, result = grad.sensitivity, grad.values
    summary = {
        "design": str(design.path), "sensitivity": str(sens),
        "gradient": result, "matched_by": rows.matched_by,
        "worst_match_distance": rows.worst_distance, "surface_nodes": grad.surface_nodes,
        "volume_nodes": grad.volume_nodes, "through_volume": grad.through_volume,
        "seconds": round(time.perf_counter() - t0, 3),
    }
    if output:          # once: rank 0 of an MPI run
        comm.root_then_bcast(plan.write, {"grad": lambda tmp: tmp.write_text(to_json(result, indent=1))})
        summary["output"] = str(output)
    lines = [f"ffd grad: {Path(design.path).name}, {len(rows.ids)} sensitivity rows matched by "
             f"{rows.matched_by}" + (f" (worst distance {rows.worst_distance:.2e})"
                                     if rows.worst_distance == rows.worst_distance else "")
             + (f", {grad.volume_nodes} volume nodes through the volume motion" if grad.through_volume else "")]
    lines += [f"  {k:<24} {v: .10e}" for k, v in result.items()]
    if output:
        lines.append(f"  wrote {output}")
    return summary, "\n".join(lines)


def jacobian_design(design, output, *, dense: bool = False, progress=None, comm=None) -> tuple[dict, str]:
    """``ffd jacobian``: the exact factors dX/dv = B @ D of a loaded design written to ``output`` (.npz;
    ``dense``: the dense J too). Returns (the ``--json`` summary, the text)."""
    comm = comm or SerialComm()
    plan = plan_outputs([("jacobian", output, False, "-o")], inputs=(design.mesh, design.path))
    model = DesignModel(load_run(design, progress=progress, comm=comm), comm=comm)
    B, D = model.jacobian_factors()
    arrays = dict(names=np.array(model.names), point_ids=model.surface_ids, values=model.values,
                  B_data=B.data, B_indices=B.indices, B_indptr=B.indptr, B_shape=np.array(B.shape), D=D,
                  points=model.surface_points())
    if dense:
        arrays["J"] = surface_jacobian(B, D)

    def write(tmp):
        with open(tmp, "wb") as fh:
            np.savez(fh, **arrays)

    comm.root_then_bcast(plan.write, {"jacobian": write})        # once: rank 0 of an MPI run
    return ({"output": str(output), "variables": len(model.names), "points": int(B.shape[0])},
            f"ffd jacobian: {len(model.names)} variables x {B.shape[0]} surface points -> {output}")
