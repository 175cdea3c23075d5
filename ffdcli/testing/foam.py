"""OpenFOAM cases for the tests and the demonstrations (fixtures, not the pipeline).

- :func:`write_msh2`: a mesh of cell blocks as a gmsh 2.2 ASCII file (physical groups = markers, and
  ``fluid`` for the cells), the input of OpenFOAM's ``gmshToFoam``;
- :func:`foam`: run an OpenFOAM utility in a case (``source /usr/share/openfoam/etc/bashrc`` first;
  :func:`have_openfoam` says whether it is installed);
- :func:`check_mesh`: checkMesh's figures parsed from its output (cells, negative volumes, face
  pyramid errors, maximum non-orthogonality, maximum skewness, failed checks);
- :func:`gmsh_case`: a generated gmsh wing (:mod:`ffdcli.testing.gmsh_wings`) converted by gmshToFoam, the
  wing patch made a ``wall``;
- :func:`potential_flow_files`: 0/, system/ of a potentialFoam run (free stream along the chord).
"""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import numpy as np

from ffdcli.testing.wings import naca4_thickness

#: Debian's OpenFOAM (ESI v1912): the environment every utility needs.
BASHRC = Path("/usr/share/openfoam/etc/bashrc")
#: OpenFOAM's tutorial cases (Debian's ``openfoam-examples``).
EXAMPLE_CASES = Path("/usr/share/doc/openfoam-examples/examples")
GMSH_TYPE = {"triangle": 2, "quad": 3, "tetra": 4, "hexahedron": 5, "wedge": 6, "pyramid": 7}


def have_openfoam() -> bool:
    """True when OpenFOAM's environment and checkMesh are installed."""
    return BASHRC.is_file() and shutil.which("bash") is not None and (
        Path("/usr/bin/checkMesh").exists() or _which_foam("checkMesh"))


def _which_foam(tool: str) -> bool:
    proc = subprocess.run(["bash", "-c", f"source {BASHRC} >/dev/null 2>&1; command -v {tool}"],
                          capture_output=True, text=True, check=False)
    return proc.returncode == 0 and bool(proc.stdout.strip())


def foam(tool: str, case: str | Path, *args: str, timeout: float = 1800) -> subprocess.CompletedProcess:
    """Run OpenFOAM's ``tool`` in ``case`` (stdout and stderr captured as text)."""
    cmd = f"source {BASHRC} >/dev/null 2>&1; {tool} " + " ".join(f"'{a}'" for a in args)
    return subprocess.run(["bash", "-c", cmd], cwd=case, capture_output=True, text=True, timeout=timeout,
                          check=False)


def check_mesh(case: str | Path) -> dict:
    """checkMesh's figures of ``case``: ``cells``, ``negative_volumes``, ``face_pyramid_errors``,
    ``max_non_orthogonality``, ``max_skewness``, ``failed_checks``, ``ok`` and the ``log``."""
    proc = foam("checkMesh", case, "-noFunctionObjects")
    log = proc.stdout + proc.stderr

    def num(pattern, default=None, cast=float):
        m = re.search(pattern, log)
        return cast(m.group(1)) if m else default

    return {
        "cells": num(r"\n\s*cells:\s+(\d+)", cast=int),
        "negative_volumes": num(r"Number of negative volume cells:\s*(\d+)", 0, int),
        "face_pyramid_errors": num(r"Error in face pyramids:\s*(\d+)", 0, int),
        "max_non_orthogonality": num(r"Mesh non-orthogonality Max:\s*([-0-9.eE+]+)"),
        "max_skewness": num(r"Max skewness = ([-0-9.eE+]+)"),
        "failed_checks": num(r"Failed (\d+) mesh checks", 0, int),
        "ok": "Mesh OK." in log,
        "returncode": proc.returncode,
        "log": log,
    }


def write_msh2(path: str | Path, mesh) -> Path:
    """``mesh`` (cell blocks and markers of triangles/quads) as a gmsh 2.2 ASCII file."""
    names = list(mesh.markers)
    lines = ["$MeshFormat", "2.2 0 8", "$EndMeshFormat", "$PhysicalNames", str(len(names) + 1)]
    lines += [f'2 {i + 1} "{n}"' for i, n in enumerate(names)] + [f'3 {len(names) + 1} "fluid"', "$EndPhysicalNames"]
    n = len(mesh.points)
    rows = np.column_stack([np.arange(1, n + 1), mesh.points])
    lines += ["$Nodes", str(n), ("%d %.17g %.17g %.17g\n" * n % tuple(rows.ravel().tolist())).rstrip("\n"), "$EndNodes"]
    elems = [(GMSH_TYPE[b.type], i + 1, b.data) for i, n_ in enumerate(names) for b in mesh.markers[n_]
             if b.type in GMSH_TYPE]
    elems += [(GMSH_TYPE[b.type], len(names) + 1, b.data) for b in mesh.cells]
    total = sum(len(d) for _, _, d in elems)
    lines += ["$Elements", str(total)]
    first = 1
    for gtype, tag, data in elems:
        k = data.shape[1]
        table = np.column_stack([np.arange(first, first + len(data)), np.full(len(data), gtype), np.full(len(data), 2),
                                 np.full(len(data), tag), np.full(len(data), tag), data + 1])
        lines.append((("%d " * (k + 4) + "%d\n") * len(data) % tuple(table.ravel().tolist())).rstrip("\n"))
        first += len(data)
    lines.append("$EndElements")
    Path(path).write_text("\n".join(lines) + "\n")
    return Path(path)


def gmsh_case(mesh, folder: str | Path, *, wall: str = "wing") -> Path:
    """The OpenFOAM case of ``mesh`` made by gmshToFoam in ``folder`` (created), ``wall`` a wall patch."""
    case = Path(folder)
    (case / "system").mkdir(parents=True, exist_ok=True)
    (case / "constant").mkdir(exist_ok=True)
    potential_flow_files(case, {})                    # gmshToFoam needs a controlDict
    write_msh2(case / "mesh.msh", mesh)
    proc = foam("gmshToFoam", case, "mesh.msh")
    if proc.returncode != 0:
        raise RuntimeError(f"gmshToFoam failed: {(proc.stdout + proc.stderr)[-2000:]}")
    boundary = case / "constant" / "polyMesh" / "boundary"
    text = boundary.read_text()
    text = re.sub(rf"(\n\s*{wall}\s*\{{\s*type\s+)patch;", r"\1wall;", text)
    boundary.write_text(text)
    return case


def potential_flow_files(case: str | Path, patches: dict[str, str], velocity=(1.0, 0.0, 0.0)) -> None:
    """``0/U``, ``0/p`` and ``system/`` for potentialFoam. ``patches``: {name: role}, role ``far``
    (free stream: fixed velocity, zero-gradient pressure... the reference is fixed on it), ``wall``
    or ``symmetry`` (slip, zero gradient), ``empty``."""
    case = Path(case)
    for d in ("0", "system"):
        (case / d).mkdir(parents=True, exist_ok=True)
    head = "FoamFile\n{{\n    version 2.0;\n    format ascii;\n    class {cls};\n    object {obj};\n}}\n"
    u = {"far": f"type fixedValue; value uniform ({velocity[0]} {velocity[1]} {velocity[2]});",
         "wall": "type slip;", "symmetry": "type slip;", "empty": "type empty;"}
    p = {"far": "type fixedValue; value uniform 0;", "wall": "type zeroGradient;",
         "symmetry": "type zeroGradient;", "empty": "type empty;"}
    for name, table, cls, dims, init in (("U", u, "volVectorField", "[0 1 -1 0 0 0 0]", "(0 0 0)"),
                                         ("p", p, "volScalarField", "[0 2 -2 0 0 0 0]", "0")):
        body = "".join(f"    {k}\n    {{\n        {table[r]}\n    }}\n" for k, r in patches.items())
        text = (head.format(cls=cls, obj=name) + f"dimensions {dims};\ninternalField uniform {init};\n"
                f"boundaryField\n{{\n{body}}}\n")
        (case / "0" / name).write_text(text)
    (case / "system" / "controlDict").write_text(head.format(cls="dictionary", obj="controlDict") + """
application potentialFoam; startFrom startTime; startTime 0; stopAt endTime; endTime 1; deltaT 1;
writeControl timeStep; writeInterval 1; writeFormat ascii; writePrecision 12; writeCompression off;
timeFormat general; timePrecision 6; runTimeModifiable false;
""")
    (case / "system" / "fvSchemes").write_text(head.format(cls="dictionary", obj="fvSchemes") + """
ddtSchemes { default steadyState; }
gradSchemes { default Gauss linear; }
divSchemes { default none; div(phi,U) bounded Gauss linearUpwind grad(U); div(div(phi,U)) Gauss linear; }
laplacianSchemes { default Gauss linear corrected; }
interpolationSchemes { default linear; }
snGradSchemes { default corrected; }
""")
    (case / "system" / "fvSolution").write_text(head.format(cls="dictionary", obj="fvSolution") + """
solvers
{
    Phi { solver GAMG; smoother DIC; tolerance 1e-06; relTol 0.01; }
    p { solver GAMG; smoother DIC; tolerance 1e-06; relTol 0.01; }
}
potentialFlow { nNonOrthogonalCorrectors 3; }
""")


def wing_block_mesh(case: str | Path, *, span: float = 2.0, radius: float = 6.0, n_seg: int = 16,
                    n_radial: int = 24, n_span: int = 8, grading: float = 40.0, code: str = "0012") -> Path:
    """``system/blockMeshDict`` of a hexahedral O-grid around a NACA wing of unit chord along x,
    thickness y, extruded along z from 0 (patch ``symmetry``) to ``span`` (``side``): four blocks from
    the airfoil (trailing edge, upper surface at 30 % chord, leading edge, lower surface) to a circle
    of ``radius`` (``farfield``), cells graded towards the wing (``wing``, a wall). Run blockMesh
    on it (:func:`foam`)."""
    case = Path(case)
    potential_flow_files(case, {})
    xs = [1.0, 0.3, 0.0, 0.3]
    ys = [0.0, float(naca4_thickness(code, np.array([0.3]))[0]), 0.0, -float(naca4_thickness(code, np.array([0.3]))[0])]
    ang = [0.0, 0.5 * np.pi, np.pi, 1.5 * np.pi]
    outer = [(0.5 + radius * np.cos(a), radius * np.sin(a)) for a in ang]
    verts = [(x, y, z) for z in (0.0, span) for x, y in list(zip(xs, ys, strict=True)) + outer]

    def v(ring: int, k: int, top: int) -> int:          # ring 0 airfoil, 1 circle
        return top * 8 + ring * 4 + k % 4

    def airfoil_between(k: int, z: float) -> str:
        sign = 1.0 if k in (0, 1) else -1.0
        a, b = xs[k], xs[(k + 1) % 4]
        x = np.linspace(a, b, 40)[1:-1]
        y = sign * naca4_thickness(code, x)
        return " ".join(f"({xi:.12g} {yi:.12g} {z:.12g})" for xi, yi in zip(x, y, strict=True))

    blocks, edges, faces = [], [], {"wing": [], "farfield": [], "symmetry": [], "side": []}
    for k in range(4):
        hexa = [v(0, k, 0), v(1, k, 0), v(1, k + 1, 0), v(0, k + 1, 0),
                v(0, k, 1), v(1, k, 1), v(1, k + 1, 1), v(0, k + 1, 1)]
        blocks.append(f"    hex ({' '.join(map(str, hexa))}) ({n_radial} {n_seg} {n_span}) "
                      f"simpleGrading ({grading} 1 1)")
        for top, z in ((0, 0.0), (1, span)):
            edges.append(f"    polyLine {v(0, k, top)} {v(0, k + 1, top)} ({airfoil_between(k, z)})")
            mid = 0.5 * (ang[k] + (ang[(k + 1) % 4] if k < 3 else 2 * np.pi))
            edges.append(f"    arc {v(1, k, top)} {v(1, k + 1, top)} ({0.5 + radius * np.cos(mid):.12g} "
                         f"{radius * np.sin(mid):.12g} {z:.12g})")
        faces["wing"].append((v(0, k, 0), v(0, k + 1, 0), v(0, k + 1, 1), v(0, k, 1)))
        faces["farfield"].append((v(1, k, 0), v(1, k, 1), v(1, k + 1, 1), v(1, k + 1, 0)))
        faces["symmetry"].append(tuple(hexa[:4]))
        faces["side"].append(tuple(hexa[4:]))
    bnd = "".join(f"    {n}\n    {{\n        type {'wall' if n == 'wing' else 'patch'};\n        faces\n        (\n"
                  + "".join(f"            ({' '.join(map(str, f))})\n" for f in fs) + "        );\n    }\n"
                  for n, fs in faces.items())
    text = ("FoamFile\n{\n    version 2.0;\n    format ascii;\n    class dictionary;\n    object blockMeshDict;\n}\n"
            "scale 1;\nvertices\n(\n" + "".join(f"    ({x:.12g} {y:.12g} {z:.12g})\n" for x, y, z in verts)
            + ");\nblocks\n(\n" + "\n".join(blocks) + "\n);\nedges\n(\n" + "\n".join(edges)
            + "\n);\nboundary\n(\n" + bnd + ");\n")
    (case / "system" / "blockMeshDict").write_text(text)
    return case
