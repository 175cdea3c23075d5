"""``ffd box``'s workflow: the box of a mesh's surface (or of every component of a design file),
built or read from the cache, its lattice written as VTK (and Plot3D); a report comes back."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ffdcli.app.prepare import prepare_box
from ffdcli.app.run import load_run
from ffdcli.design import load_design
from ffdcli.errors import InputError
from ffdcli.io.formats import format_of
from ffdcli.io.formats.lattice_vtk import write_lattice_vtk
from ffdcli.io.formats.plot3d import write_plot3d
from ffdcli.io.inputs import check_mesh_path
from ffdcli.io.outputs import component_lattice_path, lattice_kind, plan_outputs
from ffdcli.parallel.comm import SerialComm
from ffdcli.parameterization.components import find_junction
from ffdcli.settings import BoxSettings


@dataclass(frozen=True)
class BoxReport:
    """What ``ffd box`` did: the ``--json`` summary, its text, the warnings and notes, and the error
    of surface points left outside an automatic box (raised by :meth:`check` once the report is out)."""

    summary: dict
    text: str
    warnings: tuple[str, ...] = field(default=())
    notes: tuple[str, ...] = field(default=())
    outside: InputError | None = None

    def check(self) -> None:
        """Raise the error of surface points outside the automatic box, if any."""
        if self.outside is not None:
            raise self.outside


def is_design_file(path) -> bool:
    """Whether ``ffd box``'s argument is a design file (by its extension) rather than a mesh."""
    return Path(path).suffix.lower() in (".yaml", ".yml")


def box_of(mesh, *, surfaces=(), options: dict | None = None, lattice_out=None, export_plot3d=None,
           cache_dir=None, rebuild: bool = False, progress=None, comm=None) -> BoxReport:
    """The box of ``mesh`` (a mesh file, or a design file whose settings ``options`` override:
    ``points``, ``degree``, ``sections``, ``root``, ``margin``, ``file``), built or from the cache, with
    its lattice written (``lattice_out``, default ``<mesh stem>_lattice.vtk``; ``export_plot3d``)."""
    comm = comm or SerialComm()
    options = {k: v for k, v in (options or {}).items() if v is not None}
    design = None
    if is_design_file(mesh):
        design = load_design(mesh)
        mesh_path, settings, surface = design.mesh, design.box, list(surfaces) or design.surface
    else:
        mesh_path, settings, surface = Path(mesh), None, list(surfaces) or None
    settings = (settings or BoxSettings()).with_options(**{k: options.get(k) for k in
                                                           ("points", "degree", "sections", "root", "margin", "file")})
    if design is not None and getattr(design, "components", None):
        if surfaces or options:
            raise InputError("with components:, the box settings come from each component of the design "
                             "file; drop the --surface/--points/... options", path=design.path)
        return _components_box(design, lattice_out, export_plot3d, cache_dir, rebuild, progress, comm)
    mpath = Path(mesh_path)
    format_of(mpath)
    check_mesh_path(mpath)
    out = lattice_out if lattice_out is not None else mpath.with_name(mpath.stem + "_lattice.vtk")
    inputs = (mpath, mesh if design is not None else None, options.get("file"), settings.file)
    plan = plan_outputs([("lattice", out, False, "--lattice"), ("plot3d", export_plot3d, False, "--export-plot3d")],
                        inputs=inputs)          # every output checked before the work
    if design is not None and not surfaces and not options:      # the whole file checked (changes, bounds)
        prep = load_run(design, cache_dir=cache_dir, rebuild=rebuild, progress=progress, comm=comm).prep
    else:
        prep = prepare_box(mesh_path, surface, settings, cache_dir=cache_dir, rebuild=rebuild, progress=progress,
                           comm=comm)
    writers = {"lattice": lambda tmp: write_lattice_vtk(tmp, prep.box.control_points)}
    if export_plot3d:
        writers["plot3d"] = lambda tmp: write_plot3d(tmp, [prep.box.control_points])
    comm.root_then_bcast(plan.write, writers)        # once: rank 0 of an MPI run
    out = plan.path("lattice")
    junction = find_junction(prep.mesh, prep, prep.surface.names)
    s = prep.summary()
    s["lattice_file"] = str(out)
    s["root_on"] = None if junction is None else junction.marker
    if junction is not None:
        s["junction"] = junction.summary()
    text = "\n".join([f"ffd box: {mpath.name}, surface {', '.join(s['surface'])} ({s['points']} points)",
                      *_box_lines(s, prep.box.imported, junction), f"  wrote     {out}",
                      f"  cache     {s['cache'] or '(none)'} ({'reused' if prep.from_cache else 'built'} in "
                      f"{s['seconds']:.2f} s)"])
    return BoxReport(summary=s, text=text, warnings=tuple(prep.warnings),
                     notes=tuple(prep.report.get("notes", [])), outside=_outside(s, prep, mpath))


def _box_lines(s: dict, imported: bool, junction) -> list[str]:
    a = s["axes"]
    res = s["residual"]
    lines = [
        f"  axes      chord {a['chord']}, thickness {a['thickness']}, span {a['span']}; root at "
        f"{a['span']} {s['root']}; leading edge at {a['chord']} {s['leading_edge']}",
        f"  lattice   {' x '.join(map(str, s['lattice']))}, degree {' x '.join(map(str, s['degree']))}"
        f"{' (imported)' if imported else ''}",
        f"  embedded  {s['points'] - s['outside']} points, {s['outside']} outside, worst residual "
        f"{res:.2e} (mesh units)",
        f"  margins   front {s['margins']['front']:.3g}, back {s['margins']['back']:.3g}, lower "
        f"{s['margins']['lower']:.3g}, upper {s['margins']['upper']:.3g} chords"
        f" ({s['rebuilds']} rebuilds)",
    ]
    if junction is not None:
        lines.append(f"  root      on the body {junction.marker!r} ({len(junction.nodes)} shared nodes, which do "
                     f"not move): sections 0..{junction.frozen - 1} stay fixed")
    return lines


def _outside(s: dict, prep, mpath) -> InputError | None:
    if s["outside"] and not prep.box.imported:
        return InputError(f"{s['outside']} surface points are outside the automatic box even after "
                         f"{s['rebuilds']} rebuilds (worst {s.get('outside_worst', np.nan):.3g}); try a "
                         "larger --margin or more spanwise --points", path=mpath)
    return None


def _components_box(design, lattice_out, export_plot3d, cache_dir, rebuild, progress, comm) -> BoxReport:
    """``ffd box DESIGN.yaml`` of a design with ``components:``: every component's box, one lattice
    file per component (``<stem>_<component>.vtk``), one Plot3D file with a block per component."""
    mpath = Path(design.mesh)
    base = Path(lattice_out) if lattice_out else mpath.with_name(mpath.stem + "_lattice.vtk")
    names = [c.name for c in design.components]
    plan = plan_outputs([*((lattice_kind(n), component_lattice_path(base, n), False, "--lattice") for n in names),
                         ("plot3d", export_plot3d, False, "--export-plot3d")],
                        inputs=(mpath, design.path))          # every output checked before the work
    run = load_run(design, cache_dir=cache_dir, rebuild=rebuild, progress=progress, comm=comm)
    writers = {lattice_kind(c.name): (lambda tmp, c=c: write_lattice_vtk(tmp, c.P0))
               for c in run.components}
    if export_plot3d:
        writers["plot3d"] = lambda tmp: write_plot3d(tmp, [c.P0 for c in run.components])
    comm.root_then_bcast(plan.write, writers)        # once: rank 0 of an MPI run
    summaries, text, warnings = [], [f"ffd box: {mpath.name}, {len(run.components)} components"], []
    for comp in run.components:
        p = plan.path(lattice_kind(comp.name))
        s = {**comp.prep.summary(), **comp.summary(), "lattice_file": str(p)}
        summaries.append(s)
        warnings += [f"{comp.name}: {w}" for w in comp.prep.warnings]
        text += [f" {comp.name}: surface {', '.join(s['surface'])} ({s['points']} points)",
                 *_box_lines(s, comp.box.imported, comp.junction), f"  wrote     {p}"]
    errors = [e for comp, s in zip(run.components, summaries, strict=True) if (e := _outside(s, comp.prep, mpath))]
    return BoxReport(summary={"mesh": str(mpath), "components": summaries}, text="\n".join(text),
                     warnings=tuple(warnings), outside=errors[0] if errors else None)
