"""``ffd plot``'s workflow: deform the design (nothing written but pictures) and draw it."""

from __future__ import annotations

from dataclasses import dataclass, field

from ffdcli.app.deformation import deform
from ffdcli.app.run import load_run
from ffdcli.app.write import deform_writers
from ffdcli.design import load_design
from ffdcli.errors import InputError
from ffdcli.io.formats.airfoil import read_airfoil
from ffdcli.io.outputs import plan_plot


@dataclass(frozen=True)
class PlotReport:
    """The pictures written, the ``--json`` summary and what the user should know."""

    summary: dict
    text: str
    warnings: tuple[str, ...] = field(default=())


def plot_design_file(design, *, output=None, view3d: bool = True, target=None, progress=None) -> PlotReport:
    """Draw a loaded design: the PNG (and the 3D view), original black and deformed red. ``target``: an
    airfoil file drawn on a 2D design. A design the quality gate would refuse is drawn, and said so."""
    plan = plan_plot(design, output, view3d=view3d)       # checked before the work
    coords = read_airfoil(target).coords if target is not None else None
    run = load_run(design, progress=progress)
    if coords is not None and run.box.dim != 2:      # never silently ignored
        raise InputError("draws a target airfoil on a 2D design; this design is 3D "
                         "(leave it out)", path=design.path, key="--target")
    result = deform(run, progress=progress)
    q = result.quality
    warnings = []
    if q is not None and not q.ok:
        warnings.append(f"the quality gate would refuse this design (ffd deform writes nothing without "
                        f"--force): {q.summary()}")
    writers = {k: w for k, w in deform_writers(run, result, target=coords).items() if k in plan}
    written = plan.write(writers)
    if "plot_3d" in plan and "plot_3d" not in written and run.box.dim == 3:
        warnings.append("no 3D view: pyvista or an off-screen OpenGL backend is missing "
                        "(pip install 'ffdcli[viz]'); the 2D views are written")
    summary = {"plot": written["plot"], "plots": list(written.values()), "max_displacement": result.max_displacement,
               "refused": bool(q is not None and not q.ok), "quality": q.to_dict() if q is not None else None}
    return PlotReport(summary, "ffd plot: wrote " + ", ".join(written.values()), tuple(warnings))


def plot_file(design_file, overrides=(), **kwargs) -> PlotReport:
    """``ffd plot DESIGN.yaml``: the design file loaded (``--set`` ``overrides`` applied), then
    :func:`plot_design_file` with ``kwargs``."""
    return plot_design_file(load_design(design_file, overrides=overrides), **kwargs)
