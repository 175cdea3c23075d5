"""``ffd box MESH``: fit the automatic lattice to the wing, embed it, cache it, write it as VTK."""

from __future__ import annotations

from pathlib import Path

import click

from ffdcli.cli import cli, common_options
from ffdcli.errors import InputError


def int_list(ctx, param, value):
    """Click callback: ``"6,8,2"`` -> (6, 8, 2)."""
    if value is None:
        return None
    try:
        out = tuple(int(v) for v in value.replace("x", ",").split(",") if v.strip())
    except ValueError:
        raise click.BadParameter(
            f"expected integers separated by commas, like 6,8,2; got {value!r}") from None
    if not out:
        raise click.BadParameter("expected integers separated by commas, like 6,8,2")
    return out


def is_design_file(path: str) -> bool:
    return Path(path).suffix.lower() in (".yaml", ".yml")


@cli.command("box")
@click.argument("mesh", type=click.Path(dir_okay=False))
@click.option("--surface", "surfaces", multiple=True, metavar="NAME",
              help="Marker of the wing (repeat for several). Default: the only marker, or the one "
                   "named like wing/airfoil.")
@click.option("--points", callback=int_list, metavar="N,M,L",
              help="Control points chordwise, spanwise, thickness (2D: N,L). Default 6,8,2 (2D: 6,5).")
@click.option("--degree", callback=int_list, metavar="P,Q,R",
              help="B-spline degree per direction. Default min(3, points-1).")
@click.option("--sections", type=click.Choice(["xy", "xz", "yz", "yx", "zx", "zy"]),
              help="Plane of the airfoil sections, chord axis first (xy: chord x, thickness y, span z). "
                   "Default: detected (span = largest extent, thickness = smallest).")
@click.option("--root", type=click.Choice(["min", "max"]),
              help="End of the span axis where the root is. Default: the end nearer 0.")
@click.option("--margin", type=float, metavar="F",
              help="Clearance around the wing as a fraction of the local chord. Default 0.02.")
@click.option("--lattice", "lattice_out", type=click.Path(dir_okay=False), metavar="FILE",
              help="Where to write the lattice (VTK). Default: <mesh stem>_lattice.vtk beside the mesh.")
@click.option("--from", "from_file", type=click.Path(dir_okay=False), metavar="FILE.xyz",
              help="Use this single-block Plot3D lattice (a pyGeo/DAFoam FFD file) instead of fitting one.")
@click.option("--export-plot3d", type=click.Path(dir_okay=False), metavar="FILE.xyz",
              help="Also write the lattice as Plot3D in the layout pyGeo's DVGeometry reads.")
@click.option("--cache-dir", type=click.Path(file_okay=False), metavar="DIR",
              help="Keep the cache file here instead of beside the mesh.")
@click.option("--rebuild", is_flag=True, help="Ignore an existing cache file (and replace it).")
@common_options
def box_cmd(mesh, surfaces, points, degree, sections, root, margin, lattice_out, from_file,
            export_plot3d, cache_dir, rebuild, console):
    """Fit a B-spline lattice to the wing surface of MESH and embed the surface in it.

    \b
    MESH is a mesh (.su2, .cgns, .vtu, .vtk) or a design file (.yaml): then the mesh, surface and
    box settings come from the file, and options given here override them.

    \b
    The lattice has sections from the root to the tip of the wing, each a rectangle aligned with the
    local chord line, from just ahead of the leading edge to just behind the trailing edge and from
    below the lower to above the upper surface. Every surface point is embedded by Newton point
    inversion; where a point falls outside, the margin is grown there and the lattice rebuilt, so the
    summary should always say 0 outside. The result is cached beside the mesh for `ffd deform`.

    \b
    Examples:
      ffd box wing.su2
      ffd box wing.su2 --surface wing --points 8,10,2 --sections xz --json
      ffd box design.yaml --lattice out/lattice.vtk
    """
    from ffdcli.lattice.limits import check_lattice_size
    from ffdcli.settings import BoxSettings

    if points is not None:           # refused in a fraction of a second, before the heavy imports
        check_lattice_size(points, path=mesh, key="--points")

    from ffdcli.app.pipeline import prepare_box
    from ffdcli.io.formats.lattice_vtk import write_lattice_vtk

    if is_design_file(mesh):
        from ffdcli.design import load_design

        design = load_design(mesh)
        mesh_path = design.mesh
        settings = design.box
        surface = list(surfaces) or design.surface
    else:
        mesh_path = Path(mesh)
        settings = None
        surface = list(surfaces) or None
    settings = (settings or BoxSettings()).with_options(points=points, degree=degree, sections=sections,
                                                        root=root, margin=margin, file=from_file)
    from ffdcli.io.formats import format_of
    from ffdcli.io.inputs import check_input_file
    from ffdcli.io.outputs import plan_outputs

    if is_design_file(mesh) and getattr(design, "components", None):
        if surfaces or any(v is not None for v in (points, degree, sections, root, margin, from_file)):
            raise InputError("with components:, the box settings come from each component of the design "
                             "file; drop the --surface/--points/... options", path=design.path)
        return _components_box(design, lattice_out, export_plot3d, cache_dir, rebuild, console)
    mpath = Path(mesh_path)
    format_of(mpath)
    check_input_file(mpath, "mesh file")
    out = lattice_out if lattice_out is not None else mpath.with_name(mpath.stem + "_lattice.vtk")
    inputs = (mpath, mesh if is_design_file(mesh) else None, from_file, settings.file if settings else None)
    plan = plan_outputs([("lattice", out, False, "--lattice"), ("plot3d", export_plot3d, False, "--export-plot3d")],
                        inputs=inputs)          # every output checked before the work
    prep = prepare_box(mesh_path, surface, settings, cache_dir=cache_dir, rebuild=rebuild,
                       progress=console.progress, comm=console.comm)
    writers = {"lattice": lambda tmp: write_lattice_vtk(tmp, prep.box.control_points)}
    if export_plot3d:
        from ffdcli.io.formats.plot3d import write_plot3d

        writers["plot3d"] = lambda tmp: write_plot3d(tmp, [prep.box.control_points])
    console.comm.root_then_bcast(plan.write, writers)        # once: rank 0 of an MPI run
    out = plan.path("lattice")
    from ffdcli.parameterization.components import find_junction

    junction = find_junction(prep.mesh, prep, prep.surface.names)
    s = prep.summary()
    s["lattice_file"] = str(out)
    s["root_on"] = None if junction is None else junction.marker
    if junction is not None:
        s["junction"] = junction.summary()
    for w in prep.warnings:
        console.warn(w)
    for note in prep.report.get("notes", []):
        console.detail(f"note: {note}")
    text = "\n".join([f"ffd box: {mpath.name}, surface {', '.join(s['surface'])} ({s['points']} points)",
                      *_box_lines(s, prep.box.imported, junction), f"  wrote     {out}",
                      f"  cache     {s['cache'] or '(none)'} ({'reused' if prep.from_cache else 'built'} in "
                      f"{s['seconds']:.2f} s)"])
    console.result(s, text)
    _check_outside(s, prep, mpath)


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


def _check_outside(s: dict, prep, mpath) -> None:
    import numpy as np

    if s["outside"] and not prep.box.imported:
        raise InputError(f"{s['outside']} surface points are outside the automatic box even after "
                         f"{s['rebuilds']} rebuilds (worst {s.get('outside_worst', np.nan):.3g}); try a "
                         "larger --margin or more spanwise --points", path=mpath)


def _components_box(design, lattice_out, export_plot3d, cache_dir, rebuild, console) -> None:
    """``ffd box DESIGN.yaml`` of a design with ``components:``: every component's box, one lattice
    file per component (``<stem>_<component>.vtk``), one Plot3D file with a block per component."""
    from ffdcli.app.pipeline import load_run
    from ffdcli.io.formats.lattice_vtk import write_lattice_vtk
    from ffdcli.io.outputs import component_lattice_path, lattice_kind, plan_outputs

    mpath = Path(design.mesh)
    base = Path(lattice_out) if lattice_out else mpath.with_name(mpath.stem + "_lattice.vtk")
    names = [c.name for c in design.components]
    plan = plan_outputs([*((lattice_kind(n), component_lattice_path(base, n), False, "--lattice") for n in names),
                         ("plot3d", export_plot3d, False, "--export-plot3d")],
                        inputs=(mpath, design.path))          # every output checked before the work
    run = load_run(design, cache_dir=cache_dir, rebuild=rebuild, progress=console.progress, comm=console.comm)
    writers = {lattice_kind(c.name): (lambda tmp, c=c: write_lattice_vtk(tmp, c.P0))
               for c in run.components}
    if export_plot3d:
        from ffdcli.io.formats.plot3d import write_plot3d

        writers["plot3d"] = lambda tmp: write_plot3d(tmp, [c.P0 for c in run.components])
    console.comm.root_then_bcast(plan.write, writers)        # once: rank 0 of an MPI run
    summaries, text = [], [f"ffd box: {mpath.name}, {len(run.components)} components"]
    for comp in run.components:
        p = plan.path(lattice_kind(comp.name))
        s = {**comp.prep.summary(), **comp.summary(), "lattice_file": str(p)}
        summaries.append(s)
        for w in comp.prep.warnings:
            console.warn(f"{comp.name}: {w}")
        text += [f" {comp.name}: surface {', '.join(s['surface'])} ({s['points']} points)",
                 *_box_lines(s, comp.box.imported, comp.junction), f"  wrote     {p}"]
    console.result({"mesh": str(mpath), "components": summaries}, "\n".join(text))
    for comp, s in zip(run.components, summaries, strict=True):
        _check_outside(s, comp.prep, mpath)
