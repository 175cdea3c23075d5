"""Robustness of the volume-mesh follow: plausible designs x wing meshes, with the default settings.

For every mesh and design, the design file is deformed exactly as ``ffd deform`` does
(:func:`ffdcli.app.pipeline.deform`, the quality gate of :mod:`ffdcli.quality.gate`) and the table shows
whether the gate refused it, the inverted cells, the minimum scaled Jacobian before -> after and
SU2's node orthogonality of the gate (the smallest before -> after, and the largest loss of a
node), and the ``mesh_quality`` constraint's value on the deformed mesh (:mod:`ffdcli.constraints.mesh_quality`:
the smooth minimum over the cells of quality after / before; its default bound is 0.3). Target: 0
refusals and 0 inverted cells with the default ``volume:`` settings, and every design above the
``mesh_quality`` bound.

RANS meshes (SU2's RAE2822 of ``../shared/data``, a NACA 0012 O-mesh with a first cell of 1e-6 chord
and 70 layers, a NACA 2412 C-mesh with a sharp trailing edge and a conforming wake cut (129 points
round the airfoil, 33 along the cut, 65 off the wall, first cell 1e-6: ``ffdcli.testing.cmesh``),
``gen:rect_z_rans32``: 32 prism layers from 1e-6) add the wall layer's figures: the
first-cell height after / before (min-max) and the off-wall angle change at the wall nodes
(:mod:`ffdcli.quality.wall_layer`; the first cells changed by more than 1 %: ffd deform's warning); the airfoils
run the ``2d_`` designs on a 10 x 2 lattice.

Meshes: the bundled wings (``samples/rect_wing.su2``, ``samples/crm_wing.su2``), the ONERA M6 of
``../shared/data`` (skipped when absent) and the generated wings of :mod:`ffdcli.testing.gmsh_wings`
(``gen:<case>``: span along x, y and z, left and right, kinked, flat and round tips, blunt trailing
edge, prism layers, far field at 5 and 50 chords). Generated meshes, design files and box caches go
to ``--work`` (default ``out/robustness`` of the repository).

Run alone, for quick iteration on the warp settings::

    python -m benchmarks.bench_robustness --quick
    python -m benchmarks.bench_robustness --mesh gen:transport_x_bl --design sweep+10 --set volume.alpha=1.0
    python -m benchmarks.bench_robustness --list
    python -m benchmarks.bench_robustness --json rows.json --compare rows_before.json   # row by row
    python -m benchmarks.bench_robustness --compare rows_before.json rows.json          # two files, no run

It is also part of ``make bench`` (``python -m benchmarks``), whose ``--quick`` runs the quick form.

The multi-component forms come after the matrix: the bundled wing + tail + fin
(``samples/wing_tail_fin.su2``, three components) and wing on a body (``samples/wing_body.su2``, the root
on the fuselage) under planform designs of one or every component, several of which need the
recovery. Target: no crash; every outcome 0 (written) or 3 (refused by the gate, with its reason)::

    python -m benchmarks.bench_robustness --multi
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

REPO = Path(__file__).resolve().parents[1]
TITLE = "Robustness: designs x meshes with the default volume settings (target 0 refused, 0 inverted)"
NOTES = ("Cells of the matrix: ok (with how many cells/nodes the gate found shaped by the design's own map, "
         "and whether a recovery attempt was needed), or **R** (the gate of ffd deform would exit 3) with the "
         "cells inverted "
         "(inv), made worse (worse) and the nodes that lost orthogonality (ortho); INPUT / ERROR: another "
         "failure. Details: q = min scaled Jacobian before->after; ortho = min node orthogonality (SU2's, "
         "degrees) before->after and the largest loss of one node; mq = the mesh_quality constraint's value "
         "(smooth min over the cells of quality after / before, default bound 0.3). "
         "`python -m benchmarks.bench_robustness --help` runs one mesh or design.")


# ----------------------------------------------------------------------------------------------
# Designs (changes lists; m = sections of the box, chord = root chord of the mesh)
# ----------------------------------------------------------------------------------------------

def _designs() -> dict:
    def bump(m, chord):
        eta = np.linspace(0.0, 1.0, m)
        return [{"twist": [round(float(v), 4) for v in 10.0 * np.sin(np.pi * eta)]}]

    def washout_list(m, chord):
        eta = np.linspace(0.0, 1.0, m)
        return [{"twist": [round(float(v), 4) for v in 2.0 - 12.0 * eta ** 2]}]

    d = {
        "twist_tip+10": [{"twist": {"tip": 10}}],
        "twist_tip-10": [{"twist": {"tip": -10}}],
        "twist_root+tip": [{"twist": {"root": -4, "tip": 10}}],
        "twist_list_bump": bump,
        "twist_list_washout": washout_list,
        "sweep+10": [{"sweep": 10}],
        "sweep+5": [{"sweep": 5}],
        "sweep-5": [{"sweep": -5}],
        "sweep-10": [{"sweep": -10}],
        "span0.85": [{"span": 0.85}],
        "span1.1": [{"span": 1.1}],
        "span1.15": [{"span": 1.15}],
        "dihedral+5": [{"dihedral": 5}],
        "dihedral-5": [{"dihedral": -5}],
        "chord_tip0.5": [{"chord": {"tip": 0.5}}],
        "chord_tip0.6": [{"chord": {"tip": 0.6}}],
        "chord_tip0.7": [{"chord": {"tip": 0.7}}],
        "chord_tip1.4": [{"chord": {"tip": 1.4}}],
        "chord_tip1.5": [{"chord": {"tip": 1.5}}],
        "chord_root0.8": [{"chord": {"root": 0.8, "tip": 1.0}}],
        "chord_root1.2": [{"chord": {"root": 1.2, "tip": 1.0}}],
        "shape_random": lambda m, chord: [{"shape": {"random": round(0.015 * chord, 6), "seed": 7}}],
        "span1.1+sweep5": [{"span": 1.1}, {"sweep": 5}],
        "mix4_a": [{"twist": {"tip": 8}}, {"span": 1.1}, {"sweep": 5}, {"dihedral": 3}],
        "mix4_b": [{"chord": {"tip": 0.6}}, {"sweep": -8}, {"twist": {"root": 2, "tip": -6}}, {"dihedral": -4}],
        "mix4_c": [{"span": 1.15}, {"sweep": 10}, {"twist": {"tip": -10}}, {"chord": {"tip": 0.5}}],
        # control surfaces, default blend and transition
        **{f"flap{a}": [{"flap": {"span": [0.2, 0.6], "hinge": 0.75, "angle": a}}] for a in (10, 20, 30)},
        "slat15": [{"slat": {"span": [0.1, 0.9], "hinge": 0.15, "angle": 15}}],
        # devices elsewhere on the span, a tapered hinge, a device near the root, one with a twist
        # (added after the blend's ramp was chosen: held out from that choice)
        "flap_mid10": [{"flap": {"span": [0.3, 0.7], "hinge": 0.7, "angle": 10}}],
        "flap_mid25": [{"flap": {"span": [0.3, 0.7], "hinge": 0.7, "angle": 25}}],
        "flap_out20_tapered": [{"flap": {"span": [0.5, 0.9], "hinge": [0.8, 0.75], "angle": 20}}],
        "flap_root30": [{"flap": {"span": [0.05, 0.45], "hinge": 0.72, "angle": 30}}],
        "slat_mid20": [{"slat": {"span": [0.2, 0.8], "hinge": 0.12, "angle": 20}}],
        "flap15+twist": [{"flap": {"span": [0.25, 0.65], "hinge": 0.75, "angle": 15}}, {"twist": {"tip": -5}}],
        # 2D (the RANS airfoils, a 10 x 2 lattice): twist, chord (the planform of an airfoil), shape, devices
        **{f"2d_twist{a:+d}": [{"twist": {"angle": a, "axis": 0.25}}] for a in (-20, -5, 5, 20)},
        "2d_chord0.9": [{"chord": 0.9}],
        **{f"2d_shape_random{p}%": (lambda q: lambda m, chord: [{"shape": {"random": round(q / 100 * chord, 6),
                                                                             "seed": 7}}])(p) for p in (1, 5)},
        "2d_flap10": [{"flap": {"hinge": 0.75, "angle": 10}}],
        "2d_slat10": [{"slat": {"hinge": 0.15, "angle": 10}}],
    }
    return d


DESIGNS = _designs()
QUICK_DESIGNS = ["twist_tip+10", "sweep+10", "span1.15", "dihedral+5", "chord_tip0.5", "chord_tip0.7",
                 "shape_random", "mix4_a"]


# ----------------------------------------------------------------------------------------------
# Meshes
# ----------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class MeshSource:
    name: str
    surface: str
    bundled: str | None = None      # a path (relative to the repo, or absolute)
    case: str | None = None         # a ffdcli.testing.gmsh_wings case
    ogrid: tuple | None = None      # (NACA code, points around, nodes off the wall, first cell): ffdcli.testing.ogrid
    cmesh: tuple | None = None      # (NACA code, points around, along the cut, off the wall, first cell):
    #                                 ffdcli.testing.cmesh
    dim: int = 3

    def path(self, work: Path) -> Path | None:
        """The mesh file (generated into ``work`` when needed); None when it is not available."""
        if self.case is not None:
            from ffdcli.testing import gmsh_wings as testmeshes

            try:
                import gmsh  # noqa: F401
            except ImportError:         # the [test] extra brings gmsh
                return None
            return testmeshes.write_case(self.case, work / "meshes")
        if self.ogrid is not None:
            from ffdcli.io.formats import write_mesh
            from ffdcli.testing.ogrid import airfoil_ogrid_mesh

            code, n_around, n_radial, first = self.ogrid
            p = work / "meshes" / f"ogrid_{code}_{n_around}x{n_radial}_{first:g}.su2"
            if not p.is_file():
                p.parent.mkdir(parents=True, exist_ok=True)
                write_mesh(airfoil_ogrid_mesh(code, n_around, n_radial, first_cell=first), p)
            return p
        if self.cmesh is not None:
            from ffdcli.io.formats import write_mesh
            from ffdcli.testing.cmesh import cmesh
            from ffdcli.testing.naca import naca4

            code, n_around, n_wake, n_normal, first = self.cmesh
            p = work / "meshes" / f"cmesh_{code}_{n_around}x{n_wake}x{n_normal}_{first:g}.su2"
            if not p.is_file():
                p.parent.mkdir(parents=True, exist_ok=True)
                write_mesh(cmesh(naca4(code, 161), n_around, n_wake, n_normal, first), p)
            return p
        p = Path(self.bundled)
        p = p if p.is_absolute() else REPO / p
        return p if p.is_file() else None


def _meshes() -> dict[str, MeshSource]:
    from ffdcli.testing.gmsh_wings import CASES

    out = {"rect_wing": MeshSource("rect_wing", "wing", bundled="samples/rect_wing.su2"),
           "crm_wing": MeshSource("crm_wing", "wing", bundled="samples/crm_wing.su2"),
           "oneram6": MeshSource("oneram6", "WING",
                                 bundled="/work/shared/data/oneram6/mesh_ONERAM6_gmsh_coarse.su2")}
    for name in CASES:
        out[f"gen:{name}"] = MeshSource(f"gen:{name}", "wing", case=name)
    # RANS airfoils (first cells of 1e-5 and 1e-6 chord): the wall layer's figures
    out["rans:rae2822"] = MeshSource("rans:rae2822", "AIRFOIL", dim=2, bundled="/work/shared/data/su2/"
                                     "deformation__rae2822__mesh_RAE2822_turb_ffd.su2")
    out["rans:ogrid_1e-6"] = MeshSource("rans:ogrid_1e-6", "airfoil", dim=2, ogrid=("0012", 193, 71, 1e-6))
    # a C-mesh: sharp trailing edge, the wake cut conforming (its two sides the same nodes), 1e-6 chord first cell
    out["rans:cmesh"] = MeshSource("rans:cmesh", "airfoil", dim=2, cmesh=("2412", 129, 33, 65, 1e-6))
    return out


MESHES = _meshes()
QUICK_MESHES = ["rect_wing", "crm_wing", "oneram6", "gen:rect_z_bl_ff5", "gen:left_swept_round",
                "gen:transport_x_ff50"]


# ----------------------------------------------------------------------------------------------
# One deformation
# ----------------------------------------------------------------------------------------------

def _write_design(folder: Path, mesh: Path, surface: str, name: str, changes: list, points) -> Path:
    data = {"mesh": str(mesh), "surface": surface, "box": {"points": list(points)}, "changes": changes,
            "output": {"mesh": str(folder / f"{name}.su2"), "lattice": str(folder / f"{name}_lattice.vtk")}}
    path = folder / f"{name}.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def run_one(mesh_path: Path, surface: str, design: str, *, work: Path, overrides=(), points=(6, 8, 2)) -> dict:
    """Deform one mesh by one design as ``ffd deform`` does; a row of the table (nothing written)."""
    from ffdcli.app.deformation import deform, design_zone
    from ffdcli.app.run import load_run
    from ffdcli.constraints import build_constraints
    from ffdcli.design import load_design
    from ffdcli.errors import InputError, QualityError

    folder = work / "designs" / mesh_path.stem
    folder.mkdir(parents=True, exist_ok=True)
    spec = DESIGNS[design]
    row = {"mesh": None, "design": design}
    t0 = time.perf_counter()
    try:
        if callable(spec):
            base = load_run(load_design(_write_design(folder, mesh_path, surface, "base", [], points)),
                            cache_dir=work / "cache")
            chord = float(np.linalg.norm(base.box.te_points[0] - base.box.le_points[0]))
            spec = spec(base.box.shape[1], chord)
        path = _write_design(folder, mesh_path, surface, design.replace("+", "p"), spec, points)
        run = load_run(load_design(path, overrides=overrides), cache_dir=work / "cache")
        result = deform(run)
    except (InputError, QualityError) as e:
        row.update(status="ERROR" if isinstance(e, QualityError) else "INPUT", error=str(e).splitlines()[0][:160],
                   seconds=round(time.perf_counter() - t0, 2))
        return row
    q, wall = result.quality, result.wall_layer
    row["status"] = "ok" if q is None or q.ok else "REFUSED"     # the first cells: ffd deform's warning
    if wall is not None:                # the first cells on the wall (a RANS mesh)
        row.update(first_cell=[wall.ratio_min, wall.ratio_max], off_wall=wall.angle_change, wall_failed=wall.n_failed)
    if q is not None:
        row.update(inverted=q.n_inverted, failed=q.n_failed, worse=q.n_worse, ortho_failed=q.n_ortho_failed,
                   input_bad=q.n_input_bad, q_before=q.min_before, q_after=q.min_after,
                   ortho_before=q.ortho_before, ortho_after=q.ortho_after, ortho_loss=q.ortho_loss,
                   by_design=q.n_design_cells + q.n_design_nodes)
    recovery = getattr(result, "recovery", None)
    row["recovered_with"] = result.recovered_with
    if recovery:
        row["recovery"] = recovery if isinstance(recovery, str) else json.dumps(recovery, default=str)
    if run.prep.mesh.n_cells:            # the constraint an optimiser would see, on the mesh as deformed
        mq, plain = build_constraints([{"mesh_quality": {}}, {"mesh_quality": {"good": 1.0}}], run.box,
                                      run.prep.surface, [], mesh=run.prep.mesh)
        zone, P = design_zone(run), result.lattice
        X_map = zone.apply(run.prep.mesh.points, run.surface_displacement(P), run.surface_frames(P, "gradient"))
        row["mesh_quality"] = round(float(mq.measure(result.points, X_map=X_map, zone=zone.mask)[0]), 4)
        row["mesh_quality_plain"] = round(float(plain.measure(result.points, X_map=X_map, zone=zone.mask)[0]), 4)
    row["max_disp"] = result.max_displacement
    row["seconds"] = round(time.perf_counter() - t0, 2)
    return row


def run_matrix(meshes: list[str], designs: list[str], *, work: Path, overrides=(), echo=None) -> list[dict]:
    """Every design on every mesh; rows in mesh-major order. Unavailable meshes are skipped."""
    rows = []
    for mname in meshes:
        src = MESHES[mname]
        path = src.path(work)
        if path is None:
            if echo:
                echo(f"(skipped {mname}: not present)")
            continue
        for d in [d for d in designs if d.startswith("2d_") == (src.dim == 2)]:
            row = run_one(path, src.surface, d, work=work, overrides=overrides,
                          points=(10, 2) if src.dim == 2 else (6, 8, 2))
            row["mesh"] = mname
            rows.append(row)
            if echo:
                echo(_line(row))
    return rows


# ----------------------------------------------------------------------------------------------
# Multi-component forms: (design file, changes per component)
# ----------------------------------------------------------------------------------------------

#: name -> (the bundled design file it starts from, {design: {component index: changes}})
MULTI = {
    "wing_tail_fin": ("configs/wing_tail_fin.yaml", {
        "htail_dihedral+10": {1: [{"dihedral": 10}]},
        "htail_dihedral-10": {1: [{"dihedral": -10}]},
        "htail_dihedral+15": {1: [{"dihedral": 15}]},
        "htail_sweep+15": {1: [{"sweep": 15}]},
        "htail_span1.3": {1: [{"span": 1.3}]},
        "wing_dihedral+8": {0: [{"dihedral": 8}]},
        "wing_sweep+10": {0: [{"sweep": 10}]},
        "wing_span1.15": {0: [{"span": 1.15}]},
        "wing_chord_tip0.5": {0: [{"chord": {"tip": 0.5}}]},
        "vfin_sweep+15": {2: [{"sweep": 15}]},
        "vfin_span1.2": {2: [{"span": 1.2}]},
        "vfin_sweep+25": {2: [{"sweep": 25}]},
        "all_planform": {0: [{"sweep": 8}, {"span": 1.1}], 1: [{"dihedral": 8}, {"chord": {"tip": 0.7}}],
                         2: [{"sweep": 12}]},
        "all_mix": {0: [{"twist": {"tip": -6}}, {"dihedral": 4}], 1: [{"sweep": -8}], 2: [{"span": 0.85}]},
    }),
    "wing_body": ("configs/wing_body.yaml", {
        "twist_tip+8": {0: [{"twist": {"tip": 8}}]},
        "dihedral+6": {0: [{"dihedral": 6}]},
        "dihedral-6": {0: [{"dihedral": -6}]},
        "sweep+10": {0: [{"sweep": 10}]},
        "sweep-10": {0: [{"sweep": -10}]},
        "sweep+20": {0: [{"sweep": 20}]},
        "dihedral+12": {0: [{"dihedral": 12}]},
        "span1.3": {0: [{"span": 1.3}]},
        "chord_tip0.4": {0: [{"chord": {"tip": 0.4}}]},
        "span1.15": {0: [{"span": 1.15}]},
        "chord_tip0.5": {0: [{"chord": {"tip": 0.5}}]},
        "mix": {0: [{"twist": {"tip": 6}}, {"span": 1.1}, {"sweep": 6}, {"dihedral": 4}]},
    }),
}


def run_multi_one(form: str, design: str, *, work: Path) -> dict:
    """One multi-component design as ``ffd deform`` runs it (recovery included); a row of the table.
    Any exception other than ffd's exit-2/3 errors is a CRASH (the target is none)."""
    from ffdcli.app.deformation import deform
    from ffdcli.app.run import load_run
    from ffdcli.design import load_design
    from ffdcli.errors import InputError, QualityError

    base, designs = MULTI[form]
    data = yaml.safe_load((REPO / base).read_text())
    data["mesh"] = str((REPO / base).parent / data["mesh"])
    comps = data.get("components")
    for index, changes in designs[design].items():
        if comps:
            comps[index]["changes"] = changes
        else:
            data["changes"] = changes
    data.pop("output", None)
    folder = work / "designs" / f"multi_{form}"
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{design.replace('+', 'p')}.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    row = {"mesh": f"multi:{form}", "design": design}
    t0 = time.perf_counter()
    try:
        result = deform(load_run(load_design(path), cache_dir=work / "cache"))
    except (InputError, QualityError) as e:
        row.update(status="INPUT" if isinstance(e, InputError) else "ERROR", error=str(e).splitlines()[0][:160])
    except Exception as e:  # noqa: BLE001 - what the table counts
        row.update(status="CRASH", error=f"{type(e).__name__}: {e}"[:160])
    else:
        q = result.quality
        row["status"] = "ok" if q is None or q.ok else "REFUSED"
        if q is not None:
            row.update(inverted=q.n_inverted, failed=q.n_failed, worse=q.n_worse, ortho_failed=q.n_ortho_failed,
                       q_before=q.min_before, q_after=q.min_after, by_design=q.n_design_cells + q.n_design_nodes)
            if not q.ok:
                row["reason"] = f"{q.n_failed} cells or nodes fail the gate ({q.n_inverted} inverted)"
        row["recovered_with"] = result.recovered_with
        if result.recovery:
            row["recovery"] = "; ".join(f"{a['attempt']}: {'ok' if a['ok'] else a['failed']}"
                                        for a in result.recovery)
        row["max_disp"] = result.max_displacement
    row["seconds"] = round(time.perf_counter() - t0, 2)
    return row


def run_multi(*, work: Path, forms=None, echo=None) -> list[dict]:
    """Every design of every multi-component form (:data:`MULTI`)."""
    rows = []
    for form in forms or list(MULTI):
        for design in MULTI[form][1]:
            row = run_multi_one(form, design, work=work)
            rows.append(row)
            if echo:
                echo(_line(row))
    return rows


def multi_summary(rows: list[dict]) -> str:
    """The exit statuses ``ffd deform`` would give: 0 written, 3 refused by the gate, 2 bad input,
    CRASH (target: none)."""
    code = {"ok": 0, "REFUSED": 3, "INPUT": 2, "ERROR": 3}
    counts: dict = {}
    for r in rows:
        k = code.get(r["status"], "CRASH")
        counts[k] = counts.get(k, 0) + 1
    recovered = sum(r["status"] == "ok" and bool(r.get("recovered_with")) for r in rows)
    return (f"{len(rows)} multi-component deformations: exit 0 x {counts.get(0, 0)}, exit 3 x {counts.get(3, 0)}, "
            f"exit 2 x {counts.get(2, 0)}, crashes {counts.get('CRASH', 0)}; {recovered} passed after a recovery")


def _fmt(v, spec=".3g"):
    return "-" if v is None else format(v, spec)


def _line(r: dict) -> str:
    s = f"{r['mesh']:<24} {r['design']:<20} {r['status']:<8}"
    if "error" in r:
        return s + " " + r["error"]
    s += (f" inv {r.get('inverted', 0):>5} worse {r.get('worse', 0):>5} ortho {r.get('ortho_failed', 0):>5}"
          + (f" input-bad {r['input_bad']}" if r.get("input_bad") else "")
          + (f" by-design {r['by_design']}" if r.get("by_design") else ""))
    s += f"  q {_fmt(r.get('q_before'))}->{_fmt(r.get('q_after'))}"
    if r.get("ortho_after") is not None:
        s += f"  ortho {_fmt(r.get('ortho_before'), '.1f')}->{_fmt(r.get('ortho_after'), '.1f')} deg"
        s += f" (loss {_fmt(r.get('ortho_loss'), '.1f')})"
    if r.get("mesh_quality") is not None:
        s += f"  mq {r['mesh_quality']:.3f}"
    if r.get("first_cell") is not None:
        s += f"  first cell {r['first_cell'][0]:.4f}-{r['first_cell'][1]:.4f} off-wall {r['off_wall']:.2f} deg"
    if "recovery" in r:
        s += f"  [{r['recovery']}]"
    return s + f"  {r['seconds']:.1f}s"


def matrix_table(rows: list[dict]) -> str:
    """Designs (rows) x meshes (columns): ok, or R<n inverted>/<n failed>, or ERR."""
    meshes = list(dict.fromkeys(r["mesh"] for r in rows))
    designs = list(dict.fromkeys(r["design"] for r in rows))
    cell = {(r["design"], r["mesh"]): r for r in rows}
    lines = ["| design | " + " | ".join(meshes) + " |", "|---" * (len(meshes) + 1) + "|"]
    for d in designs:
        out = []
        for m in meshes:
            r = cell.get((d, m))
            if r is None:
                out.append("")
            elif r["status"] == "ok":
                notes = ([f"{r['by_design']} by design"] if r.get("by_design") else []) + \
                    (["recovered"] if r.get("recovered_with") else [])
                notes += [f"mq {r['mesh_quality']:.2f}"] if r.get("mesh_quality") is not None else []
                notes += ([f"fc {r['first_cell'][0]:.4f}-{r['first_cell'][1]:.4f}, {r['off_wall']:.2f} deg"
                           + (f", {r['wall_failed']} > 1 %" if r.get("wall_failed") else "")]
                          if r.get("first_cell") is not None else [])
                out.append("ok" + (f" ({', '.join(notes)})" if notes else ""))
            elif r["status"] == "REFUSED":
                parts = [f"{r[k]} {w}" for k, w in (("inverted", "inv"), ("worse", "worse"),
                                                      ("ortho_failed", "ortho"), ("wall_failed", "first cells"))
                         if r.get(k)]
                out.append("**R** " + ", ".join(parts))
            else:
                out.append(r["status"])
        lines.append(f"| {d} | " + " | ".join(out) + " |")
    refused = sum(r["status"] == "REFUSED" for r in rows)
    errors = sum(r["status"] not in ("ok", "REFUSED") for r in rows)
    inverted = sum(r.get("inverted", 0) for r in rows)
    by_design = sum(bool(r.get("by_design")) for r in rows)
    recovered = sum(bool(r.get("recovered_with")) for r in rows)
    mq = [r["mesh_quality"] for r in rows if r.get("mesh_quality") is not None]
    worst = min(mq, default=None)
    lines.append(f"\n{len(rows)} deformations: {refused} refused, {inverted} inverted cells in all, "
                 f"{errors} errors; {recovered} passed after a recovery, {by_design} with cells or nodes "
                 "shaped by the design's own map (accepted); mesh_quality: min over designs "
                 + ("-" if worst is None else f"{worst:.3f}, {sum(v < 0.3 for v in mq)} below 0.3")
                 + _plain_note(rows))
    return "\n".join(lines)


# ----------------------------------------------------------------------------------------------
# make bench / command line
# ----------------------------------------------------------------------------------------------

def run(quick: bool = False) -> list[dict]:
    """Rows for ``python -m benchmarks`` (quick: the quick meshes and designs)."""
    work = REPO / "out" / "robustness"
    meshes = QUICK_MESHES if quick else list(MESHES)
    designs = QUICK_DESIGNS if quick else list(DESIGNS)
    rows = run_matrix(meshes, designs, work=work)
    print(matrix_table(rows) + "\n", flush=True)
    multi = run_multi(work=work)
    print(matrix_table(multi) + "\n" + multi_summary(multi) + "\n", flush=True)
    return rows + multi


def compare_rows(before: list[dict], after: list[dict]) -> list[str]:
    """Row by row (matched by mesh and design): the rows of one side only and every field that differs
    (the seconds left out), one line per row. Empty when the tables are identical."""
    a = {(r["mesh"], r["design"]): r for r in before}
    b = {(r["mesh"], r["design"]): r for r in after}
    out = [f"only in the first: {k[0]} / {k[1]}" for k in a if k not in b]
    out += [f"only in the second: {k[0]} / {k[1]}" for k in b if k not in a]
    for k in (k for k in a if k in b):
        fields = sorted((set(a[k]) | set(b[k])) - {"seconds"})
        diff = [f"{f} {a[k].get(f)!r} -> {b[k].get(f)!r}" for f in fields if a[k].get(f) != b[k].get(f)]
        if diff:
            out.append(f"{k[0]} / {k[1]}: " + "; ".join(diff))
    return out


def _plain_note(rows: list[dict]) -> str:
    """The plain ratio's figures (``good: 1``: the reference not capped), for comparison."""
    plain = [r["mesh_quality_plain"] for r in rows if r.get("mesh_quality_plain") is not None]
    if not plain:
        return ""
    return f" (plain ratio, good 1: min {min(plain):.3f}, {sum(v < 0.3 for v in plain)} below 0.3)"


def summary(rows: list[dict]) -> list[dict]:
    refused = sum(r["status"] == "REFUSED" for r in rows)
    errors = sum(r["status"] not in ("ok", "REFUSED") for r in rows)
    inverted = sum(r.get("inverted", 0) for r in rows)
    return [{"case": f"{len(rows)} deformations: refused", "measured": refused, "target": "0", "met": refused == 0},
            {"case": "inverted cells (all deformations)", "measured": inverted, "target": "0", "met": inverted == 0},
            {"case": "errors", "measured": errors, "target": "0", "met": errors == 0},
            {"case": "passed after a recovery (information)",
             "measured": sum(bool(r.get("recovered_with")) for r in rows)},
            {"case": "with cells shaped by the design's own map (information)",
             "measured": sum(bool(r.get("by_design")) for r in rows)},
            {"case": "mesh_quality constraint, min over designs (default bound 0.3)",
             "measured": min((r["mesh_quality"] for r in rows if r.get("mesh_quality") is not None), default=None),
             "target": ">= 0.3",
             "met": all(r["mesh_quality"] >= 0.3 for r in rows if r.get("mesh_quality") is not None)},
            {"case": "RANS meshes: first-cell height after / before, farthest from 1 (wall layer)",
             "measured": max((abs(v - 1) for r in rows for v in r.get("first_cell") or ()), default=None),
             "target": "<= 0.005", "met": all(abs(v - 1) <= 0.005 for r in rows for v in r.get("first_cell") or ())},
            {"case": "RANS meshes: off-wall angle change, largest (degrees)",
             "measured": max((r["off_wall"] for r in rows if r.get("off_wall") is not None), default=None),
             "target": "< 0.5", "met": all(r["off_wall"] < 0.5 for r in rows if r.get("off_wall") is not None)}]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.bench_robustness",
                                 description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help=f"meshes {', '.join(QUICK_MESHES)}; "
                                                         f"designs {', '.join(QUICK_DESIGNS)}")
    ap.add_argument("--mesh", action="append", metavar="NAME", help="only this mesh (repeatable; see --list)")
    ap.add_argument("--design", action="append", metavar="NAME", help="only this design (repeatable)")
    ap.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                    help="override a design-file value for every run, e.g. volume.alpha=1.0")
    ap.add_argument("--work", type=Path, default=REPO / "out" / "robustness",
                    help="folder for generated meshes, design files and box caches")
    ap.add_argument("--json", metavar="FILE", type=Path, help="also write the rows as JSON")
    ap.add_argument("--compare", metavar="FILE", type=Path, nargs="+",
                    help="compare row by row with the rows of an earlier --json FILE (two files: compare "
                         "them and exit, nothing run)")
    ap.add_argument("--list", action="store_true", help="print the mesh and design names and exit")
    ap.add_argument("--multi", action="store_true", help="only the multi-component forms (wing + tail + fin, "
                                                         "wing on a body) under planform designs")
    args = ap.parse_args(argv)
    if args.compare and len(args.compare) > 2:
        ap.error("--compare takes one file (compared with this run) or two (compared with each other)")
    if args.compare and len(args.compare) == 2:
        lines = compare_rows(*(json.loads(f.read_text()) for f in args.compare))
        print("\n".join(lines) or "identical, row by row (the seconds left out)")
        return 1 if lines else 0
    if args.list:
        print("meshes: " + " ".join(MESHES))
        print("designs: " + " ".join(DESIGNS))
        return 0
    for kind, names, known in (("mesh", args.mesh, MESHES), ("design", args.design, DESIGNS)):
        for n in names or []:
            if n not in known:
                ap.error(f"unknown {kind} {n!r}; known: {', '.join(known)}")
    meshes = args.mesh or (QUICK_MESHES if args.quick else list(MESHES))
    designs = args.design or (QUICK_DESIGNS if args.quick else list(DESIGNS))
    t0 = time.perf_counter()
    rows = [] if args.multi else run_matrix(meshes, designs, work=args.work, overrides=args.overrides,
                                            echo=lambda s: print(s, flush=True))
    multi = [] if (args.mesh or args.design) else run_multi(work=args.work, echo=lambda s: print(s, flush=True))
    print()
    if rows:
        print(matrix_table(rows))
    if multi:
        print(matrix_table(multi))
        print(multi_summary(multi))
    rows = rows + multi
    print(f"({time.perf_counter() - t0:.0f} s; overrides: {' '.join(args.overrides) or 'none'})")
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1, default=str))
    if args.compare:
        lines = compare_rows(json.loads(args.compare[0].read_text()), json.loads(json.dumps(rows, default=str)))
        print(f"\nrow by row against {args.compare[0]}:\n" + ("\n".join(lines) or "identical (the seconds left out)"))
    refused = sum(r["status"] not in ("ok", "REFUSED") if r["mesh"].startswith("multi:") else r["status"] != "ok"
                  for r in rows)
    return 1 if refused else 0


if __name__ == "__main__":
    sys.exit(main())
