"""``ffd deform``'s workflow: plan the outputs, load the run, deform, gate, write; a report comes back.

The command line (:mod:`ffdcli.cli.deform`) parses its options, calls :func:`deform_design` and
prints the report; :meth:`ffdcli.api.DesignModel.write` calls the same function with the run it
keeps, so a script and the command write the same files by the same rules.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from ffdcli.app.deformation import Deformation, deform
from ffdcli.app.prepare import is_surface_mesh
from ffdcli.app.run import DesignRun, load_run
from ffdcli.app.write import write_outputs
from ffdcli.design import load_design
from ffdcli.io.formats.su2_ffd import describe
from ffdcli.io.outputs import plan_deform
from ffdcli.quality.gate import Remedies, enforce
from ffdcli.quality.wall_layer import enforce_wall_layer


@dataclass(frozen=True)
class DeformReport:
    """What one ``ffd deform`` did: the summary of ``--json``, the written files, the warnings.

    summary
        The JSON object of ``ffd deform --json`` (files, lattice, displacement, quality, recovery,
        constraints, times).
    written
        ``{output kind: path}`` of every file written.
    text
        The summary as ``ffd deform`` prints it.
    warnings
        What the user should know (surface points outside the lattice, notes of the box, SU2's own
        FFD box no longer covering the surface, a missing 3D view, cells accepted by ``--force``).
    """

    summary: dict
    written: dict
    warnings: tuple[str, ...] = field(default=())
    text: str = ""


def _size(shape) -> str:
    return " x ".join(map(str, shape))


def deform_design(design, *, output=None, lattice=None, surface_file=None, plot: bool = False,
                  force: bool = False, cache_dir=None, use_cache: bool = True, progress=None, comm=None,
                  run: DesignRun | None = None, P=None,
                  constraints_table: Callable[[DesignRun, object], list[dict]] | None = None,
                  warn: Callable[[str], None] | None = None, remedies: Remedies = Remedies()) -> DeformReport:
    """Deform a loaded design and write its outputs together: what ``ffd deform`` does.

    Parameters
    ----------
    design : ffdcli.design.Design
        The design file, loaded (``--set`` applied).
    output, lattice, surface_file : path, optional
        ``-o``, ``--lattice``, ``--surface-file`` (None: the design file's ``output:``, or none).
    plot : bool
        Also the pictures.
    force : bool
        Write a mesh the quality gate refuses (the refusal becomes a warning).
    cache_dir, use_cache, progress, comm
        As :func:`ffdcli.app.run.load_run`; under MPI each rank keeps its local mesh.
    run, P : optional
        A run already loaded (the API's) and its deformed lattice(s); default: loaded here, the
        design's own changes.
    constraints_table : callable, optional
        ``f(run, points) -> rows`` of the constraints table (``points`` (N, 3): the deformed mesh,
        which ``mesh_quality`` reads), evaluated before anything is written when the design has
        ``constraints:`` (a bad item is an input error, nothing written).
    remedies : ffdcli.quality.gate.Remedies
        The caller's words for how to override the gate (the command line names ``--force``).
    warn : callable, optional
        Called with each warning as it arises (the command line prints it at once, so that a run the
        gate then refuses still shows what was noticed before); the report keeps them all.

    Every output is checked before the work (:func:`ffdcli.io.outputs.plan_deform`); the gate
    (:func:`ffdcli.quality.gate.enforce`) raises before anything is written unless ``force``.
    """
    t0 = time.perf_counter()
    plan = plan_deform(design, mesh=output, lattice=lattice, plot=plot,    # every output, before the work
                       extra=[("surface_file", surface_file, False, "--surface-file")])
    warnings: list[str] = []

    def note(text: str) -> None:
        warnings.append(text)
        if warn is not None:
            warn(text)
    if run is None:      # MPI: each rank keeps its local mesh (its nodes, their halo, every marker node)
        run = load_run(design, cache_dir=cache_dir, use_cache=use_cache, progress=progress, comm=comm, local=True)
    for comp in run.components:
        who = f"{comp.name}: " if comp.name else ""
        for w in comp.prep.warnings:
            note(who + w)
        outside = comp.prep.summary()["outside"]
        if outside:
            note(f"{who}{outside} surface points are outside the lattice and will not move")
    result = deform(run, P=P, progress=progress)
    if result.volume_method == "none" and run.prep.mesh.n_cells and not is_surface_mesh(run.prep.mesh):
        note("volume.method none: the volume mesh was not moved and its cells are not judged (the "
             "gate judges what ffd moves); the written mesh keeps the input's volume nodes, so cells "
             "beside the moved surface may be inverted in it: move the volume with SU2_DEF "
             "(DV_KIND= SURFACE_FILE, from --surface-file) or your own tool before a solver runs on it")
    # the gate: exit 2 for cells already bad in the input, exit 3 for what the design broke
    for w in enforce(result.quality, mesh_path=design.mesh, design_path=design.path, force=force,
                     recovery=result.recovery, remedies=remedies, hints=device_hints(run)):
        note(w)
    for w in enforce_wall_layer(result.wall_layer, design_path=design.path, force=force,
                                refuse="first_cell" in (design.volume or {}),
                                write_anyway=remedies.write_anyway, forced=remedies.forced):
        note(w)
    constraints = (constraints_table(run, result.points) if constraints_table and design.data.get("constraints")
                   else None)
    # every output once, together: rank 0 of an MPI run (every node's coordinates gathered there)
    written = write_outputs(run, result, plan=plan, progress=progress, comm=comm)
    su2_ffd = written.pop("su2_ffd", None)
    if su2_ffd is not None and su2_ffd.get("outside"):
        note(f"{su2_ffd['outside']} surface nodes are now outside the mesh's own SU2 FFD box(es): SU2's "
                        "FFD design variables will not move them; enlarge the SU2 box (FFD_DEFINITION, then "
                        "DV_KIND= FFD_SETTING) before using SU2's FFD on this mesh")
    if "plot_3d" in plan and "plot_3d" not in written and run.box.dim == 3:
        note("no 3D view: pyvista or an off-screen OpenGL backend is missing (pip install 'ffdcli[viz]')")
    summary = _summary(design, run, result, written, su2_ffd, constraints, time.perf_counter() - t0)
    return DeformReport(summary=summary, written=written, warnings=tuple(warnings),
                        text=_text(summary, run, result, written))


def deform_file(design_file, overrides=(), **kwargs) -> DeformReport:
    """``ffd deform DESIGN.yaml``: the design file loaded (``--set`` ``overrides`` applied), then
    :func:`deform_design` with ``kwargs``."""
    return deform_design(load_design(design_file, overrides=overrides), **kwargs)


def _summary(design, run: DesignRun, result: Deformation, written: dict, su2_ffd, constraints,
             seconds: float) -> dict:
    q = result.quality
    summary = {
        "design": str(design.path),
        "mesh": str(design.mesh),
        "output": written["mesh"],
        "lattice_file": written.get("lattice"),
        "plot": written.get("plot"),
        "plot_3d": written.get("plot_3d"),
        "surface_file": written.get("surface_file"),
        "changes": [next(iter(c)) for c in design.changes_spec],
        "devices": {f"c{i}": ch.describe() for comp in run.components for i, ch in enumerate(comp.changes)
                    if hasattr(ch, "describe")},
        "lattice": list(run.box.lattice_shape),
        "surface_points": int(len(run.surface_ids)),
        "max_displacement": result.max_displacement,
        "volume": result.volume_method,
        "recovery": result.recovery,
        "recovered_with": result.recovered_with,
        "quality": q.to_dict() if q is not None else None,
        "wall_layer": result.wall_layer.to_dict() if result.wall_layer is not None else None,
        "su2_ffd": su2_ffd,
        "constraints": constraints,
        "cache": str(run.prep.cache) if run.prep.cache else None,
        "from_cache": run.prep.from_cache,
        "seconds": round(seconds, 3),
    }
    if not run.single:
        summary["components"] = [{"name": c.name, "surface": list(c.prep.surface.names),
                                  "lattice": list(c.box.lattice_shape), "root_on": c.summary()["root_on"],
                                  "changes": [next(iter(x)) for x in c.spec.changes_spec]} for c in run.components]
    return summary


def squeezed_blends(d: dict) -> list[tuple[str, str, float]]:
    """(end, edge, width) of each blend of a device (its ``describe()``) that the root or tip
    leaves narrower than set: there the rotation fades faster."""
    return [(end, edge, w) for end, edge, w in zip(("inner", "outer"), ("root", "tip"), d.get("blends") or ())
            if w is not None and w < d["blend"] - 1e-12]


def _squeezed(d: dict) -> str:
    return "".join(f"; {end} only {w:g}, the {edge} is nearer" for end, edge, w in squeezed_blends(d))


def device_hints(run: DesignRun) -> list[str]:
    """What a refused design could change in its devices: where the root or tip squeezes a blend,
    the device's rotation fades over less span than set (the usual cause of the cells it inverts;
    letting the device reach the root instead inverted as many on the robustness table's meshes)."""
    return [f"c{i}'s {d['kind']} fades over only {w:g} of the span at its {end} end (the {edge} is nearer "
            f"than its blend {d['blend']:g}): end it at least {d['blend']:g} from the {edge}"
            for comp in run.components for i, ch in enumerate(comp.changes) if hasattr(ch, "describe")
            for d in [ch.describe()] for end, edge, w in squeezed_blends(d)]


def device_line(name: str, d: dict) -> str:
    """One flap or slat as ``ffd deform`` prints it, with the chord width of its transition."""
    where = "behind" if d["kind"] == "flap" else "ahead of"
    span = f", span {d['span'][0]:g}-{d['span'][1]:g} (blend {d['blend']:g}{_squeezed(d)})" if d["span"] else ""
    return (f"  {d['kind']:<9} {name}: {d['angle']:g} deg{span}, hinge {'/'.join(f'{h:g}' for h in d['hinge'])} "
            f"of the local chord; turns rigidly beyond a transition of {d['transition']:.3f} local chords "
            f"{where} the hinge")


def _text(s: dict, run: DesignRun, result: Deformation, written: dict) -> str:
    """The summary as ``ffd deform`` prints it."""
    comps = s.get("components")
    head = (f"ffd deform: {Path(s['design']).name} on {Path(s['mesh']).name} ({s['surface_points']} surface "
            "points, " + (f"lattice {_size(s['lattice'])}, box {'from cache' if s['from_cache'] else 'built'})"
                          if not comps else f"{len(comps)} components)"))
    lines = [head]
    if comps:
        lines += [f"  {c['name']:<9} lattice {_size(c['lattice'])}, changes {', '.join(c['changes']) or '(none)'}"
                  + (f"; root on {c['root_on']!r}" if c["root_on"] else "") for c in comps]
    else:
        lines.append(f"  changes   {', '.join(s['changes']) or '(none)'}")
        junction = run.components[0].junction
        if junction is not None:
            lines.append(f"  root      on the body {junction.marker!r} (its nodes and the junction do not move)")
    lines += [device_line(name, d) for name, d in s["devices"].items()]
    lines.append(f"  moved     max surface displacement {s['max_displacement']:.4g}; volume: {s['volume']}"
                 + (f" (recovered: {s['recovered_with']}, after the design's settings failed the gate)"
                    if s["recovered_with"] else ""))
    if result.quality is not None:
        lines.append(f"  quality   {result.quality.summary()}")
    if result.wall_layer is not None:
        lines.append(f"  wall      {result.wall_layer.summary()}")
    if s["constraints"] is not None:
        bad = [c["name"] for c in s["constraints"] if not c["satisfied"]]
        lines.append(f"  constraints {len(s['constraints'])} items, "
                     + (f"{len(bad)} not satisfied: {', '.join(bad[:5])}" if bad else "all satisfied"))
    if s["su2_ffd"] is not None:
        lines.append(f"  su2 ffd   {describe(s['su2_ffd'])}")
    lines += [f"  wrote     {p}" for v in written.values() for p in (v if isinstance(v, list) else [v])]
    lines.append(f"  time      {s['seconds']:.2f} s")
    return "\n".join(lines)
