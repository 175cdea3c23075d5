"""``ffd fit``: fit the shape of a 2D design to a target airfoil and write the fitted design file.

The least-squares problem is :mod:`ffdcli.parameterization.fit`'s; this is the workflow around it
(the design and the target read, the run loaded, the output planned and written whole).
"""

from __future__ import annotations

import copy
import os
from pathlib import Path

import yaml

from ffdcli.app.run import load_run
from ffdcli.design import load_design
from ffdcli.errors import InputError
from ffdcli.io.formats.airfoil import read_airfoil
from ffdcli.io.outputs import plan_outputs
from ffdcli.parameterization.fit import REG, build_problem, shape_spec, solve


def fitted_design_data(design, shape: dict, out_path: Path) -> dict:
    """The design file's data with its shape change replaced by the fitted values (paths rebased)."""
    data = copy.deepcopy(design.data)
    base = Path(out_path).resolve().parent
    data["mesh"] = os.path.relpath(Path(design.mesh).resolve(), base)
    shape = {"shape": shape}
    changes = [c for c in data.get("changes") or [] if "shape" not in c]
    data["changes"] = changes + [shape]
    output = data.get("output") or {}
    for key in ("mesh", "lattice", "plot"):
        if key in output and key in design.output and design.output[key] is not None:
            output[key] = os.path.relpath(Path(design.output[key]).resolve(), base)
    if output:
        data["output"] = output
    return data


def fit_design(config, target_file, out_yaml=None, *, overrides=(), rows: str = "all", progress=None,
               reg: float = REG) -> dict:
    """Fit the shape of 2D design ``config`` to ``target_file``; write ``out_yaml`` if given."""
    design = load_design(config, overrides=overrides)
    other = [next(iter(c)) for c in design.changes_spec if "shape" not in c]
    if other:
        raise InputError(f"ffd fit fits shape values to the original airfoil; remove the other changes "
                         f"({', '.join(other)}) or fit a design that has only shape changes",
                         path=design.path, key="changes")
    design.changes_spec = []          # the fit replaces any shape change; its lengths need not match
    plan = plan_outputs([("design", out_yaml, False, "-o")],      # checked before the work
                        inputs=(design.mesh, design.path, target_file))
    target = read_airfoil(target_file)
    run = load_run(design, progress=progress)
    problem = build_problem(run, target.coords, rows)
    values, stats = solve(problem, reg)
    shape = shape_spec(problem, values)
    report = {"design": str(design.path), "target": str(target_file), "name": target.name,
              "lattice": list(run.box.lattice_shape), "chord": problem.chord,
              "points": int(len(problem.rhs)), **stats,
              "rows": rows, "shape": shape}
    if out_yaml is not None:
        data = fitted_design_data(design, shape, Path(out_yaml))

        def write(tmp):
            with open(tmp, "w") as fh:
                fh.write(f"# fitted by ffd fit to {Path(target_file).name} ({target.name}): max deviation "
                         f"{stats['before']['max']:.5f} -> {stats['after']['max']:.5f} chords\n")
                yaml.safe_dump(data, fh, sort_keys=False, default_flow_style=None)

        plan.write({"design": write})
        report["output"] = str(out_yaml)
    return report
