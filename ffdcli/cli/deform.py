"""``ffd deform DESIGN.yaml``: apply the design's changes and write the deformed mesh."""

from __future__ import annotations

import time
from pathlib import Path

import click

from ffdcli.cli import cli, common_options


@cli.command("deform")
@click.argument("design_file", metavar="DESIGN.yaml", type=click.Path(dir_okay=False))
@click.option("--set", "overrides", multiple=True, metavar="KEY=VALUE",
              help="Override one value of the design file, e.g. --set changes.0.twist.tip=12 "
                   "(repeatable; the key path uses list positions).")
@click.option("--output", "-o", type=click.Path(dir_okay=False), metavar="FILE",
              help="Write the deformed mesh here instead of the file's output.mesh; the lattice and the "
                   "picture are named after it (out/t5.su2 -> out/t5_lattice.vtk, out/t5.png) unless "
                   "--lattice is given.")
@click.option("--lattice", "lattice_out", type=click.Path(dir_okay=False), metavar="FILE.vtk",
              help="Write the lattice here (a .vtk name) instead of the file's output.lattice.")
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
    under half its quality and under 0.01 or the input's worst) or drops a node's orthogonality below 20
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
    from ffdcli.io.outputs import plan_deform

    t0 = time.perf_counter()
    design = load_design(design_file, overrides=overrides)
    plan = plan_deform(design, mesh=output, lattice=lattice_out, plot=plot,    # every output, before the work
                       extra=[("surface_file", surface_file, False, "--surface-file")])
    # the heavy part, once the input is checked
    from ffdcli.app.pipeline import deform, load_run, write_outputs
    from ffdcli.quality.gate import enforce

    comm = console.comm
    # MPI: each rank keeps its local mesh (its nodes, their halo, every marker node), never every node
    run = load_run(design, cache_dir=cache_dir, use_cache=not no_cache, progress=console.progress, comm=comm,
                   local=True)
    for comp in run.components:
        who = f"{comp.name}: " if comp.name else ""
        for w in comp.prep.warnings:
            console.warn(who + w)
        if comp.prep.summary()["outside"]:
            console.warn(f"{who}{comp.prep.summary()['outside']} surface points are outside the lattice and "
                         "will not move")
    result = deform(run, progress=console.progress)
    q = result.quality
    qd = q.to_dict() if q is not None else None
    # the gate: exit 2 for cells already bad in the input, exit 3 for what the design broke
    for w in enforce(q, mesh_path=design.mesh, design_path=design.path, force=force,
                     recovery=result.recovery):
        console.warn(w)
    constraints = None
    if design.data.get("constraints"):     # evaluated before writing: a bad item is exit 2, nothing written
        from ffdcli.api import constraints_report

        constraints = constraints_report(run)
    # every output once, together: rank 0 of an MPI run (every node's coordinates gathered there)
    written = write_outputs(run, result, plan=plan, progress=console.progress, comm=comm)
    su2_ffd = written.pop("su2_ffd", None)
    if su2_ffd is not None and su2_ffd.get("outside"):
        console.warn(f"{su2_ffd['outside']} surface nodes are now outside the mesh's own SU2 FFD box(es): "
                     "SU2's FFD design variables will not move them; enlarge the SU2 box "
                     "(FFD_DEFINITION, then DV_KIND= FFD_SETTING) before using SU2's FFD on this mesh")
    if "plot_3d" in plan and "plot_3d" not in written and run.box.dim == 3:
        console.warn("no 3D view: pyvista or an off-screen OpenGL backend is missing "
                     "(pip install 'ffdcli[viz]')")
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
        "surface_points": int(len(run.surface_ids)),
        "max_displacement": result.max_displacement,
        "volume": result.volume_method,
        "recovery": result.recovery,
        "recovered_with": result.recovered_with,
        "quality": qd,
        "su2_ffd": su2_ffd,
        "constraints": constraints,
        "cache": str(run.prep.cache) if run.prep.cache else None,
        "from_cache": run.prep.from_cache,
        "seconds": round(secs, 3),
    }
    if not run.single:
        summary["components"] = [{"name": c.name, "surface": list(c.prep.surface.names),
                                  "lattice": list(c.box.lattice_shape), "root_on": c.summary()["root_on"],
                                  "changes": [next(iter(x)) for x in c.spec.changes_spec]} for c in run.components]
    head = (f"ffd deform: {Path(design.path).name} on {Path(design.mesh).name} ({len(run.surface_ids)} surface "
            f"points, " + (f"lattice {' x '.join(map(str, run.box.lattice_shape))}, box "
                           f"{'from cache' if run.prep.from_cache else 'built'})" if run.single else
                           f"{len(run.components)} components)"))
    per = [f"  {c['name']:<9} lattice {' x '.join(map(str, c['lattice']))}, changes "
           f"{', '.join(c['changes']) or '(none)'}" + (f"; root on {c['root_on']!r}" if c["root_on"] else "")
           for c in summary.get("components", [])]
    lines = [
        head,
        *([f"  changes   {', '.join(summary['changes']) or '(none)'}"] if run.single else per),
        *([f"  root      on the body {run.components[0].junction.marker!r} (its nodes and the junction do "
            f"not move)"] if run.single and run.components[0].junction is not None else []),
        f"  moved     max surface displacement {result.max_displacement:.4g}; volume: {result.volume_method}"
        + (f" (recovered: {result.recovered_with}, after the design's settings failed the gate)"
           if result.recovered_with else ""),
    ]
    if q is not None:
        lines.append(f"  quality   {q.summary()}")
    if constraints is not None:
        bad = [c["name"] for c in constraints if not c["satisfied"]]
        lines.append(f"  constraints {len(constraints)} items, " + (f"{len(bad)} not satisfied: {', '.join(bad[:5])}"
                                                                    if bad else "all satisfied"))
    if su2_ffd is not None:
        from ffdcli.io.formats.su2_ffd import describe

        lines.append(f"  su2 ffd   {describe(su2_ffd)}")
    lines += [f"  wrote     {p}" for v in written.values() for p in (v if isinstance(v, list) else [v])]
    lines.append(f"  time      {secs:.2f} s")
    console.result(summary, "\n".join(lines))
