"""OpenFOAM cases end to end: ffd's figures against checkMesh's, before and after ``ffd deform``, and
a solver run on every deformed mesh (needs OpenFOAM: Debian's ``openfoam``; skipped without it).

Meshes: OpenFOAM's own ``incompressible/simpleFoam/airFoil2D`` (hexahedra, one cell thick, a
``walls`` patch), a hexahedral O-grid around a wing made by ``blockMesh``
(:func:`ffdcli.testing.foam.wing_block_mesh`), and two gmsh wings converted by ``gmshToFoam``
(tetrahedra; tetrahedra with prism layers; :mod:`ffdcli.testing.gmsh_wings`). Designs: a twist, a
sweep and a shape change (airFoil2D, being 2D: a twist and a shape change). For each: the cell
count, negative volumes, maximum non-orthogonality and maximum skewness of ``ffd deform``'s report
(the input and the written mesh) and of checkMesh on both; whether checkMesh passes the written
mesh (or fails no more checks than the input); whether potentialFoam (airFoil2D: 200 simpleFoam
iterations) runs; the largest difference between the wall patch's points in the written case and
the deformed surface of ffd's Python API (:class:`ffdcli.api.DesignModel`).

    python -m benchmarks.bench_openfoam            (or make bench)
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

TITLE = "OpenFOAM cases: ffd's figures against checkMesh's, deformed cases run by OpenFOAM"
REPO = Path(__file__).resolve().parents[1]
EXAMPLES = Path("/usr/share/doc/openfoam-examples/examples")
SHAPE = "  - shape: {upper: [0, 0.01, 0.015, 0.01, 0.005, 0], lower: [0, -0.005, -0.01, -0.005, 0, 0]}\n"
DESIGNS_3D = {"twist": "  - twist: {tip: 5}\n", "sweep": "  - sweep: 5\n", "shape": SHAPE}
DESIGNS_2D = {"twist": "  - twist: [3, 3]\n", "shape": SHAPE}
TOL_DEG, TOL_SKEW = 0.1, 1e-6


def _ffd(*args, cwd) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    return subprocess.run([sys.executable, "-m", "ffdcli", *map(str, args)], cwd=cwd, capture_output=True,
                          text=True, env=env, check=False)


def _figures(poly: dict) -> dict:
    return {"cells": poly["cells"], "negative_volumes": poly["negative_volumes"],
            "max_non_orthogonality": poly["max_non_orthogonality"], "max_skewness": poly["max_skewness"]}


def _agree(ffd: dict, foam: dict) -> bool:
    return (ffd["cells"] == foam["cells"] and ffd["negative_volumes"] == foam["negative_volumes"]
            and abs(ffd["max_non_orthogonality"] - foam["max_non_orthogonality"]) <= TOL_DEG
            and abs(ffd["max_skewness"] - foam["max_skewness"]) <= max(TOL_SKEW, 5e-6 * foam["max_skewness"]))


def cases(tmp: Path, quick: bool) -> dict[str, tuple[Path, str, dict, str]]:
    """{name: (case folder, wall patch, designs, solver)} made in ``tmp``."""
    from ffdcli.testing import foam
    from ffdcli.testing.gmsh_wings import CASES, smaller, wing_volume_mesh

    roles = {"wing": "wall", "farfield": "far", "symmetry": "symmetry", "side": "symmetry"}
    out = {}
    src = EXAMPLES / "incompressible" / "simpleFoam" / "airFoil2D"
    if src.is_dir():
        shutil.copytree(src, tmp / "airFoil2D")
        out["airFoil2D (example, hexahedra)"] = (tmp / "airFoil2D", "walls", DESIGNS_2D, "simpleFoam")
    block = foam.wing_block_mesh(tmp / "block_wing", n_seg=8 if quick else 16, n_radial=12 if quick else 24)
    foam.foam("blockMesh", block)
    foam.potential_flow_files(block, roles)
    out["blockMesh wing (hexahedra)"] = (block, "wing", DESIGNS_3D, "potentialFoam")
    for name, label in (("rect_z", "gmshToFoam wing (tetrahedra)"),
                        ("rect_z_bl_ff5", "gmshToFoam wing (tetrahedra, 6 prism layers)")):
        case = foam.gmsh_case(wing_volume_mesh(smaller(CASES[name], 2.0)), tmp / name)
        foam.potential_flow_files(case, {k: v for k, v in roles.items() if k != "side"})
        out[label] = (case, "wing", DESIGNS_3D, "potentialFoam")
    return out


def _solve(case: Path, solver: str) -> bool:
    from ffdcli.testing import foam

    if solver == "simpleFoam":
        cd = case / "system" / "controlDict"
        text = re.sub(r"endTime\s+[^;]+;", "endTime 200;", cd.read_text())
        cd.write_text(re.sub(r"writeInterval\s+[^;]+;", "writeInterval 200;", text))
        proc = foam.foam("simpleFoam", case)
    else:
        proc = foam.foam("potentialFoam", case, "-noFunctionObjects")
    log = proc.stdout + proc.stderr
    return proc.returncode == 0 and "\nEnd" in log and "FOAM FATAL" not in log


def run_case(label: str, case: Path, wall: str, designs: dict, solver: str, work: Path) -> list[dict]:
    """Rows of one mesh: the input, then one per design."""
    from ffdcli.api import DesignModel
    from ffdcli.io.formats import read_mesh
    from ffdcli.testing import foam

    rows = []
    before_foam = foam.check_mesh(case)
    # a 2D case: two sections along the extrusion, and the volume motion without the tree's
    # approximation (exact sums are symmetric, so the front and back planes move alike)
    sections = ("box: {points: [6, 2, 2], sections: xy}\nvolume: {tolerance: 0}\n" if designs is DESIGNS_2D
                else "box: {points: [6, 6, 2]}\n")
    for dname, change in designs.items():
        design = work / f"{case.name}_{dname}.yaml"
        out = work / f"{case.name}_{dname}"
        design.write_text(f"mesh: {case}\nsurface: {wall}\n{sections}changes:\n{change}output:\n  mesh: {out}\n")
        proc = _ffd("deform", design, "--json", cwd=work)
        if proc.returncode != 0:
            why = proc.stderr.strip()[-200:]
            rows.append({"mesh": label, "design": dname, "ffd": f"exit {proc.returncode}: {why}"})
            continue
        rep = json.loads(proc.stdout)["quality"]["polyhedral"]
        if not rows:
            ffd_in = _figures(rep["before"])
            rows.append({"mesh": label, "design": "(input)", **{f"ffd_{k}": v for k, v in ffd_in.items()},
                         **{f"checkMesh_{k}": before_foam[k] for k in ffd_in},
                         "agree": _agree(ffd_in, before_foam), "checkMesh_ok": before_foam["ok"],
                         "failed_checks": before_foam["failed_checks"]})
        after_foam = foam.check_mesh(out)
        ffd_out = _figures(rep["after"])
        model = DesignModel.from_file(design)
        written = read_mesh(out)
        wall_diff = float(np.abs(written.points[model.surface_ids] - model.surface_points()).max())
        rows.append({"mesh": label, "design": dname, **{f"ffd_{k}": v for k, v in ffd_out.items()},
                     **{f"checkMesh_{k}": after_foam[k] for k in ffd_out}, "agree": _agree(ffd_out, after_foam),
                     "checkMesh_ok": after_foam["ok"] or after_foam["failed_checks"] <= before_foam["failed_checks"],
                     "failed_checks": after_foam["failed_checks"], "solver": solver, "solver_ran": _solve(out, solver),
                     "wall_vs_ffd": wall_diff})
    return rows


def run(quick: bool = False) -> list[dict]:
    from ffdcli.testing.foam import have_openfoam

    if not have_openfoam():
        return [{"mesh": "(OpenFOAM is not installed: apt-get install openfoam openfoam-examples)"}]
    rows = []
    with tempfile.TemporaryDirectory(prefix="ffd-bench-foam-") as tmp:
        tmp = Path(tmp)
        work = tmp / "work"
        work.mkdir()
        for label, (case, wall, designs, solver) in cases(tmp, quick).items():
            rows += run_case(label, case, wall, designs, solver, work)
    return rows


def summary(rows: list[dict]) -> list[dict]:
    out = []
    for r in rows:
        if "ffd_cells" not in r:
            out.append({"case": f"{r['mesh']} {r.get('design', '')}", "measured": r.get("ffd", ""), "target": "",
                        "pyGeo reference": ""})
            continue
        meas = (f"{r['ffd_cells']} cells, {r['ffd_negative_volumes']} negative, non-orth "
                f"{r['ffd_max_non_orthogonality']:.4f} (checkMesh {r['checkMesh_max_non_orthogonality']:.4f}), "
                f"skew {r['ffd_max_skewness']:.6f} ({r['checkMesh_max_skewness']:.6f}); "
                f"checkMesh {'OK' if r['checkMesh_ok'] else 'FAILED'}")
        if "solver" in r:
            meas += f"; {r['solver']} {'ran' if r['solver_ran'] else 'FAILED'}; wall - ffd {r['wall_vs_ffd']:.1e}"
        out.append({"case": f"{r['mesh']}: {r['design']}", "measured": meas,
                    "target": "agree 0.1 deg / 1e-6; wall 1e-12", "pyGeo reference": ""})
    return out


if __name__ == "__main__":
    from benchmarks.__main__ import markdown_table

    print(markdown_table(run("--quick" in sys.argv)))
