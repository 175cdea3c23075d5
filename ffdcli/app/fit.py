"""``ffd fit``: fit the shape of a 2D design to a target airfoil and write the fitted design file.

The least-squares problem is :mod:`ffdcli.parameterization.fit`'s; this is the workflow around it
(the design and the target read, the run loaded, the output planned and written whole).
"""

from __future__ import annotations

import copy
import os
from dataclasses import dataclass, field
from pathlib import Path

import yaml

from ffdcli.app.design_output import plan_design_output, write_design_text
from ffdcli.app.run import load_run
from ffdcli.design import load_design
from ffdcli.errors import InputError
from ffdcli.io.formats.airfoil import read_airfoil
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


@dataclass(frozen=True)
class FitReport:
    """What ``ffd fit`` did: the ``--json`` summary (deviations before and after, the fitted shape, the
    file written), its text, and the fitted design file's path (None when none was asked for)."""

    summary: dict
    text: str
    output: str | None = None
    warnings: tuple[str, ...] = field(default=())

    def __getitem__(self, key):          # the dict fit_design returned before (scripts, the demo)
        return self.summary[key]


def fitted_path(design_file) -> Path:
    """The default output of ``ffd fit DESIGN.yaml``: ``<design stem>_fitted.yaml`` beside it."""
    p = Path(design_file)
    return p.with_name(p.stem + "_fitted.yaml")


def fit_design(config, target_file, out_yaml=None, *, overrides=(), rows: str = "all", progress=None,
               reg: float = REG, force: bool = False, default_output: bool = False) -> FitReport:
    """Fit the shape of 2D design ``config`` to ``target_file``; write ``out_yaml`` if given (with
    ``default_output``, None means :func:`fitted_path`). An existing design file there is replaced only
    with ``force`` (:mod:`ffdcli.app.design_output`)."""
    design = load_design(config, overrides=overrides)
    if out_yaml is None and default_output:
        out_yaml = fitted_path(design.path)
    other = [next(iter(c)) for c in design.changes_spec if "shape" not in c]
    design.changes_spec = []          # the fit replaces any shape change; its lengths need not match
    plan = (plan_design_output(out_yaml, inputs=(design.mesh, design.path, target_file), force=force)
            if out_yaml is not None else None)          # checked before the work
    target = read_airfoil(target_file)
    run = load_run(design, progress=progress)
    if run.box.dim != 2:              # what the mesh is comes first: no advice about changes of a 3D design
        raise InputError("ffd fit works on 2D airfoil meshes; this design's mesh is 3D", path=design.path)
    if other:
        raise InputError(f"ffd fit fits shape values to the original airfoil; remove the other changes "
                         f"({', '.join(other)}) or fit a design that has only shape changes",
                         path=design.path, key="changes")
    problem = build_problem(run, target.coords, rows)
    values, stats = solve(problem, reg)
    shape = shape_spec(problem, values)
    report = {"design": str(design.path), "target": str(target_file), "name": target.name,
              "lattice": list(run.box.lattice_shape), "chord": problem.chord,
              "points": int(len(problem.rhs)), **stats,
              "rows": rows, "shape": shape}
    written = None
    if plan is not None:
        data = fitted_design_data(design, shape, Path(out_yaml))
        text = (f"# fitted by ffd fit to {Path(target_file).name} ({target.name}): max deviation "
                f"{stats['before']['max']:.5f} -> {stats['after']['max']:.5f} chords\n"
                + yaml.safe_dump(data, sort_keys=False, default_flow_style=None))
        written = write_design_text(plan, text)
        report["output"] = written
    return FitReport(summary=report, text=_text(report), output=written)


def _text(rep: dict) -> str:
    b, a = rep["before"], rep["after"]
    lines = [f"ffd fit: {Path(rep['design']).name} -> {Path(rep['target']).name} ({rep['name']}), lattice "
             f"{' x '.join(map(str, rep['lattice']))}, {rep['points']} surface points",
             f"  before    max {b['max']:.5f}, rms {b['rms']:.5f} chords",
             f"  after     max {a['max']:.5f}, rms {a['rms']:.5f} chords"]
    if rep.get("output"):
        lines.append(f"  wrote     {rep['output']}")
    return "\n".join(lines)
