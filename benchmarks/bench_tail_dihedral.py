"""Tail dihedral on generated wing + tail + fin meshes: does the design's own map fold?

Usage (from the repository root; gmsh, the ``[test]`` extra, makes the meshes)::

    python -m benchmarks.bench_tail_dihedral                       # every aircraft, dihedral +-3, +-6, +-10
    python -m benchmarks.bench_tail_dihedral --case sample --dihedral 6 --json rows.json

Each aircraft is meshed once with :func:`ffdcli.testing.gmsh_wings.fluid_tets` (coarse tetrahedra,
symmetry plane y = 0) and each design changes only the tail's dihedral. A row gives, for the tail's
lattice:

- ``det min``/``det max``: ``det(dX'/dX)`` of the design's own map ``B @ P'`` on a 21^3 parametric grid
  (``det(J') / det(J)`` of the lattice's parametric derivatives). A fold would be a value <= 0; a
  dihedral is a shear, so it is 1;
- ``frozen``: root sections a body holds (a junction on the fuselage or on a fin);
- ``in lattice``, ``q map``: the tetrahedra whose nodes all lie inside the tail's lattice, and their
  worst scaled Jacobian when those nodes move by ``B @ P'`` alone (no warp);
- ``map inverted``: cells inverted by the gate's linearised map (nodes within 0.15 mean chords of the
  wall, moved by the map linearised at their nearest surface node: ``ffdcli.app.deformation.design_map``);
- ``first failed``: cells the gate refused after ``ffd deform``'s first attempt (the design's volume
  settings; 0 when it passed), and ``ok``, ``inverted``, ``recovered with``: the gate after the
  recovery attempts, and where its worst failing cell is.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from functools import partial
from pathlib import Path

import numpy as np
import yaml

from ffdcli.app.deformation import deform, design_map
from ffdcli.app.run import load_run
from ffdcli.design import load_design
from ffdcli.errors import InputError
from ffdcli.io.formats import write_mesh
from ffdcli.lattice.embedding import embed
from ffdcli.lattice.lattice import derivatives, evaluate
from ffdcli.mesh import CellBlock, Mesh
from ffdcli.quality.metrics import cell_quality
from ffdcli.testing.gmsh_wings import fluid_tets, loft, planform_sections
from ffdcli.testing.planform import Planform

REPO = Path(__file__).resolve().parents[1]
TITLE = "Tail dihedral on generated wing + tail + fin meshes (benchmarks/bench_tail_dihedral.py)"
NOTES = "Target: the design's own map never folds (det(dX'/dX) > 0 in the tail's lattice)."
DIHEDRALS = (3.0, -3.0, 6.0, -6.0, 10.0, -10.0)
WING = dict(semi_span=2.0, root_chord=1.0, taper=0.4, le_sweep_deg=25.0, root_airfoil="0012", sections="xz")
TAIL = dict(semi_span=1.0, root_chord=0.5, taper=0.6, le_sweep_deg=30.0, root_airfoil="0010", sections="xz",
            root_offset=(3.0, 0.0, 0.0))
FIN = dict(semi_span=0.7, root_chord=0.5, taper=0.6, le_sweep_deg=35.0, root_airfoil="0010", sections="xy",
           root_offset=(3.1, 0.6, 0.3))


def _part(kw: dict):
    return partial(loft, sections=planform_sections(Planform(**kw), [0.0, 1.0], n_chord=41))


def _fuselage(occ, r: float = 0.2) -> int:
    cyl = occ.addCylinder(-0.5, 0.0, 0.0, 4.1, 0.0, 0.0, r)
    (out, _) = occ.fuse([(3, cyl)], [(3, occ.addSphere(-0.5, 0.0, 0.0, r)), (3, occ.addSphere(3.6, 0.0, 0.0, r))])
    return out[0][1]


def aircraft(*, tail=None, fin=None, body=False, h=0.06, fin_component=True, sections=4) -> dict:
    """One generated aircraft: the solids, whether they are fused, whether the fin is a component of its
    own (else a wall: the body of the tail's junction when it touches it), the tail box's sections."""
    solids = {}
    if body:
        solids["fuselage"] = _fuselage
    solids["wing"] = _part({**WING, **({"root_offset": (0.6, 0.0, -0.05)} if body else {})})
    solids["htail"] = _part({**TAIL, **(tail or {})})
    if fin is not None:
        solids["vfin"] = _part({**FIN, **fin})
    return dict(solids=solids, h=h, fuse=body or not fin_component, sections=sections,
                fin_component=fin is not None and fin_component)


CASES = {
    "sample": aircraft(fin={}),                                   # the bundled sample's layout, coarser
    "no-fin": aircraft(),
    "coarse": aircraft(fin={}, h=0.1),
    "root-off-plane": aircraft(tail=dict(root_offset=(3.0, 0.04, 0.0)), fin={}),
    "tail-dihedral+5": aircraft(tail=dict(dihedral_deg=5.0), fin={}),
    "tail-anhedral-5": aircraft(tail=dict(dihedral_deg=-5.0, le_sweep_deg=40.0), fin={}),
    "tail-dihedral+8-fin-on-plane": aircraft(tail=dict(dihedral_deg=8.0, taper=0.4),
                                             fin=dict(root_offset=(3.05, 0.0, 0.08)), h=0.08),
    "fin-above-root": aircraft(fin=dict(root_offset=(3.05, 0.0, 0.06)), h=0.07),
    "fin-above-root-coarse": aircraft(fin=dict(root_offset=(3.0, 0.0, 0.04), root_chord=0.6), h=0.1),
    # a fin root 0.028 above the tail's upper surface at y = 0.3: a 6 degree dihedral lifts the tail 0.03
    # there, through the fin's root (the surfaces collide)
    "fin-just-above-tail": aircraft(fin=dict(root_offset=(3.1, 0.3, 0.05)), h=0.08),
    "root-on-fuselage": aircraft(body=True, fin={}, sections=8),
    "fin-on-root": aircraft(fin=dict(root_offset=(3.05, 0.0, 0.0), root_airfoil="0012"), fin_component=False,
                            sections=8),
    "t-tail": aircraft(tail=dict(root_offset=(3.25, 0.0, 0.7)),
                       fin=dict(root_offset=(3.0, 0.0, 0.0), root_chord=0.6, taper=0.8, le_sweep_deg=20.0,
                                root_airfoil="0014"), fin_component=False, sections=8),
}
QUICK = ("sample", "root-on-fuselage", "fin-on-root")


def mesh_path(name: str, work: Path) -> Path:
    """The aircraft's mesh, generated once into ``work``."""
    path = work / f"{name}.su2"
    if not path.exists():
        c = CASES[name]
        pts, tets, markers = fluid_tets(c["solids"], (-3.0, 0.0, -3.0), (7.0, 4.0, 3.0), symmetry_axis=1,
                                        h_solid=c["h"], h_edge=0.5 * c["h"], h_far=1.0, fuse=c["fuse"], name=name)
        work.mkdir(parents=True, exist_ok=True)
        write_mesh(Mesh(points=pts, dim=3, cells=[CellBlock("tetra", tets)],
                        markers={k: [CellBlock("triangle", v)] for k, v in markers.items()}), path)
    return path


def design_path(name: str, dihedral: float, work: Path) -> Path:
    c = CASES[name]
    comps = [{"name": "wing", "surface": "wing", "box": {"points": [5, 5, 2]}, "changes": [{"twist": {"tip": 0.0}}]},
             {"name": "htail", "surface": "htail", "box": {"points": [5, c["sections"], 2]},
              "changes": [{"dihedral": dihedral}]}]
    if c["fin_component"]:
        comps.append({"name": "vfin", "surface": "vfin", "box": {"points": [5, 4, 2]}, "changes": []})
    path = work / f"{name}_dihedral{dihedral:+g}.yaml"
    path.write_text(yaml.safe_dump({"mesh": str(mesh_path(name, work)), "components": comps,
                                    "output": {"mesh": str(work / "out.su2")}}, sort_keys=False))
    return path


def _map_figures(run, index: int) -> dict:
    """The tail's own map: its determinant on a grid, and the cells inside its lattice under it."""
    comp = run.components[index]
    P0, P1 = comp.P0, run.chain.lattices.forward(run.variables()[1])[index]
    t = np.linspace(0.0, 1.0, 21)
    grid = np.stack(np.meshgrid(t, t, t, indexing="ij"), -1).reshape(-1, 3)
    det = np.linalg.det(derivatives(comp.box.lattice(P1), grid)) / np.linalg.det(derivatives(comp.box.lattice(P0),
                                                                                                grid))
    mesh = run.prep.mesh
    X = mesh.points
    lo, hi = P0.reshape(-1, 3).min(axis=0), P0.reshape(-1, 3).max(axis=0)
    near = np.flatnonzero(np.all((X >= lo) & (X <= hi), axis=1))
    emb = embed(comp.box.lattice(P0), X[near])
    inside = np.zeros(len(X), dtype=bool)
    inside[near[emb.inside]] = True
    Xm = X.copy()
    Xm[near[emb.inside]] = evaluate(comp.box.lattice(P1), emb.params[emb.inside])
    tets = mesh.cells[0].data
    cells = [CellBlock("tetra", tets[inside[tets].all(axis=1)])]
    q = cell_quality(Xm, cells)
    return {"det min": float(det.min()), "det max": float(det.max()), "frozen": comp.frozen,
            "in lattice": len(q), "q map": float(q.min()) if len(q) else None}


def _linearised_inverted(run) -> int:
    """Cells (every node in the wall zone) inverted by the gate's linearised map."""
    mesh = run.prep.mesh
    tets = mesh.cells[0].data
    nodes = np.unique(tets)
    moved = design_map(run, run.chain.lattices.forward(run.variables()[1]))(nodes)
    good = np.isfinite(moved).all(axis=1)
    X = mesh.points.copy()
    X[nodes[good]] = moved[good]
    mapped = np.zeros(len(X), dtype=bool)
    mapped[nodes[good]] = True
    cells = [CellBlock("tetra", tets[mapped[tets].all(axis=1)])]
    return int((cell_quality(X, cells) <= 0).sum())


def run_one(name: str, dihedral: float, work: Path) -> dict:
    row = {"case": name, "dihedral": dihedral}
    t0 = time.perf_counter()
    try:
        run = load_run(load_design(design_path(name, dihedral, work)), cache_dir=work / "cache")
    except InputError as e:                             # a refused design is a row, not the end of the table
        return {**row, "error": str(e).splitlines()[0][:160]}
    tail = [c.name for c in run.components].index("htail")
    row.update(_map_figures(run, tail))
    row["map inverted"] = _linearised_inverted(run)
    res = deform(run)
    q = res.quality
    first = res.recovery[0]["failed"] if res.recovery else 0
    worst = [w for w in q.worst if w["failed"]][:1]
    row.update({"first failed": first, "ok": q.ok, "inverted": q.n_new_inverted, "min q": q.min_after,
                "recovered with": res.recovered_with,
                "worst at": np.round(worst[0]["centroid"], 3).tolist() if worst else None,
                "s": time.perf_counter() - t0})
    return row


def run_cases(names, dihedrals, work: Path, echo=None) -> list[dict]:
    rows = []
    for name in names:
        for d in dihedrals:
            rows.append(run_one(name, float(d), work))
            if echo:
                echo(json.dumps(rows[-1], default=str))
    return rows


def run(quick: bool = False) -> list[dict]:
    """Rows for ``python -m benchmarks`` (quick: three aircraft at +-6 degrees)."""
    names = QUICK if quick else list(CASES)
    return run_cases(names, (6.0, -6.0) if quick else DIHEDRALS, REPO / "out" / "tail_dihedral")


def summary(rows: list[dict]) -> list[dict]:
    done = [r for r in rows if "error" not in r]
    det = min((r["det min"] for r in done), default=None)
    return [{"case": f"{len(done)} tail dihedral designs: det(dX'/dX) of the map, min", "measured": det,
             "target": "> 0", "met": det is not None and det > 0},
            {"case": "cells inverted by the map B @ P' (inside the lattice)",
             "measured": sum(r["q map"] is not None and r["q map"] <= 0 for r in done), "target": "0",
             "met": all(r["q map"] is None or r["q map"] > 0 for r in done)},
            {"case": "refused by the gate after recovery (information)",
             "measured": sum(not r["ok"] for r in done)},
            {"case": "designs refused at load (information)", "measured": len(rows) - len(done)}]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.bench_tail_dihedral",
                                 description=__doc__.split("\n\n")[0])
    ap.add_argument("--case", action="append", choices=list(CASES), help="only this aircraft (repeatable)")
    ap.add_argument("--dihedral", action="append", type=float, help="only this tail dihedral change (repeatable)")
    ap.add_argument("--quick", action="store_true", help=f"aircraft {', '.join(QUICK)} at +-6 degrees")
    ap.add_argument("--work", type=Path, default=REPO / "out" / "tail_dihedral",
                    help="folder for the generated meshes, design files and box caches")
    ap.add_argument("--json", metavar="FILE", type=Path, help="also write the rows as JSON")
    args = ap.parse_args(argv)
    names = args.case or (list(QUICK) if args.quick else list(CASES))
    dihedrals = args.dihedral or ((6.0, -6.0) if args.quick else DIHEDRALS)
    rows = run_cases(names, dihedrals, args.work, echo=lambda s: print(s, flush=True))
    for r in summary(rows):
        print(f"{r['case']}: {r['measured']}" + (f" (target {r['target']})" if "target" in r else ""))
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1, default=str))
    return 0 if summary(rows)[0]["met"] and summary(rows)[1]["met"] else 1


if __name__ == "__main__":
    sys.exit(main())
