"""The meshes of ADODG Case 2 (RAE2822, RANS): SU2's own RAE2822 RANS mesh, copied from the shared data,
and ffd's C-meshes (:func:`ffdcli.testing.cmesh.cmesh`: a sharp trailing edge, the first cell for
y+ < 1 at Re 6.5e6, the far field 100 chords from the trailing edge, a conforming wake cut whose first
cell grows downstream, ``first cell + 1e-3 x`` at ``x`` chords behind the trailing edge).

Rebuild (from the repository root)::

    python -m benchmarks.adodg.case2_meshes --out out/adodg

=====================  ==========  =======  ========  =====================================
file                   around      wake     normal    first cell (chord)
=====================  ==========  =======  ========  =====================================
rae2822_su2.su2        SU2's mesh (13,937 points, hybrid, first cell ~1e-5)
rae2822_c0.su2         129         33       65        2e-6   (the CI test's coarse mesh)
rae2822_c1.su2         385         97       129       1e-6   (the finer mesh, ~75k points)
rae2822_s1.su2         385         97       129       1e-6   (the same on SU2's mesh's section)
=====================  ==========  =======  ========  =====================================

The airfoil: the RAE2822 coordinates of ``shared/data/airfoils/rae2822.dat`` (the UIUC database's
file, as shipped with AeroSandbox: both surfaces end at (1, 0), a sharp trailing edge already; a blunt
file is closed by :func:`ffdcli.testing.cmesh.close_trailing_edge`), resampled with a cubic spline.
SU2's mesh has a different RAE2822: the same thickness (to 2e-4 chord) but up to 0.16 % chord more
camber (at mid-chord); ``rae2822_s1`` is the C-mesh of SU2's section (its 192 wall nodes, chained in
Selig order), the finer mesh an optimum found on SU2's mesh is evaluated on.
"""

from __future__ import annotations

import argparse
import filecmp
import shutil
import sys
from pathlib import Path

import numpy as np

from ffdcli.io.formats import read_mesh, write_mesh
from ffdcli.testing.cmesh import cmesh, read_airfoil

ROOT = Path(__file__).resolve().parents[2]
SHARED = ROOT.parent / "shared" / "data"
AIRFOIL = SHARED / "airfoils" / "rae2822.dat"
SU2_MESH = SHARED / "su2" / "optimization_rans__steady_rae2822__mesh_RAE2822_turb.su2"
#: name: (points around, points along each side of the cut, points out, first cell in chords)
LEVELS = {"rae2822_c0": (129, 33, 65, 2e-6), "rae2822_c1": (385, 97, 129, 1e-6), "rae2822_s1": (385, 97, 129, 1e-6)}
FARFIELD = 100.0


def wall_loop(mesh, marker: str = "AIRFOIL") -> np.ndarray:
    """The node ids (n,) of a 2D mesh's closed wall ``marker`` in Selig order: the trailing edge (the
    node of largest x) first, then the upper surface, the leading edge and the lower surface (the loop
    runs counter-clockwise; the first node is not repeated at the end). Its line segments chained."""
    seg = np.concatenate([b.data for b in mesh.markers[marker]])
    nxt = dict(zip(seg[:, 0].tolist(), seg[:, 1].tolist()))
    start = int(seg[np.argmax(mesh.points[seg[:, 0], 0]), 0])
    loop = [start]
    while nxt[loop[-1]] != start:
        loop.append(nxt[loop[-1]])
    ids = np.asarray(loop, dtype=np.int64)
    xy = mesh.points[np.append(ids, start), :2]
    area = 0.5 * np.sum(xy[:-1, 0] * xy[1:, 1] - xy[1:, 0] * xy[:-1, 1])
    return ids if area > 0 else np.append(ids[:1], ids[1:][::-1])


def wall_section(mesh_path: Path, marker: str = "AIRFOIL") -> np.ndarray:
    """The wall of a 2D mesh as airfoil coordinates (n + 1, 2) in Selig order (trailing edge, the point
    of largest x, first and last; upper surface first): :func:`wall_loop`, closed."""
    mesh = read_mesh(mesh_path)
    ids = wall_loop(mesh, marker)
    return mesh.points[np.append(ids, ids[0]), :2]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("out/adodg"))
    ap.add_argument("--airfoil", type=Path, default=AIRFOIL)
    ap.add_argument("--levels", nargs="*", default=list(LEVELS), choices=list(LEVELS),
                    help="the C-meshes to generate besides SU2's mesh (none: --levels with no name)")
    args = ap.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    copy = args.out / "rae2822_su2.su2"
    if SU2_MESH.is_file():
        # never rewritten when it is already the same bytes: a running `ffd optimize` refuses a mesh
        # that changed on disk since it was read (measured: a second run of this command stopped one)
        if not (copy.is_file() and filecmp.cmp(SU2_MESH, copy, shallow=False)):
            shutil.copyfile(SU2_MESH, copy)
        print(f"{copy}: SU2's RAE2822 RANS mesh")
    else:
        print(f"note: {SU2_MESH} not found; SU2's mesh not copied", file=sys.stderr)
    sections = {"c": read_airfoil(args.airfoil), "s": wall_section(SU2_MESH) if SU2_MESH.is_file() else None}
    for name in args.levels:
        around, wake, normal, first = LEVELS[name]
        xy = sections[name.split("_")[1][0]]
        if xy is None:
            continue
        mesh = cmesh(xy, around, wake, normal, first, FARFIELD)
        write_mesh(mesh, args.out / f"{name}.su2")
        print(f"{args.out / (name + '.su2')}: {len(mesh.points):,} points, {around} around, {wake} along "
              f"each side of the cut, {normal} out, first cell {first:g} chord, far field {FARFIELD:g} chords")
    return 0


if __name__ == "__main__":
    sys.exit(main())
