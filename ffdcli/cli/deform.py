"""``ffd deform DESIGN.yaml``: apply the design's changes and write the deformed mesh."""

from __future__ import annotations

import time
from pathlib import Path

import click

from ffdcli.cli import cli, common_options
from ffdcli.errors import InputError


@cli.command("deform")
@click.argument("design_file", metavar="DESIGN.yaml", type=click.Path(dir_okay=False))
@click.option("--set", "overrides", multiple=True, metavar="KEY=VALUE",
              help="Override one value of the design file, e.g. --set changes.0.twist.tip=12 "
                   "(repeatable; the key path uses list positions).")
@click.option("--output", "-o", type=click.Path(dir_okay=False), metavar="FILE",
              help="Write the deformed mesh here instead of the file's output.mesh.")
@click.option("--lattice", "lattice_out", type=click.Path(dir_okay=False), metavar="FILE.vtk",
              help="Write the lattice here instead of the file's output.lattice.")
@click.option("--surface-file", "surface_file", type=click.Path(dir_okay=False), metavar="FILE",
              help="Also write the deformed surface nodes as SU2's surface-positions file (DV_KIND= "
                   "SURFACE_FILE, DV_FILENAME= FILE), for SU2_DEF's own volume deformation. See docs/su2.md.")
@click.option("--plot", "plot", is_flag=True,
              help="Also write a PNG picture (original black, deformed red) beside the mesh, and for "
                   "a 3D wing <picture>_3d.png, the 3D view (needs pyvista: the [viz] extra).")
@click.option("--force", is_flag=True, help="Write the mesh even if the quality check fails.")
@click.option("--cache-dir", type=click.Path(file_okay=False), metavar="DIR",
              help="Where the box cache lives (default: beside the mesh).")
@click.option("--no-cache", is_flag=True, help="Neither read nor write the box cache.")
@common_options
def deform_cmd(design_file, overrides, output, lattice_out, surface_file, plot, force, cache_dir, no_cache,
               console):
    """Apply the changes of DESIGN.yaml to its mesh and write the deformed mesh and lattice.

    \b
    The box (lattice and embedding) is loaded from its cache, or built and cached. The changes
    (twist, span, sweep, dihedral, chord, shape) are applied in file order to the lattice; the wing
    surface follows exactly (X = X0 + B (P' - P0)), the rest of the mesh by inverse-distance
    warping (volume.method: idw) or not at all (none). Every cell and node is checked (the gate of
    `ffd check`, same words): if the design inverts a cell, makes one markedly worse (below 0.05,
    under half its quality and under the input's worst) or drops a node's orthogonality below 20
    degrees by more than 10, nothing is written and the exit status is 3; a cell already inverted or
    degenerate in the input mesh is exit 2 (--force writes anyway in both cases).

    \b
    Examples:
      ffd deform configs/rect_twist_linear.yaml
      ffd deform design.yaml --set changes.0.twist.tip=12 -o out/tip12.su2 --json
      ffd deform design.yaml --surface-file out/wing_surface.dat   # for SU2_DEF (DV_KIND= SURFACE_FILE)
      for t in 5 10 15; do ffd deform design.yaml --set changes.0.twist.tip=$t -o out/t$t.su2; done
    """
    from ffdcli.design import load_design
    from ffdcli.pipeline import deform, load_run, write_outputs
    from ffdcli.quality import enforce

    t0 = time.perf_counter()
    design = load_design(design_file, overrides=overrides)
    out_mesh = Path(output) if output else design.output["mesh"]
    from ffdcli.atomic import check_writable

    given = set(design.data.get("output") or {})
    want_plot = plot or "plot" in given
    # Default outputs go to out/ beside the design file: create it. A folder the user named must exist.
    for key, cli_value in (("mesh", output), ("lattice", lattice_out), ("plot", None)):
        if cli_value is None and key not in given and (key != "plot" or want_plot):
            Path(design.output[key]).parent.mkdir(parents=True, exist_ok=True)
    # Every output is checked before minutes of work, not after.
    check_writable(out_mesh, inputs=(design.mesh, design.path))
    out_lattice = Path(lattice_out) if lattice_out else Path(design.output["lattice"])
    check_writable(out_lattice, inputs=(design.mesh, out_mesh, design.path))
    if out_lattice.suffix.lower() != ".vtk":
        raise InputError("the lattice is written as legacy VTK: give it a .vtk name", path=out_lattice)
    png = None
    if want_plot:
        png = Path(design.output["plot"]) if "plot" in given else Path(out_mesh).with_suffix(".png")
        check_writable(png, inputs=(design.mesh, out_mesh, out_lattice, design.path))
        if png.suffix.lower() != ".png":
            raise InputError("pictures are written as PNG: give it a .png name", path=png)
        check_writable(png.with_name(png.stem + "_3d.png"),
                       inputs=(design.mesh, out_mesh, out_lattice, design.path))
    if surface_file is not None:
        check_writable(surface_file, inputs=(design.mesh, out_mesh, out_lattice, design.path))
    comm = console.comm
    run = load_run(design, cache_dir=cache_dir, use_cache=not no_cache, progress=console.progress, comm=comm)
    for w in run.prep.warnings:
        console.warn(w)
    if run.prep.summary()["outside"]:
        console.warn(f"{run.prep.summary()['outside']} surface points are outside the lattice and "
                     "will not move")
    result = deform(run, progress=console.progress)
    q = result.quality
    qd = q.to_dict() if q is not None else None
    # the gate: exit 2 for cells already bad in the input, exit 3 for what the design broke
    for w in enforce(q, mesh_path=design.mesh, design_path=design.path, force=force):
        console.warn(w)

    def write():             # every output once: rank 0 of an MPI run
        out = write_outputs(run, result, mesh_path=out_mesh, lattice_path=lattice_out,
                            surface_file=surface_file, progress=console.progress)
        if png is not None:
            from ffdcli.plot import plot_design

            plot_design(run, result, png)
            out["plot"] = str(png)
            if run.box.dim == 3:
                from ffdcli.plot import plot_3d

                got = plot_3d(run, result, png.with_name(png.stem + "_3d.png"))
                if got is None:
                    console.warn("no 3D view: pyvista or an off-screen OpenGL backend is missing "
                                 "(pip install 'ffdcli[viz]')")
                else:
                    out["plot_3d"] = str(got)
        return out

    written = comm.root_then_bcast(write)
    su2_ffd = written.pop("su2_ffd", None)
    if su2_ffd is not None and su2_ffd.get("outside"):
        console.warn(f"{su2_ffd['outside']} surface nodes are now outside the mesh's own SU2 FFD box(es): "
                     "SU2's FFD design variables will not move them; enlarge the SU2 box "
                     "(FFD_DEFINITION, then DV_KIND= FFD_SETTING) before using SU2's FFD on this mesh")
    secs = time.perf_counter() - t0
    summary = {
        "design": str(design.path),
        "mesh": str(design.mesh),
        "output": written["mesh"],
        "lattice_file": written.get("lattice"),
        "plot": written.get("plot"),
        "plot_3d": written.get("plot_3d"),
        "surface_file": written.get("surface_file"),
        "changes": [next(iter(c)) for c in design.changes_spec],
        "lattice": list(run.box.lattice_shape),
        "surface_points": int(len(run.prep.surface.ids)),
        "max_displacement": result.max_displacement,
        "volume": result.volume_method,
        "quality": qd,
        "su2_ffd": su2_ffd,
        "cache": str(run.prep.cache) if run.prep.cache else None,
        "from_cache": run.prep.from_cache,
        "seconds": round(secs, 3),
    }
    lines = [
        f"ffd deform: {Path(design.path).name} on {Path(design.mesh).name} "
        f"({len(run.prep.surface.ids)} surface points, lattice {' x '.join(map(str, run.box.lattice_shape))}"
        f", box {'from cache' if run.prep.from_cache else 'built'})",
        f"  changes   {', '.join(summary['changes']) or '(none)'}",
        f"  moved     max surface displacement {result.max_displacement:.4g}; volume: {result.volume_method}",
    ]
    if q is not None:
        lines.append(f"  quality   {q.summary()}")
    if su2_ffd is not None:
        from ffdcli.formats.su2_ffd import describe

        lines.append(f"  su2 ffd   {describe(su2_ffd)}")
    lines += [f"  wrote     {p}" for p in written.values()]
    lines.append(f"  time      {secs:.2f} s")
    console.result(summary, "\n".join(lines))
